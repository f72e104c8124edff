"""Voltage-offset search, the compensating-beam rule and the kick effect."""

import dataclasses
import math

import numpy as np
import pytest

from sphere_sim.kicks.characteristics import (
    OFFSET_BISECTIONS,
    OFFSET_LOWEST_ROOT_STEP_V,
    OFFSET_REFINEMENTS,
    OFFSET_STEP_V,
    KickEffect,
    find_offset,
    lowest_crossing,
    offset_grid,
    upper_right_nodes,
)
from sphere_sim.kicks.design import KickDesign


def test_offset_search_finds_the_root_inside_the_bracket_of_a_non_monotone_error():
    calls = []

    def error(v):  # zero at 8 V; a second, far sign change beyond 30 V
        calls.append(v)
        return math.atan(0.05 * (v - 8.0)) * (1.0 if v < 30.0 else -1.0)

    offset, residual, evaluations = find_offset(error, (-10.0, 5.0, 10.0, 20.0, 45.0),
                                                tol_rad=1e-3, refinements=6)
    assert offset == pytest.approx(8.0, abs=0.05)
    assert abs(residual) <= 1e-3
    assert evaluations == len(calls) <= 6 + 6


def test_offset_search_goes_on_by_bisection_where_regula_falsi_stalls():
    """A steep, one-sided error (as far out in the cone, where V1 passes its own pull-in):
    three regula falsi steps from the scan's bracket stay far off; the bisections that follow
    reach the tolerance. A search regula falsi finishes is the same with or without them."""
    calls = []

    def error(v):  # root at 39.86 V, flat below it and steep above it
        calls.append(v)
        return ((max(v, 20.0) - 20.0) / 25.0) ** 10 - 0.1

    scan = (-10.0, 5.0, 10.0, 20.0, 45.0)
    tol = math.radians(1.0)
    _, stalled, _ = find_offset(error, scan, tol_rad=tol, bisections=0)
    assert abs(stalled) > 5.0 * tol
    calls.clear()
    offset, residual, evaluations = find_offset(error, scan, tol_rad=tol)
    assert abs(residual) <= tol
    assert offset == pytest.approx(20.0 + 25.0 * 0.1 ** 0.1, abs=0.1)
    # ... and the lowest-crossing check samples 21-38 V below the root, finding none.
    sampled = math.floor((offset - 20.0) / OFFSET_LOWEST_ROOT_STEP_V) - 1
    assert evaluations == len(calls) <= (len(scan) + 1 + OFFSET_REFINEMENTS + OFFSET_BISECTIONS
                                         + sampled)

    def smooth(v):
        return math.atan(0.05 * (v - 8.0))

    assert find_offset(smooth, scan, tol_rad=tol) == find_offset(smooth, scan, tol_rad=tol,
                                                                 bisections=0)


def test_offset_search_takes_the_lowest_zero_crossing_of_the_bracket():
    """Near the cone's edge the scan's 20-45 V bracket holds three roots: the full kick's
    error at (0.48, 0.24) against V1's offset (docs/motion_primitives.md, degrees), a low
    branch near 31.4 V and a high one near 40 V with the collapsed kick between them. The
    search keeps to the low branch, as its neighbours do."""
    volts = [0, 20, 30, 32, 33, 34, 35, 37, 39, 40, 41, 42.18, 45]
    degrees = [-42.9, -31.0, -6.6, 2.9, 0.4, 8.4, 37.0, 17.7, -9.9, -0.1, 6.1, 10.7, 16.6]

    def error(v):
        return math.radians(float(np.interp(v, volts, degrees)))

    scan = (-20.0, -10.0, -5.0, 5.0, 7.5, 10.0, 20.0, 45.0)
    tol = math.radians(1.0)
    offset, residual, _ = find_offset(error, scan, tol_rad=tol)
    assert abs(residual) <= tol
    assert 30.0 < offset < 33.0
    # From the high root alone, the check finds the low one; from the low one, nothing lower.
    lower, _ = lowest_crossing(error, (20.0, error(20.0)), (40.016, error(40.016)), tol)
    assert lower is not None and 30.0 < lower[0] < 33.0
    assert lowest_crossing(error, (20.0, error(20.0)), lower, tol) == (None, 10)


