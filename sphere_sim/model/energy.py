"""Energy bookkeeping of a trajectory: mechanical energy and electrical work done on it.

With the voltage V_k of beam k held between programme edges, the electrostatic force does the
work V_k^2/2 (C_k(t) - C_k(t_edge)) on the mechanism. Without losses, E_mech - W_el is constant;
with damping, contact losses and friction it can only fall.
"""

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class EnergyBalance:
    """Energies along a trajectory, each shape (n_times,), in J."""

    t: np.ndarray
    mechanical_j: np.ndarray
    electrical_work_j: np.ndarray

    @property
    def surplus_j(self):
        """E_mech(t) - E_mech(0) - W_el(t): zero without losses, never positive with them."""
        return self.mechanical_j - self.mechanical_j[0] - self.electrical_work_j


def energy_balance(traj):
    """Mechanical energy and cumulative electrical work at the trajectory's samples."""
    model = traj.model
    mech = np.array([model.mechanical_energy(traj.x[:, i]) for i in range(traj.t.size)])
    work = np.zeros(traj.t.size)
    if model.scene.effects.electrostatics:
        caps = np.array([model.capacitances(traj.x[:, i]) for i in range(traj.t.size)])
        half_v2 = 0.5 * traj.u**2  # (n_beams, n_times): the voltage of the segment after t_i
        # Work over [t_i, t_{i+1}] uses the voltage of that interval, which traj.u[:, i+1] holds.
        step = np.sum(half_v2[:, 1:] * (caps[1:] - caps[:-1]).T, axis=0)
        work[1:] = np.cumsum(step)
    return EnergyBalance(traj.t, mech, work)
