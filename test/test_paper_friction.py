"""The ``paper`` reading's friction: the paper's law while sliding, an elasto-plastic bristle
below it, checked against its closed forms (the law itself, the steady force, the elastic
zone) and for passivity, at the level of the compiled kernel's own functions."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from sphere_sim.model import dynamics as dyn
from sphere_sim.model.assembly import assemble, pack_parameters
from sphere_sim.model.friction import (
    bristle_rate,
    paper_sliding_force,
    plastic_share,
    stribeck_bump,
)
from sphere_sim.model.parameters import ParameterError, load_parameter_set
from sphere_sim.model.scene import load_scene

NORMAL = np.array([0.0, 0.0, 1.0])
LOAD_N = 2e-3  # a tip's normal force during a kick's contact


@pytest.fixture(scope='module')
def kernel_inputs():
    model = assemble(load_scene('rest'), load_parameter_set('calibrated'))
    return pack_parameters(model.params), model.flags, model.params.friction


def drag(kernel_inputs, bristle, slip, load_n=LOAD_N, gate=1.0):
    """(force on the sphere, bristle rate) of one tip, from the compiled kernel's function."""
    p, flags, _ = kernel_inputs
    x = np.asarray(bristle, dtype=float)
    dxdt = np.zeros(3)
    force = dyn._elastoplastic_drag(x, 0, (0.0, 0.0, 1.0), tuple(slip), load_n, gate, p, flags,
                                    dxdt)
    return np.array(force), dxdt


def steady_force(kernel_inputs, speed, load_n=LOAD_N):
    """The force after the bristle has settled under a constant slip ``speed`` along x."""
    _, _, f = kernel_inputs
    slip = (speed, 0.0, 0.0)

    def rate(_t, b):
        return drag(kernel_inputs, b, slip, load_n)[1]

    # Settled after many relaxation lengths of its steady deflection (at most f_ss / k_b).
    longest = (f.static_coefficient * load_n + 1.0) / f.bristle_stiffness_n_per_m
    sol = solve_ivp(rate, (0.0, 40.0 * longest / speed), np.zeros(3), method='LSODA',
                    rtol=1e-10, atol=1e-18)
    return drag(kernel_inputs, sol.y[:, -1], slip, load_n)[0]


def test_the_sliding_law_is_eq_47_48_with_d_v_beside_it():
    """Table A1's coefficients: Coulomb and Stribeck total mu_s F_n at v_s, the viscous term
    d_v v_s beside them; Coulomb's tanh far above v_s; the viscous term alone without load."""
    f = load_parameter_set('table_a1').friction
    args = (f.viscous_ns_per_m, f.coulomb, f.coulomb_velocity_m_per_s, f.stribeck,
            f.stribeck_velocity_m_per_s)
    v_s = f.stribeck_velocity_m_per_s
    assert paper_sliding_force(v_s, LOAD_N, 1.0, *args) == pytest.approx(
        f.stribeck * LOAD_N + f.viscous_ns_per_m * v_s, rel=1e-12)
    fast = 20.0 * v_s
    coulomb = f.coulomb * LOAD_N * math.tanh(fast / f.coulomb_velocity_m_per_s)
    assert paper_sliding_force(fast, LOAD_N, 1.0, *args) == pytest.approx(
        f.viscous_ns_per_m * fast + coulomb, rel=1e-9)
    assert paper_sliding_force(v_s, 0.0, 1.0, *args) == pytest.approx(f.viscous_ns_per_m * v_s)
    assert paper_sliding_force(v_s, 0.0, 0.0, *args) == 0.0  # nothing before the contact's onset
    # Dissipative at every speed: it never drives.
    speeds = np.geomspace(1e-7, 10.0, 400)
    assert all(paper_sliding_force(v, LOAD_N, 1.0, *args) > 0.0 for v in speeds)
    assert stribeck_bump(1.0) == 1.0


@pytest.mark.parametrize('speed_factor', [10.0, 30.0, 1e3, 1e5])
def test_from_ten_bristle_speeds_on_the_force_is_the_papers_law_to_one_percent(kernel_inputs,
                                                                                speed_factor):
    _, _, f = kernel_inputs
    speed = speed_factor * f.bristle_speed_m_per_s
    force = steady_force(kernel_inputs, speed)
    law = paper_sliding_force(speed, LOAD_N, 1.0, f.viscous_ns_per_m, f.coulomb,
                              f.coulomb_velocity_m_per_s, f.stribeck,
                              f.stribeck_velocity_m_per_s)
    assert force[0] < 0.0 and force[1] == 0.0 and force[2] == 0.0  # against the slip
    assert abs(-force[0] - law) <= 0.01 * law


