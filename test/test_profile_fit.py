"""Profile-likelihood intervals and the multi-start (sphere_sim.fitting.profile_fit) on misfits
whose answers are known in closed form."""

import math

import numpy as np
import pytest

from sphere_sim.fitting import profile_fit
from sphere_sim.fitting.profile_fit import (
    CHI2_95,
    DETERMINED_SHARE,
    SEEN_RESIDUAL,
    SEEN_STEP_UNIT,
    ProfileInterval,
    fit_profiles,
    region_draws,
    search_coordinates,
    search_minimum,
    seen_coordinates,
)


def linear_residuals(matrix, centre):
    matrix, centre = np.asarray(matrix, float), np.asarray(centre, float)
    return lambda u: matrix @ (np.asarray(u, float) - centre)


def test_the_profile_interval_of_a_quadratic_misfit_is_its_closed_form():
    # Two correlated parameters: the profile's interval is sqrt(3.84 (H^-1)_jj) either side,
    # wider than the conditional one, sqrt(3.84 / H_jj), that holding the other would give.
    matrix = np.array([[40.0, 0.0], [25.0, 30.0], [3.0, -2.0]])
    centre = np.array([0.4, 0.55])
    fit = fit_profiles(linear_residuals(matrix, centre), 2, max_evaluations=400)
    cov = np.linalg.inv(matrix.T @ matrix)
    for j, interval in enumerate(fit.intervals):
        half = math.sqrt(CHI2_95 * cov[j, j])
        assert interval.low_u == pytest.approx(centre[j] - half, abs=1e-4)
        assert interval.high_u == pytest.approx(centre[j] + half, abs=1e-4)
        assert half > math.sqrt(CHI2_95 / (matrix.T @ matrix)[j, j])  # not the conditional one
        assert interval.complete and not (interval.low_at_bound or interval.high_at_bound)
    assert not fit.cost_limited and not fit.lower_found


def test_a_polished_start_reaches_the_minimum_of_a_quadratic_misfit_for_fewer_evaluations():
    # From a start a search brought near (as the joint fit's staged searches do), Levenberg-
    # Marquardt on one difference Jacobian lands on a quadratic's minimum at its first step,
    # and its intervals are the closed form's, as after a descent by least squares.
    matrix = np.array([[40.0, 0.0, 5.0], [25.0, 30.0, 0.0], [3.0, -2.0, 20.0]])
    centre = np.array([0.4, 0.55, 0.3])
    near = centre + np.array([0.02, -0.03, 0.01])
    fits = {polish: fit_profiles(linear_residuals(matrix, centre), 3, starts=0,
                                 descents=0 if polish else 1, extra_starts=[near],
                                 polish=polish, max_evaluations=400)
            for polish in (False, True)}
    cov = np.linalg.inv(matrix.T @ matrix)
    for fit in fits.values():
        assert fit.u == pytest.approx(centre, abs=1e-6)
        for j, interval in enumerate(fit.intervals):
            half = math.sqrt(CHI2_95 * cov[j, j])
            assert interval.low_u == pytest.approx(centre[j] - half, abs=1e-4)
            assert interval.high_u == pytest.approx(centre[j] + half, abs=1e-4)
    assert fits[True].evaluations < fits[False].evaluations


def rosenbrock(u):
    """Rosenbrock's valley on the cube (its minimum at 0.75, 0.75), whose Jacobian at a start
    on the valley's far side points the first steps out of the cube."""
    x = 4.0 * np.asarray(u, float) - 2.0
    return 5.0 * np.array([10.0 * (x[1] - x[0] ** 2), 1.0 - x[0]])


def test_the_polish_reaches_a_curved_valleys_minimum_from_a_far_start():
    # One Jacobian carried from (0.2, 0.75) stalls at a sum of squares of 75 (the polish on one
    # had the profiles read about a point 0.6 above the minimum); with a fresh one each time the
    # carried one stops, the polish ends at the minimum.
    fit = fit_profiles(rosenbrock, 2, starts=0, descents=0, extra_starts=[[0.2, 0.75]],
                       polish=True, max_evaluations=400)
    assert fit.u == pytest.approx([0.75, 0.75], abs=1e-3)
    assert fit.chi2 < 1e-3
    assert not fit.lower_found and not fit.cost_limited


