"""Tangential friction at a beam tip, eq. (45)-(51), and the bristle that makes it stick.

Five readings of the paper's friction (docs/parameters.md compares them):

``paper`` (default)
    The paper's law while sliding, with stiction added below it. Sliding at |v| the force is
    ``f(v) = d_v v + mu_c F_n tanh(v/v_c) + (mu_s - mu_c tanh(v_s/v_c)) F_n x exp((1 - x^2)/2)``,
    ``x = v/v_s``: eq. (47)-(48) with Table A1's coefficients (as magnitudes: Table A1's signs
    with Q = F d|v|/dq_dot), which make the Coulomb and Stribeck terms total ``mu_s F_n`` at
    v_s, and eq. (46)'s load-independent viscous term beside them (so the total at v_s is
    ``mu_s F_n + d_v v_s``). Below a bristle speed ``v_b`` far under v_c an elasto-plastic
    bristle (Dupont et al. 2002) carries the force: a spring of constant stiffness ``k_b``,
    purely elastic up to a break-away deflection, whose steady sliding force is
    ``f(v) + mu_b F_n exp(-(v/v_b)^2)``: the static limit ``mu_b F_n`` at rest, the paper's
    law (exactly) from a few v_b on. Sub-break-away loads, however they oscillate, cause no
    drift.
``stiction``
    An elastic bristle per contact (LuGre family) carries the friction force, so that a contact
    loaded below its static limit sticks instead of creeping. Its deflection ``b`` (m) obeys
    ``db/dt = v_t - p b / (delta mu(|v_t|)/mu_c)``, p the slip rate |v_t| (smoothed below
    1 nm/s, :func:`plastic_speed`), and the force on the sphere is
    ``-mu_c F_n (b + tau_b db/dt)_t / delta - eta F_n v_t``: stiff as a spring up to the
    static limit ``mu_c F_n`` (reached after a presliding displacement ``delta``), sliding at
    ``mu(|v|) F_n`` with the curve of eq. (46)-(48) read so that the total at v_s is
    ``mu_s F_n``: ``mu(v) = mu_c + (mu_s - mu_c - eta v_s) x exp((1 - x^2)/2)``, ``x = v/v_s``.
    Every coefficient scales with the normal force, so nothing acts without a load.
``structure``
    Eq. (46)-(48) regularised as printed, with the coefficients' magnitudes: the total at v_s is
    ``mu_s F_n`` (48's construction), clipped at zero where the literal set would drive.
``additive``
    f = d_v |v| + mu_c F_n tanh(|v|/v_c) + mu_s F_n (|v|/v_s) exp((1 - (|v|/v_s)^2)/2): the
    Stribeck term added to the Coulomb term, all >= 0 (about 2.02 F_n at v_s with Table A1).
``printed``
    f = -dD/d|v| with D of eq. (46)-(48) and Table A1's signs (d_v < 0, mu_c < 0, mu_s > 0),
    which gives f = mu_s F_n < 0 at v_s: it injects energy. Kept only as a flagged variant.

The regularised readings return a force magnitude f with Q = -f d|v_t|/dq_dot; they have no
stiction, so a tilted resting sphere creeps back towards level under them.
"""

import math

import numba

# Codes of the readings in the compiled kernel (index into READINGS).
READINGS = ('stiction', 'structure', 'additive', 'printed', 'paper')
READING_STICTION = 0
READING_STRUCTURE = 1
READING_ADDITIVE = 2
READING_PRINTED = 3
READING_PAPER = 4
# The readings that carry a bristle per tip (states of the model).
BRISTLE_READINGS = (READING_STICTION, READING_PAPER)

# A bristle whose tip has left the sphere relaxes with this time constant, so that the next
# touch starts unloaded: 10 us, short against a flight (>= 0.3 ms) and long against the
# contact's own rates only where nothing is in contact (the relaxation is linear and stiff-safe).
BRISTLE_RELEASE_S = 1.0e-5
# Slip speed below which the bristle's plastic rate is smoothed (plastic_speed): a creep of
# 1 nm/s turns the sphere by 6e-5 deg/s, far below anything measured.
PLASTIC_SMOOTHING_M_PER_S = 1.0e-9


@numba.njit(cache=True)
def onset_gate(gap_m, onset_m):
    """Smooth 0..1 ramp over the first ``onset_m`` of overlap (C1)."""
    if gap_m >= 0.0:
        return 0.0
    if onset_m <= 0.0 or gap_m <= -onset_m:
        return 1.0
    xi = -gap_m / onset_m
    return xi * xi * (3.0 - 2.0 * xi)


