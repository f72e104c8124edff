"""The compiled right-hand side of the continuous model (paper §3).

One kernel evaluates whatever parts the assembly switched on through ``flags``; a part that
is off is never entered. State layout for ``n`` beams, with ``o = 4 n``:

======================  =====================================================
``x[2k], x[2k+1]``      z_S,k (m) and phi_k (rad) of beam k
``x[2n+2k], ...+1``     their rates (m/s, rad/s)
``x[o:o+3]``            sphere centre of gravity xi_S (m), inertial frame
``x[o+3:o+7]``          unit quaternion [w, x, y, z], body to inertial
``x[o+7:o+10]``         velocity of the centre of gravity (m/s)
``x[o+10:o+13]``        angular velocity in the body frame (rad/s)
``x[o+13+3k:o+16+3k]``  deflection of beam k's friction bristle (m), inertial
                        frame; only with a bristle reading (``F_STICTION``)
======================  =====================================================

Corrections to the printed equations (each tested, see docs/parameters.md): the mass matrix
is derived from eq. (2) by eq. (1), so L_cog enters with factor 1, not 0.5 and 0.25; damping
acts on rates (eq. 13 prints positions); Q_ES = +V^2/2 dC/dq (the co-energy gradient pulls the
plate down); the sphere's Euler equation has the gyroscopic term omega x J omega (eq. 19);
the velocity of a body point is v_S + omega x r (eq. 34/36 print the opposite sign); the
contact normal points from the full-sphere centre (eq. 42 prints the centre of gravity).
"""

import math

import numba
import numpy as np

from sphere_sim.model.capacitance import closed_form
from sphere_sim.model.capacitance_rbf import rbf_evaluate
from sphere_sim.model.contact_law import contact_force
from sphere_sim.model.friction import (
    BRISTLE_RELEASE_S,
    READING_PAPER,
    bristle_rate,
    elastoplastic_steady_force,
    friction_magnitude,
    onset_gate,
    plastic_share,
    plastic_speed,
)
from sphere_sim.model.packed import Packed
from sphere_sim.model.rotations import quat_rows
from sphere_sim.model.vec3 import add, cross, dot, mat_t_vec, matvec, scale, sub

# Indices into the integer ``flags`` vector: which parts the scene assembled.
F_N_BEAMS = 0
F_SPHERE = 1
F_GRAVITY = 2
F_ELECTROSTATICS = 3
F_RBF = 4
F_FRINGE = 5
F_GROUND_CONTACT = 6
F_SPHERE_CONTACT = 7
F_CONTACT_LOSSES = 8
F_DAMPING = 9
F_VISCOUS = 10
F_COULOMB = 11
F_STRIBECK = 12
F_FRICTION_READING = 13  # a code of sphere_sim.model.friction.READINGS
F_STICTION = 14  # the model carries a bristle per tip (readings ``paper`` and ``stiction``)
# The sphere's orientation is held: its quaternion's and angular velocity's rates are zero. Not
# a part of the device: rest_state relaxes a tilted sphere so, with every other state free.
F_ORIENTATION_HELD = 15
N_FLAGS = 16

SPHERE_STATES = 13
BRISTLE_STATES = 3  # per beam

# Diagnostics the kernel writes alongside the derivative (powers in W, gaps in m).
D_POWER_ELECTROSTATIC = 0
D_POWER_DAMPING = 1
D_POWER_CONTACT_LOSS = 2
D_POWER_FRICTION = 3
D_MIN_GROUND_GAP = 4
D_MIN_SPHERE_GAP = 5
N_DIAG = 6

# The ``part`` of the model a kernel call evaluates: every term, one beam alone (its index,
# >= 0), only the terms that depend on the sphere's state, or those of one beam's tip alone
# (``TIP_OF_BEAM - k`` for beam k; see rhs_kernel).
WHOLE_MODEL = -1
SPHERE_DEPENDENT = -2
TIP_OF_BEAM = -3

QUATERNION_GAIN_PER_S = 1.0e3  # pulls |q| back to 1 without touching the rotation itself
FAR_GAP_M = 1.0  # reported gap when a contact does not exist


