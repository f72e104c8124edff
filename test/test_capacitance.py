"""Capacitance of eq. (8)-(12): the smooth closed form, its guards and the RBF net."""

import math
from decimal import Decimal, localcontext

import numpy as np
import pytest

from sphere_sim.model import capacitance as cap
from sphere_sim.model import capacitance_rbf as rbf

LENGTH_M = 500e-6  # L_ES, Table A1
WIDTH_M = 1300e-6  # w_ES, Table A1
Z_GROUND_M = -10e-6  # z_G, Table A1
THETA_F = cap.DEFAULT_FRINGE_ANGLE_RAD
EPS_W = cap.EPSILON_0_F_PER_M * WIDTH_M
DIGITS = 60  # working precision of the Decimal references


# --- high-precision references ---------------------------------------------------------------

def _sin_cos(x):
    """sin and cos of a Decimal by their Taylor series (|x| <= 1 here)."""
    sin = term_s = x
    cos = term_c = Decimal(1)
    k = 1
    tiny = Decimal(10) ** -(DIGITS + 5)
    while abs(term_s) > tiny or abs(term_c) > tiny:
        term_c *= -x * x / ((2 * k - 1) * (2 * k))
        term_s *= -x * x / ((2 * k) * (2 * k + 1))
        cos += term_c
        sin += term_s
        k += 1
    return sin, cos


def literal_main_term(gap_m, phi_rad):
    """eps0 w/theta ln(R/L) with R, L of eq. (9), (10), to DIGITS digits."""
    with localcontext() as ctx:
        ctx.prec = DIGITS
        g, phi, length = Decimal(gap_m), Decimal(phi_rad), Decimal(LENGTH_M)
        theta = abs(phi)
        sin_phi = _sin_cos(phi)[0]
        radius = length / 2 + (2 * g + length * sin_phi) / (2 * abs(sin_phi))
        inner = radius - length
        return float(Decimal(EPS_W) / theta * (radius / inner).ln())


def literal_fringe_term(phi_rad):
    """Second term of eq. (8) with theta = |phi| (float, valid away from phi = 0)."""
    theta = abs(phi_rad)
    two_pi = 2 * math.pi
    return 2 * EPS_W * (math.log(two_pi / theta) / (two_pi - theta)
                        + math.log(two_pi / (two_pi - theta)) / theta)


def _reference_helpers(x):
    """(sinc, sinc') and, for x > -1, (f, f') at Decimal(x), f(x) = log1p(x)/x."""
    with localcontext() as ctx:
        ctx.prec = DIGITS
        d = Decimal(x)
        sin, cos = _sin_cos(d)
        values = (float(sin / d), float((d * cos - sin) / (d * d)))
        if x > -1.0:
            log = (1 + d).ln()
            values += (float(log / d), float((d / (1 + d) - log) / (d * d)))
        return values


def close(expected, rel):
    """pytest.approx with a purely relative tolerance (its default abs of 1e-12 would
    swallow any capacitance in F)."""
    return pytest.approx(expected, rel=rel, abs=0.0)


def _central_difference(fun, x, step):
    return (fun(x + step) - fun(x - step)) / (2.0 * step)


def _closed(gap_m, phi_rad, fringe=True):
    return cap.closed_form(gap_m, phi_rad, LENGTH_M, WIDTH_M, THETA_F, fringe)


# --- closed form -----------------------------------------------------------------------------

