"""``sphere-twin bench``: work-precision of the integrators and the regularisation study.

``bench work-precision`` runs three scenes (the optimised diagonal kick from rest, an 80 V kick
on all beams, the optimised kick from a 35 deg tilt) with every method over a range of
tolerances and writes ``bench/results/work_precision.{csv,md,png}``. Wall times are medians of
at least three runs after one warm-up run; errors are against a reference made of two
different methods at the tightest tolerance, whose agreement is printed. Its last line is
``speedup vs best scipy at 1e-6 rad: <x>x; real-time factor: <r>``.

``bench regularisation`` runs the convergence study of the friction regularisations (the
viscous onset ramp and epsilon of eq. 51) and writes ``bench/results/regularisation.{csv,md}``.
"""

import contextlib
import csv
import dataclasses
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from msg_defs.device import KICK_WINDOW_S, VOLTAGE_LIMIT_V
from sphere_sim.integrate.kernel_replay import RecordingModel, replay_wall_s
from sphere_sim.integrate.solve import (
    DEFAULT_METHOD,
    DEFAULT_RTOL,
    SCIPY_METHODS,
    SolverError,
    simulate,
)
from sphere_sim.kicks.design import KickDesign
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.programme import Pulse, PulseProgramme
from sphere_sim.model.scaling import state_scale
from sphere_sim.model.scene import load_scene

RESULTS_DIR = Path(__file__).resolve().parents[2] / 'bench' / 'results'
KICK_FILE = RESULTS_DIR / 'kick_optimization.json'
# Half decades where the final-angle error crosses TARGET_ANGLE_ERROR_RAD: at loose tolerances
# that error scatters by 10x between runs differing only in rounding, and a single decade
# point decides the interpolated time.
TOLERANCES = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)
QUICK_TOLERANCES = (1e-3, 1e-5, 1e-7)
METHODS = ('fast', 'Radau', 'BDF', 'LSODA', 'DOP853', 'CVODE')
QUICK_METHODS = ('fast', 'LSODA', 'Radau')
REPEATS = 3  # timed runs per point; the median is reported (the issue asks for >= 3)
RTF_REPEATS = 11  # real-time-factor runs take ~50 ms: a median of many is cheap and steadier
QUICK_REPEATS = 1
# Reference: two different methods at the tightest tolerance; their agreement is printed.
REFERENCE_METHODS = ('fast', 'CVODE')
QUICK_REFERENCE_METHODS = ('fast', 'LSODA')
QUICK_REFERENCE_RTOL = 1e-9
# Error samples: the normal and the state are compared on this fixed grid (s).
SAMPLE_PERIOD_S = 1e-3
TARGET_ANGLE_ERROR_RAD = 1e-6  # the speedup is compared at this final-angle error
# The final-angle error is the largest angle between the surface normals over the samples of
# this last stretch of a run, not at its last sample alone: at the end of the kick windows
# the sphere still rocks on the tips (the reference's normal moves by up to 1.2e-5 rad over
# its last 10 ms), and a solution that rocks about the reference can meet it at one sample by
# chance. Measured: LSODA at rtol 1e-3 on the diagonal kick was 2.1e-6 rad off at one of its
# last ten samples and 4e-8 rad off two samples later. The last sample's error is reported
# beside it.
FINAL_WINDOW_S = 10e-3
# A run longer than this (first, untimed run) is not repeated and tighter tolerances of the
# same method are skipped: DOP853 on this stiff model needs minutes.
RUN_BUDGET_S = 30.0
REPEAT_LIMIT_S = 20.0  # a first run longer than this is reported as one timed run
QUICK_RUN_BUDGET_S = 10.0
TILT_DEG = 35.0
ALL_BEAMS_V = VOLTAGE_LIMIT_V
ALL_BEAMS_WIDTH_S = 5e-3  # the pulse width of Fig. 4
ALL_BEAMS_WINDOW_S = 0.03
RTF_DURATION_S = 0.1  # "the full four-beam + sphere kick (100 ms simulated)"
# The replayed kernel evaluations of the best library method are timed as the fastest of
# this many compiled loops: they take 10-50 ms, and between processes the same loop was
# measured up to 30 % slower.
KERNEL_REPLAY_REPEATS = 7


