"""Closed-form capacitance of one beam electrode over the ground plate, eq. (8).

The beam electrode is a rigid plate of length L_ES and width w_ES. With the gap
g = z_S - z_G at its suspension end and the tilt phi (phi > 0 lifts the far end), the far-end
gap is h = g + L_ES sin(phi). Eq. (8) with (9), (10) is

    C = eps0 w / theta ln(R/L) + 2 eps0 w (ln(2 pi/theta)/(2 pi - theta)
                                           + ln(2 pi/(2 pi - theta))/theta),  theta = |phi|.

Main (first) term
    For either sign of phi, ln(R/L)/theta = ln(1 + x)/phi with x = L_ES sin(phi)/g = h/g - 1,
    so the term equals eps0 w (L_ES/g) sinc(phi) f(x) with sinc(phi) = sin(phi)/phi and
    f(x) = log1p(x)/x. Both factors are evaluated by Taylor series near 0, which makes the term
    and its derivatives exact and smooth through phi = 0, where it is the parallel plate
    eps0 w L_ES / g. It is defined for h > 0 only. States with h below a floor (the far end
    on or under the ground plate) are clamped, see :func:`main_term`.
Fringe (second) term
    It diverges like ln(1/theta)/(2 pi) as theta -> 0, and its phi-derivative like
    -1/(2 pi phi): a property of the formula, not of its evaluation. It is regularised by
    theta_eff = sqrt(phi^2 + theta_f^2), with theta_f = ``fringe_angle_rad`` (default the RBF
    width sigma_phi of eq. 12, finer than the paper's own fit resolves); exact for
    |phi| >> theta_f. It does not depend on g.

The RBF net of eq. (12) fitted to this closed form is :mod:`sphere_sim.model.capacitance_rbf`.
The scalar function the dynamics kernel calls (:func:`closed_form`) is compiled with numba and
returns ``(C in F, dC/dz_S = dC/dg in F/m, dC/dphi in F/rad)``.
"""

import math

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

EPSILON_0_F_PER_M = 8.8541878128e-12  # vacuum permittivity, CODATA 2018

# Floor of the gaps (m): g is floored at this, the far-end gap h at min(this, g/2) (see
# main_term). A nanometre is far below any state the contact model admits (the insulation
# alone keeps 1.5 um), yet keeps ln(h/g) finite when a solver probes a state with the plate
# on or under the ground plate.
MIN_GAP_M = 1.0e-9

# Default theta_f of the fringe regularisation: the RBF width sigma_phi of eq. (12). The
# paper's own fit cannot resolve structure in phi finer than this.
DEFAULT_FRINGE_ANGLE_RAD = 0.75e-3

# theta_eff is kept in [FRINGE_MIN_ANGLE_RAD, FRINGE_MAX_ANGLE_RAD]. The lower bound only
# matters for fringe_angle_rad = 0 at phi = 0 (where eq. 8 is infinite); the upper one keeps
# 2 pi - theta away from 0 for wild tilts (a plate tilted by more than pi is no longer above
# its ground plate anyway). Beyond either bound the term is constant.
FRINGE_MIN_ANGLE_RAD = 1.0e-12
FRINGE_MAX_ANGLE_RAD = math.pi

# sinc(phi) and sinc'(phi) by their Taylor series for |phi| below this (rad). The closed
# expression of sinc' = (phi cos phi - sin phi)/phi^2 loses about log10(3/phi^2) digits to
# cancellation, i.e. < 1e-15 relative only from |phi| ~ 1 on; 11 terms keep the series'
# truncation error below 1e-19 up to |phi| = 1.
SINC_SERIES_MAX_RAD = 1.0
SINC_SERIES_TERMS = 11

# f(x) = log1p(x)/x and f'(x) by their Taylor series for |x| below this. The closed
# expression f' = (x/(1 + x) - log1p(x))/x^2 loses digits to cancellation, about
# log10((|x/(1+x)| + |log1p x|)/|x/(1+x) - log1p x|): relative error up to 1.1e-15 just above
# x = 0.5 (measured), 2e-15 at 0.3. 64 terms keep the series' truncation below 1e-19 up to
# |x| = 0.5. (f itself is accurate in closed form for every x != 0; its series covers 0.)
LOG1P_SERIES_MAX = 0.5
LOG1P_SERIES_TERMS = 64

