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
from sphere_sim.integrate.solve import simulate
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
# The offsets are searched on half the table's grid step. Between nodes the offset's effect is
# not linear in the volts: over 307 states of a 0.02 grid on the lower right of the half cone,
# the full kick strayed more than 5 deg from 55 with the offsets on the table's own step and
# from 31 on half of it (22 with the two branches kept apart; docs/motion_primitives.md).
OFFSET_GRID_STEP = 0.5 * TableSpec.grid_step
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
# The lowest zero crossing: where the search ends on a root at least two of these above the
# scanned offset below it, the error is sampled at this step from that offset up to one step
# short of the root, and the first sign change found there is refined and taken instead, unless
# the error keeps its sign from there up to the root (the root's own crossing). Near the cone's
# edge the scan's 20-45 V bracket holds up to three roots: a low branch (V1 pulled in, the kick
# 0.4-0.85 deg wide) at 31-34 V and a high one (0.17-0.30 deg wide) at 40-42 V, the kick collapsing
# between them (at (0.48, 0.24): -6.6 deg at 30 V, +2.9 at 32, +37 at 35, -9.9 at 39, -0.1 at
# 40). The search had put (0.48, 0.24), (0.48, 0.32), (0.48, 0.40), (0.40, 0.48) and
# (0.56, 0.24) on the high branch (40.0-41.9 V) and their neighbours on the low one (31.0-33.3
# V), and the table's bilinear offset between them (38.35 V at (0.589, 0.216)) sent the full
# kick 40 deg off. The lobe between the branches is several volts wide (at (0.56, 0.24):
# -1.4 deg at 32.5 V, +35 at 35, +14.6 at 37.5), so a 1 V step sees it. With the rule those
# five moved to 31.5-34.1 V and every other node kept its offset.
OFFSET_LOWEST_ROOT_STEP_V = 1.0
# A sign change below a root within the tolerance is the root's own crossing unless the error
# turns back between them; sampled there at more than this times the larger of the root's error
# and the tolerance, it has (lowest_crossing).
OWN_CROSSING_FACTOR = 2.0
# Whether the compensating beam's tip pushes the sphere until that beam's rear lands (the
# offsets' two branches, :meth:`KickBench.tip_pushes`) is read off samples this far apart. Where
# the tip loses the sphere and strikes it again as the rear lands (at (0.48, -0.24), 13.4 V:
# off from 0.95 to 1.17 ms), it is off for about 0.2 ms.
TIP_CONTACT_SAMPLE_S = 2e-5
# A tip that leaves the sphere no earlier than this before its beam's rear lands has pushed it
# through the stroke. Measured at (0.48, -0.24), (0.48, -0.16), (0.40, -0.16), (0.30, 0.30)
# and (0, 0.24): pushing tips leave 0-0.02 ms before the landing; released ones, and those that
# strike again, 0.22-0.42 ms before it.
TIP_RELEASE_MARGIN_S = 1e-4


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

    def tip_pushes(self, normal: NDArray[np.float64], design: KickDesign, intensity: float,
                   offset_v: float, beam: int) -> bool:
        """Whether ``beam``'s tip stays on the sphere until the beam's rear lands, within its
        pulse: the branch of the offsets on which that beam pushes the sphere through its whole
        stroke.

        Its pull-in races the sphere, which the high pair lifts away from it. Below the race's
        voltage the tip loses the sphere before the rear lands; just above, it loses it and
        strikes it again as the rear lands; well above, it keeps it (docs/motion_primitives.md,
        "Two branches of the offset").
        """
        programme = design.programme(intensity, offset_v, beam)
        pulse = next(p for p in programme.pulses if p.beam == beam)
        traj = simulate(self.model, self.rest(normal), pulse.end_s, programme, rtol=self.rtol,
                        sample_period_s=TIP_CONTACT_SAMPLE_S)
        k = self.model.beams.index(beam)
        rear = np.array([self.model.ground_gaps(traj.x[:, i])[0, k] for i in range(traj.t.size)])
        landed = np.flatnonzero(rear <= 0.0)
        if not landed.size:
            return False
        before = traj.t < traj.t[landed[0]] - TIP_RELEASE_MARGIN_S
        tip = np.array([self.model.sphere_gaps(traj.x[:, i])[k]
                        for i in np.flatnonzero(before)])
        return bool(np.all(tip <= 0.0))


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
    # Whether the compensating beam's tip pushes the sphere until its rear lands, at offset_v
    # (KickBench.tip_pushes); None in a file of a search that did not measure it.
    pushes: bool | None = None


