"""Running a scene end to end and summarising the outcome in the paper's terms."""

import dataclasses
from typing import Any

import numpy as np

from sphere_sim.integrate.solve import Trajectory, check_sample_grid, simulate
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import initial_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.rotations import quat_to_cardan
from sphere_sim.model.scene import Scene, load_scene


@dataclasses.dataclass(frozen=True)
class KickOutcome:
    """Final sphere state of a run, in the paper's interface quantities.

    ``cardan_deg`` are alpha, beta, gamma (eq. A1); ``surface_normal`` the inertial unit normal
    of the flat face; ``x_sn``/``y_sn`` its first two components (eq. 53); ``rotation_deg`` the
    angle between the initial and final normals; ``direction_deg`` the polar angle of the
    normal's displacement in the x-y plane.
    """

    scene: str
    parameter_set: str
    duration_s: float
    cardan_deg: tuple[float, ...]
    surface_normal: tuple[float, ...]
    rotation_deg: float
    direction_deg: float
    sphere_position_m: tuple[float, ...]
    max_tilt_change_deg: float
    airborne_s: float
    wall_time_s: float

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def run_scene(scene: Scene, params: ParameterSet | None = None, rtol: float = DEFAULT_RTOL,
              sample_period_s: float = 1e-4, method: str = 'fast') -> Trajectory:
    """Simulate a scene from its initial state for its duration; returns the Trajectory."""
    model = assemble(scene, params)
    # Before the initial state's solve: a run too long to sample is refused at once.
    check_sample_grid(model, scene.duration_s, sample_period_s)
    x0 = initial_state(model)
    return simulate(model, x0, scene.duration_s, rtol=rtol, sample_period_s=sample_period_s,
                    method=method)


def summarize(traj: Trajectory) -> KickOutcome:
    """The :class:`KickOutcome` of a trajectory with a sphere."""
    model = traj.model
    if not model.has_sphere:
        raise ValueError('the scene has no sphere to summarise')
    normals = traj.surface_normal()
    n0, n1 = normals[:, 0], normals[:, -1]
    rotation = np.degrees(np.arccos(np.clip(n0 @ n1, -1.0, 1.0)))
    d = n1[:2] - n0[:2]
    direction = float(np.degrees(np.arctan2(d[1], d[0]))) if np.any(d) else 0.0
    change = np.degrees(np.arccos(np.clip(n0 @ normals, -1.0, 1.0)))
    gaps = np.array([model.sphere_gaps(traj.x[:, i]).min() for i in range(traj.t.size)])
    dt = np.diff(traj.t)
    airborne = float(np.sum(dt[(gaps[1:] > 0) & (gaps[:-1] > 0)]))
    o = model.sphere_offset
    return KickOutcome(
        scene=model.scene.name,
        parameter_set=model.params.name,
        duration_s=float(traj.t[-1] - traj.t[0]),
        cardan_deg=tuple(float(a) for a in np.degrees(quat_to_cardan(traj.x[o + 3:o + 7, -1]))),
        surface_normal=tuple(float(c) for c in n1),
        rotation_deg=float(rotation),
        direction_deg=direction,
        sphere_position_m=tuple(float(c) for c in traj.x[o:o + 3, -1]),
        max_tilt_change_deg=float(np.max(change)),
        airborne_s=airborne,
        wall_time_s=traj.stats.wall_time_s,
    )


@dataclasses.dataclass(frozen=True)
class BeamsOutcome:
    """What a run of beams without a sphere shows: each beam's tip height at the end and its
    largest excursion from the start (m), and the smallest electrode gap reached (m; near
    zero means the beam was pulled in)."""

    scene: str
    parameter_set: str
    duration_s: float
    beams: tuple[int, ...]
    final_tip_change_m: tuple[float, ...]
    max_tip_excursion_m: tuple[float, ...]
    min_electrode_gap_m: tuple[float, ...]
    wall_time_s: float

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def summarize_beams(traj: Trajectory) -> BeamsOutcome:
    """The :class:`BeamsOutcome` of any trajectory (the beams are in every scene)."""
    model = traj.model
    tip_z = np.stack([model.tip_positions(traj.x[:, i])[:, 2] for i in range(traj.t.size)],
                     axis=1)
    change = tip_z - tip_z[:, :1]
    gaps = np.stack([model.electrode_gaps(traj.x[:, i]) for i in range(traj.t.size)], axis=1)
    return BeamsOutcome(
        scene=model.scene.name,
        parameter_set=model.params.name,
        duration_s=float(traj.t[-1] - traj.t[0]),
        beams=tuple(int(b) for b in model.beams),
        final_tip_change_m=tuple(float(c) for c in change[:, -1]),
        max_tip_excursion_m=tuple(float(c) for c in np.max(np.abs(change), axis=1)),
        min_electrode_gap_m=tuple(float(g) for g in np.min(gaps, axis=1)),
        wall_time_s=traj.stats.wall_time_s,
    )


LITERAL_KICK_SCENE = 'literal_kick'


def literal_kick(params: ParameterSet | None = None, rtol: float = DEFAULT_RTOL) -> KickOutcome:
    """The :class:`KickOutcome` of the paper's kick read literally (35 V on beams 1-2, 80 V on
    beams 3-4, §4.1; the ``literal_kick`` scene) on ``params`` (default: the scene's set)."""
    scene = load_scene(LITERAL_KICK_SCENE)
    return summarize(run_scene(scene, scene.parameters(params), rtol=rtol))
