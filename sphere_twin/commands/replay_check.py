"""``sphere-twin replay-check BAG``: the bag's commands replayed through the twin, open loop and
one kick ahead."""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from msg_defs.device import DEFAULT_PARAMETER_SET, KICK_WINDOW_S
from sphere_twin.commands.bag import BAG_HELP
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    add_params_option,
    output_directory,
    parameter_set,
    positive_int,
)

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from sphere_sim.kicks.engine import SerialEngine
    from sphere_sim.model.parameters import ParameterSet
    from sphere_twin.kick_ahead import KickAheadResult
    from sphere_twin.run_analysis import RecordedRun, RecordedTruth, ReplayResult

# Resting samples that differ by more than this are a noisy sensor's, not rounding.
SCATTER_RAD = 1e-12


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'replay-check', help='replay a bag\'s commands open loop and one kick ahead, and '
                             'compare the normals',
        description='Feed the recorded voltage commands and pulse programmes into the '
                    'simulator open loop, from the first recorded resting normal (the mean of '
                    'the samples before the first command), and report the '
                    'simulated surface normal\'s error against the recorded one over time; and '
                    'run each programme alone from the recorded rest before it and report its '
                    'landing\'s error against the recorded landing (one kick ahead: whether '
                    'the model is right about one kick from where the device was). The way to '
                    'hold the twin against recordings of the real device.')
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
                             'replayed too (default: the file\'s base:, else '
                             f'{DEFAULT_PARAMETER_SET})')
    parser.add_argument('--out', type=output_directory, default=None,
                        help='output directory (default: the working directory)')
    parser.add_argument('--workers', type=positive_int, default=2,
                        help='processes the kicks run one kick ahead spread over (default 2)')
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
    from sphere_sim.kicks.engine import engine_of
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.run_analysis import (
        load_run,
        load_truth,
        recorded_integration_method,
        replay_kick_period_s,
        replay_start_index,
        unclosed_bag_warning,
    )

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
        # A fitted file is compared with the set it was fitted from.
        before = load_parameter_set(args.params.base) if args.params.base else shipped
    runs = ([('before', before)] if before is not None else []) + [('after', args.params)]
    method = recorded_integration_method(bag.directory)
    results = {label: _replay(recorded, start, plant, params, args.tables,
                              f'{label} ({params.name})' if before else '', method)
               for label, params in runs}
    window_s = replay_kick_period_s(args.tables)
    noisy = noisy_sensor(recorded, start)
    # A twin's bag records where its sphere and beams were: one kick ahead starts there.
    truth = load_truth(bag.directory) if plant == 'continuous' else None
    with engine_of(args.workers) as engine:
        ahead = {label: _kick_ahead(recorded, plant, params, args.tables, window_s, noisy,
                                    engine, f'{label} ({params.name})' if before else '', truth,
                                    method)
                 for label, params in runs}
    for line in dict.fromkeys(s.warning() for a in ahead.values() for s in a.skipped):
        print(f'sphere-twin replay-check: warning: {line}', file=sys.stderr, flush=True)
    out = args.out or DEFAULT_OUT_DIR
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f'{bag.name}_replay'
    improvement = (improvement_text(results['before'].rms_error_rad,
                                    results['after'].rms_error_rad)
                   if before is not None else '')
    _plot(results, stem.with_suffix('.png'), bag.name, plant, args.params.name,
          before.name if before else None, improvement)
    data = _json_data(args, plant, recorded, results, ahead, before, warning)
    if plant == 'continuous':
        data['integration_method'] = method
    stem.with_suffix('.json').write_text(json.dumps(data, indent=2) + '\n')
    integrated = f' (integrated by {method}, as recorded)' if plant == 'continuous' else ''
    print(f'replayed {len(recorded.kicks)} programmes and {len(recorded.holds)} voltage '
          f'commands through the {plant} plant{integrated} against '
          f'{results["after"].times_s.size} samples')
    print(f'wrote {stem.with_suffix(".png")} and {stem.with_suffix(".json")}')
    _print_errors(results, ahead, args.params.name, before.name if before else None,
                  improvement)
    return 0


def _plot(results: dict[str, ReplayResult], path: Path, bag_name: str, plant: str,
          params_name: str, before_name: str | None, improvement: str) -> None:
    """The open loop's error against time (the replay's plot, as before)."""
    from sphere_twin.plots import plot_replay_errors

    labels = {'before': f'{plant} plant, {before_name} (before)',
              'after': f'{plant} plant, {params_name}' + (' (after)' if before_name else '')}
    # In rad, as the lines below print it; the improvement's line is the title's second.
    plot_replay_errors(results['after'].times_s,
                       {labels[k]: results[k].error_rad for k in results}, path,
                       title='\n'.join(filter(None, (f'open-loop replay of {bag_name}',
                                                      improvement))))


