"""``sphere-twin bench``: work-precision of the integrators and the regularisation study.

``bench work-precision`` runs three scenes (the optimised diagonal kick from rest, an 80 V kick
on all beams, the optimised kick from a 35 deg tilt) with every method over a range of
tolerances and writes ``work_precision.{csv,md,png}`` (into ``--out``; the committed ones are
in ``bench/results``). Wall times are medians of
at least three runs after one warm-up run; errors are against a reference made of two
different methods at the tightest tolerance, whose agreement is printed. The line before its
last gives the real-time factor of each scene; its last line is
``speedup vs best scipy at 1e-6 rad: <x>x; real-time factor: <r>`` (best of every library
method, odeint included; the real-time factor of the 80 V all-beams scene).

``bench regularisation`` runs the convergence study of the friction regularisations (the
viscous onset ramp and epsilon of eq. 51) and writes ``regularisation.{csv,md}``.

``bench throughput`` runs the kick workloads (table build, kick optimisation, calibration) on
one worker, and on a process pool and a Dask cluster of each worker count asked (``--workers
2,4``; 2 by default), against the bare integration rate of their kicks and a CPU loop's scaling
on as many processes, and writes ``throughput.{json,md}``. Its last line is
``throughput vs bare integration: <a> table build, <b> optimisation``.

``bench thresholds`` searches each threshold of a protocol recording at its truth from the
recorded brackets and from predicted cells, and writes ``threshold_search.md``
(``sphere_twin/commands/bench_thresholds.py``).

``bench startup`` installs the package as colcon does into a scratch prefix and times a
simulator from there to its first ``/sphere/surface_normal``, cold (compiling the physics) and
warm, and writes ``startup.{json,md}`` (``sphere_twin/commands/bench_startup.py``).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import sys
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TextIO

from tqdm import tqdm

from msg_defs.device import KICK_WINDOW_S
from sphere_sim.fitting import throughput as tp
from sphere_sim.integrate.solve import DEFAULT_METHOD
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.scene import load_scene
from sphere_sim.studies.regularisation import STUDIES, STUDY_RTOLS, regularisation_rows
from sphere_sim.studies.work_precision import (
    FINAL_WINDOW_S,
    KERNEL_REPLAY_REPEATS,
    METHODS,
    REFERENCE_NOTE,
    RTF_DURATION_S,
    TARGET_ANGLE_ERROR_RAD,
    BenchScene,
    Plan,
    work_precision,
)
from sphere_twin.commands import (
    bench_fidelity,
    bench_levers,
    bench_startup,
    bench_thresholds,
    bench_twin,
)
from sphere_twin.commands.bench_scenes import optimised_design, work_precision_scenes
from sphere_twin.commands.options import DEFAULT_OUT_DIR, output_directory, worker_counts


def run_work_precision_bench(quick: bool = False,
                             out_dir: str | os.PathLike[str] = DEFAULT_OUT_DIR,
                             stream: TextIO = sys.stdout,
                             ) -> tuple[list[dict[str, Any]], dict[str, Any]]:
    """Run the benchmark with a progress bar, write its results; returns (rows, summary)."""
    scenes = work_precision_scenes()
    with tqdm(desc='work-precision', unit='run', file=sys.stderr) as bar:
        rows, summary = work_precision(scenes, Plan.of(quick), bar,
                                       lambda line: print(line, file=stream, flush=True))
    write_results(rows, summary, scenes[:1] if quick else scenes, out_dir)
    print(f"speedup vs best scipy at 1e-6 rad: {summary['speedup']:.1f}x; "
          f"real-time factor: {summary['real_time_factor']:.2f}", file=stream, flush=True)
    return rows, summary


COLUMNS = ('scene', 'method', 'rtol', 'status', 'wall_s', 'angle_error_rad',
           'last_sample_angle_error_rad', 'state_error', 'steps', 'nfev', 'njev', 'note')


def write_results(rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any],
                  scenes: Sequence[BenchScene], out_dir: str | os.PathLike[str]) -> None:
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


def _seconds(t: float) -> str:
    """A time in s, or - where no run reached the error it is read at."""
    return f'{t:.4g} s' if math.isfinite(t) else '-'


def markdown(rows: Sequence[Mapping[str, Any]], summary: Mapping[str, Any],
             scenes: Sequence[BenchScene]) -> str:
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
                      f"{q['best_scipy_s']:.4g} s: {q['speedup']:.1f}x. The compiled "
                      'Rosenbrock W-method (rosenbrock) at 1e-6 rad: '
                      + _seconds(p.get('rosenbrock_s', math.nan)) + '.', '',
                      'Each library method at 1e-6 rad (interpolated; - where no run reaches '
                      'it): ' + ', '.join(f'{m} ' + _seconds(t)
                                          for m, t in p['scipy_s'].items()) + '.', '']
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
              f"({RTF_DURATION_S * 1e3:.0f} ms of scene {summary['rtf_scene']} in "
              f"{summary['rtf_wall_s']:.3f} s with method {DEFAULT_METHOD!r}, rtol "
              f'{DEFAULT_RTOL:g}).', '',
              f'Real-time factor of each scene ({RTF_DURATION_S * 1e3:.0f} ms of its programme '
              'from its start state, integration only, median of the runs):', '',
              '| scene | real-time factor | wall (s) |', '|---|---|---|',
              *(f'| {name} | {rtf:.2f} | {wall:.4f} |'
                for name, (rtf, wall) in summary['real_time_factors'].items()), '']
    return '\n'.join(lines)


def plot(rows: Sequence[Mapping[str, Any]], scenes: Sequence[BenchScene], path: Path) -> None:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(scenes), figsize=(4.2 * len(scenes), 7.5), squeeze=False)
    markers = dict(zip(METHODS, 'oPs^v<Dx', strict=True))
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
def run_regularisation_study(quick: bool = False, out_dir: str | os.PathLike[str] = DEFAULT_OUT_DIR,
                             stream: TextIO = sys.stdout) -> list[dict[str, Any]]:
    """The study with a progress bar; writes regularisation.{csv,md} and returns the rows."""
    design, _ = optimised_design()
    programmes = {'diagonal_kick': design.programme(),
                  'asymmetric_kick': load_scene('asymmetric_kick').programme}
    rtols = STUDY_RTOLS[:1] if quick else STUDY_RTOLS
    total = sum(len(v) for _, v in STUDIES) * len(programmes) * len(rtols)
    with tqdm(total=total, desc='regularisation', unit='run', file=sys.stderr) as bar:
        rows = regularisation_rows(programmes, design.direction_rad, rtols, bar.update)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)  # checked creatable before the study ran
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
    for path, values in STUDIES:
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


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'bench', help='integrator benchmarks (work-precision, regularisation study)',
        description='Benchmarks of the numerics; results go to --out (default: the working '
                    'directory; the committed ones: --out bench/results).')
    sub = parser.add_subparsers(dest='bench_command', metavar='BENCH', required=True)
    wp = sub.add_parser('work-precision', help='wall time against error for every method',
                        description='Three scenes, tolerances 1e-3..1e-10, every method; '
                                    'writes work_precision.{csv,md,png} into --out.')
    wp.add_argument('--quick', action='store_true',
                    help='one scene, three methods, three tolerances, one timed run (< 1 min)')
    wp.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                    help='output directory')
    wp.set_defaults(func=run_work_precision)
    reg = sub.add_parser('regularisation', help='convergence study of the friction ramps',
                         description='Kick outcomes as the viscous onset ramp and epsilon of '
                                     'eq. (51) shrink; writes regularisation.* into --out')
    reg.add_argument('--quick', action='store_true', help='one tolerance only')
    reg.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                     help='output directory')
    reg.set_defaults(func=run_regularisation)
    thr = sub.add_parser('throughput', help='kicks/s of the kick workloads against bare '
                                            'integration',
                         description='Table build, kick optimisation and calibration on one '
                                     'worker, and on a process pool and a Dask cluster of n '
                                     'workers for each n of --workers; each 1 -> n scaling '
                                     'beside that of a pure CPU loop on n processes. Writes '
                                     'throughput.{json,md} into --out.')
    thr.add_argument('--quick', action='store_true', help='tiny workloads (< 1 min)')
    thr.add_argument('--workers', type=worker_counts, default=tp.DEFAULT_WORKER_COUNTS,
                     metavar='N[,N...]',
                     help='worker counts of the pool and Dask runs, e.g. 2,4,8 (one worker '
                          'always runs; default %(default)s)')
    thr.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                     help='output directory')
    thr.set_defaults(func=run_throughput)
    bench_twin.register(sub)
    bench_fidelity.register(sub)
    bench_levers.register(sub)
    bench_startup.register(sub)
    bench_thresholds.register(sub)


def run_work_precision(args: argparse.Namespace) -> int:
    run_work_precision_bench(quick=args.quick, out_dir=args.out)
    return 0


def run_regularisation(args: argparse.Namespace) -> int:
    run_regularisation_study(quick=args.quick, out_dir=args.out)
    return 0


# --- throughput of the kick workloads ------------------------------------------------------
WORKLOAD_LABELS = {'table': 'table build', 'optimisation': 'optimisation',
                   'calibration': 'calibration'}


def engine_label(engine: str, workers: int) -> str:
    return {'serial': '1 worker', 'pool': f'{workers}-process pool',
            'dask': f'{workers} Dask workers'}[engine]


def run_throughput(args: argparse.Namespace) -> int:
    run_throughput_bench(quick=args.quick, out_dir=args.out, worker_counts=args.workers)
    return 0


def run_throughput_bench(quick: bool = False, out_dir: str | os.PathLike[str] = DEFAULT_OUT_DIR,
                         stream: TextIO = sys.stdout, **kwargs: Any) -> tp.Summary:
    """The throughput study with a progress bar; writes throughput{,_quick}.{json,md}."""
    engines = kwargs.get('engines', tp.ENGINES)
    counts = kwargs.get('worker_counts', tp.DEFAULT_WORKER_COUNTS)
    n_runs = len(kwargs.get('workloads', tp.WORKLOADS)) * (1 + (len(engines) - 1) * len(counts))
    with tqdm(total=n_runs, desc='throughput', unit='run', file=sys.stderr) as bar:
        def progress(workload: str, engine: str, done: int) -> None:
            bar.set_postfix_str(f'{workload} on {engine}')
            bar.update(done - bar.n)

        summary = tp.throughput(quick=quick, progress=progress, **kwargs)
        bar.update(bar.total - bar.n)
    lines = throughput_lines(summary)
    stem = 'throughput_quick' if quick else 'throughput'
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / f'{stem}.json').write_text(json.dumps(summary.to_dict(), indent=2) + '\n')
    (out_dir / f'{stem}.md').write_text(throughput_markdown(summary, lines))
    print('\n'.join(lines), file=stream, flush=True)
    return summary


def throughput_lines(summary: tp.Summary) -> list[str]:
    """The table of runs, the scaling, and the summary line last."""
    lines = [f"{'workload':<13} {'engine':<15} {'kicks':>5} {'wall (s)':>8} "
             f"{'start-up (s)':>12} {'kicks/s/core':>12} {'vs bare':>7} {'CPU s/kick':>10} "
             f"{'CPU eff.':>8}"]
    for r in summary.runs:
        lines.append(f'{r.workload:<13} {engine_label(r.engine, r.workers):<15} {r.kicks:>5} '
                     f'{r.wall_s:>8.2f} {r.startup_s:>12.2f} {r.kicks_per_s_per_core:>12.2f} '
                     f'{summary.ratio(r.workload, r.engine, r.workers):>7.2f} '
                     f'{r.cpu_s_per_kick:>10.3f} '
                     f'{summary.cpu_efficiency(r.workload, r.engine, r.workers):>8.2f}')
    for workload in summary.workloads():
        for n in summary.worker_counts():
            scaling = ', '.join(
                f'{engine_label(e, n)} {summary.scaling(workload, e, n):.2f}x '
                f'({summary.of_loop(workload, e, n):.2f} of the loop)'
                for e in summary.engines() if e != 'serial')
            lines.append(f'{workload}: bare integration '
                         f'{summary.bare_kicks_per_s[workload]:.2f} kicks/s; 1 -> {n} workers: '
                         f'{scaling}')
    for n in summary.worker_counts():
        lines.append('the machine meanwhile: a CPU loop scaled '
                     + ' and '.join(f'{x:.2f}x' for x in summary.machine_scaling[n])
                     + f' from 1 to {n} processes (before and after the runs; {n} on an idle '
                       f'machine with {n} cores)')
    lines.append(f'{os.cpu_count()} cores; load average '
                 + ' and '.join(f'{x:.2f}' for x in summary.load_average))
    lines.append('scaling against the CPU loop\'s, worst over workloads and engines: '
                 + ', '.join(f'{n} workers {_worst_of_loop(summary, n):.2f}'
                             for n in summary.worker_counts()))
    lines.append('throughput vs bare integration: '
                 + ', '.join(f"{_ratio_text(summary, w)} {WORKLOAD_LABELS[w]}"
                             for w in ('table', 'optimisation')))
    return lines


def _worst_of_loop(summary: tp.Summary, workers: int) -> float:
    return min(summary.of_loop(r.workload, r.engine, workers)
               for r in summary.parallel_runs() if r.workers == workers)


def _ratio_text(summary: tp.Summary, workload: str) -> str:
    return f'{summary.ratio(workload):.2f}' if workload in summary.bare_kicks_per_s else 'n/a'


def throughput_markdown(summary: tp.Summary, lines: Sequence[str]) -> str:
    return '\n'.join([
        '# Throughput of the kick workloads', '',
        'Written by `sphere-twin bench throughput' + (' --quick' if summary.quick else '')
        + ('' if tuple(summary.worker_counts()) == tp.DEFAULT_WORKER_COUNTS
           else ' --workers ' + ','.join(map(str, summary.worker_counts())))
        + '`. kicks/s/core is a workload\'s kicks over its wall time and workers; "vs bare" '
        'divides it by the rate of the same kicks\' `simulate` calls alone, timed in the '
        'one-worker run. Engine start-up (processes, cluster, a warm-up kick in each worker) is '
        'outside the wall time and listed beside it. CPU s/kick counts this process and the '
        'workers; "CPU eff." is the one-worker run\'s CPU per kick over the run\'s: the work '
        'a pool or Dask adds per kick, which other load on the machine hardly changes (the '
        'wall-time scaling it does).', '', '```', *lines, '```', ''])
