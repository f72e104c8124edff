"""What the run figures draw, read back from their matplotlib Axes (every figure goes to
tmp_path): units in the axis labels, the setpoint and the reference trajectory, kicks as ticks
or as a rate, and the replay's errors in the unit its text prints."""

import math

import numpy as np
import pytest

from sphere_sim.kicks.discrete import normal_from_xy
from sphere_twin import plots
from sphere_twin.run_analysis import RecordedRun, plot_report


@pytest.fixture
def drawn(monkeypatch):
    """The figures the code under test closes, kept open for the test to read."""
    figures = []
    close = plots.plt.close
    monkeypatch.setattr(plots.plt, 'close', figures.append)
    yield figures
    for figure in figures:
        close(figure)


def _run(kick_times_s, duration_s=2.0, period_s=0.01, trajectory=False):
    """A run resting at a setpoint (x_sn 0.02) for half its time, then, with ``trajectory``,
    following a reference that moves along y."""
    t = np.arange(0.0, duration_s + period_s / 2, period_s)
    normals = np.array([normal_from_xy(0.02 * min(1.0, 4 * s), 0.0) for s in t])
    setpoint = normal_from_xy(0.02, 0.0)
    ref_t = [0.0, duration_s / 2]
    refs = [setpoint, setpoint]
    if trajectory:
        ref_t = [0.0, *np.arange(duration_s / 2, duration_s, 0.1)]
        refs = [setpoint] + [normal_from_xy(0.02, 0.01 * (s - duration_s / 2 + 0.1))
                             for s in ref_t[1:]]
    return RecordedRun(t, normals, np.array(ref_t), np.array(refs),
                       kicks=[(float(s), None, None) for s in kick_times_s], holds=[])


def _lines_labelled(ax, label):
    return [line for line in ax.get_lines() if line.get_label() == label]


def _tick_lines(ax):
    return [line for line in ax.get_lines() if line.get_marker() == '|']


# --- kicks: ticks or a rate -----------------------------------------------------------------

def test_kicks_switch_from_ticks_to_a_rate_at_the_tick_gap_threshold():
    # 400 px for 10 s: 40 px/s, so the threshold gap of MIN_KICK_TICK_GAP_PX is 0.1 s.
    threshold_gap_s = plots.MIN_KICK_TICK_GAP_PX / 40.0
    sparse = np.arange(0.0, 10.0, threshold_gap_s * 1.01)
    dense = np.arange(0.0, 10.0, threshold_gap_s * 0.99)
    assert plots.kick_marks(sparse, 10.0, 400.0) == 'ticks'
    assert plots.kick_marks(dense, 10.0, 400.0) == 'rate'
    assert plots.kick_marks([], 10.0, 400.0) == 'none'
    assert plots.kick_marks([3.0], 10.0, 400.0) == 'ticks'


def test_kicks_in_bursts_between_long_rests_are_dense():
    """The median gap decides: five bursts of five kicks 10 ms apart merge, however long the
    rests between the bursts make the mean gap."""
    bursts = np.concatenate([start + 0.01 * np.arange(5) for start in np.arange(0, 30, 6.0)])
    assert np.mean(np.diff(bursts)) * 400 / 30 > plots.MIN_KICK_TICK_GAP_PX
    assert plots.kick_marks(bursts, 30.0, 400.0) == 'rate'


def test_sparse_kicks_are_one_tick_each_on_the_error_axis(tmp_path, drawn):
    plot_report(_run([0.05, 0.6, 1.3]), tmp_path / 'sparse.png')
    figure, = drawn
    ax_err = figure.axes[0]
    assert len(figure.axes) == 2  # no rate axis
    ticks, = _tick_lines(ax_err)
    np.testing.assert_allclose(ticks.get_xdata(), [0.05, 0.6, 1.3])
    assert ticks.get_label() == plots.KICK_TICK_LABEL
    assert ax_err.get_ylabel() == 'angle to reference (deg)'
    assert ax_err.get_xlabel() == 'time (s)'


def test_dense_kicks_are_a_rate_in_kicks_per_second_on_a_twin_axis(tmp_path, drawn):
    kicks = np.arange(0.0, 33.0, 1.0 / 15)  # the demo's 15 kicks a second
    plot_report(_run(kicks, duration_s=33.0), tmp_path / 'dense.png')
    figure, = drawn
    ax_err = figure.axes[0]
    assert not _tick_lines(ax_err)
    rate_ax, = [ax for ax in figure.axes if ax.get_ylabel() == plots.KICK_RATE_LABEL]
    assert '(kicks/s)' in rate_ax.get_ylabel()
    stairs, = rate_ax.patches
    values = stairs.get_data().values
    assert values.size == 33  # one bin per second
    np.testing.assert_allclose(values, 15.0, atol=1.0)
    legend_texts = [t.get_text() for t in rate_ax.get_legend().get_texts()]
    assert legend_texts == ['error', plots.KICK_RATE_LABEL]


