"""The piecewise-linear rotation-width network (59)-(60), its inverse rules and updates."""

import numpy as np
import pytest

from sphere_control.rotation_network import NetworkShape, RotationWidthNetwork

KNOTS = NetworkShape(4).knots()  # 0, 0.25, 0.5, 0.75


def test_network_is_the_sum_of_ramps():
    net = RotationWidthNetwork(0.1, [1.0, 2.0, -1.0, 0.5], KNOTS)
    for u in np.linspace(0.0, 1.0, 21):
        expected = 0.1 + sum(w * max(0.0, u - k) for w, k in zip([1.0, 2.0, -1.0, 0.5], KNOTS,
                                                                  strict=True))
        assert net(u) == pytest.approx(expected)


def test_linear_prior_inverts_exactly():
    net = RotationWidthNetwork.linear(2.0, NetworkShape(5))
    for psi in (0.0, 0.3, 1.1, 2.0):
        assert net(net.inverse(psi)) == pytest.approx(psi)
        assert net.inverse(psi) == pytest.approx(psi / 2.0)


def test_above_the_maximum_gives_the_argmax_and_below_the_minimum_the_argmin():
    # rises to 0.5 at u = 0.5, falls to 0.25 at u = 1: the maximum lies inside
    net = RotationWidthNetwork(0.0, [1.0, 0.0, -1.5, 0.0], KNOTS)
    assert net.inverse(10.0) == pytest.approx(0.5)
    net_neg = RotationWidthNetwork(0.2, [-1.0, 0.0, 2.0, 0.0], KNOTS)  # dips to -0.3 at u=0.5
    assert net_neg.inverse(-5.0) == pytest.approx(0.5)
    assert net_neg(net_neg.inverse(-5.0)) == pytest.approx(-0.3)


def test_several_solutions_take_the_least_intensity():
    # up to 0.5 at u = 0.5, down to 0.25 at u = 0.75, up again to 0.5 at u = 1
    net = RotationWidthNetwork(0.0, [1.0, 0.0, -2.0, 2.0], KNOTS)
    u = net.inverse(0.4)
    assert u == pytest.approx(0.4)
    assert net(u) == pytest.approx(0.4)
    # the value 0.3 is reached three times; the first crossing wins
    assert net.inverse(0.3) == pytest.approx(0.3)


def test_flat_network_returns_the_least_intensity():
    net = RotationWidthNetwork(0.1, [0.0, 0.0, 0.0, 0.0], KNOTS)
    assert net.inverse(0.1) == 0.0
    assert net.inverse(1.0) == 0.0
    assert net.inverse(-1.0) == 0.0


def test_inverse_always_stays_in_the_intensity_range():
    rng = np.random.default_rng(7)
    for _ in range(200):
        net = RotationWidthNetwork(rng.normal(), rng.normal(size=4), KNOTS)
        u = net.inverse(rng.normal(scale=3.0))
        assert 0.0 <= u <= 1.0


def test_updates_learn_a_convex_characteristic():
    """Repeated (62)-(63) updates at random intensities fit h(u) = u^2.

    At constant learning rates the fit keeps fluctuating with the last samples, so it is
    compared with the prior's error (0.25 at u = 0.5) rather than with the best fit's.
    """
    net = RotationWidthNetwork.linear(1.0, NetworkShape(5))
    rng = np.random.default_rng(0)
    for _ in range(3000):
        u = rng.uniform()
        net.update(u, u ** 2, bias_rate=0.1, weight_rate=0.1)
    grid = np.linspace(0.0, 1.0, 41)
    errors = np.array([net(u) - u ** 2 for u in grid])
    assert np.mean(np.abs(errors)) < 0.03
    assert np.max(np.abs(errors)) < 0.1
    assert net.inverse(0.25) == pytest.approx(0.5, abs=0.05)


def test_knots_must_increase():
    with pytest.raises(ValueError, match='increasing'):
        RotationWidthNetwork(0.0, [1.0, 1.0], [0.5, 0.1])
