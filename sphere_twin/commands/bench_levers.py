"""``sphere-twin bench levers``: what a cheaper Jacobian, fewer Newton iterations or fewer
right-hand sides would buy `fast`.

Runs the compiled Radau IIA on the three work-precision scenes at rtol 1e-3 ... 1e-6 (half
decades) as it is and with its simplified Newton iteration capped at 4, 3 and 2 iterations
(scipy's and ours: 6). The cap is a
compile-time constant of ``radau_compiled``, so each capped variant runs in its own process
with its own numba cache. Times are CPU seconds, fastest of ``REPEATS``; errors are the
benchmark's final-angle errors against ``fast`` at rtol 1e-9; times at 1e-6 rad are
interpolated as the benchmark does. The right-hand side's and the Jacobian's cost per call are
timed on the states an odeint run evaluates (compiled replay, ``kernel_replay``); times their
counts in a run of ``fast``, they are what a free right-hand side or a free (analytic)
Jacobian would save it at most. An exact Jacobian would not change the steps: central
differences, 1e4 times more accurate, did not (docs/numerics.md, "Jacobian").

    sphere-twin bench levers      # about 5 minutes; writes fast_costs.md into --out
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sphere_twin.commands.options import DEFAULT_OUT_DIR, output_directory

if TYPE_CHECKING:
    from sphere_sim.integrate.solve import Trajectory
    from sphere_sim.studies.work_precision import BenchScene

RESULTS_NAME = 'fast_costs.md'
RTOLS = (1e-3, 3e-4, 1e-4, 3e-5, 1e-5, 3e-6, 1e-6)
REFERENCE_RTOL = 1e-9
REPEATS = 3  # CPU time of a run: the fastest of this many (the machine is shared)
REPLAY_REPEATS = 7
VARIANTS = ('as is', 'newton<=4', 'newton<=3', 'newton<=2')


def _scenes() -> list[BenchScene]:
    from sphere_twin.commands.bench_scenes import scenes_of_this_tree
    return scenes_of_this_tree()


def _cpu_s(run: Callable[..., object]) -> float:
    best = np.inf
    for _ in range(REPEATS):
        started = time.process_time()
        run()
        best = min(best, time.process_time() - started)
    return best


def _measure(variant: str) -> None:
    """One JSON line per (scene, rtol) of ``variant``, run in this process."""
    from sphere_sim.integrate import radau_compiled, solve
    from sphere_sim.studies import work_precision as wp
    if variant.startswith('newton<='):
        radau_compiled.NEWTON_MAXITER = int(variant.removeprefix('newton<='))
    for scene in _scenes():
        def run(rtol: float, scene: BenchScene = scene) -> Trajectory:
            return solve.simulate(scene.model, scene.x0, scene.duration_s, scene.programme,
                                  rtol=rtol, method='fast', sample_period_s=wp.SAMPLE_PERIOD_S)
        reference = run(REFERENCE_RTOL)
        for rtol in RTOLS:
            traj = run(rtol)
            s = traj.stats
            print(json.dumps({
                'variant': variant, 'scene': scene.name, 'rtol': rtol,
                'cpu_s': _cpu_s(lambda rtol=rtol: run(rtol)),
                'angle_error_rad': wp.errors(scene, traj, reference)[0], 'steps': s.n_steps,
                'rejected': s.n_rejected, 'nfev': s.nfev, 'njev': s.njev, 'nlu': s.nlu,
                'newton_failed': s.n_newton_failed}), flush=True)


def _kernel_costs() -> dict[str, tuple[float, ...]]:
    """{scene: (right-hand side s, Jacobian s)} per call, at the states odeint evaluates."""
    from sphere_sim.integrate.kernel_replay import RecordingModel, replay
    from sphere_sim.integrate.solve import simulate
    costs: dict[str, tuple[float, ...]] = {}
    for scene in _scenes():
        recording = RecordingModel(scene.model)
        simulate(recording, scene.x0, scene.duration_s, scene.programme, rtol=1e-5,
                 method='odeint', sample_period_s=1e-3)
        per_call: list[float] = []
        for calls, jacobian in ((recording.rhs_calls, False), (recording.jac_calls, True)):
            replay(scene.model, calls[:1], jacobian)
            best = min(replay(scene.model, calls, jacobian)[1] for _ in range(REPLAY_REPEATS))
            per_call.append(best / len(calls))
        costs[scene.name] = tuple(per_call)
    return costs


def _run_variant(variant: str) -> list[dict[str, Any]]:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ)
        if variant.startswith('newton<='):
            env['NUMBA_CACHE_DIR'] = cache  # the cap is compiled in: no cached kernel may serve
        out = subprocess.run([sys.executable, '-m', __name__, '--variant', variant], env=env,
                             check=True, capture_output=True, text=True).stdout
    return [json.loads(line) for line in out.splitlines() if line.startswith('{')]


def _time_at_error(rows: Sequence[dict[str, Any]], scene: str, variant: str) -> float:
    from sphere_sim.studies.work_precision import TARGET_ANGLE_ERROR_RAD, time_at_error
    rows = [{**r, 'method': r['variant'], 'status': 'ok', 'wall_s': r['cpu_s']} for r in rows]
    return time_at_error(rows, scene, variant, TARGET_ANGLE_ERROR_RAD)


def _reaching(rows: Sequence[dict[str, Any]], scene: str,
              variant: str) -> dict[str, Any]:
    """The loosest run of ``variant`` that reaches 1e-6 rad (the benchmark's bound)."""
    from sphere_sim.studies.work_precision import TARGET_ANGLE_ERROR_RAD
    runs = sorted((r for r in rows if r['scene'] == scene and r['variant'] == variant),
                  key=lambda r: -r['rtol'])
    return next(r for r in runs if r['angle_error_rad'] <= TARGET_ANGLE_ERROR_RAD)


def _shares(run: Mapping[str, Any], rhs_s: float,
            jac_s: float) -> tuple[float, float, float, float]:
    """Fractions of ``run``'s CPU time in right-hand sides, in Jacobians, and in the
    right-hand sides of Newton iterations beyond the first of each attempted step."""
    attempts = run['steps'] + run['rejected']
    # Each Newton iteration evaluates the three stages; one more f at each step's end.
    iterations = (run['nfev'] - run['steps']) / 3
    beyond_first = 3 * (iterations - attempts) * rhs_s / run['cpu_s']
    return (run['nfev'] * rhs_s / run['cpu_s'], run['njev'] * jac_s / run['cpu_s'],
            beyond_first, iterations / attempts)


def _per_step_lines(rows: Sequence[dict[str, Any]],
                    costs: Mapping[str, tuple[float, ...]]) -> list[str]:
    lines = ['| scene | rtol | CPU (ms) | steps | rejected | f per step | Newton iterations per '
             'attempt | Jacobians | f: µs per call, share | Jacobian: µs per call, share | '
             'f of iterations beyond the first | rest |', '|---|' * 12]
    lines[-1] = lines[-1].replace('||', '|')
    for scene, (rhs_s, jac_s) in costs.items():
        r = _reaching(rows, scene, 'as is')
        rhs, jac, beyond, per_attempt = _shares(r, rhs_s, jac_s)
        lines.append(f"| {scene} | {r['rtol']:g} | {r['cpu_s'] * 1e3:.1f} | {r['steps']} | "
                     f"{r['rejected']} | {r['nfev'] / r['steps']:.2f} | {per_attempt:.2f} | "
                     f"{r['njev']} | {rhs_s * 1e6:.2f}, {rhs:.0%} | {jac_s * 1e6:.1f}, "
                     f'{jac:.0%} | {beyond:.0%} | {1 - rhs - jac:.0%} |')
    return lines


def _time_lines(rows: Sequence[dict[str, Any]], scenes: Sequence[str],
                costs: Mapping[str, tuple[float, ...]]) -> list[str]:
    lines = ['| variant | ' + ' | '.join(scenes) + ' |', '|---|' + '---|' * len(scenes)]
    base = {s: _time_at_error(rows, s, 'as is') for s in scenes}
    for variant in VARIANTS:
        cells = []
        for s in scenes:
            t = _time_at_error(rows, s, variant)
            cells.append(f'{t * 1e3:.1f} ms ({t / base[s]:.2f})')
        lines.append(f'| {variant} | ' + ' | '.join(cells) + ' |')
    for label, index in (('free Jacobians', 1), ('free right-hand sides', 0)):
        cells = []
        for s in scenes:
            # The shares of the run that bounds the interpolation, applied to its time.
            t = base[s] * (1 - _shares(_reaching(rows, s, 'as is'), *costs[s])[index])
            cells.append(f'{t * 1e3:.1f} ms ({t / base[s]:.2f})')
        lines.append(f'| as is, {label} (at most) | ' + ' | '.join(cells) + ' |')
    return lines


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``levers`` to the ``bench`` subcommands."""
    parser = sub.add_parser(
        'levers', help='what a cheaper Jacobian, fewer Newton iterations or fewer right-hand '
                       'sides would buy the compiled Radau',
        description='Runs fast with its Newton iterations capped at 4, 3 and 2 (each in a '
                    'process of its own, with its own numba cache) and times the kernels; '
                    f'writes {RESULTS_NAME} into --out (about 5 minutes).')
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory (default: the working directory; the committed '
                             'one: bench/results)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    main(args.out)
    return 0


def main(out_dir: Path = DEFAULT_OUT_DIR) -> None:
    rows = [row for variant in VARIANTS for row in _run_variant(variant)]
    costs = _kernel_costs()
    scenes = list(costs)
    lines = ['# What a cheaper Jacobian, fewer Newton iterations or fewer right-hand sides '
             'would buy `fast`', '', 'Written by `sphere-twin bench levers`; see '
             'docs/numerics.md. CPU time, fastest of '
             f'{REPEATS}; time at 1e-6 rad interpolated as in the work-precision benchmark '
             f'(ratio to `fast` as it is in brackets).', '', *_time_lines(rows, scenes, costs), '',
             'At the loosest tolerance that reaches 1e-6 rad (`fast` as it is). The shares '
             'are the counts times the cost per call, over the CPU time:', '',
             *_per_step_lines(rows, costs), '', '## Runs', '',
             '```', *(json.dumps(r) for r in rows), '```', '']
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / RESULTS_NAME).write_text('\n'.join(lines))
    print('\n'.join(lines[:lines.index('## Runs')]))


if __name__ == '__main__':
    if len(sys.argv) == 3 and sys.argv[1] == '--variant':
        _measure(sys.argv[2])
    else:
        main()