def test_at_creeping_speeds_the_bristle_holds_the_static_limit(kernel_inputs):
    """Far below the bristle speed the steady force is mu_b F_n, where the paper's law alone
    would give almost nothing: that is what holds a resting sphere."""
    _, _, f = kernel_inputs
    speed = 1e-2 * f.bristle_speed_m_per_s
    force = steady_force(kernel_inputs, speed)
    # Within 2e-3: the Gaussian's 1e-4 and the plastic speed's smoothing (1 nm/s of 1 um/s).
    assert -force[0] == pytest.approx(f.static_coefficient * LOAD_N, rel=2e-3)
    law = paper_sliding_force(speed, LOAD_N, 1.0, f.viscous_ns_per_m, f.coulomb,
                              f.coulomb_velocity_m_per_s, f.stribeck,
                              f.stribeck_velocity_m_per_s)
    assert law < 1e-3 * f.static_coefficient * LOAD_N


def test_oscillating_loads_below_break_away_cause_no_drift(kernel_inputs):
    """A tip swept back and forth inside the elastic zone returns its bristle exactly to where
    it started, cycle after cycle; the LuGre bristle of the ``stiction`` reading, loaded the
    same way, creeps (the ratchet the elastic zone removes)."""
    _, _, f = kernel_inputs
    limit = f.breakaway_ratio * f.static_coefficient * LOAD_N / f.bristle_stiffness_n_per_m
    amplitude = 0.5 * limit
    omega = 2.0 * math.pi * 1e3
    offset = np.array([0.3 * limit, 0.0, 0.0])

    def rate(t, b):
        slip = (amplitude * omega * math.cos(omega * t), 0.0, 0.0)
        return drag(kernel_inputs, b, slip)[1]

    periods = 20
    t_end = periods * 2.0 * math.pi / omega
    sol = solve_ivp(rate, (0.0, t_end), offset, method='LSODA', rtol=1e-11, atol=1e-22,
                    max_step=0.02 * 2.0 * math.pi / omega)
    assert np.max(np.linalg.norm(sol.y, axis=0)) < limit  # stayed elastic
    assert np.linalg.norm(sol.y[:, -1] - offset) < 1e-6 * limit

    dry = load_parameter_set('dry_contact').friction

    def lugre(t, b):
        slip = (amplitude * omega * math.cos(omega * t), 0.0, 0.0)
        return bristle_rate(tuple(b), slip, 1.0, slip[0] ** 2, dry.coulomb, dry.stribeck,
                            dry.stribeck_velocity_m_per_s, 0.0, dry.presliding_m,
                            dry.epsilon_m2_per_s2)

    start = np.array([0.3 * dry.presliding_m, 0.0, 0.0])
    crept = solve_ivp(lugre, (0.0, t_end), start, method='LSODA', rtol=1e-11, atol=1e-22,
                      max_step=0.02 * 2.0 * math.pi / omega)
    assert abs(crept.y[0, -1] - start[0]) > 1e-3 * dry.presliding_m


def test_the_plastic_share_is_zero_in_the_elastic_zone_and_one_beyond_the_steady_deflection():
    assert plastic_share(0.0, 0.5) == 0.0
    assert plastic_share(0.5, 0.5) == 0.0
    assert plastic_share(0.75, 0.5) == pytest.approx(0.5)
    assert plastic_share(1.0, 0.5) == 1.0
    assert plastic_share(3.0, 0.5) == 1.0
    ratios = np.linspace(0.0, 1.2, 241)
    shares = [plastic_share(r, 0.5) for r in ratios]
    assert np.all(np.diff(shares) >= 0.0)


def test_the_bristle_never_makes_energy(kernel_inputs):
    """At random deflections (inside and far beyond the steady one), slips, loads and onset
    gates: the power the friction takes from the bodies exceeds what the bristle stores,
    -(F . v_t) - d/dt (k_b |b|^2 / 2) >= 0."""
    _, _, f = kernel_inputs
    rng = np.random.default_rng(11)
    worst = math.inf
    for _ in range(4000):
        load = 10.0 ** rng.uniform(-6, -1)
        scale_m = f.static_coefficient * load / f.bristle_stiffness_n_per_m
        bristle = rng.normal(0.0, scale_m * 10.0 ** rng.uniform(-2, 1), 3)
        speed = 10.0 ** rng.uniform(-8, 0)
        slip = rng.normal(size=3)
        slip[2] = 0.0  # tangential to the normal (0, 0, 1)
        slip *= speed / np.linalg.norm(slip)
        gate = rng.choice([1.0, rng.uniform()])
        force, rate = drag(kernel_inputs, bristle, slip, load, gate)
        taken = -float(force @ slip)
        stored = f.bristle_stiffness_n_per_m * float(bristle @ rate)
        dissipated = taken - stored
        magnitude = abs(taken) + abs(stored) + 1e-30
        worst = min(worst, dissipated / magnitude)
    assert worst > -1e-9


def test_a_sliding_law_that_would_drive_is_refused(tmp_path):
    """Coefficients whose Coulomb and Stribeck terms turn negative at some speed would inject
    energy; the set is refused at load time with one line."""
    path = tmp_path / 'driving.yaml'
    # mu_s = 0 under Table A1's mu_c = 2: the Stribeck term's -mu_c tanh(v_s/v_c) wins at low speed
    path.write_text('name: driving\nbase: table_a1\noverrides:\n  friction.stribeck: 0.0\n')
    with pytest.raises(ParameterError, match='drives'):
        load_parameter_set(path)