@numba.njit(cache=True)
def kinematic_pairs(flags):
    """The positions whose derivative :func:`rhs_kernel` sets to another state, exactly.

    Returns
    -------
    pos, vel : ndarray of int64, shape (2 n + 3 with the sphere, else 2 n,)
        ``dx[pos[i]]/dt = x[vel[i]]``: each beam's z_S and phi, and the sphere's centre of
        gravity (not its quaternion, whose rate depends on the quaternion too).
    """
    n = flags[F_N_BEAMS]
    n_pairs = 2 * n + (3 if flags[F_SPHERE] else 0)
    pos = np.empty(n_pairs, dtype=np.int64)
    vel = np.empty(n_pairs, dtype=np.int64)
    for i in range(2 * n):
        pos[i] = i
        vel[i] = 2 * n + i
    if flags[F_SPHERE]:
        o = 4 * n
        for i in range(3):
            pos[2 * n + i] = o + i
            vel[2 * n + i] = o + 7 + i
    return pos, vel


@numba.njit(cache=True)
def capacitance_of(z_m, phi_rad, p, flags, rbf_cz, rbf_cphi, rbf_w):
    """C (F) and its partial derivatives by z_S (F/m) and phi (F/rad) for one beam."""
    if flags[F_RBF]:
        return rbf_evaluate(z_m, phi_rad, rbf_cz, rbf_cphi, p[Packed.RBF_SIGMA_Z],
                            p[Packed.RBF_SIGMA_PHI], rbf_w)
    return closed_form(z_m - p[Packed.GROUND_Z], phi_rad, p[Packed.ELECTRODE_LENGTH],
                       p[Packed.ELECTRODE_WIDTH], p[Packed.FRINGE_ANGLE], flags[F_FRINGE] != 0)


@numba.njit(cache=True)
def _bristle_drag(x, ob, e, slip_t, f_n, gate, p, flags, dxdt):
    """Friction force on the sphere (N) of the bristle at ``x[ob:ob+3]``, whose rate it
    writes into ``dxdt`` (:func:`sphere_sim.model.friction.bristle_rate`).

    The bristle's component along the normal ``e`` carries no force (it is not a tangential
    deflection); the viscous term scales with the normal force like the rest.
    """
    bristle = (x[ob], x[ob + 1], x[ob + 2])
    speed_squared = dot(slip_t, slip_t)
    mu_c = p[Packed.COULOMB]
    eta = p[Packed.VISCOUS_PER_NEWTON] if flags[F_VISCOUS] else 0.0
    mu_s = p[Packed.STRIBECK] if flags[F_STRIBECK] else mu_c + eta * p[Packed.STRIBECK_VELOCITY]
    rate = bristle_rate(bristle, slip_t, gate, speed_squared, mu_c, mu_s,
                        p[Packed.STRIBECK_VELOCITY], eta, p[Packed.PRESLIDING], p[Packed.EPSILON])
    for i in range(BRISTLE_STATES):
        dxdt[ob + i] = rate[i]
    # The bristle's force: its deflection and, through the damping time, its rate, each
    # without the component along the normal.
    tau = p[Packed.BRISTLE_DAMPING]
    loaded = (bristle[0] + tau * rate[0], bristle[1] + tau * rate[1],
              bristle[2] + tau * rate[2])
    tangential = sub(loaded, scale(dot(e, loaded), e))
    stiffness = mu_c * f_n / p[Packed.PRESLIDING]
    return (-stiffness * tangential[0] - eta * f_n * slip_t[0],
            -stiffness * tangential[1] - eta * f_n * slip_t[1],
            -stiffness * tangential[2] - eta * f_n * slip_t[2])