# sinc(phi) = sum_k (-1)^k phi^(2k)/(2k+1)!, a polynomial in phi^2;
# sinc'(phi) = phi * sum_k (-1)^(k+1) (2k+2) phi^(2k)/(2k+3)!.
_SINC_COEFFS = np.array([(-1.0) ** k / math.factorial(2 * k + 1)
                         for k in range(SINC_SERIES_TERMS)])
_SINC_DERIV_COEFFS = np.array([(-1.0) ** (k + 1) * (2 * k + 2) / math.factorial(2 * k + 3)
                               for k in range(SINC_SERIES_TERMS)])
# f(x) = sum_n (-1)^n x^n/(n+1);  f'(x) = sum_n (-1)^(n+1) (n+1) x^n/(n+2).
_LOG1P_RATIO_COEFFS = np.array([(-1.0) ** n / (n + 1) for n in range(LOG1P_SERIES_TERMS)])
_LOG1P_RATIO_DERIV_COEFFS = np.array([(-1.0) ** (n + 1) * (n + 1) / (n + 2)
                                      for n in range(LOG1P_SERIES_TERMS)])

# The series are summed only as far as |x|^n falls below this: every coefficient is at most 1
# in magnitude, so the remainder is below it too (the sums are ~1). The beams' tilts keep the
# fringe term's x near 1e-3, where 8 terms do, against 64 at |x| = 0.5.
SERIES_REMAINDER = 1e-20
# Terms are taken in multiples of this many interleaved Horner chains (see _series).
SERIES_CHAINS = 4

# The numba kernels below carry no annotations (numba reads their types from the arguments),
# hence the `type: ignore[no-untyped-def]` on their defs.


# --- series helpers ----------------------------------------------------------------------

