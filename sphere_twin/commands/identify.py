"""``sphere-twin identify BAG [BAG ...]``: fit the twin's parameters to a device's recordings.

Reads only what the device records (``/beams/pulse_program``, ``/beams/voltage_command``,
``/sphere/surface_normal``), hands the kicks to :mod:`sphere_sim.fitting.identification`, and
writes a parameter file (``base:`` + ``overrides:``, with an ``identification:`` section of
values, intervals and per-kick residuals) and a plot of recorded against fitted normals.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import os
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import yaml
from numpy.typing import NDArray
from tqdm import tqdm

from sphere_sim.fitting.identification import (
    DETERMINACY_SIMULATIONS_PER_KICK,
    START_PARAMETER_SET,
)
from sphere_twin.commands.bag import BAG_HELP
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    add_params_option,
    output_file,
    positive_int,
)

if TYPE_CHECKING:
    from sphere_sim.fitting.identification import Evaluator, FitParameter, IdentificationResult
    from sphere_sim.fitting.joint_fit import JointFitResult
    from sphere_sim.fitting.observations import KickObservation, Observations
    from sphere_sim.fitting.protocol import ProbeBracket
    from sphere_sim.fitting.ramps import PullInObservation, RampObservation
    from sphere_sim.fitting.thresholds import ThresholdObservation
    from sphere_sim.model.parameters import ParameterSet
    from sphere_twin.bag.locate import BagLocation

TRUTH_FILE = 'truth.yaml'
# --max-evaluations' defaults: per optimiser run of the kicks' fit; the joint fit's cost limit
# (sphere_sim.fitting.joint_fit.MAX_EVALUATIONS, not imported at parse time).
KICK_EVALUATIONS = 30
JOINT_EVALUATIONS = 300
# Wall seconds between two redraws of the progress bar while a batch of kicks runs: the first
# batch (the start and a step per fitted parameter) takes minutes before the count first moves.
BAR_REDRAW_S = 5.0


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'identify', help='fit the twin to recordings of one device',
        description='Fit the parameters the set declares uncertain (or those named with --fit) '
                    'so that the continuous model, started at rest at each kick\'s recorded '
                    'normal and driven by its recorded programme, reproduces the recorded '
                    'normal after it. Reads only the device\'s topics; writes a parameter file '
                    'usable with every --params and, for kicks alone, a plot of recorded '
                    'against fitted normals. '
                    'A bag of the experiment protocol (sphere-twin experiment) adds its '
                    'thresholds to the same misfit: a multi-start over the declared ranges '
                    'and each parameter\'s 95 % profile-likelihood interval, undetermined '
                    'where the recordings leave it open. '
                    'Resumable: an interrupted fit goes on from its checkpoint file.')
    parser.add_argument('bags', nargs='+', metavar='BAG', help=BAG_HELP)
    add_params_option(parser, default=START_PARAMETER_SET,
                      help='the start, and every parameter not fitted: a set\'s name or a YAML '
                           f'file (default {START_PARAMETER_SET}, the paper\'s device; '
                           'dry_contact for a device of the dry holding contact)')
    parser.add_argument('--fit', nargs='+', metavar='NAME', default=None,
                        help='parameter paths to fit (default: those the set declares '
                             'uncertain), e.g. beam.damping_phi_nms_per_rad')
    parser.add_argument('--out', type=output_file('.yaml'), default=None,
                        help='fitted parameter file (default: <first bag>_identified.yaml in the '
                             'working directory)')
    parser.add_argument('--workers', type=positive_int, default=2, help='local processes')
    parser.add_argument('--scheduler', default=None,
                        help='Dask scheduler address, e.g. tcp://host:8786')
    parser.add_argument('--max-evaluations', type=positive_int, default=None,
                        help="most evaluations of the residuals by the optimiser (each one "
                             "simulates every kick; a Jacobian's columns come on top; default "
                             f"{KICK_EVALUATIONS}); for a bag of the experiment protocol the "
                             "cost limit of the fit, starts and profiles together, and "
                             "another as large for the search on its thresholds alone that "
                             f"comes first (default {JOINT_EVALUATIONS})")
    parser.add_argument('--thresholds', action='store_true',
                        help="fit the experiment protocol's recorded thresholds alone, "
                             "leaving its kicks out")
    parser.set_defaults(func=run)


@dataclasses.dataclass(frozen=True)
class Recording:
    """What one bag holds for identification: its kicks and, from the experiment protocol, its
    thresholds (none in a bag of kicks alone) and the searches with a side never seen."""

    kicks: Observations
    thresholds: list[ThresholdObservation]
    one_sided: list[ProbeBracket]
    no_kicks: str = ''  # why the bag has no kick to fit, if it has none
    ramps: tuple[RampObservation, ...] = ()  # the slow ramps whose jump was seen

    @property
    def pull_ins(self) -> list[PullInObservation]:
        """What the fit takes of the protocol: the threshold searches, then the ramps."""
        return [*self.thresholds, *self.ramps]


def read_recording(bag_dir: str | os.PathLike[str]) -> Recording:
    """The kicks and the protocol's thresholds of one bag, from the device's topics only. The
    kicks are every programme but the protocol's probes and ramps, whose resting normals tell
    thresholds, not landings."""
    from sphere_sim.fitting.observations import (
        SETTLE_S,
        IdentificationError,
        Observations,
        observations_from_samples,
    )
    from sphere_sim.fitting.protocol import friction_kicks
    from sphere_sim.fitting.thresholds import observations_of
    from sphere_twin.protocol_bag import distinct_samples, protocol_of
    from sphere_twin.run_analysis import DEVICE_TOPICS, load_run

    run = load_run(bag_dir, DEVICE_TOPICS)
    t_s, normals = distinct_samples(run)
    protocol = protocol_of(run)
    thresholds, one_sided = observations_of(protocol.brackets)
    try:
        kicks = friction_kicks(observations_from_samples(t_s, normals, run.kicks, run.holds,
                                                         SETTLE_S))
    except IdentificationError as exc:  # a protocol's thresholds may still be fitted
        return Recording(Observations((), 0.0), thresholds, one_sided, str(exc),
                         protocol.ramp_observations)
    return Recording(kicks, thresholds, one_sided, ramps=protocol.ramp_observations)


def read_observations(bag_dir: str | os.PathLike[str]) -> Observations:
    """The kicks of one bag (:func:`read_recording`).

    Raises
    ------
    IdentificationError
        When the bag has no kick to fit.
    """
    from sphere_sim.fitting.observations import IdentificationError

    recording = read_recording(bag_dir)
    if recording.no_kicks:
        raise IdentificationError(recording.no_kicks)
    return recording.kicks


def run(args: argparse.Namespace) -> int:
    from sphere_sim.fitting.identification import fit_parameters
    from sphere_sim.fitting.observations import IdentificationError, merge_observations
    from sphere_twin.bag.locate import locate_bag

    bags = [locate_bag(b) for b in args.bags]
    base = args.params
    try:
        # The request first: a parameter that cannot be fitted is refused before any reading.
        fits = fit_parameters(base, args.fit)
        recordings = [_read_saying(b.directory, i, len(bags)) for i, b in enumerate(bags, 1)]
    except IdentificationError as exc:
        raise CommandError(str(exc)) from None
    thresholds = [t for r in recordings for t in r.pull_ins]
    for bracket in (b for r in recordings for b in r.one_sided):
        print(f'left out {bracket.label}: the bracket has a side never seen')
    if args.thresholds and not thresholds:
        raise CommandError(
            f'{", ".join(str(b.directory) for b in bags)}: no threshold search of the '
            'experiment protocol with both sides seen (record one with sphere-twin '
            'experiment or sphere-twin synthetic record --protocol)')
    if not thresholds and any(r.no_kicks for r in recordings):
        raise CommandError(next(r.no_kicks for r in recordings if r.no_kicks))
    with_kicks = [r.kicks for r in recordings if r.kicks.kicks]
    obs = merge_observations(with_kicks) if with_kicks and not args.thresholds else None
    out = args.out or DEFAULT_OUT_DIR / f'{bags[0].name}_identified.yaml'
    out.parent.mkdir(parents=True, exist_ok=True)
    checkpoint = out.with_suffix('.partial.jsonl')
    if obs is not None:
        print(f'{len(obs.kicks)} kicks from {len(bags)} bag(s) ({obs.dropped} programmes '
              'without settled samples around them left out); sensor noise '
              f'{obs.noise_std_rad:.3g} rad per axis, from the resting stretches')
    for fit in fits:
        where = 'declared range' if fit.declared else 'search bound, no declared range'
        print(f'fit {fit.path}{" (with " + ", ".join(fit.tied) + ")" if fit.tied else ""}: '
              f'start {base.get(fit.path):.4g}, {where} [{fit.low:.4g}, {fit.high:.4g}]')
    if thresholds:
        return run_joint(args, bags, fits, obs, thresholds, out, checkpoint)
    if obs is None:
        raise CommandError(f'{", ".join(str(b.directory) for b in bags)}: no kick to fit '
                           '(every programme is a probe or a ramp of the protocol)')
    return run_kicks(args, bags, fits, obs, out, checkpoint)


def run_kicks(args: argparse.Namespace, bags: Sequence[BagLocation],
              fits: Sequence[FitParameter], obs: Observations, out: Path,
              checkpoint: Path) -> int:
    """Recordings of kicks alone: the kicks' fit, with intervals from the misfit's curvature
    (sphere_sim.fitting.identification)."""
    from sphere_sim.fitting.identification import identify
    from sphere_sim.fitting.observations import IdentificationError
    from sphere_sim.model.parameters import ParameterError, load_parameter_set

    base = args.params
    say_setup(args.workers, args.scheduler, len(fits), len(obs.kicks))
    started = time.perf_counter()
    with tqdm(desc='identify', unit='kick') as bar, redrawn(bar, BAR_REDRAW_S):
        def progress(evaluator: Evaluator) -> None:
            bar.n = evaluator.simulated
            bar.set_postfix_str(f'{len(evaluator.cache)} evaluations')
            bar.refresh()

        try:
            result = identify(base, obs, fits, args.workers, args.scheduler,
                              checkpoint=checkpoint, progress=progress,
                              max_nfev=args.max_evaluations or KICK_EVALUATIONS)
        except IdentificationError as exc:
            raise CommandError(str(exc)) from None
    wall_s = time.perf_counter() - started
    print_result(result, wall_s)
    fitted_obs = result.observations or obs
    write_fitted(out, args.params, result, fitted_obs, [str(b.directory) for b in bags], wall_s,
                 [obs.kicks[i] for i in result.undetermined])
    load_parameter_set.cache_clear()
    try:
        fitted = load_parameter_set(str(out))
    except ParameterError as exc:  # pragma: no cover - a bug, said plainly
        raise CommandError(f'the fitted file does not load: {exc}') from None
    png = plot_fit(out.with_suffix('.png'), fitted_obs, result, bags[0].name)
    checkpoint.unlink(missing_ok=True)
    print(f'wrote {out} and {png}')
    truth_path = bags[0].directory / TRUTH_FILE
    if truth_path.exists():
        report_truth(result, load_parameter_set(str(truth_path.resolve())), fitted)
    return 0


def run_joint(args: argparse.Namespace, bags: Sequence[BagLocation],
              fits: Sequence[FitParameter], kicks: Observations | None,
              thresholds: Sequence[PullInObservation], out: Path, checkpoint: Path) -> int:
    """A protocol's recordings: its thresholds and its kicks (``kicks`` None: the thresholds
    alone) in one misfit, with profile intervals (sphere_sim.fitting.joint_fit)."""
    from sphere_sim.fitting.joint_fit import fit_jointly, thresholds_checkpoint
    from sphere_sim.fitting.observations import IdentificationError
    from sphere_sim.fitting.ramps import RampObservation
    from sphere_sim.fitting.thresholds import (
        OUTCOME_PULSES,
        OUTCOME_STEP_V,
        OUTCOME_WINDOW_V,
        ThresholdError,
    )
    from sphere_sim.model.parameters import load_parameter_set

    limit = args.max_evaluations or JOINT_EVALUATIONS
    ramps = sum(isinstance(t, RampObservation) for t in thresholds)
    what = (f'{len(thresholds) - ramps} thresholds, {ramps} ramps'
            + (f' and {len(kicks.kicks)} kicks' if kicks else ''))
    print(f'{what}, in one misfit; a multi-start over the declared ranges, then each '
          f'parameter\'s 95 % profile interval (cost limit {limit} evaluations, each every '
          'threshold, some 0.3 s apiece near points already searched and up to 1.7 s where the '
          'model lies volts off the recording, and every kick)')
    if len(thresholds) > ramps:
        say(f'first: {len(thresholds) - ramps} scans of {OUTCOME_PULSES} '
            f'pulses (each threshold at the start values, every {OUTCOME_STEP_V:g} V within '
            f'{OUTCOME_WINDOW_V:g} V of its bracket, to leave out those whose pulses switch '
            'more than once)')
    say(f'on {args.workers} local process(es)' if args.scheduler is None
        else f'on the Dask cluster at {args.scheduler}')
    started = time.perf_counter()
    with tqdm(desc='identify', unit='evaluation') as bar, redrawn(bar, BAR_REDRAW_S):
        def progress(evaluator: Evaluator) -> None:
            bar.n = len(evaluator.cache)
            bar.refresh()

        try:
            result = fit_jointly(args.params, fits, kicks, thresholds, args.workers,
                                 args.scheduler, checkpoint, progress, max_evaluations=limit)
        except (IdentificationError, ThresholdError) as exc:
            raise CommandError(str(exc)) from None
    wall_s = time.perf_counter() - started
    print_joint_result(result, wall_s)
    write_joint_fitted(out, args.params, fits, result, [str(b.directory) for b in bags], wall_s)
    for done in (checkpoint, thresholds_checkpoint(checkpoint)):
        done.unlink(missing_ok=True)
    print(f'wrote {out}')
    truth_path = bags[0].directory / TRUTH_FILE
    if truth_path.exists():
        truth = load_parameter_set(str(truth_path.resolve()))
        inside = [e.contains(truth.get(e.path)) for e in result.estimates]
        for e, within in zip(result.estimates, inside, strict=True):
            print(f'  {e.path}: truth {truth.get(e.path):.4g}, '
                  f'{"inside" if within else "OUTSIDE"} its 95 % interval')
        print(f'identified: {sum(inside)} of {len(inside)} parameters within their 95 % '
              f'profile interval of the truth; determined '
              f'{sum(e.determined for e in result.estimates)} of {len(inside)}')
    return 0


def undetermined_kicks_line(count: int) -> str:
    """What both printers say of the kicks ``undetermined_kicks`` left out, by its two rules."""
    return (f'{count} kick(s) left out: the model does not determine their end (at a tenth of '
            'the tolerance it ends further off than the residual\'s noise, or, started that far '
            'off along x or y, further than that from where the shift alone would put it)')


def print_joint_result(result: JointFitResult, wall_s: float) -> None:
    from sphere_sim.fitting.protocol import missing_experiment

    count = (f'{result.threshold_search_evaluations} evaluations of the thresholds alone, then '
             f'{result.evaluations} of the thresholds and kicks together ('
             f'{result.kick_search_evaluations} searching on the kicks, '
             f'{result.region_draws} starts drawn over the thresholds\' region),'
             if result.threshold_search_evaluations else f'{result.evaluations} evaluations')
    print(f'{count} in {wall_s:.0f} s; sum of squares '
          f'{result.chi2:.2f}: {result.threshold_chi2:.2f} over {len(result.thresholds)} thresholds'
          + (f', {result.kicks_chi2:.2f} over {2 * len(result.kicks.kicks)} kick residuals'
             if result.kicks.kicks else '')
          + (' (stopped by the cost limit)' if result.profile.cost_limited else ''))
    if result.threshold_search_evaluations:
        others = [e.path for e in result.estimates if e.path not in result.seen_by_thresholds]
        print('searched on the thresholds alone: ' + (', '.join(result.seen_by_thresholds)
                                                      or 'none, they see no parameter')
              + ('; on the kicks, the thresholds\' held: ' + ', '.join(others)
                 if others else ''))
    if result.undetermined:
        print(undetermined_kicks_line(len(result.undetermined)))
    for search, switches in result.non_monotone:
        print(f'left out {search.label} (recorded {search.low_v:.2f}-{search.high_v:.2f} V): '
              f'at the start values its pulses switch more than once around it ({switches}), so '
              'which switch a bisection finds turns on its path')
    if result.kicks.kicks:
        print(f'per-kick residual RMS: {_rms(np.hypot(*result.kick_vectors_start.T)):.3g} rad '
              f'at the start, {_rms(np.hypot(*result.kick_vectors_fitted.T)):.3g} rad fitted')
    if result.profile.lower_found:
        print('a profile went lower than the optimum the search found: the intervals are read '
              'about a point that is not the lowest (raise --max-evaluations)')
    for obs, model_v, r in zip(result.thresholds, result.model_thresholds_v,
                               result.threshold_residuals, strict=True):
        print(f'  {obs.label}: recorded {obs.low_v:.2f}-{obs.high_v:.2f} V, model '
              f'{model_v:.2f} V ({r:+.2f} sd)')
    for e in result.estimates:
        status = 'determined' if e.determined else 'undetermined'
        lacking = None if e.determined else missing_experiment(
            e.path, bool(result.thresholds), bool(result.kicks.kicks))
        print(f'{e.path}: {e.value:.4g}, 95 % profile interval [{e.low:.4g}, {e.high:.4g}] '
              f'in the range [{e.range_low:.4g}, {e.range_high:.4g}]: {status} ({e.note})'
              + (f'; the recordings hold no {lacking}, which determine it' if lacking else ''))


def write_joint_fitted(path: Path, params: ParameterSet, fits: Sequence[FitParameter],
                       result: JointFitResult, bags: Sequence[str], wall_s: float) -> Path:
    """The fitted parameter file of a joint fit: ``base:`` + ``overrides:``, and what the fit
    found (profile intervals, each threshold and each kick at the optimum)."""
    overrides = {q: float(e.value) for fp, e in zip(fits, result.estimates, strict=True)
                 for q in (fp.path, *fp.tied)}
    data = {
        'name': f'{Path(bags[0]).name}_identified',
        'description': f'{params.name} with the parameters identified from '
                       f'{len(result.model_thresholds_v)} thresholds and '
                       f'{len(result.kicks.kicks)} kicks ({", ".join(Path(b).name for b in bags)})',
        'base': base_reference(params, path),
        'overrides': overrides,
        'identification': {
            'bags': list(bags),
            'kicks': len(result.kicks.kicks),
            'thresholds': len(result.model_thresholds_v),
            'sensor_noise_rad': float(result.kicks.noise_std_rad),
            'interval': '95 % profile likelihood: where the sum of squares, the others '
                        're-minimised, has risen by 3.84 over the optimum',
            'wall_s': round(wall_s, 1),
            'evaluations': result.evaluations,
            'threshold_search_evaluations': result.threshold_search_evaluations,
            'sum_of_squares': {'thresholds': result.threshold_chi2,
                               'kicks': result.kicks_chi2},
            'parameters': [{'path': e.path, 'tied': list(fp.tied),
                            'start': float(params.get(e.path)), 'value': e.value,
                            'interval': [e.low, e.high], 'range': [e.range_low, e.range_high],
                            'declared_range': fp.declared,
                            'status': 'determined' if e.determined else 'undetermined',
                            'note': e.note}
                           for fp, e in zip(fits, result.estimates, strict=True)],
            'left_out_thresholds': [{'step': o.label, 'recorded_v': [o.low_v, o.high_v],
                                     'switches': switches}
                                    for o, switches in result.non_monotone],
            'per_threshold': [{'step': o.label, 'recorded_v': [o.low_v, o.high_v],
                               'model_v': float(m), 'residual_sd': float(r)}
                              for o, m, r in zip(result.thresholds,
                                                 result.model_thresholds_v,
                                                 result.threshold_residuals, strict=True)],
            'per_kick': [{'time_s': round(float(k.time_s), 6),
                          'residual_start_rad': float(np.hypot(*b)),
                          'residual_fitted_rad': float(np.hypot(*a))}
                         for k, b, a in zip(result.kicks.kicks, result.kick_vectors_start,
                                            result.kick_vectors_fitted, strict=True)],
        },
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False, width=96))
    return path


def say(line: str) -> None:
    """A progress line, on stderr: stdout holds the results."""
    print(f'identify: {line}', file=sys.stderr, flush=True)


def _read_saying(bag_dir: Path, number: int, count: int) -> Recording:
    say(f'reading {bag_dir} (bag {number} of {count}) ...')
    return read_recording(bag_dir)


def say_setup(workers: int, scheduler: str | None, fitted: int, kicks: int) -> None:
    """What happens before the bar's count first moves, which takes minutes: the engine
    starts, each worker builds the model and loads its compiled kernels, and the first batch
    simulates every kick at the start and at a step along each fitted parameter."""
    where = f'the Dask cluster at {scheduler}' if scheduler else f'{workers} local process(es)'
    say(f'starting {where}; each builds the model and loads its compiled kernels '
        '(numba compiles them on first use, a minute or more)')
    say(f'first: {DETERMINACY_SIMULATIONS_PER_KICK * kicks} kick simulations (every kick at '
        'the start values, at the fit\'s tolerance and a tenth of it and from starts shifted '
        'along x and y, to leave out those the model does not determine), then '
        f'a batch of {(1 + fitted) * kicks} (the start and one step per fitted parameter) '
        'before the count below first moves')


@contextlib.contextmanager
def redrawn(bar: tqdm[Any], period_s: float) -> Iterator[None]:
    """Redraw ``bar`` every ``period_s`` while the block runs, so that its elapsed time runs
    on through a batch that has not reported yet."""
    stop = threading.Event()

    def redraw() -> None:
        while not stop.wait(period_s):
            bar.refresh()

    thread = threading.Thread(target=redraw, name='identify-bar', daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def print_result(result: IdentificationResult, wall_s: float) -> None:
    print(f'{result.evaluations} evaluations, {result.simulated_kicks} kicks simulated '
          f'({result.resumed_evaluations} evaluations read back from the checkpoint) in '
          f'{wall_s:.1f} s; optimiser: {result.converged}')
    if result.undetermined:
        print(undetermined_kicks_line(len(result.undetermined)))
    print(f'per-kick residual RMS: {_rms(result.residuals_before):.3g} rad at the start, '
          f'{_rms(result.residuals_after):.3g} rad fitted; sum of squares '
          f'{result.cost_ratio:.2f} x what the sensor noise explains')
    if result.restarts:
        print(f'the scan of the misfit found a lower point than the optimiser\'s: restarted '
              f'{result.restarts} x')
    for p in result.parameters:
        if p.fitted:
            print(f'{p.path} = {p.value:.5g} in {interval_text(p.interval)} (2 standard errors; '
                  f'start {p.start:.5g})')
        if p.status != 'fitted':
            print(f'{p.path}: {p.status}, {p.note}')


def interval_text(interval: Sequence[float]) -> str:
    low, high = interval
    return f'[{low:.4g}, {high:.4g}]'


def _rms(values: Sequence[float] | NDArray[np.float64]) -> float:
    return float(np.sqrt(np.mean(np.square(values)))) if len(values) else 0.0


def base_reference(params: ParameterSet, path: Path) -> str:
    """What a fitted file's ``base:`` names: the shipped set ``params`` is, or else a file
    beside ``path`` holding ``params`` whole (a start given as a file of its own)."""
    return set_reference(params, path.with_name(f'{path.stem}_start.yaml'))


def set_reference(params: ParameterSet, whole_file: Path) -> str:
    """How another set's ``base:`` or a node's ``params`` names ``params``: its shipped name
    where it is that set unchanged, or else ``whole_file``, written here with it whole."""
    from sphere_sim.model.parameters import available_parameter_sets, load_parameter_set

    if params.name in available_parameter_sets() and \
            load_parameter_set(params.name).digest() == params.digest():
        return params.name
    # Whole, so without the base it was derived from (a base would make its sections unread).
    whole = {k: v for k, v in params.to_dict().items() if k != 'base'}
    whole_file.write_text(yaml.safe_dump(json_safe(whole), sort_keys=False, width=96))
    return str(whole_file.resolve())


def json_safe(data: Any) -> Any:
    """Tuples as lists, for yaml.safe_dump."""
    if isinstance(data, dict):
        return {k: json_safe(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [json_safe(v) for v in data]
    return data


def write_fitted(path: Path, params: ParameterSet, result: IdentificationResult,
                 obs: Observations, bags: Sequence[str], wall_s: float,
                 undetermined: Sequence[KickObservation] = ()) -> Path:
    """The fitted parameter file: ``base:`` + ``overrides:``, and what the fit found."""
    overrides: dict[str, float] = {}
    for p in result.parameters:
        if p.fitted:
            for q in (p.path, *p.tied):
                overrides[q] = float(p.value)
    data = {
        'name': f'{Path(bags[0]).name}_identified',
        'description': f'{params.name} with the parameters identified from '
                       f'{len(obs.kicks)} recorded kicks ({", ".join(Path(b).name for b in bags)})',
        'base': base_reference(params, path),
        'overrides': overrides,
        'identification': {
            'bags': bags,
            'kicks': len(obs.kicks),
            'undetermined_kicks_s': [round(float(k.time_s), 6) for k in undetermined],
            'sensor_noise_rad': float(obs.noise_std_rad),
            'interval': '2 standard errors either side in the scaled (logarithmic) '
                        'coordinate, from the curvature of the misfit measured over the '
                        'interval itself; the residuals weighed by the sensor noise measured '
                        'in the resting stretches, the interval widened by the fit\'s own '
                        'misfit where it exceeds that noise',
            'restarts': result.restarts,
            'wall_s': round(wall_s, 1),
            'optimiser': result.converged,
            'parameters': [p.to_dict() for p in result.parameters],
            'correlation_of_fitted': np.round(result.correlation, 4).tolist(),
            'residual_rms_rad': {'start': _rms(result.residuals_before),
                                 'fitted': _rms(result.residuals_after)},
            'per_kick': [{'time_s': round(float(k.time_s), 6),
                          'residual_start_rad': float(b), 'residual_fitted_rad': float(a)}
                         for k, b, a in zip(obs.kicks, result.residuals_before,
                                            result.residuals_after, strict=True)],
        },
    }
    path.write_text(yaml.safe_dump(data, sort_keys=False, width=96))
    return path


def plot_fit(path: Path, obs: Observations, result: IdentificationResult, title: str) -> Path:
    """Each kick's displacement of the resting normal, recorded against the model's at the
    start values and fitted, and the residual per kick."""
    from sphere_twin.plots import plt

    t = np.array([k.time_s for k in obs.kicks])
    before = np.array([k.normal_before[:2] for k in obs.kicks])
    recorded = np.array([k.normal_after[:2] for k in obs.kicks]) - before
    start = recorded + result.vectors_before
    fitted = recorded + result.vectors_after
    fig, axes = plt.subplots(3, 1, figsize=(9, 8), sharex=True)
    for i, name in enumerate(('$x_{sn}$', '$y_{sn}$')):
        ax = axes[i]
        ax.plot(t, np.degrees(recorded[:, i]), 'ko', ms=4, label='recorded (resting means)')
        ax.plot(t, np.degrees(start[:, i]), 'x', color='tab:blue', label='model, start')
        ax.plot(t, np.degrees(fitted[:, i]), '+', color='tab:red', ms=9, label='model, fitted')
        ax.set_ylabel(f'kick: change of {name} (deg)')
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[2].semilogy(t, np.degrees(result.residuals_before), 'x', color='tab:blue',
                     label='start')
    axes[2].semilogy(t, np.degrees(result.residuals_after), '+', color='tab:red', ms=9,
                     label='fitted')
    # RMS of a kick's residual from the sensor noise alone (both means, both axes).
    expected = obs.noise_std_rad * math.sqrt(2.0 * np.mean(
        [1.0 / k.samples_before + 1.0 / k.samples_after for k in obs.kicks]))
    axes[2].axhline(math.degrees(expected), color='grey', lw=1, ls='--',
                    label='expected from the sensor noise')
    axes[2].set_ylabel('model - recorded (deg)')
    axes[2].set_xlabel('kick start (s)')
    axes[2].grid(alpha=0.3, which='both')
    axes[2].legend(fontsize=8)
    fig.suptitle(f'identification: {title}')
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def report_truth(result: IdentificationResult, truth: ParameterSet,
                 fitted: ParameterSet) -> None:
    """Each parameter against the bag's ``truth.yaml``, and the count that the issue asks."""
    from sphere_sim.fitting.identification import within_truth

    rows = within_truth(result, truth)
    print(f'against {TRUTH_FILE}:')
    for path, value, interval, true, inside, status in rows:
        unc_text = f'in {interval_text(interval)}' if interval else f'({status}, held)'
        print(f'  {path}: {value:.5g} {unc_text}, true {true:.5g} '
              f'({(value / true - 1) * 100:+.1f} %): {"within" if inside else "OUTSIDE"}')
    others = [f.name for f in dataclasses.fields(truth) if f.name in (
        'beam', 'sphere', 'contact', 'friction', 'electrostatics')]
    changed = [f'{section}.{key}' for section in others
               for key, value in truth.to_dict()[section].items()
               if fitted.to_dict()[section][key] != value]
    unfitted = [c for c in changed if c not in {r[0] for r in rows}
                and not any(c in p.tied for p in result.parameters)]
    if unfitted:
        print(f'  the truth also differs in {", ".join(unfitted)}, which was not fitted')
    k = sum(r[4] for r in rows)
    print(f'identified: {k} of {len(rows)} parameters within their uncertainty of the truth')