@numba.njit(cache=True)
def _elastoplastic_drag(x, ob, e, slip_t, f_n, gate, p, flags, dxdt):
    """Friction force on the sphere (N) of the ``paper`` reading's elasto-plastic bristle at
    ``x[ob:ob+3]``, whose rate it writes into ``dxdt``.

    The bristle b follows the slip, ``db/dt = v_t - alpha |v_t| b / b_ss`` in contact, with
    ``b_ss = f_ss(|v_t|) / k_b`` (:func:`~sphere_sim.model.friction.elastoplastic_steady_force`)
    and alpha the plastic share (0 in the elastic zone); out of contact it relaxes. The force is
    ``-gate (k_b b + tau_b k_b (1 - alpha) (v_t - alpha |v_t| b / b_ss))_t``: its damping acts
    on the elastic part of the rate only, which keeps every term's dissipation >= 0 with the
    stored energy 1/2 k_b |b|^2 (Model.bristle_energy).
    """
    bristle = (x[ob], x[ob + 1], x[ob + 2])
    speed = plastic_speed(dot(slip_t, slip_t))
    viscous = p[Packed.VISCOUS] if flags[F_VISCOUS] else 0.0
    coulomb = p[Packed.COULOMB]
    # Without the Stribeck part its peak is nothing beyond the Coulomb term's value at v_s.
    stribeck = (p[Packed.STRIBECK] if flags[F_STRIBECK]
                else coulomb * math.tanh(p[Packed.STRIBECK_VELOCITY] / p[Packed.COULOMB_VELOCITY]))
    stiffness = p[Packed.BRISTLE_STIFFNESS]
    steady = elastoplastic_steady_force(speed, f_n, gate, viscous, coulomb,
                                        p[Packed.COULOMB_VELOCITY], stribeck,
                                        p[Packed.STRIBECK_VELOCITY], p[Packed.STATIC_COEFFICIENT],
                                        p[Packed.BRISTLE_SPEED])
    steady_deflection = steady / stiffness
    length = math.sqrt(dot(bristle, bristle))
    alpha = plastic_share(length / steady_deflection, p[Packed.BREAKAWAY_RATIO])
    flow = alpha * speed / steady_deflection
    elastic = (slip_t[0] - flow * bristle[0], slip_t[1] - flow * bristle[1],
               slip_t[2] - flow * bristle[2])
    release = (1.0 - gate) / BRISTLE_RELEASE_S
    for i in range(BRISTLE_STATES):
        dxdt[ob + i] = gate * elastic[i] - release * bristle[i]
    damping = p[Packed.BRISTLE_DAMPING] * (1.0 - alpha)
    loaded = (bristle[0] + damping * elastic[0], bristle[1] + damping * elastic[1],
              bristle[2] + damping * elastic[2])
    tangential = sub(loaded, scale(dot(e, loaded), e))
    return scale(-gate * stiffness, tangential)


