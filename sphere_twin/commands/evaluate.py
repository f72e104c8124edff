"""``sphere-twin evaluate``: the closed-loop results of §5 beside the paper's.

Runs :func:`sphere_control.evaluation.evaluate` on the discrete model (the shipped lookup
table, or ``--plant analytic``: kicks of the paper's 0.54 deg), prints the comparison table,
writes ``evaluation.json`` and the figures like the paper's Figs. 13-15 to ``--out`` (the
working directory by default; the committed ones are in ``bench/results``), and ends with
Fig. 15 in the paper's set-up (f1 = 0.02 Hz, the basic controller's best of the paper's two
bands, sigma learned from kicks longer than the table's stray kicks, the kick period the
full kick's settle time): ``trajectory MSE extended/basic without preview: <ratio>``, then
``trajectory MSE extended/basic: <ratio>`` with preview, the default.
"""

from __future__ import annotations

import argparse
import dataclasses
import enum
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from sphere_control.controllers import ControllerKind
from sphere_control.evaluation import evaluate
from sphere_control.kick_plants import AnalyticKickPlant
from sphere_control.studies import (
    PAPER_PHI_MIN_RAD,
    PAPER_SETUP,
    EvaluationConfig,
    PlantUnderTest,
)
from sphere_sim.kicks.discrete import LEVEL_NORMAL, PAPER_FULL_KICK_RAD
from sphere_sim.kicks.lookup_table import AXIS_TABLE_PATH
from sphere_twin.commands.options import DEFAULT_OUT_DIR, number_in_range, output_directory

if TYPE_CHECKING:
    from sphere_control.closed_loop import LoopHistory
    from sphere_control.evaluation import EvaluationReport
    from sphere_control.studies import TrackingResult
    from sphere_sim.kicks.lookup_table import CombinedKickPlant, LookupTable

# The analytic stand-in for the paper's plant: the 0.54 deg kick with a convex intensity
# characteristic like Fig. 10 and widths shrinking by a tenth towards the cone's edge.
ANALYTIC_EXPONENT = 1.7
ANALYTIC_SOFTENING = 0.1
# A decision every 10 ms at the fastest (one sample of the device) and every 10 s at the
# slowest: the trajectories of §5 change over seconds, so slower ones follow nothing.
KICK_PERIOD_S = number_in_range(0.01, 10.0, 'one sample of the device to ten seconds')
COLORS = {ControllerKind.BASIC: 'tab:red', ControllerKind.EXTENDED: 'tab:blue',
          ControllerKind.PRELEARNED: 'black'}


class PlantChoice(enum.Enum):
    TABLE = 'table'
    ANALYTIC = 'analytic'

    def __str__(self) -> str:  # what --help and a usage error show
        return self.value


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'evaluate', help='closed-loop studies of §5 (Figs. 13-15) beside the paper\'s findings',
        description='Basic, extended and pre-learned extended controllers on the discrete '
                    'model: setpoint (Figs. 13, 14), trajectory under 33 deg mismatch (Fig. 15), '
                    'eight against four directions, a Kalman filter under measurement noise, '
                    'and a few kicks on the continuous model.')
    parser.add_argument('--quick', action='store_true',
                        help='shorter trajectory runs and two continuous kicks')
    parser.add_argument('--table', type=Path, default=None,
                        help='lookup table (default: the shipped one)')
    parser.add_argument('--axis-table', type=Path, default=AXIS_TABLE_PATH,
                        help='axis-parallel kick table for the eight-direction study')
    parser.add_argument('--plant', type=PlantChoice, choices=list(PlantChoice),
                        default=PlantChoice.TABLE, help='discrete model to evaluate on')
    parser.add_argument('--kick-period-s', type=KICK_PERIOD_S, default=None,
                        help='time per decision in the trajectory runs (s, 0.01 to 10; default: '
                             "the full kick's settle time rounded up to 10 ms)")
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory')
    parser.set_defaults(func=run)