@numba.njit(cache=True)
def stribeck_bump(ratio):
    """x exp((1 - x^2)/2): zero at rest, 1 at x = 1 (v = v_s), the shape of eq. (48)."""
    return ratio * math.exp(0.5 - 0.5 * ratio * ratio)


@numba.njit(cache=True)
def sliding_coefficient(speed_m_per_s, coulomb, stribeck, stribeck_velocity_m_per_s,
                        viscous_s_per_m):
    """mu(v) of the ``stiction`` reading: the bristle's sliding limit over F_n.

    mu_c at rest and at high speed, mu_s - eta v_s at v_s, so that with the viscous term
    eta v the total at v_s is mu_s (the structure of eq. 48).
    """
    amplitude = stribeck - coulomb - viscous_s_per_m * stribeck_velocity_m_per_s
    return coulomb + amplitude * stribeck_bump(speed_m_per_s / stribeck_velocity_m_per_s)


@numba.njit(cache=True)
def plastic_speed(speed_squared):
    """|v_t| for the bristle's slip: v^2 / (sqrt(v0^2 + v^2) + v0), v0 = ``PLASTIC_SMOOTHING``.

    Zero at rest and smooth there, and within v0 of |v| everywhere. Eq. (51)'s sqrt(eps + v^2)
    would leave the bristle slipping at sqrt(eps) = 1e-5 m/s at rest, a creep of its own. The
    exact |v| has a kink at rest that a stiff solver at tight tolerance chatters on (a resting
    sphere took 2.4 million steps over 10 s at rtol 1e-8). Below v0 the smoothing lets a bristle
    pass its static limit (as v0/v), but only while the contact creeps slower than 1 nm/s.
    """
    return speed_squared / (math.sqrt(PLASTIC_SMOOTHING_M_PER_S**2 + speed_squared)
                            + PLASTIC_SMOOTHING_M_PER_S)


@numba.njit(cache=True)
def bristle_rate(bristle, slip_t, gate, speed_squared, coulomb, stribeck,
                 stribeck_velocity_m_per_s, viscous_s_per_m, presliding_m, epsilon_m2_per_s2):
    """d b/dt of one contact's bristle (m/s, a 3-tuple).

    In contact (``gate`` 1) it follows the tangential slip ``slip_t`` until its deflection
    reaches ``presliding_m mu(|v|)/mu_c``; out of contact (``gate`` 0) it relaxes in
    ``BRISTLE_RELEASE_S``; the onset gate blends the two over the first overlap.
    """
    ratio = (sliding_coefficient(math.sqrt(epsilon_m2_per_s2 + speed_squared), coulomb,
                                 stribeck, stribeck_velocity_m_per_s, viscous_s_per_m) / coulomb)
    plastic = plastic_speed(speed_squared) / (presliding_m * ratio)
    release = (1.0 - gate) / BRISTLE_RELEASE_S
    return (gate * (slip_t[0] - plastic * bristle[0]) - release * bristle[0],
            gate * (slip_t[1] - plastic * bristle[1]) - release * bristle[1],
            gate * (slip_t[2] - plastic * bristle[2]) - release * bristle[2])