@numba.njit(cache=True)
def _series(coefficients, x):  # type: ignore[no-untyped-def]
    """sum_k coefficients[k] x^k, summed only over as many terms as ``|x|`` needs.

    The first n terms are taken, n the smallest of 8, 16, 32, ... with |x|^n below
    ``SERIES_REMAINDER`` (all of them if none is). They are summed in ``SERIES_CHAINS``
    interleaved Horner chains in x^4, since one chain of 64 terms waits ~4 cycles per term on
    the previous multiply-add: this is the inner loop of every capacitance evaluation.
    """
    size = coefficients.size
    ax2 = x * x
    power = ax2 * ax2
    power *= power  # |x|^8
    n = 8
    while n < size and power >= SERIES_REMAINDER:
        power *= power
        n *= 2
    n = min(n, size)
    x4 = ax2 * ax2
    a0 = 0.0
    a1 = 0.0
    a2 = 0.0
    a3 = 0.0
    for j in range((n + SERIES_CHAINS - 1) // SERIES_CHAINS - 1, -1, -1):
        k = SERIES_CHAINS * j
        a0 = a0 * x4 + coefficients[k]
        a1 = a1 * x4 + (coefficients[k + 1] if k + 1 < n else 0.0)
        a2 = a2 * x4 + (coefficients[k + 2] if k + 2 < n else 0.0)
        a3 = a3 * x4 + (coefficients[k + 3] if k + 3 < n else 0.0)
    return a0 + x * a1 + ax2 * (a2 + x * a3)


@numba.njit(cache=True)
def sinc(phi_rad):  # type: ignore[no-untyped-def]
    """sin(phi)/phi, 1 at phi = 0 (dimensionless, relative error < 1e-15)."""
    if abs(phi_rad) < SINC_SERIES_MAX_RAD:
        return _series(_SINC_COEFFS, phi_rad * phi_rad)
    return math.sin(phi_rad) / phi_rad


@numba.njit(cache=True)
def sinc_derivative(phi_rad):  # type: ignore[no-untyped-def]
    """d sinc/d phi in 1/rad, 0 at phi = 0 (relative error < 1e-15)."""
    if abs(phi_rad) < SINC_SERIES_MAX_RAD:
        return phi_rad * _series(_SINC_DERIV_COEFFS, phi_rad * phi_rad)
    return (phi_rad * math.cos(phi_rad) - math.sin(phi_rad)) / (phi_rad * phi_rad)


@numba.njit(cache=True)
def log1p_ratio(x):  # type: ignore[no-untyped-def]
    """f(x) = log1p(x)/x for x > -1, 1 at x = 0 (dimensionless)."""
    if abs(x) < LOG1P_SERIES_MAX:
        return _series(_LOG1P_RATIO_COEFFS, x)
    return math.log1p(x) / x


@numba.njit(cache=True)
def log1p_ratio_derivative(x):  # type: ignore[no-untyped-def]
    """f'(x) for x > -1, -1/2 at x = 0."""
    if abs(x) < LOG1P_SERIES_MAX:
        return _series(_LOG1P_RATIO_DERIV_COEFFS, x)
    return (x / (1.0 + x) - math.log1p(x)) / (x * x)


# --- closed form ---------------------------------------------------------------------------

@numba.njit(cache=True)
def main_term(gap_m, phi_rad, length_m, width_m):  # type: ignore[no-untyped-def]
    """First term of eq. (8), smooth through phi = 0, and its partial derivatives.

    C = eps0 w ln(h/g)/phi = eps0 w (L/g) sinc(phi) f(x), x = L sin(phi)/g, h = g (1 + x);
    dC/dg = -eps0 w L sinc(phi)/(g h);
    dC/dphi = eps0 w (L/g) (sinc'(phi) f(x) + sinc(phi) f'(x) L cos(phi)/g).

    Guards, so that no state gives NaN or infinity: g is floored at ``MIN_GAP_M`` (dC/dg = 0
    below it), and the far-end gap h at h_min = min(MIN_GAP_M, g/2): for h < h_min, C =
    eps0 w ln(h_min/g)/phi, with its own exact derivatives. C is continuous across h = h_min,
    dC/dphi jumps there (the formula is invalid beyond it anyway). Since h_min <= g/2 the
    clamped region keeps |sin phi| >= g/(2L) away from phi = 0.

    Parameters
    ----------
    gap_m : float
        Gap g = z_S - z_G at the suspension end (m).
    phi_rad : float
        Tilt phi (rad), > 0 lifts the far end.
    length_m, width_m : float
        Electrode length L_ES and width w_ES (m).

    Returns
    -------
    C_F, dC_dgap_F_per_m, dC_dphi_F_per_rad : float
    """
    floored = gap_m < MIN_GAP_M
    g = MIN_GAP_M if floored else gap_m
    sin_phi = math.sin(phi_rad)
    far_gap = g + length_m * sin_phi
    far_floor = min(MIN_GAP_M, 0.5 * g)
    eps_w = EPSILON_0_F_PER_M * width_m
    if far_gap < far_floor:
        # Far end on or under the ground plate: C frozen at h = far_floor along this phi.
        c = eps_w * math.log(far_floor / g) / phi_rad
        # dC/dg = 0 if g is floored, or if h_min = g/2 so that ln(h_min/g) is constant.
        dc_dgap = 0.0 if floored or far_floor < MIN_GAP_M else -eps_w / (g * phi_rad)
        return c, dc_dgap, -c / phi_rad
    x = length_m * sin_phi / g
    s = sinc(phi_rad)
    f = log1p_ratio(x)
    plate = eps_w * length_m / g  # the parallel plate at phi = 0
    c = plate * s * f
    dc_dgap = 0.0 if floored else -plate * s / far_gap
    dc_dphi = plate * (sinc_derivative(phi_rad) * f
                       + s * log1p_ratio_derivative(x) * length_m * math.cos(phi_rad) / g)
    return c, dc_dgap, dc_dphi


@numba.njit(cache=True)
def fringe_term(phi_rad, width_m, fringe_angle_rad):  # type: ignore[no-untyped-def]
    """Second term of eq. (8) with theta_eff = sqrt(phi^2 + theta_f^2), and dC/dphi.

    C = 2 eps0 w F(theta_eff), F(t) = ln(2 pi/t)/(2 pi - t) + f(-t/(2 pi))/(2 pi) with
    f(x) = log1p(x)/x (the second summand is ln(2 pi/(2 pi - t))/t); dC/dphi =
    2 eps0 w F'(theta_eff) phi/theta_eff, which is 0 at phi = 0 and bounded by about
    eps0 w/(2 pi theta_f). theta_eff is kept within [FRINGE_MIN_ANGLE_RAD,
    FRINGE_MAX_ANGLE_RAD].

    Parameters
    ----------
    phi_rad : float
        Tilt (rad).
    width_m : float
        Electrode width w_ES (m).
    fringe_angle_rad : float
        theta_f (rad), > 0.

    Returns
    -------
    C_F, dC_dphi_F_per_rad : float
    """
    theta = math.sqrt(phi_rad * phi_rad + fringe_angle_rad * fringe_angle_rad)
    if theta < FRINGE_MIN_ANGLE_RAD:
        theta = FRINGE_MIN_ANGLE_RAD
        dtheta_dphi = 0.0
    elif theta > FRINGE_MAX_ANGLE_RAD:
        theta = FRINGE_MAX_ANGLE_RAD
        dtheta_dphi = 0.0
    else:
        dtheta_dphi = phi_rad / theta
    two_pi = 2.0 * math.pi
    rest = two_pi - theta
    log_ratio = math.log(two_pi / theta)
    u = theta / two_pi
    f_value = log_ratio / rest + log1p_ratio(-u) / two_pi
    f_slope = (log_ratio / (rest * rest) - 1.0 / (theta * rest)
               - log1p_ratio_derivative(-u) / (two_pi * two_pi))
    scale = 2.0 * EPSILON_0_F_PER_M * width_m
    return scale * f_value, scale * f_slope * dtheta_dphi


@numba.njit(cache=True)
def closed_form(gap_m, phi_rad, length_m, width_m,  # type: ignore[no-untyped-def]
                fringe_angle_rad, include_fringe):
    """Capacitance of eq. (8), smooth through phi = 0, and its partial derivatives.

    Parameters
    ----------
    gap_m : float
        Gap g = z_S - z_G at the suspension end (m); floored at ``MIN_GAP_M``.
    phi_rad : float
        Tilt phi (rad), > 0 lifts the far end.
    length_m, width_m : float
        Electrode length L_ES and width w_ES (m).
    fringe_angle_rad : float
        theta_f of the fringe regularisation (rad).
    include_fringe : bool
        Whether the (regularised) fringe term is added.

    Returns
    -------
    C_F : float
        Capacitance (F).
    dC_dgap_F_per_m : float
        dC/dg = dC/dz_S (F/m).
    dC_dphi_F_per_rad : float
        dC/dphi (F/rad).

    See Also
    --------
    main_term, fringe_term : the two terms and their guards.
    """
    c, dc_dgap, dc_dphi = main_term(gap_m, phi_rad, length_m, width_m)
    if include_fringe:
        c_fringe, dc_fringe = fringe_term(phi_rad, width_m, fringe_angle_rad)
        c += c_fringe
        dc_dphi += dc_fringe
    return c, dc_dgap, dc_dphi


@numba.njit(cache=True)
def _closed_form_many(gap_m, phi_rad, length_m, width_m,  # type: ignore[no-untyped-def]
                      fringe_angle_rad, include_fringe, c, dc_dgap, dc_dphi):
    for k in range(gap_m.size):
        c[k], dc_dgap[k], dc_dphi[k] = closed_form(gap_m[k], phi_rad[k], length_m, width_m,
                                                   fringe_angle_rad, include_fringe)


def closed_form_array(gap_m: ArrayLike, phi_rad: ArrayLike, length_m: float, width_m: float,
                      fringe_angle_rad: float = DEFAULT_FRINGE_ANGLE_RAD,
                      include_fringe: bool = True) -> tuple[NDArray[np.float64], ...]:
    """:func:`closed_form` on arrays.

    Parameters
    ----------
    gap_m, phi_rad : array_like
        Gaps g (m) and tilts (rad); broadcast against each other to a shape S.
    length_m, width_m, fringe_angle_rad, include_fringe
        As for :func:`closed_form`.

    Returns
    -------
    C_F, dC_dgap_F_per_m, dC_dphi_F_per_rad : ndarray, shape S
    """
    gap, phi = np.broadcast_arrays(np.asarray(gap_m, dtype=float),
                                   np.asarray(phi_rad, dtype=float))
    out = [np.empty(gap.shape) for _ in range(3)]
    _closed_form_many(np.ascontiguousarray(gap).ravel(), np.ascontiguousarray(phi).ravel(),
                      float(length_m), float(width_m), float(fringe_angle_rad),
                      bool(include_fringe), *(o.reshape(-1) for o in out))
    return tuple(out)