def sheeted(u):
    """A quadratic misfit (its minimum at 0.4, 0.55) with a thin sheet beside the start of the
    test below: over 0.505 < u_0 < 0.515 one more residual is 20 standard deviations off, as
    a kick on its other branch is."""
    u = np.asarray(u, float)
    sheet = 20.0 if 0.505 < u[0] < 0.515 else 0.0
    return np.append(linear_residuals([[40.0, 0.0], [25.0, 30.0]], [0.4, 0.55])(u), sheet)


def test_a_difference_step_onto_a_sheet_does_not_stop_the_polish(monkeypatch):
    # From (0.5, 0.6) the forward step in u_0 lands on the sheet and reads a column of norm
    # 2000 where the slope is 47: a polish on it barely moves u_0. The step the other way
    # reads the slope, and the polish lands on the minimum.
    def polished():
        return profile_fit._polished(profile_fit._Counted(sheeted, 400), np.array([0.5, 0.6]))
    u, chi2 = polished()
    assert u == pytest.approx([0.4, 0.55], abs=1e-6)
    assert chi2 < 1e-9
    monkeypatch.setattr(profile_fit, 'SHEET_RESIDUAL', math.inf)
    u, chi2 = polished()
    assert u[0] > 0.45 and chi2 > 10.0  # one way only, the polish stays by the sheet


def bent_valley(u):
    """Three parameters whose valley bends: the minimum of u_1 moves with u_0 squared, and
    u_2's with u_1, so a profile's others must follow a curve, not a line."""
    u = np.asarray(u, float)
    return np.array([60.0 * (u[1] - 0.5 - 2.0 * (u[0] - 0.4) ** 2), 25.0 * (u[0] - 0.4),
                     40.0 * (u[2] - 0.3 - 0.5 * (u[1] - 0.5)),
                     50.0 * (u[0] - 0.4) * (u[2] - 0.3)])


def exact_profile_ends(residuals, dim, j, u_opt):
    """The 95 % profile interval by brute force: a tight minimisation of the others at each
    u_j, and the crossing found by root finding."""
    from scipy.optimize import brentq, minimize

    others = [k for k in range(dim) if k != j]
    chi_opt = float(np.sum(residuals(u_opt) ** 2))

    def rise(x):
        def chi(y):
            v = np.array(u_opt, float)
            v[j], v[others] = x, y
            return float(np.sum(residuals(v) ** 2))
        best = minimize(chi, np.asarray(u_opt, float)[others], method='Nelder-Mead',
                        options={'xatol': 1e-9, 'fatol': 1e-12, 'maxiter': 20000})
        return best.fun - chi_opt - CHI2_95

    return (brentq(rise, u_opt[j] - 0.3, u_opt[j], xtol=1e-7),
            brentq(rise, u_opt[j], u_opt[j] + 0.3, xtol=1e-7))


def test_the_profiles_follow_a_bent_valley_to_its_exact_ends_within_a_cost_limit():
    # Each step starts the others where the optimum's linearisation puts them and re-minimises
    # them on a Jacobian carried from the optimum: the ends must still be the brute-force
    # profile's, and the whole fit (descent from the start, three profiles) stays under 80
    # evaluations (233 when every step took its own difference Jacobians).
    fit = fit_profiles(bent_valley, 3, start=[0.5] * 3, starts=0, descents=1,
                       max_evaluations=80)
    assert not fit.cost_limited
    assert fit.u == pytest.approx([0.4, 0.5, 0.3], abs=1e-4)
    for j, interval in enumerate(fit.intervals):
        low, high = exact_profile_ends(bent_valley, 3, j, [0.4, 0.5, 0.3])
        assert interval.low_u == pytest.approx(low, abs=5e-4)
        assert interval.high_u == pytest.approx(high, abs=5e-4)


def test_a_direction_the_residuals_do_not_see_is_undetermined_with_its_whole_range():
    matrix = np.array([[80.0, 0.0, 0.0], [50.0, 60.0, 0.0], [6.0, -4.0, 0.0]])
    fit = fit_profiles(linear_residuals(matrix, [0.4, 0.55, 0.3]), 3, max_evaluations=600)
    flat = fit.intervals[2]
    assert (flat.low_u, flat.high_u) == (0.0, 1.0)
    assert flat.low_at_bound and flat.high_at_bound and not flat.determined
    # The two the residuals see stay determined: their intervals are a few hundredths wide.
    assert all(i.determined for i in fit.intervals[:2])