def _json_data(args: argparse.Namespace, plant: str, recorded: RecordedRun,
               results: dict[str, ReplayResult], ahead: dict[str, KickAheadResult],
               before: ParameterSet | None, warning: str | None) -> dict[str, Any]:
    """The replay's JSON: the open loop's error (``max_error_rad``, ``rms_error_rad``) and the
    one-kick-ahead figures with every kick's landings, each error's question beside it."""
    from sphere_twin.kick_ahead import ONE_KICK_AHEAD_QUESTION, OPEN_LOOP_QUESTION

    result = results['after']
    data: dict[str, Any] = {
        'bag': str(args.bag), 'plant': plant, 'samples': int(result.times_s.size),
        'kicks': len(recorded.kicks), 'params': args.params.name,
        'questions': {'open_loop': OPEN_LOOP_QUESTION,
                      'one_kick_ahead': ONE_KICK_AHEAD_QUESTION},
        'max_error_rad': result.max_error_rad, 'rms_error_rad': result.rms_error_rad,
        'one_kick_ahead': ahead['after'].to_dict(),
        **({'warning': warning} if warning else {})}
    if before is not None:
        data['before'] = {'params': before.name,
                          'max_error_rad': results['before'].max_error_rad,
                          'rms_error_rad': results['before'].rms_error_rad,
                          'one_kick_ahead': ahead['before'].to_dict()}
    return data


def _print_errors(results: dict[str, ReplayResult], ahead: dict[str, KickAheadResult],
                  params_name: str, before_name: str | None, improvement: str) -> None:
    """The errors on stdout; the last line is the one-kick-ahead and open-loop summary."""
    result, kicks = results['after'], ahead['after']
    if before_name is not None:
        for label, name in (('before', before_name), ('after', params_name)):
            r = results[label]
            print(f'replay error {label} ({name}): open loop max {r.max_error_rad:.3g} rad, RMS '
                  f'{r.rms_error_rad:.3g} rad; one kick ahead {ahead[label].summary()}')
        print(improvement)
    else:
        print(f'open loop, from the first rest: max {result.max_error_rad:.3g} rad, RMS '
              f'{result.rms_error_rad:.3g} rad')
    skipped = f' ({len(kicks.skipped)} skipped)' if kicks.skipped else ''
    worst = f': the worst at {kicks.worst_s:.3f} s' if kicks.error_rad.size else ''
    print(f'one kick ahead, each of {kicks.error_rad.size} kicks from the recorded rest before '
          f'it ({kicks.start_text()}){skipped}{worst}')
    print(f'replay error: one kick ahead {kicks.summary()}; open loop max '
          f'{result.max_error_rad:.3g} rad')


def improvement_text(before_rms_rad: float, after_rms_rad: float) -> str:
    """The before-and-after line, printed and the plot's title alike."""
    return (f'improvement: RMS {before_rms_rad:.3g} -> {after_rms_rad:.3g} rad '
            f'({before_rms_rad / max(after_rms_rad, 1e-300):.2f}x)')


def _replay(recorded: RecordedRun, start: int, plant: str, params: ParameterSet,
            tables: Iterable[str | Path], label: str, method: str) -> ReplayResult:
    from sphere_twin.run_analysis import build_replay_plant, replay

    start_s = float(recorded.normal_t_s[start])
    replay_plant = build_replay_plant(plant, resting_start(recorded, start), start_s, params,
                                      tables, method=method)
    progress = _progress_line(label, start_s, float(recorded.normal_t_s[-1]))
    return replay(recorded, replay_plant, start, progress)


def _kick_ahead(recorded: RecordedRun, plant: str, params: ParameterSet,
                tables: Iterable[str | Path], window_s: float, noisy: bool,
                engine: SerialEngine, label: str,
                truth: RecordedTruth | None, method: str) -> KickAheadResult:
    from sphere_twin.kick_ahead import ReplayPlantSpec, one_kick_ahead
    from sphere_twin.run_analysis import ProgressClock

    clock = ProgressClock()
    what = f'one kick ahead {label}' if label else 'one kick ahead'

    def report(done: int, total: int) -> None:
        # On stderr every few seconds, as the open loop's: the example's 497 kicks take
        # minutes on the physics.
        if clock.due():
            print(f'replay-check: {what}: {done} of {total} kicks ({100.0 * done / total:.0f}%)',
                  file=sys.stderr, flush=True)

    spec = ReplayPlantSpec(plant, params, tuple(str(t) for t in tables), method)
    return one_kick_ahead(recorded, spec, window_s, engine, average=noisy, progress=report,
                          truth=truth)


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
    from sphere_twin.kick_ahead import unit_mean

    resting = _first_rest(recorded, start)
    return unit_mean(resting) if _scatters(resting) else recorded.normals[start]


def noisy_sensor(recorded: RecordedRun, start: int) -> bool:
    """Whether the recording's sensor is noisy: its samples from ``start`` until the first
    command, where the sphere rests, scatter by more than rounding."""
    return _scatters(_first_rest(recorded, start))


def _first_rest(recorded: RecordedRun, start: int) -> NDArray[np.float64]:
    """The samples from ``start`` until the first command, shape (k, 3)."""
    import numpy as np

    t = recorded.normal_t_s
    first = min((k[0] for k in recorded.kicks if k[0] >= t[start] - 1e-9), default=np.inf)
    first = min([first] + [h[0] for h in recorded.holds if h[0] >= t[start]])
    return recorded.normals[start:][t[start:] < first - 1e-9]


def _scatters(resting: NDArray[np.float64]) -> bool:
    import numpy as np

    return len(resting) >= 2 and float(np.ptp(resting, axis=0).max()) >= SCATTER_RAD
