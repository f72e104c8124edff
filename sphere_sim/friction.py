"""Tangential friction at a beam tip, eq. (45)-(51), as a force magnitude.

The generalised friction force is Q = -f d|v_t|/dq_dot with f >= 0 when dissipative. Two
readings of the paper's coefficients are offered (docs/parameters.md):

``dissipative`` (default)
    f = d_v |v| + mu_c F_n tanh(|v|/v_c) + mu_s F_n (|v|/v_s) exp((1 - (|v|/v_s)^2)/2),
    all coefficients >= 0: viscous, regularised Coulomb and a Stribeck bump of height
    mu_s F_n at |v| = v_s. Every term is >= 0, so friction never adds energy.
``printed``
    f = -dD/d|v| with D of eq. (46)-(48) and Table A1's signs (d_v < 0, mu_c < 0, mu_s > 0),
    which gives f = mu_s F_n < 0 at v_s: it injects energy. Kept only as a flagged variant.
"""

import math

import numba


@numba.njit(cache=True)
def onset_gate(gap_m, onset_m):
    """Smooth 0..1 ramp of the viscous term over the first ``onset_m`` of overlap (C1)."""
    if gap_m >= 0.0:
        return 0.0
    if onset_m <= 0.0 or gap_m <= -onset_m:
        return 1.0
    xi = -gap_m / onset_m
    return xi * xi * (3.0 - 2.0 * xi)


@numba.njit(cache=True)
def friction_magnitude(speed_m_per_s, normal_force_n, gate, viscous_ns_per_m, coulomb,
                       coulomb_velocity_m_per_s, stribeck, stribeck_velocity_m_per_s,
                       use_viscous, use_coulomb, use_stribeck, printed):
    """Friction force magnitude f in N at tangential speed ``speed_m_per_s`` (>= 0).

    ``gate`` scales the velocity-proportional terms, which do not scale with the normal force.
    """
    ratio_s = speed_m_per_s / stribeck_velocity_m_per_s
    bump = ratio_s * math.exp(0.5 - 0.5 * ratio_s * ratio_s)
    f = 0.0
    if printed:
        d_v = -viscous_ns_per_m
        mu_c = -coulomb
        mu_s = stribeck
        if use_viscous:
            f -= gate * d_v * speed_m_per_s
        if use_coulomb:
            f -= mu_c * normal_force_n * math.tanh(speed_m_per_s / coulomb_velocity_m_per_s)
        if use_stribeck:
            peak = (gate * d_v * stribeck_velocity_m_per_s
                    - (mu_s - mu_c * math.tanh(stribeck_velocity_m_per_s
                                              / coulomb_velocity_m_per_s)) * normal_force_n)
            f += peak * bump
        return f
    if use_viscous:
        f += gate * viscous_ns_per_m * speed_m_per_s
    if use_coulomb:
        f += coulomb * normal_force_n * math.tanh(speed_m_per_s / coulomb_velocity_m_per_s)
    if use_stribeck:
        f += stribeck * normal_force_n * bump
    return f