def test_a_wide_interval_is_undetermined_though_it_reaches_no_bound():
    # A standard error such that the 95 % interval spans 1.5 times the determined share.
    sd = 1.5 * DETERMINED_SHARE / (2 * math.sqrt(CHI2_95))
    fit = fit_profiles(linear_residuals([[1.0 / sd]], [0.5]), 1, max_evaluations=200)
    (interval,) = fit.intervals
    assert interval.width_u == pytest.approx(1.5 * DETERMINED_SHARE, rel=1e-3)
    assert not interval.determined and not interval.low_at_bound


def test_the_multistart_finds_the_deeper_of_two_basins_a_descent_from_the_start_misses():
    # A double well along u: the start sits in the shallow basin at 0.2, the deep one at 0.8.
    def residuals(u):
        x = float(u[0])
        return np.array([30.0 * (x - 0.2) * (x - 0.8), 0.5 * (x - 0.8) / 0.1])

    fit = fit_profiles(residuals, 1, start=[0.2], max_evaluations=300)
    assert fit.u[0] == pytest.approx(0.8, abs=1e-3)


def double_well(u):
    """Shallow basin at 0.2 (where the start sits), deep one at 0.8."""
    x = float(u[0])
    return np.array([30.0 * (x - 0.2) * (x - 0.8), 0.5 * (x - 0.8) / 0.1])


def test_a_search_started_only_where_another_fit_ended_descends_into_that_basin():
    # No Latin hypercube: the search from the start values alone stays in the shallow basin
    # (the profiles would then find the deep one: the test below), a further start in the deep
    # one (as the thresholds' optimum is for the joint fit) reaches it.
    shallow_u, shallow_chi2, _ = search_minimum(double_well, 1, start=[0.2], starts=0,
                                                descents=1, max_evaluations=300)
    assert shallow_u[0] < 0.5
    deep = fit_profiles(double_well, 1, start=[0.2], starts=0, descents=2,
                        max_evaluations=300, extra_starts=[[0.75]])
    assert deep.u[0] == pytest.approx(0.8, abs=1e-3)
    assert deep.chi2 < shallow_chi2 - 1.0


def test_the_coordinates_seen_are_those_a_tenth_of_the_range_moves_by_a_standard_deviation():
    # Slopes in standard deviations per unit: a tenth of the range moves the first residual by
    # 20, the second by 10.5 (once shifted downward, from the top), the third by 0.95: unseen.
    slopes = np.array([200.0, 105.0, 0.95 / SEEN_STEP_UNIT])
    assert seen_coordinates(lambda u: slopes * u, [0.5, 1.0, 0.3]) == (0, 1)
    # Seen through any residual, not just through one of its own.
    mixed = np.array([[0.0, 0.0], [0.0, 2.0 * SEEN_RESIDUAL / SEEN_STEP_UNIT]])
    assert seen_coordinates(lambda u: mixed @ u, [0.5, 0.5]) == (1,)


def test_a_search_over_some_coordinates_holds_the_others_and_finds_the_deeper_basin():
    # The double well along the second coordinate; the first, held at 0.3, would pull the
    # search to 0.9 if it were free.
    def residuals(u):
        return np.concatenate([[10.0 * (u[0] - 0.9)], double_well(u[1:])])

    calls = []

    def counted(u):
        calls.append(np.array(u))
        return residuals(u)

    u, chi, evaluations = search_coordinates(counted, [0.3, 0.2], [1], max_evaluations=300)
    assert u[0] == 0.3 and u[1] == pytest.approx(0.8, abs=1e-3)
    assert chi == pytest.approx(float(np.sum(residuals(u) ** 2)))
    assert all(c[0] == 0.3 for c in calls) and evaluations <= len(calls)
    # Nothing free: the point itself, evaluated once.
    u, chi, evaluations = search_coordinates(residuals, [0.3, 0.2], [])
    assert list(u) == [0.3, 0.2] and evaluations == 1
    assert chi == pytest.approx(float(np.sum(residuals(u) ** 2)))


def test_the_search_alone_returns_the_lowest_point_it_saw_when_the_limit_stops_it():
    u, chi, evaluations = search_minimum(double_well, 1, start=[0.2], max_evaluations=300)
    assert u[0] == pytest.approx(0.8, abs=1e-3) and evaluations <= 300
    u, chi, evaluations = search_minimum(double_well, 1, start=[0.2], max_evaluations=3)
    assert evaluations == 3
    assert chi == pytest.approx(float(np.sum(double_well(u) ** 2)))
    assert chi <= float(np.sum(double_well([0.2]) ** 2))