@dataclasses.dataclass
class BenchScene:
    """One work-precision scene: a model, its start state and programme, a duration."""

    name: str
    description: str
    model: object
    x0: np.ndarray
    programme: PulseProgramme
    duration_s: float


def optimised_design():
    """The optimised diagonal kick of bench/results/kick_optimization.json (or the paper's)."""
    if not KICK_FILE.exists():
        return KickDesign(), False
    data = json.loads(KICK_FILE.read_text())['design']
    fields = {f.name for f in dataclasses.fields(KickDesign)}
    kwargs = {k: (tuple(v) if isinstance(v, list) else v) for k, v in data.items() if k in fields}
    return KickDesign(**kwargs), True


def all_beams_programme(amplitude_v=ALL_BEAMS_V, width_s=ALL_BEAMS_WIDTH_S):
    return PulseProgramme(tuple(Pulse(b, amplitude_v, 0.0, width_s) for b in (1, 2, 3, 4)))


def bench_scenes():
    """The three scenes of the work-precision benchmark."""
    design, optimised = optimised_design()
    model = assemble(load_scene('rest'))
    kick = design.programme()
    label = 'optimised diagonal kick' if optimised else '35 V / 80 V asymmetric pulse pair'
    return [
        BenchScene('diagonal_kick', f'{label} from rest', model, rest_state(model), kick,
                   KICK_WINDOW_S),
        BenchScene('all_beams_80v', f'{ALL_BEAMS_V:.0f} V, {ALL_BEAMS_WIDTH_S * 1e3:.0f} ms on '
                   'all four beams from rest', model, rest_state(model), all_beams_programme(),
                   ALL_BEAMS_WINDOW_S),
        BenchScene('tilted_35deg', f'{label} from a {TILT_DEG:.0f} deg tilt', model,
                   rest_state(model, (TILT_DEG, 0.0, 0.0)), kick, KICK_WINDOW_S),
    ]


