"""``sphere-twin replay-check BAG``: the bag's commands replayed open loop through the twin."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING

from msg_defs.device import DEFAULT_PARAMETER_SET, KICK_WINDOW_S
from sphere_twin.commands.bag import BAG_HELP
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    add_params_option,
    output_directory,
    parameter_set,
)

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from sphere_sim.model.parameters import ParameterSet
    from sphere_twin.run_analysis import RecordedRun, ReplayResult

# Resting samples that differ by more than this are a noisy sensor's, not rounding.
SCATTER_RAD = 1e-12


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'replay-check', help='replay a bag\'s commands open loop and compare the normals',
        description='Feed the recorded voltage commands and pulse programmes into the '
                    'simulator open loop, from the first recorded resting normal (the mean of '
                    'the samples before the first command), and report the '
                    'simulated surface normal\'s error against the recorded one over time: the '
                    'way to hold the twin against recordings of the real device.')
    parser.add_argument('bag', help=BAG_HELP)
    parser.add_argument('--plant', choices=('discrete', 'continuous'), default=None,
                        help='the plant replayed (default: the one that recorded the bag, '
                             'and continuous with any set but the shipped one: the kick table '
                             'holds only the shipped set\'s kicks)')
    parser.add_argument('--tables', nargs='*', default=[],
                        help='kick tables of the discrete plant (default: the shipped one)')
    add_params_option(parser)
    parser.add_argument('--before', type=parameter_set, default=None, metavar='NAME|FILE',
                        help='with a --params other than the shipped set (a file that '
                             '`sphere-twin identify` fitted, say): the set to compare it with, '
                             f'replayed too (default {DEFAULT_PARAMETER_SET})')
    parser.add_argument('--out', type=output_directory, default=None,
                        help='output directory (default: the working directory)')
    parser.set_defaults(func=run)


def recorded_from_the_physics(bag_dir: Path) -> bool:
    """Whether the bag was recorded from the continuous plant: only it publishes the sphere's
    and the beams' full state (the discrete plant knows the normal alone)."""
    from msg_defs.topics import SPHERE_STATE
    from sphere_twin.bag.reader import read_metadata

    counts = {t['topic_metadata']['name']: t['message_count']
              for t in read_metadata(bag_dir).get('topics_with_message_count', [])}
    return counts.get(SPHERE_STATE.name, 0) > 0


def default_plant(bag_dir: Path, shipped_set: bool) -> str:
    """The plant a replay uses unless told: the one that recorded the bag, and the continuous
    one for any set but the shipped one (the kick table holds only the shipped set's kicks)."""
    if recorded_from_the_physics(bag_dir) or not shipped_set:
        return 'continuous'
    return 'discrete'


