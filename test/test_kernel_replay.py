"""Recording a solver's evaluations and replaying them in compiled loops."""

import numpy as np
import pytest

from sphere_sim.integrate.kernel_replay import RecordingModel, replay, replay_wall_s
from sphere_sim.integrate.solve import simulate
from sphere_sim.model.programme import Pulse, PulseProgramme

# Voltages on and off within the run: the recorded voltages must follow the segments.
PROGRAMME = PulseProgramme((Pulse(3, 80.0, 0.0, 0.2e-3), Pulse(4, 80.0, 0.0, 0.2e-3)))


@pytest.fixture(scope='module')
def recorded(model, x_rest):
    recording = RecordingModel(model)
    traj = simulate(recording, x_rest, 0.4e-3, PROGRAMME, rtol=1e-4, method='LSODA',
                    sample_period_s=1e-4)
    return recording, traj


def test_recording_changes_nothing_and_sees_every_evaluation(model, x_rest, recorded):
    recording, traj = recorded
    plain = simulate(model, x_rest, 0.4e-3, PROGRAMME, rtol=1e-4, method='LSODA',
                     sample_period_s=1e-4)
    np.testing.assert_array_equal(traj.x, plain.x)
    assert len(recording.rhs_calls) == traj.stats.nfev == plain.stats.nfev
    assert len(recording.jac_calls) == traj.stats.njev > 0
    voltages = {tuple(u) for _, _, u in recording.rhs_calls}
    assert voltages == {(0.0, 0.0, 80.0, 80.0), (0.0, 0.0, 0.0, 0.0)}


def test_replay_evaluates_what_the_solver_received(model, recorded):
    recording, _ = recorded
    calls = recording.rhs_calls[::7]
    values, wall_s = replay(model, calls)
    for (t, x, u), value in zip(calls, values, strict=True):
        np.testing.assert_array_equal(value, model.rhs(t, x, u))
    assert wall_s > 0.0
    calls = recording.jac_calls
    values, _ = replay(model, calls, jacobian=True)
    for (t, x, u), value in zip(calls, values, strict=True):
        np.testing.assert_array_equal(value, model.jacobian(t, x, u))


def test_a_run_that_recorded_nothing_is_an_error(model, x_rest):
    recording = RecordingModel(model)
    simulate(recording, x_rest, 0.1e-3, PROGRAMME, rtol=1e-4, method='fast')
    assert recording.rhs_calls == [] and recording.jac_calls == []
    with pytest.raises(ValueError, match='nothing was recorded'):
        replay_wall_s(model, recording, repeats=1)