def load_table(path: Path | None) -> tuple[LookupTable, str]:
    """(table, note); TableError for a missing or stale table."""
    from sphere_sim.kicks.lookup_table import DEFAULT_TABLE_PATH, LookupTable

    path = DEFAULT_TABLE_PATH if path is None else path
    return LookupTable.load_current(path), f'table {shown_path(path)}'


def load_eight_directions(table: LookupTable, axis_path: Path) -> tuple[CombinedKickPlant, str]:
    """The diagonal table with the axis-parallel one, and a note."""
    from sphere_sim.kicks.lookup_table import CombinedKickPlant, LookupTable

    axis = LookupTable.load_current(axis_path)
    return CombinedKickPlant([table, axis]), f'eight directions: {shown_path(axis_path)} added'


def shown_path(path: Path) -> Path:
    """``path`` as the note shows it: relative to the working directory where it lies below
    it (a shipped table, from a checkout), else as given."""
    try:
        return path.resolve().relative_to(Path.cwd().resolve())
    except ValueError:
        return path


def run(args: argparse.Namespace) -> int:
    config = EvaluationConfig.quick() if args.quick else EvaluationConfig()
    table = None
    if args.plant is PlantChoice.TABLE:
        table, note = load_table(args.table)
        eight, eight_note = load_eight_directions(table, args.axis_table)
        note = f'{note}; {eight_note}'
        put = PlantUnderTest.measure('lookup table', table)
    else:
        eight = None
        note = 'analytic plant with the paper\'s 0.54 deg kick'
        put = PlantUnderTest.measure(note, AnalyticKickPlant(
            PAPER_FULL_KICK_RAD, exponent=ANALYTIC_EXPONENT, softening=ANALYTIC_SOFTENING))
    print(note)
    print(f'full kick {math.degrees(put.full_width_rad):.4f} deg (paper 0.54 deg; scale '
          f'{put.kick_scale:.4f})')
    config = dataclasses.replace(config, kick_period_s=args.kick_period_s).for_plant(put)
    how = ('as given' if args.kick_period_s is not None else
           f'the full kick settles in {put.settle_time_s * 1e3:.1f} ms, rounded up'
           if put.settle_time_s > 0 else 'the kick window: the plant reports no settle time')
    # for_plant() resolved the period (a float from here on).
    print(f'kick period {cast(float, config.kick_period_s) * 1e3:.0f} ms ({how})')
    report = evaluate(put, config, table=table, progress=lambda m: print(m, flush=True),
                      eight_plant=eight)
    args.out.mkdir(parents=True, exist_ok=True)
    print_table(report.rows)
    data = {'note': note, 'quick': args.quick, 'figures': report.figures, 'rows': report.rows,
            'trajectory_mse_ratio': report.final_ratio,
            'trajectory_mse_ratio_without_preview': report.no_preview_ratio}
    json_path = args.out / 'evaluation.json'
    json_path.write_text(json.dumps(data, indent=2, default=_jsonable))
    paths = write_figures(report, put, args.out)
    print(f'wrote {json_path} and {", ".join(str(p) for p in paths)}')
    print(f'trajectory MSE extended/basic without preview: {report.no_preview_ratio:.3f}')
    print(f'trajectory MSE extended/basic: {report.final_ratio:.3f}')
    return 0


def _jsonable(value: object) -> object:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f'{type(value)} is not JSON-able')


def print_table(rows: Sequence[Mapping[str, Any]]) -> None:
    widths = [max(len(str(r[k])) for r in rows) for k in ('quantity', 'paper', 'ours')]
    widths[0] = max(widths[0], len('quantity'))
    widths[1] = min(max(widths[1], len('paper')), 80)
    scenario = None
    header = f'{"quantity":<{widths[0]}}  {"paper":<{widths[1]}}  ours'
    print(header)
    print('-' * len(header))
    for r in rows:
        if r['scenario'] != scenario:
            scenario = r['scenario']
            print(f'[{scenario}]')
        print(f'{r["quantity"]:<{widths[0]}}  {r["paper"]:<{widths[1]}}  {r["ours"]}')


