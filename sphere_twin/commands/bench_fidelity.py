"""``sphere-twin bench fidelity``: the ladder of models, each rung's landing error against the
full model printed beside its cost (:mod:`sphere_sim.twin.ladder`)."""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Sequence

from sphere_sim.integrate.tolerances import LIVE_RTOL
from sphere_sim.kicks.engine import engine_of
from sphere_sim.kicks.lookup_table import TableError
from sphere_sim.twin.ladder import (
    LIVE_MAX_BUDGET_RAD,
    LIVE_P95_BUDGET_RAD,
    TIMING_REPEATS,
    Ladder,
    measure_ladder,
)
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    add_params_option,
    output_directory,
    positive_int,
)

RESULTS_STEM = 'fidelity'


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``fidelity`` to the ``bench`` subcommands."""
    parser = sub.add_parser(
        'fidelity', help='every rung of the model ladder: landing error against the full '
                         'model beside CPU time per kick',
        description='Run 30 kicks (the diagonal and axis designs at intensities 0.6, 0.8 and '
                    '1, from rest at 0, 20 and 35 deg of tilt) on the full model at rtol 1e-9 '
                    'and on every rung as the live twin runs it; print each rung\'s landing '
                    'error (median, 95th percentile, max) beside its CPU time per kick and '
                    'the live budget. Writes fidelity{,_quick}.{json,md} into --out.')
    parser.add_argument('--quick', action='store_true',
                        help='4 kicks against rtol 1e-7 (about 10 s)')
    parser.add_argument('--workers', type=positive_int, default=2,
                        help='local processes for the reference runs (the rungs run alone)')
    add_params_option(parser)
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory')
    parser.set_defaults(func=run)


def table_lines(ladder: Ladder) -> list[str]:
    """The ladder as a Markdown table, its budget and its verdict (the last line)."""
    full = ladder.rung('full')
    lines = [f'{len(ladder.kicks)} kicks; landing error against the full model at rtol '
             f'{ladder.reference_rtol:g}; the live tolerance is rtol {LIVE_RTOL:g}; CPU time '
             f'per kick the median of the kicks (each the fastest of {TIMING_REPEATS} runs, one '
             f'process).',
             f'Live budget: p95 <= {LIVE_P95_BUDGET_RAD:.2e} rad (a tenth of the sensor noise) '
             f'and max <= {LIVE_MAX_BUDGET_RAD:.2e} rad (the sensor noise).', '',
             '| rung | leaves out | median (rad) | p95 (rad) | max (rad) | ms per kick | '
             'within the live budget |', '|---|---|---|---|---|---|---|']
    for r in ladder.rungs:
        lines.append(f'| {r.label} | {r.leaves_out or "nothing"} | '
                     f'{r.median_rad:.2e} | {r.p95_rad:.2e} | {r.max_rad:.2e} | '
                     f'{r.ms_per_kick:.3g} | {"yes" if r.meets_live_budget else "no"} |')
    lines.append('')
    lines.append(f'the twin runs: {full.label}, '
                 f'{"within" if full.meets_live_budget else "outside"} the live budget')
    live = ladder.live_rung()
    if live is None:
        lines.append(f'live rung none: no model rung meets the budget (full model '
                     f'{full.ms_per_kick:.3g} ms per kick)')
    else:
        lines.append(f'live rung {live.label}: p95 {live.p95_rad:.2e} rad, max '
                     f'{live.max_rad:.2e} rad, {live.ms_per_kick:.3g} ms per kick (full model at '
                     f'the live tolerance {full.ms_per_kick:.3g} ms)')
    return lines


def kick_lines(ladder: Ladder) -> list[str]:
    """Each kick's error on each rung (rad), worst first by the full rung's."""
    names = [r.label for r in ladder.rungs]
    rows = ['| kick | ' + ' | '.join(names) + ' |', '|---|' + '---|' * len(names)]
    order = sorted(range(len(ladder.kicks)),
                   key=lambda i: -ladder.rung('full').errors_rad[i])
    for i in order:
        rows.append(f'| {ladder.kicks[i].label} | '
                    + ' | '.join(f'{r.errors_rad[i]:.1e}' for r in ladder.rungs) + ' |')
    return rows


def run(args: argparse.Namespace) -> int:
    load_before = os.getloadavg()[0]
    with engine_of(args.workers) as engine:
        try:
            ladder = measure_ladder(args.params, quick=args.quick, engine=engine,
                                    progress=lambda text: print(f'bench fidelity: {text}',
                                                                file=sys.stderr, flush=True))
        except TableError as error:  # the table rung's tables are built for one set
            raise CommandError(f'the table rung cannot serve --params: {error}') from None
    write_results(ladder, args.out, args.quick, load_before)
    print('\n'.join(table_lines(ladder)))
    return 0


def write_results(ladder: Ladder, out_dir: os.PathLike[str], quick: bool,
                  load_before: float) -> Sequence[str]:
    """fidelity{,_quick}.{json,md} in ``out_dir``; returns the Markdown's lines."""
    from pathlib import Path

    load = (f'load average (1 min) {load_before:.2f} at the start, {os.getloadavg()[0]:.2f} '
            'at the end')
    stem = Path(out_dir) / (RESULTS_STEM + ('_quick' if quick else ''))
    stem.parent.mkdir(parents=True, exist_ok=True)
    stem.with_suffix('.json').write_text(json.dumps({**ladder.to_dict(), 'machine': load},
                                                   indent=1) + '\n')
    lines = ['# The ladder of models', '',
             f'Written by `sphere-twin bench fidelity{" --quick" if quick else ""}`; {load}.',
             '', *table_lines(ladder), '', '## Each kick', '', *kick_lines(ladder)]
    stem.with_suffix('.md').write_text('\n'.join(lines) + '\n')
    return lines