def test_a_root_within_the_tolerance_keeps_its_own_crossing_below_it():
    """Where the error is shallow, a root within 1 deg can lie more than a sampling step
    above its zero: the sign change below it is its own (the error does not turn back
    between them), and the search keeps the root it found."""
    def error(v):  # one root, at 24.6 V, 0.5 deg per V
        return math.radians(0.5 * (v - 24.6))

    assert lowest_crossing(error, (20.0, error(20.0)), (26.3, error(26.3))) == (None, 5)
    scan = (-20.0, -10.0, -5.0, 5.0, 7.5, 10.0, 20.0, 45.0)
    offset, _, _ = find_offset(error, scan)
    assert offset == pytest.approx(24.6, abs=2.0)


def test_a_root_that_only_nears_zero_above_a_hump_gives_way_to_the_crossing_below_it():
    """At (0.32, 0.44) the search ended at 36.42 V, +0.46 deg, where the error dips towards
    zero without crossing it; below it lies a hump (+23.7 deg at 34.5 V) and, below that, a
    crossing at 31.6 V whose kick is four times as wide. The sign change at 31-32 V is not the
    root's own: the error at 32 V already lies further from zero than twice the tolerance."""
    volts = [20.0, 30.0, 31.0, 31.5, 32.0, 33.0, 34.0, 34.5, 35.5, 36.0, 36.42, 37.0]
    degrees = [-30.0, -5.25, -2.39, -0.29, 2.83, 0.86, 7.64, 23.73, 18.97, 5.41, 0.46, 6.2]

    def error(v):
        return math.radians(float(np.interp(v, volts, degrees)))

    lower, evaluations = lowest_crossing(error, (20.0, error(20.0)), (36.42, error(36.42)))
    assert lower is not None and 31.0 < lower[0] < 32.0
    assert abs(lower[1]) <= math.radians(1.0)
    assert evaluations <= 12 + OFFSET_REFINEMENTS + OFFSET_BISECTIONS


def test_offset_search_locates_a_step_of_the_error_without_taking_it_for_a_root():
    """A beam snapping down can turn the error's sign with no root between: the bisections
    narrow the step to OFFSET_STEP_V and stop, the residual stays the step's."""
    calls = []

    def error(v):
        calls.append(v)
        return -0.2 if v < 30.0 else 0.2

    scan = (-10.0, 5.0, 10.0, 20.0, 45.0)
    _, residual, evaluations = find_offset(error, scan, tol_rad=math.radians(1.0))
    assert abs(residual) == pytest.approx(0.2)
    assert evaluations < len(scan) + 1 + OFFSET_REFINEMENTS + OFFSET_BISECTIONS
    below = max(v for v in calls if v < 30.0)
    above = min(v for v in calls if v >= 30.0)
    assert above - below <= OFFSET_STEP_V


def test_offset_search_without_a_sign_change_returns_the_best_scanned_offset():
    offset, residual, evaluations = find_offset(lambda v: 0.1 + 0.001 * (v - 5.0) ** 2,
                                                (-10.0, 5.0, 10.0), tol_rad=1e-3)
    assert (offset, evaluations) == (5.0, 4)
    assert residual == pytest.approx(0.1)


def test_offsets_are_searched_on_the_upper_right_half_whose_mirror_is_the_rest():
    design = KickDesign()
    nodes = offset_grid(0.16, math.radians(40.0))
    half = upper_right_nodes(design, 0.16, math.radians(40.0))
    assert all(x + y >= -1e-9 for x, y in half)
    # The half and its mirror image at y = -x cover the grid, the axis belongs to the half.
    images = {(round(-y, 9), round(-x, 9)) for x, y in half}
    assert images | {(round(x, 9), round(y, 9)) for x, y in half} == \
        {(round(x, 9), round(y, 9)) for x, y in nodes}
    assert len(half) == (len(nodes) + sum(abs(x + y) < 1e-9 for x, y in nodes)) // 2


def test_offset_grid_stays_inside_the_cone_and_is_symmetric():
    nodes = offset_grid(0.16, math.radians(40.0))
    assert all(math.hypot(x, y) <= math.sin(math.radians(40.0)) + 1e-12 for x, y in nodes)
    assert {(round(-x, 9), round(-y, 9)) for x, y in nodes} == \
        {(round(x, 9), round(y, 9)) for x, y in nodes}


def test_kick_effect_width_and_direction():
    effect = KickEffect(np.array([1e-3, -1e-3]))
    assert effect.width_rad == pytest.approx(math.sqrt(2) * 1e-3)
    assert effect.direction_rad == pytest.approx(math.radians(-45.0))