def write_figures(report: EvaluationReport, put: PlantUnderTest, out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    paths = []
    for fig_key, title in (('fig13', 'Fig. 13: setpoint'),
                           ('fig14', 'Fig. 14: setpoint, 12 deg direction mismatch')):
        fig, axes = plt.subplots(2, 2, figsize=(11, 8.5))
        for row, index in enumerate((0, 1)):
            runs = cast('dict[ControllerKind, LoopHistory]',
                        report.histories[(fig_key, PAPER_SETUP, index)])
            phi = math.degrees(PAPER_PHI_MIN_RAD[index])
            ax_xy, ax_err = axes[row]
            for kind, h in runs.items():
                ax_xy.plot(np.degrees(h.normals[:, 0]), np.degrees(h.normals[:, 1]), '.-',
                           color=COLORS[kind], label=kind.value, lw=0.8, ms=3)
                ax_err.semilogy(np.maximum(np.degrees(h.errors_rad) ** 2, 1e-12), '.-',
                                color=COLORS[kind], label=kind.value, lw=0.8, ms=3)
            target = runs[ControllerKind.BASIC].references[0]
            ax_xy.plot(0.0, 0.0, 'ko', mfc='none', ms=9)
            ax_xy.plot(*np.degrees(target[:2]), 'o', color='gray', ms=9, alpha=0.6)
            ax_xy.set_xlabel('x_sn (x 180/pi, ~deg)')
            ax_xy.set_ylabel('y_sn (x 180/pi, ~deg)')
            ax_xy.set_title(f'Phi_min = {phi:.2f} deg (the paper\'s set-up)')
            ax_xy.axis('equal')
            ax_err.axhline(phi ** 2, color='gray', ls=':', lw=0.8)
            ax_err.set_xlabel('step (kick period)')
            ax_err.set_ylabel('Phi^2 (deg^2)')
            for ax in (ax_xy, ax_err):
                ax.grid(alpha=0.3)
                ax.legend(fontsize=8)
        fig.suptitle(f'{title} on the {put.label}')
        fig.tight_layout()
        path = out / f'evaluation_{fig_key}.png'
        fig.savefig(path, dpi=110)
        plt.close(fig)
        paths.append(path)

    result = cast('TrackingResult', report.histories[('fig15', PAPER_SETUP, True)])
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    best = f'basic (best Phi_min {math.degrees(result.basic_phi_min_rad):.4f} deg)'
    for ax, h, name in ((axes[0], result.basic, best), (axes[1], result.extended, 'extended')):
        ax.plot(h.references[:, 0], h.references[:, 1], color='gray', lw=2, alpha=0.5,
                label='reference')
        ax.plot(h.normals[:, 0], h.normals[:, 1], lw=0.6,
                color='tab:red' if h is result.basic else 'tab:blue', label=name)
        ax.plot(*LEVEL_NORMAL[:2], 'ko', mfc='none')
        ax.set_xlabel('x_sn')
        ax.set_ylabel('y_sn')
        ax.axis('equal')
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    for h, color, name in ((result.basic, 'tab:red', 'basic'),
                           (result.extended, 'tab:blue', 'extended')):
        axes[2].semilogy(h.times_s, np.maximum(h.squared_xy_errors, 1e-14), color=color,
                         lw=0.5, label=name)
    axes[2].axvline(result.basic.times_s[result.catch_up_step], color='gray', ls=':',
                    label='tracking phase starts')
    axes[2].set_xlabel('time (s)')
    axes[2].set_ylabel('squared x-y error')
    axes[2].legend(fontsize=8)
    axes[2].grid(alpha=0.3)
    fig.suptitle(f'Fig. 15: eq. (64) under 33 deg mismatch, the paper\'s set-up with preview '
                 f'(f1 {report.figures["fig15"]["paper"]["frequency_hz"]:g} Hz); MSE '
                 f'extended/basic {result.ratio:.3f}')
    fig.tight_layout()
    path = out / 'evaluation_fig15.png'
    fig.savefig(path, dpi=110)
    plt.close(fig)
    paths.append(path)
    return paths