# Exempt from C901: the four readings side by side in one compiled branch per call; a
# reading per function would be four kernels dispatched by a code the caller must also carry.
@numba.njit(cache=True)
def friction_magnitude(speed_m_per_s, normal_force_n, gate, viscous_ns_per_m, coulomb,  # noqa: C901
                       coulomb_velocity_m_per_s, stribeck, stribeck_velocity_m_per_s,
                       use_viscous, use_coulomb, use_stribeck, reading):
    """Friction force magnitude f in N of a regularised reading at tangential speed
    ``speed_m_per_s`` (>= 0).

    ``gate`` scales the velocity-proportional terms, which do not scale with the normal force.
    """
    if reading == READING_PAPER:
        # The law the bristle slides with (dynamics._elastoplastic_drag), without the bristle:
        # without the Stribeck part its peak is the Coulomb term's value at v_s.
        if not use_coulomb:
            return 0.0
        peak = (stribeck if use_stribeck
                else coulomb * math.tanh(stribeck_velocity_m_per_s / coulomb_velocity_m_per_s))
        return paper_sliding_force(speed_m_per_s, normal_force_n, gate,
                                   viscous_ns_per_m if use_viscous else 0.0, coulomb,
                                   coulomb_velocity_m_per_s, peak, stribeck_velocity_m_per_s)
    bump = stribeck_bump(speed_m_per_s / stribeck_velocity_m_per_s)
    coulomb_shape = math.tanh(speed_m_per_s / coulomb_velocity_m_per_s)
    f = 0.0
    if reading == READING_PRINTED:
        d_v = -viscous_ns_per_m
        mu_c = -coulomb
        mu_s = stribeck
        if use_viscous:
            f -= gate * d_v * speed_m_per_s
        if use_coulomb:
            f -= mu_c * normal_force_n * coulomb_shape
        if use_stribeck:
            peak = (gate * d_v * stribeck_velocity_m_per_s
                    - (mu_s - mu_c * math.tanh(stribeck_velocity_m_per_s
                                              / coulomb_velocity_m_per_s)) * normal_force_n)
            f += peak * bump
        return f
    if reading == READING_STRUCTURE:
        # The total at v_s is mu_s F_n: the Stribeck term makes up the difference to the
        # viscous and Coulomb terms there.
        at_v_s = 0.0
        if use_viscous:
            f += gate * viscous_ns_per_m * speed_m_per_s
            at_v_s += gate * viscous_ns_per_m * stribeck_velocity_m_per_s
        if use_coulomb:
            f += coulomb * normal_force_n * coulomb_shape
            at_v_s += coulomb * normal_force_n * math.tanh(stribeck_velocity_m_per_s
                                                           / coulomb_velocity_m_per_s)
        if use_stribeck:
            f += (stribeck * normal_force_n - at_v_s) * bump
        return max(f, 0.0)
    if use_viscous:
        f += gate * viscous_ns_per_m * speed_m_per_s
    if use_coulomb:
        f += coulomb * normal_force_n * coulomb_shape
    if use_stribeck:
        f += stribeck * normal_force_n * bump
    return f


@numba.njit(cache=True)
def paper_sliding_force(speed_m_per_s, normal_force_n, gate, viscous_ns_per_m, coulomb,
                        coulomb_velocity_m_per_s, stribeck, stribeck_velocity_m_per_s):
    """f(v) in N of the ``paper`` reading while sliding at ``speed_m_per_s`` (>= 0).

    Eq. (47) and (48) with the Coulomb and Stribeck coefficients of Table A1 (their total at
    v_s is ``stribeck`` F_n), and eq. (46)'s viscous term, which does not scale with the normal
    force and so is ramped in by the contact's onset ``gate``.
    """
    peak = stribeck - coulomb * math.tanh(stribeck_velocity_m_per_s / coulomb_velocity_m_per_s)
    loaded = (coulomb * math.tanh(speed_m_per_s / coulomb_velocity_m_per_s)
              + peak * stribeck_bump(speed_m_per_s / stribeck_velocity_m_per_s))
    return gate * viscous_ns_per_m * speed_m_per_s + normal_force_n * loaded


@numba.njit(cache=True)
def plastic_share(deflection_ratio, breakaway_ratio):
    """alpha of the elasto-plastic bristle (Dupont et al. 2002), 0..1, of |b| / b_ss.

    0 up to the break-away ``breakaway_ratio`` (the elastic zone: no slip of the bristle at
    all), 1 from the steady deflection b_ss on, a half sine between (C1).
    """
    if deflection_ratio <= breakaway_ratio:
        return 0.0
    if deflection_ratio >= 1.0:
        return 1.0
    middle = 0.5 * (1.0 + breakaway_ratio)
    return 0.5 + 0.5 * math.sin(math.pi * (deflection_ratio - middle) / (1.0 - breakaway_ratio))


@numba.njit(cache=True)
def elastoplastic_steady_force(speed_m_per_s, normal_force_n, gate, viscous_ns_per_m, coulomb,
                               coulomb_velocity_m_per_s, stribeck, stribeck_velocity_m_per_s,
                               static_coefficient, bristle_speed_m_per_s):
    """The bristle's steady sliding force (N) of the ``paper`` reading at a slip speed: the
    paper's law plus the static limit ``mu_b F_n``, which fades as exp(-(v/v_b)^2)."""
    ratio = speed_m_per_s / bristle_speed_m_per_s
    return (paper_sliding_force(speed_m_per_s, normal_force_n, gate, viscous_ns_per_m, coulomb,
                                coulomb_velocity_m_per_s, stribeck, stribeck_velocity_m_per_s)
            + static_coefficient * normal_force_n * math.exp(-ratio * ratio))
