"""Characteristics of a kick design: rotation width against intensity (Fig. 10) and the voltage
offsets that keep a kick on its nominal direction from tilted states (Fig. 8).

Both measure the *kick effect*: the resting normal's displacement over the kick window. The
contacts' friction holds a resting sphere (docs/parameters.md, "Friction that holds"), so the
displacement is the kick's alone: there is no drift to subtract.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import math
from collections.abc import Callable, Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from msg_defs.device import KICK_WINDOW_S
from sphere_sim.kicks.design import KickDesign, cardan_of_normal, simulate_kick
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD, normal_from_cardan, normal_from_xy
from sphere_sim.kicks.lookup_table import TableSpec
from sphere_sim.kicks.offset_lookup import ON_AXIS_TOL, compensating_beam, side_of_axis
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.scene import load_scene

CHARACTERISTIC_RTOL = 1e-6
# The offset search stops once the kick's direction is this close to the nominal one; below it
# the direction is set by the interpolation of the table rather than by the offset.
OFFSET_DIRECTION_TOL_RAD = math.radians(1.0)
# Offsets scanned on the compensating beam before refining. The low pair sits at 35 V and the
# threshold with the sphere on is near 42.6 V, so the scan is dense around +7.6 V.
OFFSET_SCAN_V = (-20.0, -10.0, -5.0, 5.0, 7.5, 10.0, 20.0, 45.0)
OFFSET_REFINEMENTS = 3
# Where those regula falsi steps leave the kick more than the tolerance off, the search goes on
# by bisection, for at most this many kicks more, in the bracket of all the offsets tried so far
# whose end is nearest the nominal direction. Far out in the cone the error against the offset
# is steep and not monotone once V1 passes its own pull-in (at (0.48, 0.24): -6.6 deg at 30 V,
# +37 deg at 35 V, -0.1 deg at 40 V, +10.7 deg at 42.2 V), and three regula falsi steps from
# the scan's 20-45 V bracket stopped 10.7 deg off (docs/motion_primitives.md).
OFFSET_BISECTIONS = 12
# A bracket narrower than this straddles a step of the error (a beam snapping down), not a root.
OFFSET_STEP_V = 0.02


@dataclasses.dataclass(frozen=True)
class KickEffect:
    """The kick's own displacement of the resting normal.

    Attributes
    ----------
    displacement : ndarray, shape (2,)
        x-y displacement of the unit normal over the kick window.
    """

    displacement: NDArray[np.float64]

    @property
    def width_rad(self) -> float:
        """Rotation width: the length of the displacement (small-angle, rad)."""
        return float(np.hypot(*self.displacement))

    @property
    def direction_rad(self) -> float:
        return float(math.atan2(self.displacement[1], self.displacement[0]))


class KickBench:
    """A model and cached rest states for many kicks of one parameter set (one per process).

    ``params`` is a :class:`~sphere_sim.model.parameters.ParameterSet`, None for the default.
    """

    def __init__(self, params: ParameterSet | None = None, window_s: float = KICK_WINDOW_S,
                 rtol: float = CHARACTERISTIC_RTOL) -> None:
        self.model = assemble(load_scene('rest'), params)
        self.window_s = window_s
        self.rtol = rtol
        self._rest: dict[tuple[float, ...], NDArray[np.float64]] = {}

    def rest(self, normal: NDArray[np.float64]) -> NDArray[np.float64]:
        key = tuple(np.round(normal, 12))
        if key not in self._rest:
            self._rest[key] = rest_state(self.model, cardan_of_normal(normal))
        return self._rest[key]

    def final_normal(self, normal: NDArray[np.float64],
                     programme: PulseProgramme) -> NDArray[np.float64]:
        result, _ = simulate_kick(self.model, normal, programme, window_s=self.window_s,
                                  rtol=self.rtol, x_rest=self.rest(normal))
        return result.normal

    def effect(self, normal: NDArray[np.float64], design: KickDesign, intensity: float,
               offset_v: float = 0.0, offset_beam: int | None = None) -> KickEffect:
        """The :class:`KickEffect` of ``design`` at ``intensity`` from rest at ``normal``."""
        moved = self.final_normal(normal, design.programme(intensity, offset_v, offset_beam))
        return KickEffect(moved[:2] - normal[:2])


@dataclasses.dataclass(frozen=True)
class WidthCurve:
    """Rotation width (rad) over intensities for one initial tilt."""

    alpha_deg: float
    intensities: NDArray[np.float64]
    width_rad: NDArray[np.float64]
    direction_rad: NDArray[np.float64]


def rotation_width_curves(design: KickDesign | None = None,
                          alphas_deg: Iterable[float] = (0.0, 20.0, 35.0),
                          intensities: ArrayLike | None = None,
                          params: ParameterSet | None = None,
                          progress: Callable[[], object] | None = None) -> list[WidthCurve]:
    """Fig. 10: rotation width against u_K for initial tilts alpha (about x).

    Returns
    -------
    list of WidthCurve
    """
    design = KickDesign() if design is None else design
    intensities = np.linspace(0.0, 1.0, 11) if intensities is None else np.asarray(intensities)
    bench = KickBench(params)
    curves = []
    for alpha in alphas_deg:
        normal = normal_from_cardan(alpha)
        effects = []
        for u in intensities:
            effects.append(bench.effect(normal, design, float(u)))
            if progress is not None:
                progress()
        curves.append(WidthCurve(float(alpha), intensities,
                                 np.array([e.width_rad for e in effects]),
                                 np.array([e.direction_rad for e in effects])))
    return curves


def direction_error(effect: KickEffect, design: KickDesign) -> float:
    return math.remainder(effect.direction_rad - design.direction_rad, 2.0 * math.pi)


@dataclasses.dataclass(frozen=True)
class OffsetSolution:
    x_sn: float
    y_sn: float
    beam: int
    offset_v: float
    direction_error_rad: float  # remaining after the search
    direction_error_without_rad: float
    width_rad: float
    evaluations: int  # kicks simulated by the search


def find_offset(error_of_offset: Callable[[float], float], candidates_v: Iterable[float],
                tol_rad: float = OFFSET_DIRECTION_TOL_RAD,
                refinements: int = OFFSET_REFINEMENTS,
                bisections: int = OFFSET_BISECTIONS) -> tuple[float, float, int]:
    """Offset whose kick goes closest to the nominal direction: a scan, regula falsi, then
    bisection where regula falsi stalls.

    The error is not monotone in the offset (an offset above the pull-in threshold turns the
    low beam into a kicking one), so a scan over ``candidates_v`` finds the sign changes first;
    the bracket around the best scanned point is then refined by regula falsi. If that ends
    more than ``tol_rad`` off, up to ``bisections`` more offsets are tried, each the middle of
    the sign change, among all the offsets tried so far, whose end is nearest zero (brackets
    narrower than :data:`OFFSET_STEP_V` are steps, not roots, and are left alone). A search
    that regula falsi finishes is the same with or without the bisections.

    Parameters
    ----------
    error_of_offset : callable
        Offset (V) -> signed direction error (rad), in (-pi, pi].
    candidates_v : sequence of float
        Offsets to scan; 0 is always included.

    Returns
    -------
    (offset_v, error_rad, evaluations)
    """
    points = [(v, error_of_offset(v)) for v in sorted({0.0, *map(float, candidates_v)})]
    evaluations = len(points)
    best = min(points, key=lambda p: abs(p[1]))
    brackets = [(a, b) for a, b in itertools.pairwise(points)
                if a[1] * b[1] < 0.0 and abs(a[1] - b[1]) < math.pi]  # not a wrap at +-pi
    if abs(best[1]) <= tol_rad or not brackets:
        return best[0], best[1], evaluations
    (va, ea), (vb, eb) = min(brackets, key=lambda ab: min(abs(ab[0][1]), abs(ab[1][1])))
    for _ in range(refinements):
        v = vb - eb * (vb - va) / (eb - ea)
        e = error_of_offset(v)
        evaluations += 1
        best = min(best, (v, e), key=lambda p: abs(p[1]))
        if abs(e) <= tol_rad:
            break
        if e * ea < 0.0:
            vb, eb = v, e
        else:
            va, ea = v, e
        points.append((v, e))
    for _ in range(bisections if abs(best[1]) > tol_rad else 0):
        points.sort()
        brackets = [(a, b) for a, b in itertools.pairwise(points)
                    if a[1] * b[1] < 0.0 and abs(a[1] - b[1]) < math.pi
                    and b[0] - a[0] > OFFSET_STEP_V]
        if not brackets:
            break
        (va, ea), (vb, eb) = min(brackets, key=lambda ab: min(abs(ab[0][1]), abs(ab[1][1])))
        v = 0.5 * (va + vb)
        e = error_of_offset(v)
        evaluations += 1
        points.append((v, e))
        best = min(best, (v, e), key=lambda p: abs(p[1]))
        if abs(e) <= tol_rad:
            break
    return best[0], best[1], evaluations


def _offset_job(
        args: tuple[ParameterSet | None, KickDesign, float, float, float]) -> OffsetSolution:
    params, design, intensity, x_sn, y_sn = args
    bench = _bench(params)
    normal = normal_from_xy(x_sn, y_sn)
    beam = compensating_beam(design, upper_right=True)
    high = design.voltage_limit_v - design.low_v
    candidates = [v for v in OFFSET_SCAN_V if -design.low_v <= v <= high]

    effects: dict[float, KickEffect] = {}

    def effect(offset_v: float) -> KickEffect:
        if offset_v not in effects:
            effects[offset_v] = bench.effect(normal, design, intensity, offset_v, beam)
        return effects[offset_v]

    def error(offset_v: float) -> float:
        return direction_error(effect(offset_v), design)

    error_at_zero = error(0.0)
    offset_v, residual, evaluations = find_offset(error, candidates)
    return OffsetSolution(x_sn, y_sn, beam, offset_v, residual, error_at_zero,
                          effect(offset_v).width_rad, evaluations)


_BENCHES: dict[ParameterSet | None, KickBench] = {}


def _bench(params: ParameterSet | None) -> KickBench:
    if params not in _BENCHES:
        _BENCHES[params] = KickBench(params)
    return _BENCHES[params]


def offset_grid(grid_step: float, cone_half_angle_rad: float) -> list[tuple[float, float]]:
    """(x_sn, y_sn) nodes inside the cone."""
    half = math.floor(math.sin(cone_half_angle_rad) / grid_step)
    axis = grid_step * np.arange(-half, half + 1)
    return [(float(x), float(y)) for x in axis for y in axis
            if math.hypot(x, y) <= math.sin(cone_half_angle_rad) + 1e-12]


def upper_right_nodes(design: KickDesign, grid_step: float,
                      cone_half_angle_rad: float) -> list[tuple[float, float]]:
    """The grid nodes of the upper-right half-space of the kick's axis (and on it): the lower
    left half is their mirror image (Fig. 7)."""
    return [(x, y) for x, y in offset_grid(grid_step, cone_half_angle_rad)
            if side_of_axis(design.direction_rad, x, y) >= -ON_AXIS_TOL]


def voltage_offsets(design: KickDesign | None = None, grid_step: float = TableSpec.grid_step,
                    cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD, intensity: float = 1.0,
                    params: ParameterSet | None = None, workers: int = 1,
                    progress: Callable[[], object] | None = None,
                    reuse: Iterable[OffsetSolution] = ()) -> list[OffsetSolution]:
    """Fig. 8: the offset on the upper-right half's compensating beam (§4.1's V1) for every
    grid state of that half.

    ``reuse`` holds solutions of an earlier search of the same design, parameters, intensity
    and grid: those that ended within :data:`OFFSET_DIRECTION_TOL_RAD` are taken, not searched
    again (:func:`find_offset` takes the same path for them today), and only the others are
    searched. The caller vouches that they were searched for the same kick.

    Returns
    -------
    list of OffsetSolution
    """
    design = KickDesign() if design is None else design
    nodes = upper_right_nodes(design, grid_step, cone_half_angle_rad)
    kept = {(round(s.x_sn, 9), round(s.y_sn, 9)): s for s in reuse
            if abs(s.direction_error_rad) <= OFFSET_DIRECTION_TOL_RAD}
    jobs = [(params, design, intensity, x, y) for x, y in nodes
            if (round(x, 9), round(y, 9)) not in kept]
    searched = {}
    if workers > 1:
        with concurrent.futures.ProcessPoolExecutor(max_workers=workers) as pool:
            for solution in pool.map(_offset_job, jobs):
                searched[(round(solution.x_sn, 9), round(solution.y_sn, 9))] = solution
                if progress is not None:
                    progress()
    else:
        for job in jobs:
            solution = _offset_job(job)
            searched[(round(solution.x_sn, 9), round(solution.y_sn, 9))] = solution
            if progress is not None:
                progress()
    return [kept.get(key) or searched[key]
            for key in ((round(x, 9), round(y, 9)) for x, y in nodes)]