def angle_between(a, b):
    """Angle (rad) between two unit vectors, accurate for small angles."""
    return float(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


def run_once(scene, method, rtol, max_wall_s):
    """One timed run; returns (trajectory, wall time in s)."""
    started = time.perf_counter()
    traj = simulate(scene.model, scene.x0, scene.duration_s, scene.programme, rtol=rtol,
                    method=method, sample_period_s=SAMPLE_PERIOD_S, max_wall_s=max_wall_s)
    return traj, time.perf_counter() - started


def errors(scene, traj, reference):
    """Errors of ``traj`` against ``reference`` (same sample grid).

    Returns
    -------
    final_angle_rad : float
        Largest angle between their surface normals over the last ``FINAL_WINDOW_S``.
    state : float
        Largest scaled state error over the whole sample grid.
    last_sample_angle_rad : float
        Angle between the surface normals at the last sample.
    """
    model = scene.model
    angles = [angle_between(model.surface_normal(traj.x[:, i]),
                            model.surface_normal(reference.x[:, i]))
              for i in np.flatnonzero(traj.t >= traj.t[-1] - FINAL_WINDOW_S)]
    last = angle_between(model.surface_normal(traj.final_state),
                         model.surface_normal(reference.final_state))
    scale = state_scale(model)[:, None]
    state = float(np.max(np.abs(traj.x - reference.x) / scale))
    return max(angles), state, last


def reference_runs(scene, methods, rtol, budget_s):
    """Two reference trajectories and their agreement (angle rad, scaled state)."""
    a, _ = run_once(scene, methods[0], rtol, budget_s * 10)
    b, _ = run_once(scene, methods[1], rtol, budget_s * 10)
    return a, b, errors(scene, a, b)


def work_precision(quick=False, out_dir=RESULTS_DIR, stream=sys.stdout):
    """Run the benchmark; returns (rows, summary dict)."""
    tolerances = QUICK_TOLERANCES if quick else TOLERANCES
    methods = QUICK_METHODS if quick else METHODS
    repeats = QUICK_REPEATS if quick else REPEATS
    budget_s = QUICK_RUN_BUDGET_S if quick else RUN_BUDGET_S
    ref_methods = QUICK_REFERENCE_METHODS if quick else REFERENCE_METHODS
    ref_rtol = QUICK_REFERENCE_RTOL if quick else min(tolerances)
    scenes = bench_scenes()
    if quick:
        scenes = scenes[:1]
    # Warm every method (compilation, imports) so that no timing includes it. Not under the
    # runs' budget: compiling the kernels into an empty numba cache takes longer than a run.
    for method in methods:
        simulate(scenes[0].model, scenes[0].x0, 2e-4, scenes[0].programme, method=method,
                 rtol=1e-3)
    rows = []
    agreements = {}
    total = len(scenes) * (2 + len(methods) * len(tolerances))
    with tqdm(total=total, desc='work-precision', unit='run', file=sys.stderr) as bar:
        for scene in scenes:
            ref, _other, agree = reference_runs(scene, ref_methods, ref_rtol, budget_s)
            bar.update(2)
            agreements[scene.name] = agree
            print(f'{scene.name}: reference {ref_methods[0]} vs {ref_methods[1]} at rtol '
                  f'{ref_rtol:g} agree to {agree[0]:.2e} rad (final normal), {agree[1]:.2e} '
                  '(largest scaled state difference)', file=stream, flush=True)
            for method in methods:
                skip = False
                for rtol in tolerances:
                    bar.set_postfix_str(f'{scene.name} {method} {rtol:g}')
                    if skip:
                        bar.update()
                        continue
                    rows.append(_measure(scene, method, rtol, ref, budget_s))
                    if rows[-1]['status'] != 'ok':
                        skip = True
                    bar.update()
        # The further timed runs go in passes over every point, not back to back: a burst of
        # load on a shared machine then slows one run of a point, which the median drops,
        # rather than all of them (the same LSODA run, same steps, took 0.30 s in one full
        # run and 0.41 s in the next when its repeats were consecutive).
        bar.total = bar.n + len(rows) * (repeats - 1)
        by_name = {scene.name: scene for scene in scenes}
        for _ in range(repeats - 1):
            for row in rows:
                bar.set_postfix_str(f"{row['scene']} {row['method']} {row['rtol']:g}")
                if row['status'] == 'ok' and row['times'][0] < REPEAT_LIMIT_S:
                    # Only the wall-clock budget can end a run that once succeeded.
                    with contextlib.suppress(SolverError):
                        row['times'].append(run_once(by_name[row['scene']], row['method'],
                                                     row['rtol'], budget_s)[1])
                bar.update()
    for row in rows:
        times = row.pop('times')
        if times:
            row['wall_s'] = statistics.median(times)
            row['note'] = f'{len(times)} timed run(s)'
    mark_reference(rows, ref_methods[0], ref_rtol)
    summary = summarise(rows, scenes[0].name)
    add_kernel_evaluations(summary, rows, scenes, stream)
    summary['agreement'] = agreements
    summary['reference'] = {'methods': ref_methods, 'rtol': ref_rtol}
    summary['real_time_factor'], summary['rtf_wall_s'] = real_time_factor(
        QUICK_REPEATS if quick else RTF_REPEATS)
    summary['quick'] = quick
    write_results(rows, summary, scenes, out_dir)
    line = (f"speedup vs best scipy at 1e-6 rad: {summary['speedup']:.1f}x; "
            f"real-time factor: {summary['real_time_factor']:.2f}")
    print(line, file=stream, flush=True)
    return rows, summary


REFERENCE_NOTE = 'the reference run itself: error 0 by construction'


def mark_reference(rows, method, rtol):
    """Note on the rows that repeat the reference run: their zero error is by construction."""
    for row in rows:
        if row['method'] == method and row['rtol'] == rtol:
            row['note'] = '; '.join(filter(None, (row.get('note'), REFERENCE_NOTE)))


def _measure(scene, method, rtol, reference, budget_s):
    """One point: its errors and its first timed run (``times``; work_precision adds the
    others and replaces them by their median ``wall_s``)."""
    row = {'scene': scene.name, 'method': method, 'rtol': rtol}
    try:
        traj, first = run_once(scene, method, rtol, budget_s)
    except SolverError as exc:
        return {**row, 'status': exc.status.value, 'wall_s': math.nan, 'times': [],
                'angle_error_rad': math.nan, 'last_sample_angle_error_rad': math.nan,
                'state_error': math.nan, 'steps': -1,
                'nfev': -1, 'njev': -1, 'note': str(exc).splitlines()[0][:80]}
    angle, state, last = errors(scene, traj, reference)
    s = traj.stats
    # Each method was warmed up beforehand, so the first run counts.
    return {**row, 'status': 'ok', 'times': [first], 'angle_error_rad': angle,
            'last_sample_angle_error_rad': last, 'state_error': state,
            'steps': -1 if s.n_steps is None else s.n_steps, 'nfev': s.nfev, 'njev': s.njev}


def time_at_error(rows, scene, method, target, key='angle_error_rad'):
    """Wall time (s) of ``method`` at final-angle error ``target`` (the rows' ``key``).

    Interpolated linearly in log(error)-log(time) between the two tolerances, loosest first,
    across which the error first falls to ``target``; the loosest run's time if that run
    is already as accurate; NaN if no run reaches ``target``.
    """
    pts = _points(rows, scene, method, key)
    for i, (_, err, wall) in enumerate(pts):
        if err <= target:
            if i == 0:
                return wall
            _, err0, wall0 = pts[i - 1]
            if err <= 0.0:
                return wall
            w = math.log(err0 / target) / math.log(err0 / err)
            return math.exp((1 - w) * math.log(wall0) + w * math.log(wall))
    return math.nan


def run_reaching(rows, scene, method, target, key='angle_error_rad'):
    """(rtol, error, wall time) of the loosest run of ``method`` that reaches ``target``, the
    run that bounds :func:`time_at_error`'s interpolation from below; NaNs if none does."""
    return next((pt for pt in _points(rows, scene, method, key) if pt[1] <= target),
                (math.nan,) * 3)


def _points(rows, scene, method, key):
    """(rtol, error, wall time) of the method's successful runs on the scene, loosest first."""
    return sorted(((r['rtol'], r[key], r['wall_s']) for r in rows
                   if r['scene'] == scene and r['method'] == method and r['status'] == 'ok'),
                  reverse=True)


def kernel_evaluations_s(scene, method, rtol, repeats=KERNEL_REPLAY_REPEATS):
    """Wall time (s) of the model's kernel evaluations alone in one run of ``method``.

    The run records every state its solver evaluates the right-hand side and the Jacobian
    at; those evaluations are replayed in compiled loops. No compiled version of the method,
    taking the same steps, could run faster than that.
    """
    recording = RecordingModel(scene.model)
    simulate(recording, scene.x0, scene.duration_s, scene.programme, rtol=rtol, method=method,
             sample_period_s=SAMPLE_PERIOD_S)
    return replay_wall_s(scene.model, recording, repeats)


def add_kernel_evaluations(summary, rows, scenes, stream):
    """Time the best library method's bare kernel evaluations on each scene, at the tolerance
    where it reaches the target, into ``summary['per_scene']``; print a line per scene."""
    for scene in scenes:
        p = summary['per_scene'][scene.name]
        rtol, _, p['kernels_run_s'] = (
            run_reaching(rows, scene.name, p['best_scipy'], TARGET_ANGLE_ERROR_RAD)
            if p['best_scipy'] else (math.nan,) * 3)
        p['kernels_rtol'] = rtol
        p['kernels_s'] = math.nan
        if math.isfinite(rtol):
            p['kernels_s'] = kernel_evaluations_s(scene, p['best_scipy'], rtol)
            print(f"{scene.name}: {p['best_scipy']} at rtol {rtol:g}: its kernel evaluations "
                  f"alone {p['kernels_s'] * 1e3:.1f} ms, the run {p['kernels_run_s'] * 1e3:.1f}"
                  f" ms; fast at 1e-6 rad {p['fast_s'] * 1e3:.1f} ms", file=stream, flush=True)
    summary.update({k: summary['per_scene'][summary['scene']][k]
                    for k in ('kernels_rtol', 'kernels_s', 'kernels_run_s')})


def summarise(rows, scene):
    """Speedup of 'fast' over the best scipy method at TARGET_ANGLE_ERROR_RAD, on ``scene``
    and on each scene (``per_scene``), by the final-angle error and (``last_sample``) by the
    last sample's."""
    per_scene = {}
    for name in sorted({r['scene'] for r in rows}):
        per_scene[name] = {'last_sample': _speedup(rows, name, 'last_sample_angle_error_rad'),
                           **_speedup(rows, name, 'angle_error_rad')}
    return {'scene': scene, **per_scene[scene], 'per_scene': per_scene}


def _speedup(rows, scene, key):
    fast = time_at_error(rows, scene, 'fast', TARGET_ANGLE_ERROR_RAD, key)
    scipy_times = {m: time_at_error(rows, scene, m, TARGET_ANGLE_ERROR_RAD, key)
                   for m in SCIPY_METHODS}
    finite = {m: t for m, t in scipy_times.items() if math.isfinite(t)}
    best = min(finite, key=finite.get) if finite else None
    return {'fast_s': fast, 'best_scipy': best, 'best_scipy_s': finite.get(best, math.nan),
            'speedup': finite[best] / fast if best and math.isfinite(fast) else math.nan}


def real_time_factor(repeats):
    """Simulated seconds per wall second of the 80 V four-beam kick over 100 ms at the
    defaults of ``solve`` (integration only; the rest state is computed beforehand)."""
    model = assemble(load_scene('rest'))
    x0 = rest_state(model)
    programme = all_beams_programme()
    times = []
    for _ in range(max(3, repeats)):
        traj = simulate(model, x0, RTF_DURATION_S, programme, rtol=DEFAULT_RTOL,
                        method=DEFAULT_METHOD)
        times.append(traj.stats.wall_time_s)
    wall = statistics.median(times)
    return RTF_DURATION_S / wall, wall


COLUMNS = ('scene', 'method', 'rtol', 'status', 'wall_s', 'angle_error_rad',
           'last_sample_angle_error_rad', 'state_error', 'steps', 'nfev', 'njev', 'note')


def write_results(rows, summary, scenes, out_dir):
    # A quick run writes beside the full results, never over them.
    stem = 'work_precision_quick' if summary['quick'] else 'work_precision'
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    with open(out_dir / f'{stem}.csv', 'w', newline='') as stream:
        writer = csv.DictWriter(stream, fieldnames=COLUMNS)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: (f'{v:.6g}' if isinstance(v, float) else v)
                             for k, v in row.items()})
    (out_dir / f'{stem}.md').write_text(markdown(rows, summary, scenes))
    plot(rows, scenes, out_dir / f'{stem}.png')