def test_the_cost_limit_stops_a_profile_and_marks_it_undetermined():
    matrix = np.array([[40.0, 0.0], [25.0, 30.0]])
    residuals = linear_residuals(matrix, [0.4, 0.55])
    whole = fit_profiles(residuals, 2, max_evaluations=400)
    assert not whole.cost_limited and all(i.complete for i in whole.intervals)
    # A limit a few evaluations short of what the whole fit took stops its last profile.
    limit = whole.evaluations - 4
    fit = fit_profiles(residuals, 2, max_evaluations=limit)
    assert fit.evaluations <= limit and fit.cost_limited
    assert not all(i.complete for i in fit.intervals)
    assert not all(i.determined for i in fit.intervals)


def test_an_interval_at_a_bound_is_undetermined_however_narrow():
    assert not ProfileInterval(0, 0.0, 0.02, True, False, True, ()).determined
    assert ProfileInterval(0, 0.4, 0.42, False, False, True, ()).determined


class Batched:
    """Residuals with a ``many``: the batches asked for, and the single points."""

    def __init__(self, residuals):
        self.residuals, self.batches, self.singles = residuals, [], 0

    def __call__(self, u):
        self.singles += 1
        return self.residuals(u)

    def many(self, points):
        self.batches.append(len(points))
        return [self.residuals(u) for u in points]


def test_independent_points_come_as_one_batch_and_give_the_fit_of_single_points():
    """The multi-start's points and each Jacobian's columns are one batch each; the fit is the
    one that the same residuals give point by point."""
    matrix = np.array([[40.0, 0.0], [25.0, 30.0], [3.0, -2.0]])
    residuals = linear_residuals(matrix, [0.4, 0.55])
    batched = Batched(residuals)
    fit = fit_profiles(batched, 2, start=[0.5, 0.5], starts=6, max_evaluations=400)
    single = fit_profiles(residuals, 2, start=[0.5, 0.5], starts=6, max_evaluations=400)
    assert batched.batches[0] == 7  # the start and the six Latin-hypercube points
    # Every descent's Jacobian: one column per parameter (its point is cached by then).
    assert batched.batches.count(2) >= 2
    assert fit.u.tolist() == single.u.tolist()
    assert [(i.low_u, i.high_u) for i in fit.intervals] == [
        (i.low_u, i.high_u) for i in single.intervals]
    assert fit.evaluations == single.evaluations


def test_a_batch_over_the_cost_limit_evaluates_up_to_it_and_stops():
    batched = Batched(linear_residuals([[1.0]], [0.5]))
    u, chi, evaluations = search_minimum(batched, 1, start=[0.2], starts=8, max_evaluations=5)
    assert evaluations == 5 and batched.batches == [5]  # the start and four of the eight
    # The lowest of the five evaluated is kept (no descent was reached).
    assert chi == float((u[0] - 0.5) ** 2) <= float((0.2 - 0.5) ** 2)


def test_a_profile_started_far_too_short_reaches_its_exact_end_in_a_few_steps():
    # A quadratic whose 95 % half-width is 0.05, walked from a first step of 1e-3 (a curvature
    # read fifty times too steep): each step aims past where the rise so far says the
    # crossing is, at most four times the last, so the end comes within five steps a side
    # where doubling takes seven, and it is still the closed form's.
    from sphere_sim.fitting.profile_fit import MAX_GROWTH, _Counted, next_step, profile

    half = 0.05
    residuals = linear_residuals([[math.sqrt(CHI2_95) / half]], [0.5])
    fun = _Counted(residuals, 100)
    interval = profile(fun, np.array([0.5]), 0.0, 0, 1e-3, np.array([[math.sqrt(CHI2_95) / half]]))
    assert interval.low_u == pytest.approx(0.5 - half, abs=1e-6)
    assert interval.high_u == pytest.approx(0.5 + half, abs=1e-6)
    assert len(interval.points) <= 2 * 5
    # The rule itself: a rise of a quarter of CHI2_95 aims at 1.2 x 2 = 2.4 steps; no rise, or
    # a jitter below zero, the longest.
    assert next_step(0.01, CHI2_95 / 4) == pytest.approx(0.024)
    assert next_step(0.01, -0.3) == next_step(0.01, 0.0) == MAX_GROWTH * 0.01
    assert next_step(0.01, 0.9 * CHI2_95) == pytest.approx(0.015)  # at least 1.5 times