def test_design_round_trips_through_the_optimisation_json(tmp_path):
    import json

    design = KickDesign(width_low_s=1.2e-3, width_high_s=0.4e-3, delay_s=0.65e-3)
    path = tmp_path / 'kick.json'
    path.write_text(json.dumps({'design': {**design.to_dict(), 'direction_deg': -45.0}}))
    assert KickDesign.load(path) == design


def test_reused_offsets_are_only_checked_for_a_lower_crossing(monkeypatch):
    """`primitives offsets --reuse`: a state on the high branch moves to the low one, where a
    new search puts it too (by another path, so not to the same last bits); a state already on
    the lowest root is taken as it was, object and all."""
    from sphere_sim.kicks import characteristics

    volts = [-20, 0, 20, 30, 32, 33, 34, 35, 37, 39, 40, 41, 42.18, 45]
    degrees = [-50, -42.9, -31.0, -6.6, 2.9, 0.4, 8.4, 37.0, 17.7, -9.9, -0.1, 6.1, 10.7, 16.6]

    class Bench:  # the kick's direction error against V1's offset, as at (0.48, 0.24)
        def effect(self, normal, design, intensity, offset_v=0.0, offset_beam=None):
            angle = design.direction_rad + math.radians(float(np.interp(offset_v, volts,
                                                                        degrees)))
            return KickEffect(1e-3 * np.array([math.cos(angle), math.sin(angle)]))

        def tip_pushes(self, normal, design, intensity, offset_v, beam):
            return offset_v > 36.0

    monkeypatch.setattr(characteristics, '_bench', lambda params: Bench())
    design = KickDesign()
    fresh = characteristics.voltage_offsets(design, 0.16, math.radians(12.0))
    assert all(30.0 < s.offset_v < 33.0 and s.pushes is False for s in fresh)
    high = [dataclasses.replace(s, offset_v=40.016, direction_error_rad=math.radians(0.1),
                                pushes=True) for s in fresh]
    moved = characteristics.voltage_offsets(design, 0.16, math.radians(12.0), reuse=high)
    # The moved states' branch is measured at their new offset, not carried over.
    assert all(30.0 < s.offset_v < 33.0 and abs(s.direction_error_rad) <= math.radians(1.0)
               and s.evaluations > h.evaluations and s.pushes is False
               for s, h in zip(moved, high, strict=True))
    # A file of a search that did not measure the branch gets it measured.
    unmeasured = [dataclasses.replace(s, pushes=None) for s in fresh]
    measured = characteristics.voltage_offsets(design, 0.16, math.radians(12.0),
                                               reuse=unmeasured)
    assert [dataclasses.replace(s, pushes=None) for s in measured] == unmeasured
    assert all(s.pushes is False for s in measured)
    kept = characteristics.voltage_offsets(design, 0.16, math.radians(12.0), reuse=fresh)
    assert all(a is b for a, b in zip(kept, fresh, strict=True))


def test_the_offsets_two_branches_meet_where_the_compensating_tip_strikes_the_sphere_again():
    """At (0.48, -0.24), V1's tip loses the sphere before V1's rear lands up to 13.25 V of
    offset; from 13.3 V it loses it and strikes it again as the rear lands; from 15 V it keeps
    it. Released, the kick is wide and turns slowly with the offset (-1.76 deg at 13 V, 0.21
    deg wide); pushed, V1 turns it onto its direction but takes most of it (+3.8 deg, 0.04 deg
    wide at 15 V); in the band between, the second strike sends it 17 deg off at 14 V."""
    from pathlib import Path

    from sphere_sim.kicks.characteristics import KickBench, direction_error
    from sphere_sim.kicks.discrete import normal_from_xy
    from sphere_sim.kicks.offset_lookup import compensating_beam
    from sphere_sim.model.parameters import load_parameter_set

    design = KickDesign.load(Path(__file__).parents[1] / 'bench' / 'results'
                             / 'kick_optimization.json')
    bench = KickBench(load_parameter_set('calibrated'))
    normal = normal_from_xy(0.48, -0.24)
    beam = compensating_beam(design, upper_right=True)
    assert [bench.tip_pushes(normal, design, 1.0, v, beam) for v in (13.0, 14.0, 15.0)] == \
        [False, False, True]
    released, band, pushed = (bench.effect(normal, design, 1.0, v, beam)
                              for v in (13.0, 14.0, 15.0))
    assert abs(direction_error(released, design)) < math.radians(3.0)
    assert abs(direction_error(pushed, design)) < math.radians(5.0)
    assert abs(direction_error(band, design)) > math.radians(10.0)
    assert released.width_rad > 3.0 * pushed.width_rad