@pytest.mark.parametrize('phi_rad', [0.0, 1e-12, -1e-12])
@pytest.mark.parametrize('gap_m', [0.1e-6, 1.5e-6, 10e-6, 13.3e-6])
def test_zero_tilt_is_the_parallel_plate(gap_m, phi_rad):
    c, dc_dgap, dc_dphi = _closed(gap_m, phi_rad, fringe=False)
    plate = EPS_W * LENGTH_M / gap_m
    # C = eps0 w ln(1 + a phi)/phi + O(phi^2), a = L/g: the plate plus its first-order tilt
    # correction, which is a phi/2 = 2.5e-9 relative at g = 0.1 um and phi = 1e-12, so it is
    # kept; the neglected terms are ~(a phi)^2 < 3e-17.
    a = LENGTH_M / gap_m
    aphi = a * phi_rad
    assert c == close(plate * (1 - aphi / 2), rel=1e-14)
    assert dc_dgap == close(-plate / gap_m * (1 - aphi), rel=1e-14)
    # Tilting about the suspension end moves the plate's centroid by L/2 per radian; the
    # last term is sinc'(phi) = -phi/3.
    assert dc_dphi == close(-plate * a / 2 * (1 - 4 * aphi / 3 + 2 * phi_rad / (3 * a)),
                            rel=1e-14)


# Moderate tilts of both signs, where eq. (8) is well conditioned in float64 and valid
# (the far end at least 10 % of g above the ground plate).
LITERAL_STATES = [(gap, sign * theta) for gap in (0.5e-6, 3e-6, 10e-6, 13.3e-6, 40e-6)
                  for theta in (1e-3, 3e-3, 1e-2, 0.05) for sign in (1.0, -1.0)
                  if gap + LENGTH_M * math.sin(sign * theta) >= 0.1 * gap]


@pytest.mark.parametrize('gap_m, phi_rad', LITERAL_STATES)
def test_main_term_equals_literal_eq8(gap_m, phi_rad):
    c = _closed(gap_m, phi_rad, fringe=False)[0]
    assert c == close(literal_main_term(gap_m, phi_rad), rel=1e-12)


@pytest.mark.parametrize('x', [1e-9, 1e-4, 0.01, 0.1, 0.3, 0.499, 0.501, 0.66, 0.9, 0.999,
                               1.001, 1.5, 3.0])
def test_series_and_closed_expressions_agree_with_high_precision(x):
    # Both sides of each threshold (0.5 for f, f'; 1 rad for sinc, sinc'), both signs.
    for arg in (x, -x):
        got = (cap.sinc(arg), cap.sinc_derivative(arg))
        if arg > -1.0:
            got += (cap.log1p_ratio(arg), cap.log1p_ratio_derivative(arg))
        for value, reference in zip(got, _reference_helpers(arg), strict=False):
            assert value == close(reference, rel=2e-15), arg


def test_helpers_at_zero():
    assert (cap.sinc(0.0), cap.sinc_derivative(0.0)) == (1.0, 0.0)
    assert (cap.log1p_ratio(0.0), cap.log1p_ratio_derivative(0.0)) == (1.0, -0.5)