def run(args: argparse.Namespace) -> int:
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.plots import plot_replay_errors
    from sphere_twin.run_analysis import load_run, replay_start_index, unclosed_bag_warning

    bag = locate_bag(args.bag)
    if bag.note:
        print(bag.note)
    recorded = load_run(bag.directory)
    warning = unclosed_bag_warning(bag.directory, recorded)
    if warning:
        print(f'sphere-twin replay-check: warning: {warning}', file=sys.stderr, flush=True)
    start = replay_start_index(recorded, KICK_WINDOW_S)
    if start >= recorded.normal_t_s.size:
        raise CommandError(f'{args.bag}: the recording ends before a kick that began before '
                           'it settles')
    shipped = load_parameter_set(DEFAULT_PARAMETER_SET)
    plant = args.plant or default_plant(bag.directory, args.params.digest() == shipped.digest())
    before = args.before
    if before is None and args.params.digest() != shipped.digest():
        before = shipped
    runs = ([('before', before)] if before is not None else []) + [('after', args.params)]
    results = {label: _replay(recorded, start, plant, params, args.tables,
                              f'{label} ({params.name})' if before else '')
               for label, params in runs}
    out = args.out or DEFAULT_OUT_DIR
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f'{bag.name}_replay'
    result = results['after']
    labels = {'before': f'{plant} plant, {before.name if before else ""} (before)',
              'after': f'{plant} plant, {args.params.name}' + (' (after)' if before else '')}
    improvement = (improvement_text(results['before'].rms_error_rad, result.rms_error_rad)
                   if before is not None else '')
    # In rad, as the lines below print it; the improvement's line is the title's second.
    plot_replay_errors(result.times_s, {labels[k]: results[k].error_rad for k in results},
                       stem.with_suffix('.png'),
                       title='\n'.join(filter(None, (f'open-loop replay of {bag.name}',
                                                      improvement))))
    data = {'bag': str(args.bag), 'plant': plant, 'samples': int(result.times_s.size),
            'kicks': len(recorded.kicks), 'params': args.params.name,
            'max_error_rad': result.max_error_rad, 'rms_error_rad': result.rms_error_rad,
            **({'warning': warning} if warning else {})}
    if before is not None:
        data['before'] = {'params': before.name,
                          'max_error_rad': results['before'].max_error_rad,
                          'rms_error_rad': results['before'].rms_error_rad}
    stem.with_suffix('.json').write_text(json.dumps(data, indent=2) + '\n')
    print(f'replayed {len(recorded.kicks)} programmes and {len(recorded.holds)} voltage '
          f'commands through the {plant} plant against {result.times_s.size} samples')
    print(f'wrote {stem.with_suffix(".png")} and {stem.with_suffix(".json")}')
    if before is not None:
        b = results['before']
        print(f'replay error before ({before.name}): max {b.max_error_rad:.3g} rad, RMS '
              f'{b.rms_error_rad:.3g} rad')
        print(f'replay error after ({args.params.name}): max {result.max_error_rad:.3g} rad, '
              f'RMS {result.rms_error_rad:.3g} rad')
        print(improvement)
    else:
        print(f'replay error: max {result.max_error_rad:.3g} rad, RMS '
              f'{result.rms_error_rad:.3g} rad')
    return 0


def improvement_text(before_rms_rad: float, after_rms_rad: float) -> str:
    """The before-and-after line, printed and the plot's title alike."""
    return (f'improvement: RMS {before_rms_rad:.3g} -> {after_rms_rad:.3g} rad '
            f'({before_rms_rad / max(after_rms_rad, 1e-300):.2f}x)')


def _replay(recorded: RecordedRun, start: int, plant: str, params: ParameterSet,
            tables: Iterable[str | Path], label: str) -> ReplayResult:
    from sphere_twin.run_analysis import build_replay_plant, replay

    start_s = float(recorded.normal_t_s[start])
    replay_plant = build_replay_plant(plant, resting_start(recorded, start), start_s, params,
                                      tables)
    progress = _progress_line(label, start_s, float(recorded.normal_t_s[-1]))
    return replay(recorded, replay_plant, start, progress)


def _progress_line(label: str, start_s: float, end_s: float) -> Callable[[float], None]:
    """A replay's progress, on stderr (stdout holds the results) every few seconds: a long
    continuous replay (a minute for the example bag) would otherwise be silent throughout."""
    from sphere_twin.run_analysis import ProgressClock

    clock = ProgressClock()
    what = f'replaying {label}' if label else 'replaying'
    span_s = max(end_s - start_s, 1e-9)

    def report(time_s: float) -> None:
        if clock.due():
            done_s = time_s - start_s
            print(f'replay-check: {what}: {done_s:.1f} of {span_s:.1f} s of the recording '
                  f'({100.0 * done_s / span_s:.0f}%)', file=sys.stderr, flush=True)

    return report


def resting_start(recorded: RecordedRun, start: int) -> NDArray[np.float64]:
    """The normal the replay starts from: the sample at ``start``, or, where the samples until
    the first command scatter by more than rounding (a noisy sensor), their mean: the sphere
    rests there, and the mean beats the noise. (A noiseless recording keeps its first sample:
    a replay through contacts amplifies even a 1e-17 change to the live tolerance's 1e-5 rad.)
    """
    import numpy as np

    t = recorded.normal_t_s
    first = min((k[0] for k in recorded.kicks if k[0] >= t[start] - 1e-9), default=np.inf)
    first = min([first] + [h[0] for h in recorded.holds if h[0] >= t[start]])
    resting = recorded.normals[start:][t[start:] < first - 1e-9]
    if len(resting) < 2 or np.ptp(resting, axis=0).max() < SCATTER_RAD:
        return recorded.normals[start]
    mean = resting.mean(axis=0)
    return mean / np.linalg.norm(mean)
