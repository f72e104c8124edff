"""Validation figures of the continuous model (rest, symmetry, energy), shared by CLI and tests."""

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from msg_defs.device import BEAM_COUNT
from sphere_sim.integrate.solve import simulate
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.assembly import Model, rest_model
from sphere_sim.model.energy import energy_balance
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.programme import Pulse, PulseProgramme
from sphere_sim.model.rotations import angle_between

LOSSLESS = dict(damping=False, contact_losses=False, viscous=False, coulomb=False,
                stribeck=False)
MIRROR_XZ_BEAMS = {1: 1, 2: 4, 3: 3, 4: 2}  # mirroring at the x-z plane swaps beams 2 and 4
MIRROR_XZ_NORMAL = np.array([[1.0], [-1.0], [1.0]])


def all_beams(amplitudes_v: Sequence[float], width_s: float,
              start_s: float = 0.0) -> PulseProgramme:
    return PulseProgramme(tuple(Pulse(b, float(a), start_s, width_s)
                                for b, a in zip((1, 2, 3, 4), amplitudes_v, strict=True) if a))


def tilt_rad(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    """Angle of each normal (shape (3, n)) from the vertical."""
    return np.arccos(np.clip(normals[2], -1.0, 1.0))


@dataclasses.dataclass(frozen=True)
class RestReport:
    force_imbalance: float  # largest, relative to the weight per tip
    front_gaps_m: NDArray[np.float64]
    rear_gaps_m: NDArray[np.float64]
    tilt_drift_rad: float
    position_drift_m: float
    duration_s: float


def force_imbalance(model: Model, x: NDArray[np.float64]) -> float:
    """Largest force (or torque over beam length) left on a beam or the sphere's centre at
    ``x`` with no voltage, relative to the weight per tip."""
    dxdt = model.rhs(0.0, x, np.zeros(model.n_beams))
    b, s = model.params.beam, model.params.sphere
    n, o = model.n_beams, model.sphere_offset
    forces = np.concatenate([dxdt[2 * n:4 * n:2] * b.mass_kg,
                             dxdt[2 * n + 1:4 * n:2] * b.inertia_suspension_kg_m2 / b.length_m,
                             dxdt[o + 7:o + 10] * s.mass_kg])
    return float(np.max(np.abs(forces)) / (s.mass_kg * model.params.gravity_m_per_s2 / 4.0))


def rest_report(params: ParameterSet | None = None, duration_s: float = 1.0) -> RestReport:
    """Rest equilibrium and how far the sphere moves from it in ``duration_s``."""
    model = rest_model(params)
    x0 = rest_state(model)
    traj = simulate(model, x0, duration_s, PulseProgramme(), rtol=1e-7,
                    sample_period_s=duration_s / 10)
    o = model.sphere_offset
    rear, front = model.ground_gaps(x0)
    return RestReport(
        force_imbalance=force_imbalance(model, x0),
        front_gaps_m=front, rear_gaps_m=rear,
        tilt_drift_rad=float(np.max(tilt_rad(traj.surface_normal()))),
        position_drift_m=float(np.max(np.abs(traj.x[o:o + 3] - x0[o:o + 3, None]))),
        duration_s=duration_s)


def symmetric_pulse_tilt(amplitude_v: float = 50.0, width_s: float = 5e-3,
                         duration_s: float = 0.02,
                         params: ParameterSet | None = None) -> tuple[float, float]:
    """Largest tilt (rad) after equal pulses on all beams from rest, and the sphere's lift (m)."""
    model = rest_model(params)
    x0 = rest_state(model)
    programme = all_beams([amplitude_v] * BEAM_COUNT, width_s)
    traj = simulate(model, x0, duration_s, programme, rtol=1e-7, sample_period_s=1e-4)
    lift = float(np.max(traj.x[model.sphere_offset + 2] - x0[model.sphere_offset + 2]))
    return float(np.max(tilt_rad(traj.surface_normal()))), lift


def mirror_mismatch(amplitudes_v: Sequence[float] = (35, 35, 80, 80), width_s: float = 4e-3,
                    duration_s: float = 0.01,
                    params: ParameterSet | None = None) -> tuple[float, float]:
    """Largest normal difference between a programme's run and its mirror image's, mirrored back.

    Returns (mismatch, largest normal x-y excursion) so that a zero motion cannot pass.
    """
    model = rest_model(params)
    x0 = rest_state(model)
    programme = all_beams(amplitudes_v, width_s)
    a = simulate(model, x0, duration_s, programme, rtol=1e-8, sample_period_s=5e-4)
    b = simulate(model, x0, duration_s, programme.mirrored(MIRROR_XZ_BEAMS), rtol=1e-8,
                 sample_period_s=5e-4)
    na, nb = a.surface_normal(), b.surface_normal()
    return float(np.max(np.abs(nb - na * MIRROR_XZ_NORMAL))), float(np.max(np.abs(na[:2])))


def lossless_drop(lift_m: float = 5e-6, duration_s: float = 2.5e-3,
                  spin_rad_per_s: Sequence[float] = (50.0, -30.0, 10.0),
                  params: ParameterSet | None = None) -> tuple[float, int]:
    """Energy surplus of a spinning sphere dropped onto the tips without any loss.

    Returns (largest |surplus| relative to m g lift, number of impacts).
    """
    model = rest_model(params, **LOSSLESS)
    x0 = rest_state(model)
    o = model.sphere_offset
    x0[o + 2] += lift_m
    x0[o + 10:o + 13] = spin_rad_per_s
    traj = simulate(model, x0, duration_s, PulseProgramme(), rtol=1e-8, sample_period_s=1e-5)
    gaps = np.array([model.sphere_gaps(traj.x[:, i]).min() for i in range(traj.t.size)])
    touching = gaps < 0
    impacts = int(np.count_nonzero(touching[1:] & ~touching[:-1]))
    drop = model.params.sphere.mass_kg * model.params.gravity_m_per_s2 * lift_m
    return float(np.max(np.abs(energy_balance(traj).surplus_j)) / drop), impacts


def lossless_pulse(amplitudes_v: Sequence[float] = (40, 40, 45, 45), width_s: float = 0.6e-3,
                   duration_s: float = 1e-3,
                   params: ParameterSet | None = None) -> tuple[float, float]:
    """Energy surplus relative to the electrical work without losses; and the final work (J)."""
    model = rest_model(params, **LOSSLESS)
    traj = simulate(model, rest_state(model), duration_s, all_beams(amplitudes_v, width_s),
                    rtol=1e-8, sample_period_s=1e-5)
    balance = energy_balance(traj)
    work = np.max(np.abs(balance.electrical_work_j))
    return float(np.max(np.abs(balance.surplus_j)) / work), float(balance.electrical_work_j[-1])


def lossy_kick(amplitudes_v: Sequence[float] = (35, 35, 80, 80), width_s: float = 3e-3,
               duration_s: float = 0.01, params: ParameterSet | None = None) -> tuple[float, float]:
    """With all losses: (largest surplus, final surplus) relative to the largest electrical work.

    The mechanical energy includes what the friction bristles hold (``Model.bristle_energy``).
    """
    model = rest_model(params)
    traj = simulate(model, rest_state(model), duration_s, all_beams(amplitudes_v, width_s),
                    rtol=1e-8, sample_period_s=1e-5)
    balance = energy_balance(traj)
    work = np.max(np.abs(balance.electrical_work_j))
    return float(np.max(balance.surplus_j) / work), float(balance.surplus_j[-1] / work)


def tilted_creep_rate(tilt_deg: float = 20.0, duration_s: float = 1.0,
                      params: ParameterSet | None = None) -> float:
    """How fast a tilted sphere released at rest turns back towards zero tilt (rad/s).

    The centre of gravity below the full-sphere centre gives a restoring torque of
    m g d_cog sin(tilt). A friction that sticks holds it (the ``paper`` and ``stiction``
    readings: the rate is zero to the solver's tolerance); a regularised one (tanh(|v|/v_c), no
    stiction) only slows the return. The rate is the tilt lost over ``duration_s`` divided by it.
    """
    model = rest_model(params)
    x0 = rest_state(model, (tilt_deg, 0.0, 0.0))
    traj = simulate(model, x0, duration_s, PulseProgramme(), rtol=DEFAULT_RTOL,
                    sample_period_s=duration_s / 4)
    tilt = tilt_rad(traj.surface_normal())
    return float((tilt[0] - tilt[-1]) / duration_s)



TILTED_REST_DEG = (5.0, 10.0, 20.0, 35.0)


def tilted_rests(tilts_deg: Sequence[float] = TILTED_REST_DEG,
                 params: ParameterSet | None = None) -> list[tuple[float, float, float]]:
    """The solved rest at each tilt (about x): (tilt, largest force imbalance relative to the
    weight per tip, how far the normal ended from the tilt asked for in rad). ``rest_state``
    raises RestError where it finds none."""
    model = rest_model(params)
    out = []
    for tilt in tilts_deg:
        x = rest_state(model, (tilt, 0.0, 0.0))
        asked = np.array([0.0, -math.sin(math.radians(tilt)), math.cos(math.radians(tilt))])
        normal = model.surface_normal(x)
        out.append((tilt, force_imbalance(model, x), angle_between(asked, normal)))
    return out
