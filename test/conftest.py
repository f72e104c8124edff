"""Shared fixtures.

``ros_nodes`` is the only way a test starts ROS node processes: it is built on
:mod:`sphere_twin.processes`, the same supervisor ``sphere-twin demo`` uses.
"""

import pytest

from sphere_twin.processes import fresh_domain_id, running_nodes

# Per-signal timeout when stopping at teardown: a node shuts down in well under a second, so
# this only matters for a hung one, which then gets SIGTERM and SIGKILL.
TEARDOWN_STOP_TIMEOUT_S = 5.0


@pytest.fixture
def ros_nodes():
    """Start node processes for one test, on a ROS domain of its own.

    Yields a :class:`sphere_twin.processes.NodeGroup`. ``ros_nodes.start('simulator', args)``
    starts a node with ``ROS_DOMAIN_ID=ros_nodes.domain_id`` and discovery limited to
    localhost, and returns its :class:`~sphere_twin.processes.NodeProcess`. Every process
    started through it is stopped by its PID at teardown (SIGINT, then SIGTERM, then
    SIGKILL), whether the test passed or not.
    """
    with running_nodes(domain_id=fresh_domain_id(),
                       stop_timeout_s=TEARDOWN_STOP_TIMEOUT_S) as group:
        yield group


@pytest.fixture
def twin():
    """A lockstep simulator (discrete plant) on a private domain; see sphere_twin.testing."""
    from sphere_twin.testing import lockstep_twin

    with lockstep_twin(plant='discrete', seed=0) as client:
        yield client


@pytest.fixture(scope='session')
def model():
    """The shipped rest scene's model (calibrated parameters, four beams and the sphere)."""
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.scene import load_scene

    return assemble(load_scene('rest'))


@pytest.fixture(scope='session')
def x_rest(model):
    """The sphere resting level on the four tips."""
    from sphere_sim.model.initial_state import rest_state

    return rest_state(model)


@pytest.fixture
def context(monkeypatch):
    """An rclpy context of its own, on a fresh domain with localhost discovery, for nodes
    built and driven inside the test's process."""
    import rclpy

    from sphere_twin.node_runtime.ros_env import DISCOVERY_RANGE_VAR

    monkeypatch.setenv(DISCOVERY_RANGE_VAR, 'LOCALHOST')
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=fresh_domain_id())
    yield context
    rclpy.try_shutdown(context=context)


@pytest.fixture(scope='session')
def kick_trajectory(model, x_rest):
    """The committed optimised kick, 40 ms from rest sampled every 0.5 ms: every contact phase
    (pressed, released, bouncing, settling) for tests that need states along a real kick."""
    from pathlib import Path

    from sphere_sim.integrate.solve import simulate
    from sphere_sim.kicks.design import KickDesign

    design = Path(__file__).parents[1] / 'bench' / 'results' / 'kick_optimization.json'
    return simulate(model, x_rest, 40e-3, KickDesign.load(design).programme(),
                    sample_period_s=0.5e-3)