def find_offset(error_of_offset: Callable[[float], float], candidates_v: Iterable[float],
                tol_rad: float = OFFSET_DIRECTION_TOL_RAD,
                refinements: int = OFFSET_REFINEMENTS,
                bisections: int = OFFSET_BISECTIONS) -> tuple[float, float, int]:
    """Offset whose kick goes closest to the nominal direction: a scan, regula falsi, then
    bisection where regula falsi stalls, then the lowest zero crossing of the bracket.

    The error is not monotone in the offset (an offset above the pull-in threshold turns the
    low beam into a kicking one), so a scan over ``candidates_v`` finds the sign changes first;
    the bracket around the best scanned point is then refined by regula falsi. If that ends
    more than ``tol_rad`` off, up to ``bisections`` more offsets are tried, each the middle of
    the sign change, among all the offsets tried so far, whose end is nearest zero (brackets
    narrower than :data:`OFFSET_STEP_V` are steps, not roots, and are left alone). A search
    that regula falsi finishes is the same with or without the bisections. The offset found,
    within ``tol_rad`` or not, is then checked for a lower root within it in its scanned
    bracket (:func:`lowest_crossing`); where there is none, the result is the same as without
    the check. (At (0.2, 0.6) the bisections ended at 36.37 V, 1.34 deg off with a kick 0.27 deg
    wide; the crossing below lies at 31.5 V, 0.86 deg wide.)

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
    scanned = list(points)
    evaluations = len(points)
    best = min(points, key=lambda p: abs(p[1]))
    brackets = [(a, b) for a, b in itertools.pairwise(points)
                if a[1] * b[1] < 0.0 and abs(a[1] - b[1]) < math.pi]  # not a wrap at +-pi
    if abs(best[1]) <= tol_rad or not brackets:
        return best[0], best[1], evaluations
    (va, ea), (vb, eb) = min(brackets, key=lambda ab: min(abs(ab[0][1]), abs(ab[1][1])))
    best, evaluations = _refine(error_of_offset, points, (va, ea), (vb, eb), best, evaluations,
                                tol_rad, refinements, bisections)
    below = [p for p in scanned if p[0] < best[0]]
    if not below:
        return best[0], best[1], evaluations
    lower, extra = lowest_crossing(error_of_offset, below[-1], best, tol_rad, refinements,
                                   bisections)
    return (*(best if lower is None else lower), evaluations + extra)


def _refine(error_of_offset: Callable[[float], float], points: list[tuple[float, float]],
            a: tuple[float, float], b: tuple[float, float], best: tuple[float, float],
            evaluations: int, tol_rad: float, refinements: int,
            bisections: int) -> tuple[tuple[float, float], int]:
    """Regula falsi in the bracket (a, b), then bisections among ``points`` (appended to)."""
    (va, ea), (vb, eb) = a, b
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
        brackets = [(p, q) for p, q in itertools.pairwise(points)
                    if p[1] * q[1] < 0.0 and abs(p[1] - q[1]) < math.pi
                    and q[0] - p[0] > OFFSET_STEP_V]
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
    return best, evaluations


def lowest_crossing(error_of_offset: Callable[[float], float], scanned: tuple[float, float],
                    root: tuple[float, float], tol_rad: float = OFFSET_DIRECTION_TOL_RAD,
                    refinements: int = OFFSET_REFINEMENTS, bisections: int = OFFSET_BISECTIONS
                    ) -> tuple[tuple[float, float] | None, int]:
    """A root of the error below ``root`` = (offset, error) and above ``scanned``, the scanned
    (offset, error) next below it: the lowest zero crossing a
    :data:`OFFSET_LOWEST_ROOT_STEP_V` sampling sees, refined as :func:`find_offset` refines,
    or None where there is none.

    The sampling stops one step short of ``root``. Its first sign change is ``root``'s own
    crossing (the error within the tolerance but not yet at zero) unless the error turns back
    between them: changes sign again at ``root`` itself or at a sampled offset above the sign
    change, or lies there further from zero than :data:`OWN_CROSSING_FACTOR` times the larger
    of ``root``'s error and ``tol_rad`` (a hump: ``root`` is then a near miss of zero, not a
    crossing, as at (0.32, 0.44): +2.8 deg at 32 V, +23.7 deg at 34.5 V, +0.46 deg at the
    root, 36.42 V, whose kick is a quarter as wide as the crossing's at 31.6 V). A sign
    change that refines to no root within ``tol_rad`` is a step of the error (a beam
    snapping down), and None. The rule keeps neighbouring nodes of the cone's edge on one
    branch of the offsets (the low one, where the kick is widest; see
    :data:`OFFSET_LOWEST_ROOT_STEP_V`).

    Returns
    -------
    ((offset_v, error_rad) or None, evaluations)
    """
    step = OFFSET_LOWEST_ROOT_STEP_V
    grid: list[float] = []
    while scanned[0] + (len(grid) + 1) * step <= root[0] - step:
        grid.append(scanned[0] + (len(grid) + 1) * step)
    previous = scanned
    evaluations = 0
    for n, v in enumerate(grid):
        e = error_of_offset(v)
        evaluations += 1
        if previous[1] * e < 0.0 and abs(previous[1] - e) < math.pi:
            # Between its own crossing and the root the error runs from zero to the root's;
            # one further from zero than twice that (or the tolerance) rose and came back.
            hump = OWN_CROSSING_FACTOR * max(abs(root[1]), tol_rad)
            turned = e * root[1] < 0.0 or abs(e) > hump
            for w in grid[n + 1:] if not turned else ():
                evaluations += 1
                ew = error_of_offset(w)
                if e * ew < 0.0 or abs(ew) > hump:
                    turned = True
                    break
            if not turned:
                return None, evaluations
            points = [previous, (v, e)]
            best = min(points, key=lambda p: abs(p[1]))
            best, evaluations = _refine(error_of_offset, points, previous, (v, e), best,
                                        evaluations, tol_rad, refinements, bisections)
            return (best if abs(best[1]) <= tol_rad else None), evaluations
        previous = (v, e)
    return None, evaluations


def _scan_candidates(design: KickDesign) -> list[float]:
    high = design.voltage_limit_v - design.low_v
    return [v for v in OFFSET_SCAN_V if -design.low_v <= v <= high]


def _offset_job(args: tuple[ParameterSet | None, KickDesign, float, float, float,
                            OffsetSolution | None]) -> OffsetSolution:
    """Search the offset of one state, or, given an earlier ``solution`` that ended within the
    tolerance, check it for a lower zero crossing only: that is the path a new search takes
    after reaching the same root, so the solution is kept as it is where there is none."""
    params, design, intensity, x_sn, y_sn, solution = args
    bench = _bench(params)
    normal = normal_from_xy(x_sn, y_sn)
    beam = compensating_beam(design, upper_right=True)
    candidates = _scan_candidates(design)

    effects: dict[float, KickEffect] = {}

    def effect(offset_v: float) -> KickEffect:
        if offset_v not in effects:
            effects[offset_v] = bench.effect(normal, design, intensity, offset_v, beam)
        return effects[offset_v]

    def error(offset_v: float) -> float:
        return direction_error(effect(offset_v), design)

    def with_branch(found: OffsetSolution) -> OffsetSolution:
        if found.pushes is not None:
            return found
        pushes = bench.tip_pushes(normal, design, intensity, found.offset_v, beam)
        return dataclasses.replace(found, pushes=pushes)

    if solution is not None:
        scanned = sorted({0.0, *candidates})
        below = [v for v in scanned if v < solution.offset_v]
        if (solution.offset_v in scanned or not below
                or solution.offset_v - below[-1] < 2.0 * OFFSET_LOWEST_ROOT_STEP_V):
            return with_branch(solution)  # a scanned offset, or a root with no room below it
        lower, extra = lowest_crossing(error, (below[-1], error(below[-1])),
                                       (solution.offset_v, solution.direction_error_rad))
        if lower is None:
            return with_branch(solution)
        return with_branch(dataclasses.replace(
            solution, offset_v=lower[0], direction_error_rad=lower[1],
            width_rad=effect(lower[0]).width_rad, evaluations=solution.evaluations + extra,
            pushes=None))
    error_at_zero = error(0.0)
    offset_v, residual, evaluations = find_offset(error, candidates)
    return with_branch(OffsetSolution(x_sn, y_sn, beam, offset_v, residual, error_at_zero,
                                      effect(offset_v).width_rad, evaluations))


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


def voltage_offsets(design: KickDesign | None = None, grid_step: float = OFFSET_GRID_STEP,
                    cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD, intensity: float = 1.0,
                    params: ParameterSet | None = None, workers: int = 1,
                    progress: Callable[[], object] | None = None,
                    reuse: Iterable[OffsetSolution] = ()) -> list[OffsetSolution]:
    """Fig. 8: the offset on the upper-right half's compensating beam (§4.1's V1) for every
    grid state of that half.

    ``reuse`` holds solutions of an earlier search of the same design, parameters, intensity
    and grid: those that ended within :data:`OFFSET_DIRECTION_TOL_RAD` are not searched again
    (:func:`find_offset` takes the same path for them today) but only checked for a lower zero
    crossing (:func:`lowest_crossing`), and taken as they are where there is none; only the
    others are searched. The caller vouches that they were searched for the same kick.

    Returns
    -------
    list of OffsetSolution
    """
    design = KickDesign() if design is None else design
    nodes = upper_right_nodes(design, grid_step, cone_half_angle_rad)
    kept = {(round(s.x_sn, 9), round(s.y_sn, 9)): s for s in reuse
            if abs(s.direction_error_rad) <= OFFSET_DIRECTION_TOL_RAD}
    jobs = [(params, design, intensity, x, y, kept.get((round(x, 9), round(y, 9))))
            for x, y in nodes]
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
    return [searched[(round(x, 9), round(y, 9))] for x, y in nodes]
