"""Viscoelastic point contact of eq. (25)-(28): activation times the power function's slope.

The activation R_a(s) is zero for a positive gap s, quadratic for a shallow overlap and linear
(stiffness k_c) beyond the transition force C. The power function R_p(v) = v/2 -
log(cosh(r_d v))/(2 r_d) has the slope (1 - tanh(r_d v))/2: a contact at rest carries half
the activation, an approaching one (v < 0) up to all of it, a separating one almost none.
"""

import math

import numba


@numba.njit(cache=True)
def activation(gap_m, stiffness_n_per_m, transition_force_n):
    """R_a of eq. (26) in N for a signed gap ``gap_m`` (negative = overlap)."""
    if gap_m >= 0.0:
        return 0.0
    if gap_m > -2.0 * transition_force_n / stiffness_n_per_m:
        return stiffness_n_per_m**2 / (4.0 * transition_force_n) * gap_m * gap_m
    return -stiffness_n_per_m * gap_m - transition_force_n


@numba.njit(cache=True)
def power_slope(rate_m_per_s, loss_s_per_m):
    """dR_p/dv of eq. (27), dimensionless, in [0, 1]."""
    return 0.5 - 0.5 * math.tanh(loss_s_per_m * rate_m_per_s)


@numba.njit(cache=True)
def contact_force(gap_m, rate_m_per_s, stiffness_n_per_m, transition_force_n, loss_s_per_m):
    """Normal contact force F = R_a dR_p/dv of eq. (25) in N, >= 0, pushing the gap open."""
    r_a = activation(gap_m, stiffness_n_per_m, transition_force_n)
    if r_a == 0.0:
        return 0.0
    return r_a * power_slope(rate_m_per_s, loss_s_per_m)


@numba.njit(cache=True)
def elastic_energy(gap_m, stiffness_n_per_m, transition_force_n):
    """Potential of the rate-independent half of the contact force, R_a/2, in J."""
    if gap_m >= 0.0:
        return 0.0
    s0 = -2.0 * transition_force_n / stiffness_n_per_m
    if gap_m > s0:
        return stiffness_n_per_m**2 * (-gap_m) ** 3 / (24.0 * transition_force_n)
    at_transition = transition_force_n**2 / (3.0 * stiffness_n_per_m)
    beyond = 0.25 * stiffness_n_per_m * gap_m * gap_m + 0.5 * transition_force_n * gap_m
    return at_transition + beyond