# Exempt from C901: one compiled pass over the beams accumulates every switched-on part's
# force on beam and sphere; split into a kernel per part, each would re-read the state and
# re-derive the tip geometry that the others need (contact, friction, bristles).
@numba.njit(cache=True)
def rhs_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, dxdt, diag,  # noqa: C901
               part=WHOLE_MODEL):
    """Write dx/dt of the assembled model into ``dxdt`` and diagnostics into ``diag``.

    Parameters
    ----------
    t : float
        Time in s (the model is autonomous given ``u``).
    x : ndarray, shape (4 n + 13 sphere,)
    u : ndarray, shape (n,)
        Beam voltages in V, held constant by the caller between programme edges.
    p : ndarray, shape (N_PARAMS,)
    flags : ndarray of int64, shape (N_FLAGS,)
    directions : ndarray, shape (n, 2)
        cos and sin of delta_k, the angle of each beam present (``Model.beam_directions``).
    rbf_cz, rbf_cphi, rbf_w : ndarray
        RBF capacitance centres (m, rad) and weights (F); unused with the closed form.
    dxdt : ndarray, shape like ``x``
    diag : ndarray, shape (N_DIAG,)
    part : int, optional
        ``WHOLE_MODEL``; or a beam's index, to evaluate that beam alone: the other beams' rows
        of ``dxdt`` are left as they were and the sphere's rates feel only this beam's tip;
        or ``SPHERE_DEPENDENT``: the beams' own forces (gravity, springs, damping,
        electrostatics, ground contact), which do not depend on the sphere's state, are left
        out, so that each beam's rates hold only its tip's contact with the sphere; or
        ``TIP_OF_BEAM - k``: that, for beam k alone (its tip's bristle enters nothing else). The
        difference of two calls with the same ``part`` is a beam's, or the sphere's, columns
        of the Jacobian (:func:`jacobian_kernel`), since the left-out forces enter the rates
        linearly.
    """
    n = flags[F_N_BEAMS]
    has_sphere = flags[F_SPHERE] != 0
    g = p[Packed.GRAVITY] if flags[F_GRAVITY] else 0.0
    damping = flags[F_DAMPING] != 0
    r_d = p[Packed.CONTACT_LOSS] if flags[F_CONTACT_LOSSES] else 0.0
    k_c, c_transition = p[Packed.CONTACT_STIFFNESS], p[Packed.TRANSITION_FORCE]
    any_friction = flags[F_VISCOUS] or flags[F_COULOMB] or flags[F_STRIBECK]
    stiction = flags[F_STICTION] != 0
    for i in range(N_DIAG):
        diag[i] = 0.0
    diag[D_MIN_GROUND_GAP] = FAR_GAP_M
    diag[D_MIN_SPHERE_GAP] = FAR_GAP_M

    m_b = p[Packed.BEAM_MASS]
    l_cog = p[Packed.BEAM_COG]
    l_b = p[Packed.BEAM_LENGTH]

    # Sphere kinematics, shared by all tips. Defaults keep every variable typed when absent.
    o = 4 * n
    force_s = (0.0, 0.0, 0.0)
    torque_b = (0.0, 0.0, 0.0)
    pos = (0.0, 0.0, 0.0)
    vel = (0.0, 0.0, 0.0)
    omega_b = (0.0, 0.0, 0.0)
    omega_i = (0.0, 0.0, 0.0)
    r_sc = (0.0, 0.0, 0.0)
    centre = (0.0, 0.0, 0.0)
    centre_vel = (0.0, 0.0, 0.0)
    R = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    if has_sphere:
        pos = (x[o], x[o + 1], x[o + 2])
        vel = (x[o + 7], x[o + 8], x[o + 9])
        omega_b = (x[o + 10], x[o + 11], x[o + 12])
        R = quat_rows(x[o + 3:o + 7])
        omega_i = matvec(R, omega_b)
        d_cog = p[Packed.COG_OFFSET]
        r_sc = (R[0][2] * d_cog, R[1][2] * d_cog, R[2][2] * d_cog)
        centre = add(pos, r_sc)
        centre_vel = add(vel, cross(omega_i, r_sc))

    own_forces = part >= WHOLE_MODEL
    only_beam = part if part >= 0 else (TIP_OF_BEAM - part if part <= TIP_OF_BEAM else -1)
    for k in range(n):
        if only_beam >= 0 and k != only_beam:
            continue
        z = x[2 * k]
        phi = x[2 * k + 1]
        zd = x[2 * n + 2 * k]
        phid = x[2 * n + 2 * k + 1]
        cphi = math.cos(phi)
        sphi = math.sin(phi)
        f1 = 0.0
        f2 = 0.0
        if own_forces:
            f1 = m_b * l_cog * sphi * phid * phid - m_b * g
            f2 = -m_b * g * l_cog * cphi
            f1 -= p[Packed.STIFFNESS_Z] * (z - p[Packed.SUSPENSION_Z])
            f2 -= p[Packed.STIFFNESS_PHI] * phi
        if damping and own_forces:
            f1 -= p[Packed.DAMPING_Z] * zd
            f2 -= p[Packed.DAMPING_PHI] * phid
            diag[D_POWER_DAMPING] -= (p[Packed.DAMPING_Z] * zd * zd
                                      + p[Packed.DAMPING_PHI] * phid * phid)
        if flags[F_ELECTROSTATICS] and u[k] != 0.0 and own_forces:
            _, dcdz, dcdphi = capacitance_of(z, phi, p, flags, rbf_cz, rbf_cphi, rbf_w)
            half_v2 = 0.5 * u[k] * u[k]
            f1 += half_v2 * dcdz
            f2 += half_v2 * dcdphi
            diag[D_POWER_ELECTROSTATIC] += half_v2 * (dcdz * zd + dcdphi * phid)
        if flags[F_GROUND_CONTACT] and own_forces:
            gap_rear = z - p[Packed.GROUND_Z] - p[Packed.INSULATION]
            lever = p[Packed.GROUND_LENGTH] / (cphi * cphi)
            gap_front = gap_rear + p[Packed.GROUND_LENGTH] * sphi / cphi
            rate_front = zd + lever * phid
            f_rear = contact_force(gap_rear, zd, k_c, c_transition, r_d)
            f_front = contact_force(gap_front, rate_front, k_c, c_transition, r_d)
            f1 += f_rear + f_front
            f2 += f_front * lever
            if r_d != 0.0:
                elastic_rear = contact_force(gap_rear, 0.0, k_c, c_transition, 0.0)
                elastic_front = contact_force(gap_front, 0.0, k_c, c_transition, 0.0)
                diag[D_POWER_CONTACT_LOSS] += ((f_rear - elastic_rear) * zd
                                               + (f_front - elastic_front) * rate_front)
            diag[D_MIN_GROUND_GAP] = min(diag[D_MIN_GROUND_GAP], gap_rear, gap_front)
        if has_sphere and flags[F_SPHERE_CONTACT]:
            cd = directions[k, 0]
            sd = directions[k, 1]
            radial = -p[Packed.SUSPENSION_RADIUS] + l_b * cphi
            tip = (radial * cd, radial * sd, z + l_b * sphi)
            dtip_dphi = (-l_b * sphi * cd, -l_b * sphi * sd, l_b * cphi)
            tip_vel = (dtip_dphi[0] * phid, dtip_dphi[1] * phid, dtip_dphi[2] * phid + zd)
            rel = sub(tip, centre)
            dist = math.sqrt(dot(rel, rel))
            gap = dist - p[Packed.SPHERE_RADIUS]
            diag[D_MIN_SPHERE_GAP] = min(diag[D_MIN_SPHERE_GAP], gap)
            ob = o + SPHERE_STATES + BRISTLE_STATES * k
            if gap < 0.0:
                e = scale(1.0 / dist, rel)
                rate = dot(e, sub(tip_vel, centre_vel))
                f_n = contact_force(gap, rate, k_c, c_transition, r_d)
                f1 += f_n * e[2]
                f2 += f_n * dot(e, dtip_dphi)
                push = scale(-f_n, e)
                force_s = add(force_s, push)
                torque_b = add(torque_b, mat_t_vec(R, cross(r_sc, push)))
                if r_d != 0.0:
                    elastic = contact_force(gap, 0.0, k_c, c_transition, 0.0)
                    diag[D_POWER_CONTACT_LOSS] += (f_n - elastic) * rate
                if any_friction:
                    r_sp = sub(tip, pos)
                    slip = sub(add(vel, cross(omega_i, r_sp)), tip_vel)
                    slip_t = sub(slip, scale(dot(e, slip), e))
                    gate = onset_gate(gap, p[Packed.VISCOUS_ONSET])
                    if stiction and flags[F_FRICTION_READING] == READING_PAPER:
                        drag = _elastoplastic_drag(x, ob, e, slip_t, f_n, gate, p, flags, dxdt)
                    elif stiction:
                        drag = _bristle_drag(x, ob, e, slip_t, f_n, gate, p, flags, dxdt)
                    else:
                        speed = math.sqrt(p[Packed.EPSILON] + dot(slip_t, slip_t))
                        f_t = friction_magnitude(
                            speed, f_n, gate, p[Packed.VISCOUS], p[Packed.COULOMB],
                            p[Packed.COULOMB_VELOCITY], p[Packed.STRIBECK],
                            p[Packed.STRIBECK_VELOCITY], flags[F_VISCOUS] != 0,
                            flags[F_COULOMB] != 0, flags[F_STRIBECK] != 0,
                            flags[F_FRICTION_READING])
                        drag = scale(-f_t / speed, slip_t)
                    f1 -= drag[2]
                    f2 -= dot(drag, dtip_dphi)
                    force_s = add(force_s, drag)
                    torque_b = add(torque_b, mat_t_vec(R, cross(r_sp, drag)))
                    diag[D_POWER_FRICTION] += dot(drag, slip_t)
            elif stiction:
                for i in range(BRISTLE_STATES):
                    dxdt[ob + i] = -x[ob + i] / BRISTLE_RELEASE_S

        # M [zdd, phidd] = [f1, f2] with the 2x2 mass matrix of eq. (1)-(2).
        m12 = m_b * l_cog * cphi
        m22 = p[Packed.BEAM_INERTIA]
        det = m_b * m22 - m12 * m12
        dxdt[2 * k] = zd
        dxdt[2 * k + 1] = phid
        dxdt[2 * n + 2 * k] = (m22 * f1 - m12 * f2) / det
        dxdt[2 * n + 2 * k + 1] = (m_b * f2 - m12 * f1) / det

    if has_sphere:
        m_s = p[Packed.SPHERE_MASS]
        force_s = (force_s[0], force_s[1], force_s[2] - m_s * g)
        if damping:
            force_s = sub(force_s, scale(p[Packed.DAMPING_TRANS], vel))
            torque_b = sub(torque_b, scale(p[Packed.DAMPING_ROT], omega_b))
            diag[D_POWER_DAMPING] -= (p[Packed.DAMPING_TRANS] * dot(vel, vel)
                                      + p[Packed.DAMPING_ROT] * dot(omega_b, omega_b))
        inertia = (p[Packed.JXX], p[Packed.JYY], p[Packed.JZZ])
        spin = (inertia[0] * omega_b[0], inertia[1] * omega_b[1], inertia[2] * omega_b[2])
        torque_b = sub(torque_b, cross(omega_b, spin))
        w, qx, qy, qz = x[o + 3], x[o + 4], x[o + 5], x[o + 6]
        wx, wy, wz = omega_b[0], omega_b[1], omega_b[2]
        stab = QUATERNION_GAIN_PER_S * (1.0 - (w * w + qx * qx + qy * qy + qz * qz))
        for i in range(3):
            dxdt[o + i] = vel[i]
            dxdt[o + 7 + i] = force_s[i] / m_s
            dxdt[o + 10 + i] = torque_b[i] / inertia[i]
        dxdt[o + 3] = 0.5 * (-qx * wx - qy * wy - qz * wz) + stab * w
        dxdt[o + 4] = 0.5 * (w * wx + qy * wz - qz * wy) + stab * qx
        dxdt[o + 5] = 0.5 * (w * wy - qx * wz + qz * wx) + stab * qy
        dxdt[o + 6] = 0.5 * (w * wz + qx * wy - qy * wx) + stab * qz
        if flags[F_ORIENTATION_HELD]:
            for i in range(4):
                dxdt[o + 3 + i] = 0.0
            for i in range(3):
                dxdt[o + 10 + i] = 0.0