def _random_states(rng, n):
    """(gap, phi) with both gaps >= 50 nm: spread over the RBF box and a little beyond,
    within +-1e-9 rad of zero tilt, and at the box's edges."""
    gaps = rng.uniform(0.2e-6, 15e-6, n)
    phis = np.concatenate([rng.uniform(-14.5e-3, 4.5e-3, n // 2),
                           rng.uniform(-1e-9, 1e-9, n - n // 2)])
    edge_gaps = np.array([0.1e-6, 0.1e-6, 13.3e-6, 13.3e-6, 7.5e-6, 13.3e-6])
    edge_phis = np.array([0.0, 4.5e-3, 4.5e-3, -14.5e-3, -14.5e-3, 0.0])
    gaps, phis = np.concatenate([gaps, edge_gaps]), np.concatenate([phis, edge_phis])
    keep = gaps + LENGTH_M * np.sin(phis) >= 50e-9
    return list(zip(gaps[keep], phis[keep], strict=True))


@pytest.mark.parametrize('fringe', [True, False])
def test_analytic_derivatives_match_central_differences(fringe):
    states = _random_states(np.random.default_rng(7), 200)
    assert len(states) > 150
    for gap, phi in states:
        far = gap + LENGTH_M * math.sin(phi)
        step_gap = 1e-5 * min(gap, far)
        step_phi = 1e-5 * min(THETA_F, far / LENGTH_M)
        _, dc_dgap, dc_dphi = _closed(gap, phi, fringe)
        fd_gap = _central_difference(lambda g, p=phi: _closed(g, p, fringe)[0], gap, step_gap)
        fd_phi = _central_difference(lambda p, g=gap: _closed(g, p, fringe)[0], phi, step_phi)
        assert dc_dgap == close(fd_gap, rel=1e-6), (gap, phi)
        assert dc_dphi == close(fd_phi, rel=1e-6), (gap, phi)


@pytest.mark.parametrize('fringe', [False, True])
@pytest.mark.parametrize('gap_m', [0.5e-6, 10e-6])
def test_continuous_and_smooth_through_zero_tilt(gap_m, fringe):
    delta = 1e-12
    at_zero, up, down = (np.array(_closed(gap_m, phi, fringe)) for phi in (0.0, delta, -delta))
    # Each of C, dC/dg, dC/dphi changes by at most (2 L/g + 1/(theta_f^2 a^2)) delta relative,
    # i.e. < 1e-8 here: nothing jumps ...
    np.testing.assert_allclose(up, at_zero, rtol=1e-8, atol=0)
    np.testing.assert_allclose(down, at_zero, rtol=1e-8, atol=0)
    # ... and nothing kinks: the second difference is O(delta^2), only rounding is left
    # (a kink of slope k per rad would leave 2 k delta, e.g. the literal |phi| forms).
    np.testing.assert_array_less(np.abs(up + down - 2 * at_zero), 1e-13 * np.abs(at_zero))
    # The returned dC/dphi is the slope of the returned C across phi = 0.
    step = 1e-6 * gap_m / LENGTH_M
    slope = (_closed(gap_m, step, fringe)[0] - _closed(gap_m, -step, fringe)[0]) / (2 * step)
    assert at_zero[2] == close(slope, rel=1e-6)


def test_regularised_fringe_is_bounded_at_zero_and_literal_far_from_it():
    c0, slope0 = cap.fringe_term(0.0, WIDTH_M, THETA_F)
    assert math.isfinite(c0)
    assert slope0 == 0.0
    near = np.linspace(-10 * THETA_F, 10 * THETA_F, 2001)
    slopes = np.array([cap.fringe_term(p, WIDTH_M, THETA_F)[1] for p in near])
    # ~ -(eps0 w/pi) phi/(phi^2 + theta_f^2), largest at |phi| = theta_f; the literal slope
    # -eps0 w/(pi phi) is unbounded.
    assert np.max(np.abs(slopes)) <= 1.01 * EPS_W / (2 * math.pi * THETA_F)
    for phi in (0.05, -0.05, 0.1, -0.1, 0.3, -0.3):
        c, slope = cap.fringe_term(phi, WIDTH_M, THETA_F)
        tol = 2 * (THETA_F / phi) ** 2  # theta_eff/theta - 1 ~ theta_f^2/(2 phi^2)
        literal_slope = _central_difference(literal_fringe_term, phi, 1e-7)
        assert c == close(literal_fringe_term(phi), rel=tol)
        assert slope == close(literal_slope, rel=tol)


def test_fringe_switch_adds_exactly_the_fringe_term():
    for gap, phi in [(3e-6, 0.0), (8e-6, -6e-3), (1e-6, 4e-3)]:
        with_fringe, without = _closed(gap, phi, True), _closed(gap, phi, False)
        fringe_c, fringe_slope = cap.fringe_term(phi, WIDTH_M, THETA_F)
        assert with_fringe[0] == close(without[0] + fringe_c, rel=1e-15)
        assert with_fringe[1] == without[1]  # the fringe term does not depend on the gap
        assert with_fringe[2] == close(without[2] + fringe_slope, rel=1e-14)


@pytest.mark.parametrize('fringe', [True, False])
def test_physical_signs(fringe):
    gaps = np.linspace(0.2e-6, 20e-6, 60)
    phis = np.linspace(-14.5e-3, 0.3, 200)
    g, p = np.meshgrid(gaps, phis, indexing='ij')
    valid = g + LENGTH_M * np.sin(p) > 0.1e-6
    c, dc_dgap, dc_dphi = cap.closed_form_array(g, p, LENGTH_M, WIDTH_M, THETA_F, fringe)
    assert np.all(dc_dgap[valid] < 0.0)  # a wider gap always lowers C
    flat = cap.closed_form_array(gaps, 0.0, LENGTH_M, WIDTH_M, THETA_F, fringe)[0]
    rising = p > 0.0
    # Lifting the far end (phi > 0) lowers C below the flat plate's at the same gap ...
    assert np.all(c[rising] < np.broadcast_to(flat[:, None], c.shape)[rising])
    # ... and monotonically so.
    assert np.all(dc_dphi[rising] < 0.0)


def test_wild_states_stay_finite_and_the_clamp_is_continuous():
    gaps = np.concatenate([np.linspace(-20e-6, 20e-6, 81), [0.0, 1e-9, 2e-9]])
    phis = np.concatenate([np.linspace(-0.5, 0.5, 201), [0.0, 1e-12, -1e-12]])
    g, p = np.meshgrid(gaps, phis, indexing='ij')
    for fringe, angle in ((True, THETA_F), (False, THETA_F), (True, 0.0)):
        out = cap.closed_form_array(g, p, LENGTH_M, WIDTH_M, angle, fringe)
        assert all(np.all(np.isfinite(q)) for q in out)
    # Along a tilt through the clamp line h = MIN_GAP_M at g = 5 um: C continuous, and the
    # clamped branch's derivatives are those of the function it returns.
    gap = 5e-6
    phi_clamp = math.asin((cap.MIN_GAP_M - gap) / LENGTH_M)
    for delta in (1e-13, 1e-15):
        inside = _closed(gap, phi_clamp - delta)[0]
        outside = _closed(gap, phi_clamp + delta)[0]
        assert inside == close(outside, rel=1e-6)
    phi = phi_clamp - 1e-4
    _, dc_dgap, dc_dphi = _closed(gap, phi)
    assert dc_dgap == close(_central_difference(lambda x: _closed(x, phi)[0], gap, 1e-11),
                            rel=1e-6)
    assert dc_dphi == close(_central_difference(lambda x: _closed(gap, x)[0], phi, 1e-8),
                            rel=1e-6)


# --- RBF net ---------------------------------------------------------------------------------

@pytest.fixture(scope='module')
def fit():
    return rbf.RbfCapacitance.fit(LENGTH_M, WIDTH_M, Z_GROUND_M, THETA_F, True)


def test_rbf_centres_are_the_papers(fit):
    assert fit.weights.shape == (25, 25)
    np.testing.assert_allclose(fit.centres_z_m[[0, -1]], [-9.9e-6, 3.3e-6], rtol=1e-12)
    np.testing.assert_allclose(fit.centres_phi_rad[[0, -1]], [-14.5e-3, 4.5e-3], rtol=1e-12)
    assert (fit.sigma_z_m, fit.sigma_phi_rad) == (0.5e-6, 0.75e-3)


def test_rbf_reproduces_the_closed_form(fit):
    diff = {(d.region, d.quantity): d for d in rbf.compare_models(
        LENGTH_M, WIDTH_M, Z_GROUND_M, THETA_F, True, fit=fit)}
    # Measured: interior 1.20 %, 7.9 %, 18.1 %; box 1.42 %, 22.6 %, 33.5 % of the largest
    # |C|, |dC/dz|, |dC/dphi| there. The derivatives are worst within a few sigma of the
    # box's edges, where the Gaussians fall off (see the plot of `sphere-twin capacitance`).
    assert diff['interior', 'C'].relative_to_max < 0.015
    assert diff['interior', 'C'].relative_pointwise < 0.045
    assert diff['interior', 'dC_dz'].relative_to_max < 0.10
    assert diff['interior', 'dC_dphi'].relative_to_max < 0.22
    assert diff['box', 'C'].relative_to_max < 0.018
    assert diff['box', 'dC_dz'].relative_to_max < 0.28
    assert diff['box', 'dC_dphi'].relative_to_max < 0.40


def test_rbf_stays_within_the_closed_forms_range_where_not_fitted(fit):
    # The excluded corner (a gap < 0.5 um) has no samples; the ridge keeps the net tame there.
    (z_lo, z_hi), (phi_lo, phi_hi) = fit.centre_box
    z, p = np.meshgrid(np.linspace(z_lo - 2e-6, z_hi + 2e-6, 150),
                       np.linspace(phi_lo - 3e-3, phi_hi + 3e-3, 150), indexing='ij')
    c = fit.evaluate(z, p)[0]
    gap = z - Z_GROUND_M
    fitted = (gap >= rbf.FIT_MIN_GAP_M) & (gap + LENGTH_M * np.sin(p) >= rbf.FIT_MIN_GAP_M)
    largest = np.max(_closed_grid(gap[fitted], p[fitted]))
    assert np.all(c > -1e-3 * largest)
    assert np.all(c < 2.0 * largest)


def _closed_grid(gap, phi):
    return cap.closed_form_array(gap, phi, LENGTH_M, WIDTH_M, THETA_F, True)[0]


def test_rbf_derivatives_match_its_central_differences(fit):
    rng = np.random.default_rng(11)
    (z_lo, z_hi), (phi_lo, phi_hi) = fit.centre_box
    z = np.concatenate([rng.uniform(z_lo, z_hi, 300), [z_lo, z_hi, z_lo, z_hi]])
    phi = np.concatenate([rng.uniform(phi_lo, phi_hi, 300), [phi_lo, phi_lo, phi_hi, phi_hi]])
    args = (fit.centres_z_m, fit.centres_phi_rad, fit.sigma_z_m, fit.sigma_phi_rad,
            fit.weights)
    _, dc_dz, dc_dphi = fit.evaluate(z, phi)
    fd_z = np.array([_central_difference(lambda x, q=q: rbf.rbf_evaluate(x, q, *args)[0], x0,
                                         1e-4 * fit.sigma_z_m)
                     for x0, q in zip(z, phi, strict=True)])
    fd_phi = np.array([_central_difference(lambda q, x=x: rbf.rbf_evaluate(x, q, *args)[0], q0,
                                           1e-4 * fit.sigma_phi_rad)
                       for x, q0 in zip(z, phi, strict=True)])
    np.testing.assert_allclose(dc_dz, fd_z, rtol=1e-6, atol=1e-7 * np.max(np.abs(fd_z)))
    np.testing.assert_allclose(dc_dphi, fd_phi, rtol=1e-6, atol=1e-7 * np.max(np.abs(fd_phi)))


def test_fit_is_deterministic_and_cached(fit):
    first = rbf.fit_rbf(LENGTH_M, WIDTH_M, Z_GROUND_M, THETA_F, True)
    second = rbf.fit_rbf(LENGTH_M, WIDTH_M, Z_GROUND_M, THETA_F, True)
    assert np.array_equal(first.weights, second.weights)
    assert first.condition_number == second.condition_number
    np.testing.assert_allclose(first.weights, fit.weights, rtol=0, atol=0)
    assert rbf.RbfCapacitance.fit(LENGTH_M, WIDTH_M, Z_GROUND_M, THETA_F, True) is fit
    assert not fit.weights.flags.writeable  # the cached fit is shared by every model
