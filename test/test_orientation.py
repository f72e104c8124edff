"""Quaternion orientation: Cardan angles at the interface, no trouble at gimbal lock."""

import math

import numpy as np
import pytest
from physics_helpers import scene_with

from sphere_sim.integrate.solve import simulate
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import explicit_state
from sphere_sim.model.packed import Packed
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.rotations import (
    cardan_to_matrix,
    cardan_to_quat,
    matrix_to_cardan,
    quat_to_cardan,
    quat_to_matrix,
)


@pytest.mark.parametrize('angles', [(0.1, -0.2, 0.3), (-1.0, 0.5, 2.0), (0.0, 0.0, 0.0),
                                    (0.3, 1.2, -0.4)])
def test_cardan_round_trip_and_surface_normal_of_eq_53(angles):
    q = cardan_to_quat(*angles)
    np.testing.assert_allclose(quat_to_matrix(q), cardan_to_matrix(*angles), atol=1e-14)
    np.testing.assert_allclose(quat_to_cardan(q), angles, atol=1e-12)
    alpha, beta, _ = angles
    normal = quat_to_matrix(q)[:, 2]
    np.testing.assert_allclose(normal[:2], [math.sin(beta), -math.cos(beta) * math.sin(alpha)],
                               atol=1e-14)


def test_gimbal_lock_reports_finite_angles():
    R = cardan_to_matrix(0.3, math.pi / 2, 0.2)
    alpha, beta, gamma = matrix_to_cardan(R)
    assert beta == pytest.approx(math.pi / 2)
    np.testing.assert_allclose(cardan_to_matrix(alpha, beta, gamma), R, atol=1e-9)


def test_free_rotation_passes_through_gimbal_lock():
    # A sphere spinning about its body y axis, far from the beams, without gravity: the normal
    # turns through beta = 90 deg at a constant rate.
    scene = scene_with(gravity=False, damping=False)
    model = assemble(scene)
    x = explicit_state(model, sphere_position_m=(0.0, 0.0, 0.1))
    omega = 2 * math.pi * 50.0  # rad/s
    x[model.sphere_offset + 11] = omega
    t_end = 0.5 * math.pi / omega * 1.5  # 135 deg, past the singularity
    traj = simulate(model, x, t_end, PulseProgramme(), rtol=1e-10, sample_period_s=t_end / 50)
    expected = np.stack([np.sin(omega * traj.t), np.zeros_like(traj.t), np.cos(omega * traj.t)])
    np.testing.assert_allclose(traj.surface_normal(), expected, atol=1e-7)
    betas = [quat_to_cardan(traj.x[model.sphere_offset + 3:model.sphere_offset + 7, i])[1]
             for i in range(traj.t.size)]
    assert max(betas) == pytest.approx(math.pi / 2, abs=0.05)


def test_torque_free_spin_conserves_angular_momentum():
    # The gyroscopic term omega x J omega of the Euler equation (missing in eq. 19) is what
    # keeps the inertial angular momentum constant for a spin off the symmetry axis.
    scene = scene_with(gravity=False, damping=False)
    model = assemble(scene)
    x = explicit_state(model, sphere_position_m=(0.0, 0.0, 0.1))
    o = model.sphere_offset
    x[o + 10:o + 13] = [40.0, 0.0, 200.0]
    traj = simulate(model, x, 0.05, PulseProgramme(), rtol=1e-10, sample_period_s=1e-3)
    inertia = model.p[Packed.JXX:Packed.JZZ + 1]
    momenta = np.stack([quat_to_matrix(np.ascontiguousarray(traj.x[o + 3:o + 7, i]))
                        @ (inertia * traj.x[o + 10:o + 13, i]) for i in range(traj.t.size)])
    assert np.ptp(traj.x[o + 10], axis=0) > 10.0  # the body rates do precess
    np.testing.assert_allclose(momenta, np.tile(momenta[0], (traj.t.size, 1)), rtol=0,
                               atol=1e-7 * np.linalg.norm(momenta[0]))
