"""Pull-in threshold of Fig. 4: the smallest pulse amplitude that snaps the beams down.

Two estimates of the same model: the *dynamic* threshold (a rectangular pulse on all four beams
with the sphere on; pulled in when a beam's rear end reaches the ground plate during the pulse)
and the *quasi-static* one (the voltage where the static equilibrium branch from rest ends).
"""

import dataclasses
from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import NDArray

from msg_defs.device import VOLTAGE_LIMIT_V
from sphere_sim.integrate.solve import Trajectory, simulate
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.assembly import Model, assemble
from sphere_sim.model.initial_state import RestError, polish_equilibrium, rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.programme import Pulse, PulseProgramme
from sphere_sim.model.scene import Scene

PULSE_WIDTH_S = 5e-3  # Fig. 4
BRACKET_V = (20.0, VOLTAGE_LIMIT_V)
RESOLUTION_V = 0.1
QUASI_STATIC_STEP_V = 1.0
PULL_IN_GAP_M = 0.0  # rear gap at or below which the beam counts as pulled in


@dataclasses.dataclass(frozen=True)
class PullInResult:
    dynamic_v: float
    quasi_static_v: float
    n_simulations: int


def all_beams_pulse(model: Model, amplitude_v: float,
                    width_s: float = PULSE_WIDTH_S) -> PulseProgramme:
    return PulseProgramme(tuple(Pulse(b, amplitude_v, 0.0, width_s) for b in model.beams))


def pulls_in(model: Model, x_rest: NDArray[np.float64], amplitude_v: float,
             width_s: float = PULSE_WIDTH_S, rtol: float = DEFAULT_RTOL) -> bool:
    """Whether a pulse of ``amplitude_v`` on all beams brings a rear end onto the ground."""
    traj = simulate(model, x_rest, width_s, all_beams_pulse(model, amplitude_v, width_s),
                    rtol=rtol, sample_period_s=width_s / 200)
    rear = np.stack([model.ground_gaps(traj.x[:, i])[0] for i in range(traj.t.size)])
    return bool(np.min(rear) <= PULL_IN_GAP_M)


def dynamic_threshold(model: Model, x_rest: NDArray[np.float64],
                      bracket_v: tuple[float, float] = BRACKET_V,
                      resolution_v: float = RESOLUTION_V,
                      progress: Callable[[float, float], object] | None = None,
                      ) -> tuple[float, int]:
    """Bisection on the pulse amplitude to ``resolution_v``; returns (threshold_v, n_runs)."""
    lo, hi = bracket_v
    runs = 0
    if pulls_in(model, x_rest, lo) or not pulls_in(model, x_rest, hi):
        raise ValueError(f'pull-in threshold not bracketed by {bracket_v} V')
    runs += 2
    while hi - lo > resolution_v:
        mid = 0.5 * (lo + hi)
        runs += 1
        if pulls_in(model, x_rest, mid):
            hi = mid
        else:
            lo = mid
        if progress is not None:
            progress(lo, hi)
    return 0.5 * (lo + hi), runs


def static_state(model: Model, x_guess: NDArray[np.float64],
                 voltage_v: float) -> NDArray[np.float64]:
    """Static equilibrium under a constant voltage on all beams, from a nearby guess."""
    return polish_equilibrium(model, x_guess, np.full(model.n_beams, voltage_v))


def quasi_static_threshold(model: Model, x_rest: NDArray[np.float64],
                           resolution_v: float = RESOLUTION_V,
                           step_v: float = QUASI_STATIC_STEP_V,
                           max_v: float = BRACKET_V[1]) -> float:
    """End of the static branch from rest, by continuation in the voltage.

    The step halves whenever Newton fails or the beams are pulled in, which happens both at
    the fold (pull-in) and where a contact engages; the branch is followed through contact
    changes and ends at the fold, located to ``resolution_v``.
    """
    x, v_ok = x_rest, 0.0
    while step_v >= 0.5 * resolution_v:
        v = v_ok + step_v
        if v > max_v:
            raise ValueError(f'no static pull-in up to {max_v} V')
        try:
            y = static_state(model, x, v)
            ok = np.min(model.ground_gaps(y)[0]) > PULL_IN_GAP_M
        except RestError:
            ok = False
        if ok:
            x, v_ok = y, v
        else:
            step_v *= 0.5
    return v_ok + step_v


def pull_in(scene: Scene, params: ParameterSet | None = None,
            progress: Callable[[float, float], object] | None = None) -> PullInResult:
    """Both thresholds for the scene's beams and sphere."""
    model = assemble(scene, params)
    x_rest = rest_state(model)
    dynamic, runs = dynamic_threshold(model, x_rest, progress=progress)
    static = quasi_static_threshold(model, x_rest)
    return PullInResult(dynamic, static, runs)


def pulse_sweep(model: Model, x_rest: NDArray[np.float64], voltages_v: Iterable[float],
                width_s: float = PULSE_WIDTH_S, after_s: float = 10e-3, rtol: float = DEFAULT_RTOL,
                progress: Callable[[float], object] | None = None) -> list[Trajectory]:
    """Fig. 4: trajectories of a pulse on all beams for each amplitude, list of Trajectory."""
    out = []
    for v in voltages_v:
        out.append(simulate(model, x_rest, width_s + after_s, all_beams_pulse(model, v, width_s),
                            rtol=rtol, sample_period_s=2e-5))
        if progress is not None:
            progress(v)
    return out
