"""Gaps of the model's point contacts and electrodes, compiled for the integrators.

The same geometry as the kernel's (eq. 23, 24, 32): the integrators watch these gaps to land a
step on a contact's onset and to stop a run whose electrode reached the ground electrode.
"""

import math

import numba

from sphere_sim.model import dynamics as dyn
from sphere_sim.model.packed import Packed
from sphere_sim.model.rotations import quat_rows


@numba.njit(cache=True)
def n_contacts(flags):
    """Number of point contacts the gap vector of :func:`contact_gaps` holds."""
    n = flags[dyn.F_N_BEAMS]
    count = 0
    if flags[dyn.F_GROUND_CONTACT]:
        count += 2 * n
    if flags[dyn.F_SPHERE] and flags[dyn.F_SPHERE_CONTACT]:
        count += n
    return count


@numba.njit(cache=True)
def contact_gaps(x, p, flags, directions, out):
    """Signed gaps (m) of every point contact the model has, the same as the kernel's.

    Order: rear ground gaps of the beams, front ground gaps, then tip-to-sphere gaps (eq. 23,
    24, 32); only the contacts switched on are present (``n_contacts(flags)`` entries).
    ``directions`` holds the cos and sin of each beam's angle (``Model.beam_directions``).
    """
    n = flags[dyn.F_N_BEAMS]
    ground = flags[dyn.F_GROUND_CONTACT] != 0
    sphere = flags[dyn.F_SPHERE] != 0 and flags[dyn.F_SPHERE_CONTACT] != 0
    first_sphere_gap = 2 * n if ground else 0
    cx = cy = cz = 0.0
    if sphere:
        o = 4 * n
        R = quat_rows(x[o + 3:o + 7])
        d = p[Packed.COG_OFFSET]
        cx = x[o] + R[0][2] * d
        cy = x[o + 1] + R[1][2] * d
        cz = x[o + 2] + R[2][2] * d
    l_b = p[Packed.BEAM_LENGTH]
    for k in range(n):
        z = x[2 * k]
        sin_phi = math.sin(x[2 * k + 1])
        cos_phi = math.cos(x[2 * k + 1])
        if ground:
            out[k] = z - p[Packed.GROUND_Z] - p[Packed.INSULATION]
            out[n + k] = out[k] + p[Packed.GROUND_LENGTH] * sin_phi / cos_phi
        if sphere:
            radial = -p[Packed.SUSPENSION_RADIUS] + l_b * cos_phi
            rx = radial * directions[k, 0] - cx
            ry = radial * directions[k, 1] - cy
            rz = z + l_b * sin_phi - cz
            out[first_sphere_gap + k] = (math.sqrt(rx * rx + ry * ry + rz * rz)
                                         - p[Packed.SPHERE_RADIUS])


@numba.njit(cache=True)
def closed_too_deep(gaps_start, x, p, flags, directions, depth_m, gaps_end):
    """Write the contact gaps of ``x`` into ``gaps_end`` (:func:`contact_gaps`) and return
    True if a contact open in ``gaps_start`` (gap > 0) is closed deeper than ``depth_m`` (m)
    at ``x``: the library methods' per-step onset test."""
    contact_gaps(x, p, flags, directions, gaps_end)
    for c in range(n_contacts(flags)):  # noqa: SIM110 (numba compiles no generators)
        if gaps_start[c] > 0.0 and gaps_end[c] < -depth_m:
            return True
    return False


@numba.njit(cache=True)
def first_deep_closure(xs, p, flags, directions, depth_m, gaps_a, gaps_b):
    """Index i >= 1 of the first row of ``xs`` (shape (n_rows, n_states)) at which a contact
    open at row i - 1 is closed deeper than ``depth_m`` (m), or -1: odeint's onset test, which
    sees only the states at the times it was asked for. ``gaps_a`` and ``gaps_b`` are scratch
    arrays of :func:`n_contacts` entries (at least one)."""
    if xs.shape[0] == 0:
        return -1
    contact_gaps(xs[0], p, flags, directions, gaps_a)
    for i in range(1, xs.shape[0]):
        if closed_too_deep(gaps_a, xs[i], p, flags, directions, depth_m, gaps_b):
            return i
        gaps_a, gaps_b = gaps_b, gaps_a
    return -1


@numba.njit(cache=True, inline='always')
def _electrode_gap(x, p, k):
    gap = x[2 * k] - p[Packed.GROUND_Z]
    return min(gap, gap + p[Packed.ELECTRODE_LENGTH] * math.sin(x[2 * k + 1]))


@numba.njit(cache=True)
def electrode_gaps(x, p, flags, out):
    """Smallest gap (m) between each beam's electrode and the ground electrode.

    The lesser of the suspension-end gap z_S - z_G and the far-end gap z_S - z_G + L_ES sin
    phi. The contact law keeps it above d_Iso minus the contact's penetration; at zero the
    electrode touches the ground electrode, where the parallel-plate force is unbounded and
    the model no longer describes the device.
    """
    for k in range(flags[dyn.F_N_BEAMS]):
        out[k] = _electrode_gap(x, p, k)


@numba.njit(cache=True)
def crossed_electrode(x, gaps_start, p, flags):
    """Index of the first beam whose electrode gap was > 0 in ``gaps_start`` and is <= 0 at
    ``x``, or -1. Only a crossing counts: a run may start outside (the RBF grid's edges are
    tested there)."""
    for k in range(flags[dyn.F_N_BEAMS]):
        if _electrode_gap(x, p, k) <= 0.0 < gaps_start[k]:
            return k
    return -1