# Difference steps of the Jacobian: JACOBIAN_STEP times each state's characteristic scale
# (state_scale: 1e-13 m for positions), not times |x_j|: the sphere's height is ~0.8 mm, and a
# step relative to it (8e-11 m) would straddle a contact only nanometres deep. The floor
# JACOBIAN_ROUNDING |x_j| keeps the rounding of x_j + h below ~2e-6 of the step.
JACOBIAN_STEP = 1e-7
JACOBIAN_STEP_CENTRAL = 6e-6  # ~ eps^(1/3): balances O(h^2) truncation against rounding
JACOBIAN_ROUNDING = 1e-10


@numba.njit(cache=True)
def _difference_step(x_j, scale_j, relative):
    """A step h with x_j + h exactly representable, so that (f(x + h) - f(x)) / h is exact
    in h."""
    h = max(relative * scale_j, JACOBIAN_ROUNDING * abs(x_j))
    return (x_j + h) - x_j


# Exempt from C901: the column loop chooses per state which block of rows a difference
# touches (beam, sphere, bristle); the choice is the kernel's whole job and stays compiled.
@numba.njit(cache=True)
def jacobian_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale,  # noqa: C901
                    jac):
    """d(dx/dt)/dx by compiled forward differences into ``jac``, shape (n, n).

    Steps are :func:`_difference_step` with ``JACOBIAN_STEP`` and the characteristic scales
    ``scale`` (shape (n,)), so that positions in um and rates in m/s are perturbed alike. Why
    differences and not an analytic Jacobian: docs/numerics.md.

    Each column differences only the terms that depend on its state (the ``part`` of
    :func:`rhs_kernel`). A beam's state enters only its own rows and, through its tip's force,
    the sphere's, so its columns difference the kernel of that beam alone; the sphere's state
    enters the sphere's rows and the beams' through their tips, so its columns difference the
    kernel without the beams' own forces (and their capacitances). A bristle enters only its
    beam's rates, the sphere's and its own, all through its tip's contact, so its columns
    difference that tip alone (``TIP_OF_BEAM - k``). For four beams: 14 calls of
    ``SPHERE_DEPENDENT``, 20 of one beam and, with the bristles of the ``paper`` and
    ``stiction`` readings, 16 of one tip (a quarter of the contact terms each).
    """
    n = x.size
    nb = flags[F_N_BEAMS]
    o = 4 * nb
    f0 = np.empty(n)
    f1 = np.empty(n)
    diag = np.empty(N_DIAG)
    xp = x.copy()
    sphere_rows = SPHERE_STATES if flags[F_SPHERE] else 0
    rhs_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f0, diag,
               SPHERE_DEPENDENT)
    for j in range(o, o + sphere_rows):
        h = _difference_step(x[j], scale[j], JACOBIAN_STEP)
        xp[j] = x[j] + h
        rhs_kernel(t, xp, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f1, diag,
                   SPHERE_DEPENDENT)
        for i in range(n):
            jac[i, j] = (f1[i] - f0[i]) / h
        xp[j] = x[j]
    for i in range(n):
        for j in range(o):
            jac[i, j] = 0.0
        for j in range(o + sphere_rows, n):
            jac[i, j] = 0.0
    if flags[F_STICTION]:
        for k in range(nb):
            rows = (2 * k, 2 * k + 1, 2 * nb + 2 * k, 2 * nb + 2 * k + 1)
            ob = o + SPHERE_STATES + BRISTLE_STATES * k
            tip = TIP_OF_BEAM - k
            rhs_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f0, diag, tip)
            for j in range(ob, ob + BRISTLE_STATES):
                h = _difference_step(x[j], scale[j], JACOBIAN_STEP)
                xp[j] = x[j] + h
                rhs_kernel(t, xp, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f1, diag,
                           tip)
                xp[j] = x[j]
                for i in rows:
                    jac[i, j] = (f1[i] - f0[i]) / h
                for i in range(o, o + SPHERE_STATES):
                    jac[i, j] = (f1[i] - f0[i]) / h
                for i in range(ob, ob + BRISTLE_STATES):
                    jac[i, j] = (f1[i] - f0[i]) / h
    for k in range(nb):
        rows = (2 * k, 2 * k + 1, 2 * nb + 2 * k, 2 * nb + 2 * k + 1)
        rhs_kernel(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f0, diag, k)
        for j in rows:
            h = _difference_step(x[j], scale[j], JACOBIAN_STEP)
            xp[j] = x[j] + h
            rhs_kernel(t, xp, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, f1, diag, k)
            xp[j] = x[j]
            for i in rows:
                jac[i, j] = (f1[i] - f0[i]) / h
            for i in range(o, o + sphere_rows):
                jac[i, j] = (f1[i] - f0[i]) / h
            for i in range(o + sphere_rows, n):  # the bristles': only beam k's own is written
                jac[i, j] = 0.0
            if flags[F_STICTION]:
                ob = o + SPHERE_STATES + BRISTLE_STATES * k
                for i in range(ob, ob + BRISTLE_STATES):
                    jac[i, j] = (f1[i] - f0[i]) / h


@numba.njit(cache=True)
def jacobian_kernel_central(t, x, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, scale, jac):
    """d(dx/dt)/dx by compiled central differences into ``jac``, shape (n, n).

    Twice the cost of :func:`jacobian_kernel` (2 n kernel calls) for an error of O(h^2)
    instead of O(h); used as the reference of the Jacobian checks and as an option of the
    compiled integrator (docs/numerics.md compares the two).
    """
    n = x.size
    fp = np.empty(n)
    fm = np.empty(n)
    diag = np.empty(N_DIAG)
    xp = x.copy()
    for j in range(n):
        h = _difference_step(x[j], scale[j], JACOBIAN_STEP_CENTRAL)
        xp[j] = x[j] + h
        rhs_kernel(t, xp, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, fp, diag)
        xp[j] = x[j] - h
        rhs_kernel(t, xp, u, p, flags, directions, rbf_cz, rbf_cphi, rbf_w, fm, diag)
        for i in range(n):
            jac[i, j] = (fp[i] - fm[i]) / (2.0 * h)
        xp[j] = x[j]
