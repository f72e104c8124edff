"""Energy bookkeeping of a trajectory: mechanical energy and electrical work done on it.

With the voltage V_k of beam k held between programme edges, the electrostatic force does the
work V_k^2/2 (C_k(t) - C_k(t_edge)) on the mechanism. Without losses, E_mech - W_el is constant;
with damping, contact losses and friction it can only fall.
"""

import dataclasses
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from sphere_sim.model.assembly import Model


@dataclasses.dataclass(frozen=True)
class EnergyBalance:
    """Energies along a trajectory, each shape (n_times,), in J."""

    t: NDArray[np.float64]
    mechanical_j: NDArray[np.float64]
    electrical_work_j: NDArray[np.float64]

    @property
    def surplus_j(self) -> NDArray[np.float64]:
        """E_mech(t) - E_mech(0) - W_el(t): zero without losses, never positive with them."""
        return self.mechanical_j - self.mechanical_j[0] - self.electrical_work_j


class SampledTrajectory(Protocol):
    """What :func:`energy_balance` reads of a trajectory (``sphere_sim.integrate``'s, which this
    room may not import): the model, times (n_times,), states (n_states, n_times) and voltages
    (n_beams, n_times)."""

    @property
    def model(self) -> Model: ...
    @property
    def t(self) -> NDArray[np.float64]: ...
    @property
    def x(self) -> NDArray[np.float64]: ...
    @property
    def u(self) -> NDArray[np.float64]: ...


def energy_balance(traj: SampledTrajectory) -> EnergyBalance:
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