# --- the x-y panel --------------------------------------------------------------------------

def test_the_xy_panel_is_in_degrees_of_tilt_with_the_setpoint_marked(tmp_path, drawn):
    plot_report(_run([0.05]), tmp_path / 'setpoint.png')
    ax_xy = drawn[0].axes[1]
    assert ax_xy.get_xlabel().endswith('(deg)') and ax_xy.get_ylabel().endswith('(deg)')
    setpoint, = _lines_labelled(ax_xy, 'setpoint')
    # x_sn 0.02 is asin(0.02) = 1.146 deg of tilt
    np.testing.assert_allclose(setpoint.get_xdata(), [math.degrees(math.asin(0.02))])
    np.testing.assert_allclose(setpoint.get_ydata(), [0.0], atol=1e-12)
    assert not _lines_labelled(ax_xy, 'reference trajectory')  # a setpoint only
    path, = _lines_labelled(ax_xy, 'surface normal')
    assert max(path.get_xdata()) == pytest.approx(math.degrees(math.asin(0.02)))


def test_the_xy_panel_draws_the_reference_trajectory_where_there_is_one(tmp_path, drawn):
    plot_report(_run([0.05], duration_s=4.0, trajectory=True), tmp_path / 'trajectory.png')
    ax_xy = drawn[0].axes[1]
    assert len(_lines_labelled(ax_xy, 'setpoint')) == 1
    trajectory, = _lines_labelled(ax_xy, 'reference trajectory')
    # the moving references, from 2 s on every 0.1 s, 0.01 of y_sn per second
    ys = np.asarray(trajectory.get_ydata())
    assert ys.size == 20
    np.testing.assert_allclose(ys[-1], math.degrees(math.asin(0.02)), rtol=1e-9)


# --- replay errors --------------------------------------------------------------------------

def test_replay_errors_are_two_curves_in_rad_with_their_rms(tmp_path, drawn):
    rng = np.random.default_rng(3)
    times = np.arange(4100) * 0.01
    before = np.abs(rng.normal(0.0, 2.1e-3, times.size))
    after = before / 1.57  # the same noise, smaller: every sorted error is below
    plots.plot_replay_errors(times, {'before': before, 'after': after}, tmp_path / 'r.png',
                             title='replay\nimprovement: RMS 0.0021 -> 0.00134 rad (1.57x)')
    figure, = drawn
    ax_time, ax_sorted = figure.axes
    for ax in (ax_time, ax_sorted):
        assert ax.get_ylabel() == plots.REPLAY_ERROR_LABEL and ax.get_ylabel().endswith('(rad)')
        lines = ax.get_lines()
        assert len(lines) == 2 and all(line.get_marker() in ('None', None) for line in lines)
    sorted_before, sorted_after = ax_sorted.get_lines()
    assert np.all(np.diff(sorted_before.get_ydata()) >= 0)
    assert np.all(np.asarray(sorted_after.get_ydata()) <= np.asarray(sorted_before.get_ydata()))
    texts = [t.get_text() for t in ax_sorted.get_legend().get_texts()]
    rms_before = math.sqrt(np.mean(before ** 2))
    assert texts[0] == f'before: RMS {rms_before:.3g} rad'
    assert '(1.57x)' in ax_time.get_title()


def test_an_exact_replay_keeps_its_log_axis_near_its_errors():
    errors = np.concatenate([[0.0], np.full(999, 1e-6)])
    assert plots.replay_axis_bottom_rad([errors]) == pytest.approx(1e-6 / 3)
    assert plots.replay_axis_bottom_rad([np.zeros(5)]) == plots.REPLAY_FLOOR_RAD


def test_replay_check_plots_in_the_unit_it_prints(tmp_path, drawn, capsys):
    """The example's discrete replay, once with the shipped set as 'before' too: two curves,
    the axis in rad as the printed errors, the printed improvement line as the title's."""
    from msg_defs.device import DEFAULT_PARAMETER_SET
    from sphere_twin.cli import build_parser

    args = build_parser().parse_args(['replay-check', 'example', '--plant', 'discrete',
                                      '--before', DEFAULT_PARAMETER_SET,
                                      '--out', str(tmp_path)])
    assert args.func(args) == 0
    printed = capsys.readouterr().out.strip().splitlines()
    (improvement,) = [line for line in printed if line.startswith('improvement: RMS')]
    assert improvement.endswith('x)')
    assert ' rad' in printed[-1] and 'deg' not in '\n'.join(printed)
    ax_time, ax_sorted = drawn[0].axes
    assert ax_time.get_ylabel().endswith('(rad)')
    assert len(ax_sorted.get_lines()) == 2
    assert ax_time.get_title().splitlines()[-1] == improvement
    assert (tmp_path / 'example_replay.png').stat().st_size > 10_000