def markdown(rows, summary, scenes):
    lines = ['# Work-precision of the integrators', '',
             'Written by `sphere-twin bench work-precision'
             + (' --quick' if summary['quick'] else '') + '`; see docs/numerics.md.', '',
             f"Reference: {summary['reference']['methods'][0]} and "
             f"{summary['reference']['methods'][1]} at rtol {summary['reference']['rtol']:g}; "
             'wall time is the median of the timed runs (integration only, one core). The '
             f'final-angle error is the largest angle between the surface normals over the last '
             f'{FINAL_WINDOW_S * 1e3:.0f} ms of a run: the sphere still rocks slightly at the end '
             'of the window, and one sample can meet the reference by chance. The last '
             "sample's error is listed beside it.", '']
    for scene in scenes:
        agree = summary['agreement'][scene.name]
        lines += [f'## {scene.name}: {scene.description}, {scene.duration_s * 1e3:.0f} ms', '',
                  f'Reference agreement: {agree[0]:.2e} rad final normal, {agree[1]:.2e} '
                  'largest scaled state difference.', '',
                  '| method | rtol | wall (s) | final-angle error (rad) | at the last sample '
                  '(rad) | scaled state error | steps | nfev | njev | status |',
                  '|---|---|---|---|---|---|---|---|---|---|']
        for r in rows:
            if r['scene'] != scene.name:
                continue
            steps = '-' if r['steps'] < 0 else r['steps']
            status = r['status'] + (' (the reference)' if REFERENCE_NOTE in r.get('note', '')
                                    else '')
            lines.append(f"| {r['method']} | {r['rtol']:.0e} | {r['wall_s']:.4g} | "
                         f"{r['angle_error_rad']:.2e} | {r['last_sample_angle_error_rad']:.2e} | "
                         f"{r['state_error']:.2e} | {steps} | {r['nfev']} | {r['njev']} | "
                         f"{status} |")
        p = summary['per_scene'].get(scene.name, {})
        if p:
            q = p['last_sample']
            lines += ['', f"Wall time at a final-angle error of 1e-6 rad (interpolated): fast "
                      f"{p['fast_s']:.4g} s, best scipy ({p['best_scipy']}) "
                      f"{p['best_scipy_s']:.4g} s: {p['speedup']:.1f}x. By the last sample's "
                      f"error alone: fast {q['fast_s']:.4g} s, best scipy ({q['best_scipy']}) "
                      f"{q['best_scipy_s']:.4g} s: {q['speedup']:.1f}x.", '']
            if math.isfinite(p.get('kernels_s', math.nan)):
                lines += [f"{p['best_scipy']}'s kernel evaluations alone in its run at "
                          f"rtol {p['kernels_rtol']:g}, the loosest that reaches 1e-6 rad (the "
                          'right-hand sides and Jacobians at the states it evaluated, '
                          f'replayed in a compiled loop, fastest of {KERNEL_REPLAY_REPEATS}): '
                          f"{p['kernels_s']:.4g} s, against {p['kernels_run_s']:.4g} s for the "
                          f"run: a compiled {p['best_scipy']} taking the same steps would be at "
                          f"most {p['kernels_run_s'] / p['kernels_s']:.1f}x faster. fast at "
                          f"1e-6 rad: {p['fast_s']:.4g} s.", '']
    lines += ['## Summary', '',
              f"speedup vs best scipy at 1e-6 rad: {summary['speedup']:.1f}x "
              f"(scene {summary['scene']}, best scipy method {summary['best_scipy']}); "
              f"real-time factor: {summary['real_time_factor']:.2f} "
              f"({RTF_DURATION_S * 1e3:.0f} ms of the {ALL_BEAMS_V:.0f} V four-beam kick in "
              f"{summary['rtf_wall_s']:.3f} s with method {DEFAULT_METHOD!r}, rtol "
              f'{DEFAULT_RTOL:g}).', '']
    return '\n'.join(lines)