def two_basins(u):
    """u_0's misfit has a shallow basin at 0.31 (sum of squares 0.96) and, past a ridge 0.85
    above it, the lowest at 0.55 (zero); u_1 is a plain parabola about 0.5."""
    u = np.asarray(u, float)
    return np.array([20.0 * (u[0] - 0.3) * (u[0] - 0.55) / 0.25, (0.55 - u[0]) / 0.25,
                     10.0 * (u[1] - 0.5)])


def test_a_profile_that_finds_a_lower_basin_restarts_the_descent_there(monkeypatch):
    import sphere_sim.fitting.profile_fit as pf

    # Started in the shallow basin, the descent ends there, and u_0's profile crosses the ridge
    # (a rise of 0.85, under the 3.84 it stops at) into the lower one.
    fit = fit_profiles(two_basins, 2, start=[0.3, 0.5], starts=0, descents=1)
    assert fit.u[0] == pytest.approx(0.55, abs=1e-3) and fit.chi2 < 1e-6
    assert not fit.lower_found
    # Its interval is read about the lowest point: the ridge and the shallow basin lie within
    # 3.84 of zero, so the interval reaches past them.
    assert fit.intervals[0].low_u < 0.3 < 0.55 < fit.intervals[0].high_u
    assert fit.intervals[1].low_u == pytest.approx(0.5 - math.sqrt(CHI2_95) / 10.0, abs=1e-3)

    monkeypatch.setattr(pf, 'PROFILE_RESTARTS', 0)
    unrestarted = fit_profiles(two_basins, 2, start=[0.3, 0.5], starts=0, descents=1)
    assert unrestarted.u[0] == pytest.approx(0.31, abs=0.01) and unrestarted.lower_found
    assert fit.evaluations > unrestarted.evaluations


def test_draws_from_a_linear_misfits_region_spread_as_its_covariance_and_hold_the_others():
    # Residuals linear in the two free coordinates (correlated), none in the third: the draws'
    # covariance is (J^T J)^-1, their mean the minimum, the third coordinate held.
    matrix = np.array([[60.0, 0.0, 0.0], [30.0, 45.0, 0.0], [5.0, -8.0, 0.0]])
    centre = np.array([0.4, 0.6, 0.25])
    draws = np.array(region_draws(linear_residuals(matrix, centre), centre, [0, 1], 2000))
    assert draws.shape == (2000, 3) and np.all(draws[:, 2] == 0.25)
    expected = np.linalg.inv(matrix[:, :2].T @ matrix[:, :2])
    assert np.cov(draws[:, :2].T) == pytest.approx(expected, rel=0.1)
    assert draws[:, :2].mean(axis=0) == pytest.approx(centre[:2], abs=0.1 * math.sqrt(
        float(np.max(np.diag(expected)))))
    assert region_draws(linear_residuals(matrix, centre), centre, [], 5) == []


def stepped(u):
    """Smooth residuals ('thresholds') with their minimum at (0.5, 0.5), whose 95 % region is
    some 0.03 either way, and a step ('a kick on its other branch', six standard deviations)
    on the left of 0.51 in the first coordinate: the joint minimum lies just right of it."""
    u = np.asarray(u, float)
    smooth = (u - 0.5) / 0.015
    return np.concatenate([smooth, [6.0 if u[0] < 0.51 else 0.0]])


def test_starts_drawn_from_the_smooth_residuals_region_find_the_cell_their_optimum_misses():
    # Polished from the smooth optimum alone the fit stays on the step's high side (its
    # difference step across the step is taken the other way); only a profile crossing it
    # finds the low side, and the descent and the profiles start again there. Drawn starts
    # cross it at once, for fewer evaluations in all.
    from sphere_sim.fitting.profile_fit import _Counted, _polished

    def smooth(u):
        return stepped(u)[:2]

    _, chi_polished = _polished(_Counted(stepped, 100), np.array([0.5, 0.5]))
    assert chi_polished == pytest.approx(36.0)
    alone = fit_profiles(stepped, 2, starts=0, descents=0, extra_starts=[[0.5, 0.5]],
                         polish=True, max_evaluations=300)
    draws = region_draws(smooth, [0.5, 0.5], [0, 1], 8)
    fit = fit_profiles(stepped, 2, starts=0, descents=0, extra_starts=[[0.5, 0.5], *draws],
                       polish=True, max_evaluations=300)
    for ended in (alone, fit):
        assert ended.u[0] >= 0.51 and ended.chi2 < 1.0 and not ended.lower_found
    assert fit.evaluations < alone.evaluations
