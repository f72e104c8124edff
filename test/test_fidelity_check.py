"""check_fidelity: the full model beside the twin, on every kick it served."""

import concurrent.futures
import math

import numpy as np
import pytest

from sphere_sim.integrate.solve import DEFAULT_METHOD
from sphere_sim.integrate.tolerances import CHECK_RTOL
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal
from sphere_sim.kicks.lookup_table import LookupTable
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import PulseProgramme
from sphere_sim.model.rotations import angle_between
from sphere_sim.model.scene import load_scene
from sphere_sim.twin import fidelity_check as fc
from sphere_sim.twin.ladder import tilted_normal
from sphere_sim.twin.plants import LIVE_ERROR_BOUND_RAD, ContinuousPlant
from sphere_sim.twin.runner import TwinRunner

PERIOD_S = 0.01
WINDOW_S = 0.06


class InlineExecutor(concurrent.futures.Executor):
    """Runs each task at once in this process (the check's process pool, without processes)."""

    def submit(self, fn, /, *args, **kwargs):
        future = concurrent.futures.Future()
        future.set_result(fn(*args, **kwargs))
        return future


@pytest.fixture(scope='module')
def tilted():
    """The model, a rest 20 deg off level (off the mirror lines) and the diagonal kick there."""
    model = assemble(load_scene('rest'))
    normal = tilted_normal(20.0, 20.0)
    x0 = rest_state(model, cardan_of_normal(normal), relaxation=KICK_RELAXATION)
    # As the twin holds it: rebuilt from its segments (the wire carries segments).
    programme = PulseProgramme.from_segments(*LookupTable.load().programme(0, 1.0, normal)
                                             .segments())
    return model, x0, programme


def _run(model, x0, programmes_at_s, duration_s, check):
    runner = TwinRunner(ContinuousPlant(model, x0), PERIOD_S, check=check)
    for start_s, programme in programmes_at_s:
        times, volts = programme.segments()
        runner.command_programme(times, volts, start_s)
    normals = {}
    while runner.time_s < duration_s - 1e-9:
        sample, refused = runner.tick()
        assert not refused
        normals[round(sample.snapshot.time_s / PERIOD_S)] = sample.snapshot.normal
    return normals


def _advanced(model, x0, until_s):
    """The state the runner's plant holds at ``until_s``: advanced sample by sample, as it
    is (the first tick publishes without advancing)."""
    plant = ContinuousPlant(model, x0)
    for k in range(1, round(until_s / PERIOD_S) + 1):
        plant.advance(k * PERIOD_S)
    return plant.x


def _reference_at(model, x_start, programme, after_s):
    """The normal ``after_s`` into ``programme`` from ``x_start``: the twin's own plant at the
    check's tolerance and by the check's method (the studies')."""
    plant = ContinuousPlant(model, x_start, rtol=CHECK_RTOL, method=DEFAULT_METHOD)
    plant.run_programme(programme)
    for k in range(1, round(after_s / PERIOD_S) + 1):
        plant.advance(k * PERIOD_S)
    return plant.snapshot().normal


def test_the_check_compares_each_landing_with_the_full_model_from_the_same_state(tilted):
    model, x0, programme = tilted
    check = fc.FidelityCheck(model, WINDOW_S, PERIOD_S, executor=InlineExecutor())
    start_s = 2 * PERIOD_S
    normals = _run(model, x0, [(start_s, programme)], start_s + WINDOW_S + 2 * PERIOD_S, check)
    result = check.close()
    assert (result.checked, result.pending, result.skipped) == (1, 0, 0)
    # Independently: the full model at the check's tolerance from the state the twin held,
    # sample by sample as the twin's plant integrates.
    reference = _reference_at(model, _advanced(model, x0, start_s), programme, WINDOW_S)
    live = normals[round((start_s + WINDOW_S) / PERIOD_S)]
    assert result.median_rad == result.max_rad
    assert result.max_rad == pytest.approx(
        angle_between(reference, live), rel=1e-9, abs=1e-15)
    # The live tolerance's kick lands near the reference: a few of its bound off the edges.
    assert angle_between(live, tilted_normal(20.0, 20.0)) > 1e-3  # a kick, not a rest
    assert result.max_rad < 3.0 * LIVE_ERROR_BOUND_RAD


def test_a_kick_cut_short_is_compared_where_the_next_programme_cut_it(tilted):
    model, x0, programme = tilted
    check = fc.FidelityCheck(model, WINDOW_S, PERIOD_S, executor=InlineExecutor())
    first_s, second_s = PERIOD_S, PERIOD_S + 0.04
    normals = _run(model, x0, [(first_s, programme), (second_s, programme)],
                   second_s + 2 * PERIOD_S, check)
    result = check.divergence()
    assert (result.checked, result.pending) == (1, 1)  # the second is still in flight
    reference = _reference_at(model, _advanced(model, x0, first_s), programme,
                              second_s - first_s)
    live = normals[round(second_s / PERIOD_S)]
    assert result.max_rad == pytest.approx(angle_between(reference, live), rel=1e-9, abs=1e-15)
    assert math.isfinite(check.close().median_rad)


def test_a_check_that_falls_behind_skips_kicks_and_says_how_many(tilted):
    model, _, programme = tilted
    pending = concurrent.futures.Future()  # a reference that never finishes

    class StuckExecutor(concurrent.futures.Executor):
        def submit(self, fn, /, *args, **kwargs):
            return pending

    check = fc.FidelityCheck(model, WINDOW_S, PERIOD_S, executor=StuckExecutor())
    normal = np.array([0.0, 0.0, 1.0])
    for k in range(fc.MAX_PENDING + 3):
        check.started(k * WINDOW_S, None, normal, programme)
    result = check.divergence()
    assert (result.checked, result.pending, result.skipped) == (0, fc.MAX_PENDING, 3)
    assert math.isnan(result.median_rad)