def plot(rows, scenes, path):
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(scenes), figsize=(4.2 * len(scenes), 7.5), squeeze=False)
    markers = dict(zip(METHODS, 'os^vDx', strict=True))
    for col, scene in enumerate(scenes):
        for row_index, key, label in ((0, 'angle_error_rad', 'final-angle error (rad)'),
                                      (1, 'state_error', 'largest scaled state error')):
            ax = axes[row_index, col]
            for method in METHODS:
                # A run with no error is the reference itself: a log axis has no place for
                # it, and drawing it at an arbitrary floor would show an accuracy nobody has.
                pts = [(r[key], r['wall_s']) for r in rows if r['scene'] == scene.name
                       and r['method'] == method and r['status'] == 'ok' and r[key] > 0.0]
                if not pts:
                    continue
                err, wall = zip(*pts, strict=True)
                ax.loglog(err, wall, marker=markers[method], label=method)
            if row_index == 0:
                ax.axvline(TARGET_ANGLE_ERROR_RAD, color='grey', lw=0.8, ls=':')
                ax.set_title(scene.name)
            ax.set_xlabel(label)
            ax.set_ylabel('wall time (s)')
            ax.grid(True, which='both', alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


# --- regularisation study ------------------------------------------------------------------
ONSET_VALUES_M = (1e-7, 3e-8, 1e-8, 3e-9, 1e-9, 3e-10, 1e-10, 1e-11, 0.0)
EPSILON_VALUES_M2_PER_S2 = (1e-6, 1e-8, 1e-10, 1e-12, 1e-14, 1e-16)
STUDY_RTOLS = (1e-7, 1e-9)  # each value run at two tolerances: the numerics must agree


def regularisation_study(quick=False, out_dir=RESULTS_DIR, stream=sys.stdout):
    """The kick outcomes as each friction regularisation shrinks; returns the rows."""
    design, _ = optimised_design()
    scene = load_scene('rest')
    base = scene.parameters()
    programmes = {'diagonal_kick': design.programme(),
                  'asymmetric_kick': load_scene('asymmetric_kick').programme}
    studies = [('friction.viscous_onset_m', ONSET_VALUES_M),
               ('friction.epsilon_m2_per_s2', EPSILON_VALUES_M2_PER_S2)]
    rtols = STUDY_RTOLS[:1] if quick else STUDY_RTOLS
    rows = []
    total = sum(len(v) for _, v in studies) * len(programmes) * len(rtols)
    with tqdm(total=total, desc='regularisation', unit='run', file=sys.stderr) as bar:
        for path, values in studies:
            for value in values:
                params = base.replace(**{path: value})
                model = assemble(scene, params)
                x0 = rest_state(model)
                for kick, programme in programmes.items():
                    for rtol in rtols:
                        traj = simulate(model, x0, KICK_WINDOW_S, programme, rtol=rtol,
                                        method='fast', sample_period_s=SAMPLE_PERIOD_S)
                        n = model.surface_normal(traj.final_state)
                        along = (n[0] * math.cos(design.direction_rad)
                                 + n[1] * math.sin(design.direction_rad))
                        rows.append({'parameter': path, 'value': value, 'kick': kick,
                                     'rtol': rtol, 'along_deg': math.degrees(along),
                                     'normal_x': n[0], 'normal_y': n[1],
                                     'steps': traj.stats.n_steps,
                                     'wall_s': traj.stats.wall_time_s})
                        bar.update()
    out_dir = Path(out_dir)
    with open(out_dir / 'regularisation.csv', 'w', newline='') as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    lines = ['# Friction regularisations: convergence study', '',
             'Written by `sphere-twin bench regularisation`. Final surface normal after the '
             f'{KICK_WINDOW_S * 1e3:.0f} ms kick window, projected on the diagonal kick\'s '
             'nominal direction (deg), method fast.', '',
             '| parameter | value | kick | ' + ' | '.join(f'rtol {r:g}' for r in rtols)
             + ' | steps |', '|---|---|---|' + '---|' * len(rtols) + '---|']
    for path, values in studies:
        for value in values:
            for kick in programmes:
                sel = [r for r in rows if r['parameter'] == path and r['value'] == value
                       and r['kick'] == kick]
                lines.append(f'| {path} | {value:g} | {kick} | '
                             + ' | '.join(f"{r['along_deg']:+.6f}" for r in sel)
                             + f" | {sel[-1]['steps']} |")
    (out_dir / 'regularisation.md').write_text('\n'.join(lines) + '\n')
    print('\n'.join(lines), file=stream)
    return rows


def register(subparsers):
    parser = subparsers.add_parser(
        'bench', help='integrator benchmarks (work-precision, regularisation study)',
        description='Benchmarks of the numerics; results go to bench/results.')
    sub = parser.add_subparsers(dest='bench', metavar='BENCH', required=True)
    wp = sub.add_parser('work-precision', help='wall time against error for every method',
                        description='Three scenes, tolerances 1e-3..1e-10, every method; '
                                    'writes bench/results/work_precision.{csv,md,png}.')
    wp.add_argument('--quick', action='store_true',
                    help='one scene, three methods, three tolerances, one timed run (< 1 min)')
    wp.add_argument('--out', type=Path, default=RESULTS_DIR, help='output directory')
    wp.set_defaults(func=run_work_precision)
    reg = sub.add_parser('regularisation', help='convergence study of the friction ramps',
                         description='Kick outcomes as the viscous onset ramp and epsilon of '
                                     'eq. (51) shrink; writes bench/results/regularisation.*')
    reg.add_argument('--quick', action='store_true', help='one tolerance only')
    reg.add_argument('--out', type=Path, default=RESULTS_DIR, help='output directory')
    reg.set_defaults(func=run_regularisation)


def run_work_precision(args):
    work_precision(quick=args.quick, out_dir=args.out)
    return 0


def run_regularisation(args):
    regularisation_study(quick=args.quick, out_dir=args.out)
    return 0
