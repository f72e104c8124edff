"""The work-precision benchmark's bookkeeping (its timings are reported, never asserted)."""

import io
import math
import re

import numpy as np
import pytest

from sphere_sim.studies import work_precision as wp
from sphere_twin.commands import bench


def row(method, rtol, error, wall_s, scene='s'):
    return {'scene': scene, 'method': method, 'rtol': rtol, 'status': 'ok',
            'angle_error_rad': error, 'wall_s': wall_s}


def test_time_at_error_interpolates_in_log_log():
    rows = [row('fast', 1e-3, 1e-4, 1.0), row('fast', 1e-4, 1e-8, 100.0)]
    # 1e-6 is halfway in log(error), so the time is halfway in log(time).
    assert wp.time_at_error(rows, 's', 'fast', 1e-6) == pytest.approx(10.0)


def test_time_at_error_takes_the_loosest_run_that_is_accurate_enough():
    rows = [row('fast', 1e-3, 1e-7, 2.0), row('fast', 1e-4, 1e-9, 5.0)]
    assert wp.time_at_error(rows, 's', 'fast', 1e-6) == 2.0


def test_time_at_error_is_nan_when_no_run_is_accurate_enough():
    rows = [row('LSODA', 1e-3, 1e-3, 1.0), row('LSODA', 1e-4, 1e-5, 2.0)]
    assert math.isnan(wp.time_at_error(rows, 's', 'LSODA', 1e-6))


def test_run_reaching_is_the_run_that_bounds_the_interpolation():
    rows = [row('LSODA', 1e-3, 1e-4, 1.0), row('LSODA', 1e-4, 1e-8, 100.0),
            row('LSODA', 1e-5, 1e-9, 200.0)]
    assert wp.run_reaching(rows, 's', 'LSODA', 1e-6) == (1e-4, 1e-8, 100.0)
    assert wp.run_reaching(rows, 's', 'LSODA', 1e-3) == (1e-3, 1e-4, 1.0)
    assert all(math.isnan(v) for v in wp.run_reaching(rows, 's', 'LSODA', 1e-10))


def test_only_the_reference_run_is_marked_as_such():
    rows = [{**row('fast', 1e-10, 0.0, 9.0), 'note': '3 timed run(s)'},
            row('fast', 1e-9, 1e-12, 2.0), row('CVODE', 1e-10, 1e-11, 1.0)]
    wp.mark_reference(rows, 'fast', 1e-10)
    assert rows[0]['note'] == '3 timed run(s); ' + wp.REFERENCE_NOTE
    assert 'note' not in rows[1] and 'note' not in rows[2]


QUICK_RUN_REPEATS = 2  # so that the passes of further timed runs are exercised too
# The budget only stops a stuck run; Python-stepped Radau at 1e-7 takes 10-20 s on a quiet
# machine and three times that on a loaded one, where the bench's own 30 s would end it and
# the test would read the machine's load, not the bench.
QUICK_RUN_TEST_BUDGET_S = 180.0
# The quick plan's methods but Python-stepped Radau: a minute of the run at 1e-7 with its
# repeats, and its bookkeeping is the other methods' (the plan itself is `make bench`'s).
TEST_METHODS = tuple(m for m in wp.QUICK_METHODS if m != 'Radau')


@pytest.fixture(scope='module')
def quick_run(tmp_path_factory):
    out = tmp_path_factory.mktemp('bench')
    stream = io.StringIO()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(wp, 'QUICK_REPEATS', QUICK_RUN_REPEATS)
        patch.setattr(wp, 'QUICK_RUN_BUDGET_S', QUICK_RUN_TEST_BUDGET_S)
        patch.setattr(wp, 'QUICK_METHODS', TEST_METHODS)
        rows, summary = bench.run_work_precision_bench(quick=True, out_dir=out, stream=stream)
    return out, stream.getvalue(), rows, summary


def test_quick_run_times_every_point_as_often_as_asked(quick_run):
    _, _, rows, _ = quick_run
    assert len(rows) == len(TEST_METHODS) * len(wp.QUICK_TOLERANCES)
    for r in rows:
        assert r['status'] == 'ok' and 'times' not in r
        assert r['note'] == f'{QUICK_RUN_REPEATS} timed run(s)'
        assert 0.0 < r['wall_s'] < QUICK_RUN_TEST_BUDGET_S


def test_quick_run_writes_beside_the_full_results(quick_run):
    out, _, _, _ = quick_run
    assert sorted(p.name for p in out.iterdir()) == [
        'work_precision_quick.csv', 'work_precision_quick.md', 'work_precision_quick.png']


def test_quick_run_ends_with_the_summary_line(quick_run):
    _, printed, _, summary = quick_run
    last = printed.strip().splitlines()[-1]
    match = re.fullmatch(r'speedup vs best scipy at 1e-6 rad: ([0-9.]+)x; '
                         r'real-time factor: ([0-9.]+)', last)
    assert match
    assert float(match.group(1)) == pytest.approx(summary['speedup'], rel=0.05)


def test_quick_run_times_the_best_library_methods_bare_evaluations(quick_run):
    _, printed, rows, summary = quick_run
    p = summary['per_scene']['diagonal_kick']
    rtol, _, wall_s = wp.run_reaching(rows, 'diagonal_kick', p['best_scipy'],
                                         wp.TARGET_ANGLE_ERROR_RAD)
    assert (p['kernels_rtol'], p['kernels_run_s']) == (rtol, wall_s)
    assert summary['kernels_s'] == p['kernels_s'] > 0.0
    assert f"{p['best_scipy']} at rtol {p['kernels_rtol']:g}: its kernel evaluations" in printed


def test_quick_run_errors_fall_with_the_tolerance(quick_run):
    _, _, rows, summary = quick_run
    # The two reference methods agree far below the errors being measured.
    assert summary['agreement']['diagonal_kick'][0] < 1e-8
    for method in TEST_METHODS:
        errors = [r['angle_error_rad'] for r in sorted(rows, key=lambda r: -r['rtol'])
                  if r['method'] == method]
        assert errors[-1] < errors[0] / 100, method


def test_final_angle_error_is_the_largest_over_the_final_window(model):
    """A run that rocks about the reference and meets it at the last sample is charged its
    largest deviation over the final window, not the chance agreement at the end; a larger
    deviation before the window does not count."""
    from types import SimpleNamespace

    from sphere_sim.model.initial_state import rest_state

    x_rest = rest_state(model)
    o = model.sphere_offset
    t = np.arange(0.0, 0.0301, 1e-3)
    tilt_rad = np.zeros(t.size)
    tilt_rad[t < t[-1] - wp.FINAL_WINDOW_S - 1e-9] = 1e-3  # before the window
    tilt_rad[-5] = 3e-6  # inside it
    tilt_rad[-1] = 0.0  # meets the reference at the end

    def trajectory(angles):
        x = np.repeat(x_rest[:, None], t.size, axis=1)
        x[o + 3] = np.cos(angles / 2)  # rotated about the body x axis
        x[o + 4] = np.sin(angles / 2)
        x[o + 5:o + 7] = 0.0
        return SimpleNamespace(t=t, x=x, final_state=x[:, -1])

    scene = SimpleNamespace(model=model)
    final, state, last = wp.errors(scene, trajectory(tilt_rad), trajectory(0.0 * tilt_rad))
    assert final == pytest.approx(3e-6, rel=1e-6)
    assert last == 0.0
    assert state > 0.0
