"""``sphere-twin synthetic record|study``: recordings of synthetic devices, and the
identification study on them (``identification.md``; the committed one is in bench/results)."""

from __future__ import annotations

import argparse
import json
import math
import os
import tempfile
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from tqdm import tqdm

from sphere_twin.commands.identify import interval_text
from sphere_twin.commands.options import (
    CommandError,
    output_directory,
    output_file,
    positive_int,
    seed,
)
from sphere_twin.synthetic_device import PUBLISH_RATE_HZ

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from sphere_sim.fitting.identification import Evaluator
    from sphere_twin.protocol_run import ProtocolRecord
    from sphere_twin.synthetic_device import SyntheticDevice

DEFAULT_STUDY = Path('identification.md')  # the committed one: --out bench/results/...
DEFAULT_KICKS = 40


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'synthetic', help='record synthetic devices; the identification study on them',
        description='A synthetic device is the continuous twin with some parameters changed; '
                    'its bag holds what a real device records (commands and the noisy '
                    'measured normal) and its truth.yaml what was changed.')
    sub = parser.add_subparsers(dest='synthetic_command', metavar='ACTION', required=True)
    record = sub.add_parser('record', help='record one synthetic device into a bag',
                            description='Record a seeded sequence of kicks of one device of '
                                        'the study (or of --truth) into OUT, with truth.yaml.')
    record.add_argument('out', type=output_directory, help='bag directory to create')
    record.add_argument('--device', default='device_a',
                        help="a device of the study: device_a to device_e (dry_contact), "
                             "paper_a to paper_e (the paper's device, calibrated)")
    record.add_argument('--kicks', type=positive_int, default=DEFAULT_KICKS)
    record.add_argument('--seed', type=seed, default=None,
                        help="seed of the kicks and the noise (default: the device's)")
    record.add_argument('--protocol', action='store_true',
                        help='record the experiment protocol (thresholds by bisection, slow '
                             'ramps, then kicks; docs/identification.md) instead of the kicks')
    record.set_defaults(func=run_record)
    study = sub.add_parser('study', help='record every device of the study and identify it',
                           description='For each device of the study: record, identify, and '
                                       'compare with the truth; writes a Markdown table and '
                                       'its JSON.')
    study.add_argument('--kicks', type=positive_int, default=DEFAULT_KICKS)
    study.add_argument('--device', action='append', dest='devices', metavar='NAME',
                       help='study only this device (repeatable; default: device_a to '
                            "device_e; paper_a to paper_e are the paper's device's)")
    study.add_argument('--protocol', action='store_true',
                       help='record the experiment protocol on each device and fit its '
                            'thresholds and kicks in one misfit, with profile intervals '
                            '(resumable: each fit checkpoints beside --out)')
    study.add_argument('--max-evaluations', type=positive_int, default=None,
                       help='with --protocol, the cost limit of each device\'s fit (default '
                            'that of sphere-twin identify)')
    study.add_argument('--workers', type=positive_int, default=2)
    study.add_argument('--scheduler', default=None)
    study.add_argument('--out', type=output_file('.md'), default=DEFAULT_STUDY,
                       help=f'Markdown table, its JSON beside it (default {DEFAULT_STUDY})')
    study.set_defaults(func=run_study)


def _device(name: str) -> SyntheticDevice:
    from sphere_twin.synthetic_device import DEVICES, PAPER_DEVICES

    known = DEVICES + PAPER_DEVICES
    for device in known:
        if device.name == name:
            return device
    raise CommandError(f'unknown device {name!r}; the study has '
                       f'{", ".join(d.name for d in known)}')


def record(device: SyntheticDevice, out: str | os.PathLike[str], kicks: int,
           seed: int | None = None) -> int:
    """Record ``device`` into the bag ``out`` with its truth.yaml; returns the sample count."""
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.synthetic_device import record_device

    if Path(out).exists():
        raise CommandError(f'{out} exists: give a new bag directory')
    base = load_parameter_set(device.base)
    with tqdm(total=kicks, desc=device.name, unit='kick', leave=False) as bar:
        samples = record_device(out, device.truth(base), kicks,
                                device.seed if seed is None else seed,
                                progress=lambda done, total: bar.update(),
                                intensity_range=device.intensity_range)
    device.write_truth(Path(out) / 'truth.yaml', base)
    return samples


def record_protocol(device: SyntheticDevice, out: str | os.PathLike[str],
                    seed: int | None = None) -> None:
    """Record the default protocol on ``device`` into ``out`` with its truth.yaml, and print
    what it found and what it could not run."""
    from sphere_twin.protocol_bag import read_protocol
    from sphere_twin.protocol_run import result_lines

    done = record_protocol_bag(device, out, seed)
    results = read_protocol(out)
    print(f'wrote {out}: the protocol on {device.name}, {done.samples} samples; sensor noise '
          f'{results.noise_std_rad:.3g} rad per axis')
    for line in result_lines(results, done.not_run):
        print(line)


def record_protocol_bag(device: SyntheticDevice, out: str | os.PathLike[str],
                        seed: int | None = None) -> ProtocolRecord:
    """Record the default protocol on ``device`` into ``out`` with its truth.yaml."""
    from sphere_sim.fitting.protocol import DEFAULT_PROTOCOL, check_protocol
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.protocol_run import record_protocol as record_steps

    if Path(out).exists():
        raise CommandError(f'{out} exists: give a new bag directory')
    check_protocol(DEFAULT_PROTOCOL)
    base = load_parameter_set(device.base)
    with tqdm(total=len(DEFAULT_PROTOCOL.steps), desc=device.name, unit='step',
              leave=False) as bar:
        done = record_steps(out, device.truth(base), DEFAULT_PROTOCOL,
                            device.seed if seed is None else seed,
                            progress=lambda label: bar.update())
    device.write_truth(Path(out) / 'truth.yaml', base)
    return done


def run_record(args: argparse.Namespace) -> int:
    device = _device(args.device)
    if args.protocol:
        record_protocol(device, args.out, args.seed)
        return 0
    samples = record(device, args.out, args.kicks, args.seed)
    print(f'wrote {args.out}: {args.kicks} kicks of {device.name} '
          f'({", ".join(f"{p} x {f:g}" for p, f in device.factors.items())}), {samples} samples')
    return 0


def run_study(args: argparse.Namespace) -> int:
    from sphere_sim.fitting.identification import fit_parameters, identify, within_truth
    from sphere_sim.kicks.engine import engine_of
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.commands.identify import read_observations
    from sphere_twin.synthetic_device import DEVICES, NOISE_STUDY_STD_RAD

    devices = [_device(name) for name in args.devices] if args.devices else DEVICES
    if args.protocol:
        return run_protocol_study(args, devices)
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp, engine_of(args.workers, args.scheduler) as eng:
        for device in devices:
            bag = Path(tmp) / device.name
            record(device, bag, args.kicks)
            base = load_parameter_set(device.base)
            obs = read_observations(bag)
            fits = fit_parameters(base, device.fit)
            started = time.perf_counter()
            with tqdm(desc=f'identify {device.name}', unit='kick', leave=False) as bar:
                def progress(ev: Evaluator, bar: tqdm = bar) -> None:
                    bar.n = ev.simulated
                    bar.refresh()

                result = identify(base, obs, fits, eng, progress=progress)
            wall = time.perf_counter() - started
            truth = device.truth(base)
            checks = within_truth(result, truth)
            rows.append({'device': device.name, 'base': device.base, 'factors': device.factors,
                         'kicks': len(obs.kicks), 'undetermined': len(result.undetermined),
                         'noise_rad': obs.noise_std_rad,
                         'wall_s': wall, 'simulated_kicks': result.simulated_kicks,
                         'evaluations': result.evaluations,
                         'residual_rms_start_rad': _rms(result.residuals_before),
                         'residual_rms_fitted_rad': _rms(result.residuals_after),
                         'cost_ratio': result.cost_ratio,
                         'parameters': [dict(p.to_dict(), true=c[3], within=bool(c[4]))
                                        for p, c in zip(result.parameters, checks,
                                                        strict=True)]})
            _print_device(rows[-1])
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix('.json').write_text(json.dumps(rows, indent=2) + '\n')
    args.out.write_text(_markdown(rows, args, NOISE_STUDY_STD_RAD))
    print(f'wrote {args.out} and {args.out.with_suffix(".json")}')
    inside = sum(p['within'] for r in rows for p in r['parameters'])
    total = sum(len(r['parameters']) for r in rows)
    print(f'identified: {inside} of {total} parameters within their uncertainty of the truth '
          f'over {len(rows)} device{"s" if len(rows) != 1 else ""}')
    return 0


def run_protocol_study(args: argparse.Namespace, devices: Sequence[SyntheticDevice]) -> int:
    """``study --protocol``: each device's protocol recorded, then its thresholds and kicks
    fitted in one misfit; the intervals' coverage of the truth and what they determine."""
    from sphere_sim.fitting.identification import fit_parameters
    from sphere_sim.fitting.joint_fit import fit_jointly, thresholds_checkpoint
    from sphere_sim.kicks.engine import engine_of
    from sphere_sim.model.parameters import load_parameter_set
    from sphere_twin.commands.identify import JOINT_EVALUATIONS, read_recording

    limit = args.max_evaluations or JOINT_EVALUATIONS
    rows: list[dict[str, Any]] = []
    args.out.parent.mkdir(parents=True, exist_ok=True)
    checkpoints = []
    with tempfile.TemporaryDirectory() as tmp, engine_of(args.workers, args.scheduler) as eng:
        for device in devices:
            bag = Path(tmp) / device.name
            record_protocol_bag(device, bag)
            base = load_parameter_set(device.base)
            recording = read_recording(bag)
            fits = fit_parameters(base, device.fit)
            checkpoint = args.out.with_name(f'{args.out.stem}_{device.name}.partial.jsonl')
            checkpoints += [checkpoint, thresholds_checkpoint(checkpoint)]
            started = time.perf_counter()
            with tqdm(desc=f'identify {device.name}', unit='evaluation', leave=False) as bar:
                def progress(ev: Evaluator, bar: tqdm = bar) -> None:
                    bar.n = len(ev.cache)
                    bar.refresh()

                result = fit_jointly(base, fits, recording.kicks, recording.pull_ins, eng,
                                     None, checkpoint, progress, max_evaluations=limit)
            truth = device.truth(base)
            rows.append({
                'device': device.name, 'base': device.base, 'factors': device.factors,
                'thresholds': len(recording.thresholds), 'ramps': len(recording.ramps),
                'kicks': len(result.kicks.kicks),
                'undetermined': len(result.undetermined),
                'wall_s': time.perf_counter() - started, 'evaluations': result.evaluations,
                'threshold_search_evaluations': result.threshold_search_evaluations,
                'cost_limited': result.profile.cost_limited,
                'chi2_thresholds': result.threshold_chi2, 'chi2_kicks': result.kicks_chi2,
                'parameters': [{'path': e.path, 'start': base.get(e.path), 'value': e.value,
                                'interval': [e.low, e.high],
                                'range': [e.range_low, e.range_high],
                                'determined': e.determined, 'note': e.note,
                                'true': truth.get(e.path),
                                'within': e.contains(truth.get(e.path))}
                               for e in result.estimates]})
            _print_protocol_device(rows[-1])
    args.out.with_suffix('.json').write_text(json.dumps(rows, indent=2) + '\n')
    total = sum(len(r['parameters']) for r in rows)
    determined = sum(p['determined'] for r in rows for p in r['parameters'])
    coverage = sum(p['within'] for r in rows for p in r['parameters']) / total
    summary = f'determined {determined} of {total}; coverage {coverage:.2f}'
    args.out.write_text(_protocol_markdown(rows, args, limit, summary))
    for checkpoint in checkpoints:
        checkpoint.unlink(missing_ok=True)
    print(f'wrote {args.out} and {args.out.with_suffix(".json")}')
    print(summary)
    return 0


def _print_protocol_device(row: Mapping[str, Any]) -> None:
    print(f'{row["device"]}: {row["thresholds"]} thresholds and {row["kicks"]} kicks '
          f'({row["undetermined"]} undetermined), {_evaluations_text(row)} in '
          f'{row["wall_s"]:.0f} s; sum of squares {row["chi2_thresholds"]:.1f} (thresholds) '
          f'+ {row["chi2_kicks"]:.1f} (kicks)')
    for p in row['parameters']:
        print(f'  {p["path"]}: {p["value"]:.4g} in {interval_text(p["interval"])}, true '
              f'{p["true"]:.4g}: {"within" if p["within"] else "OUTSIDE"}, '
              f'{"determined" if p["determined"] else "undetermined"} ({p["note"]})')


def _protocol_markdown(rows: Sequence[Mapping[str, Any]], args: argparse.Namespace,
                       limit: int, summary: str) -> str:
    only = ''.join(f' --device {name}' for name in args.devices or ())
    lines = ['# Identification of synthetic devices from the experiment protocol', '',
             f'Made by `sphere-twin synthetic study --protocol --workers {args.workers}'
             f'{only}`: each device is recorded running the default protocol (threshold '
             'searches, slow ramps, then kicks), and its thresholds and kicks are fitted in '
             'one misfit from the bag alone: a multi-start over the declared ranges, then '
             f'each parameter\'s 95 % profile-likelihood interval (cost limit {limit} '
             'evaluations). A parameter is determined when its interval spans at most a tenth '
             'of its scaled range and reaches neither end. See docs/identification.md.', '']
    for r in rows:
        lines += [_device_heading(r), '',
                  f'{r["thresholds"]} thresholds and {r["kicks"]} kicks ({r["undetermined"]} '
                  f'left out: the model does not determine them), {_evaluations_text(r)}'
                  f'{" (stopped by the cost limit)" if r["cost_limited"] else ""} '
                  f'in {r["wall_s"]:.0f} s on {args.workers} workers; sum of squares '
                  f'{r["chi2_thresholds"]:.1f} over the thresholds and {r["chi2_kicks"]:.1f} '
                  f'over {2 * r["kicks"]} kick residuals.', '',
                  '| parameter | true | start | identified | 95 % profile interval | '
                  'determined | within |', '|---|---|---|---|---|---|---|']
        for p in r['parameters']:
            lines.append(f'| `{p["path"]}` | {p["true"]:.4g} | {p["start"]:.4g} | '
                         f'{p["value"]:.4g} | {interval_text(p["interval"])} | '
                         f'{"yes" if p["determined"] else "no: " + p["note"]} | '
                         f'{"yes" if p["within"] else "**no**"} |')
        lines.append('')
    lines += [summary]
    return '\n'.join(lines) + '\n'


def _evaluations_text(row: Mapping[str, Any]) -> str:
    searched = row['threshold_search_evaluations']
    return (f'{searched} evaluations of the thresholds alone and {row["evaluations"]} of the '
            'thresholds and kicks together' if searched else f'{row["evaluations"]} evaluations')


def _device_heading(row: Mapping[str, Any]) -> str:
    """A study table's heading of one device: its base set and what was changed."""
    factors = ', '.join(f'`{p}` x {f:g}' for p, f in row['factors'].items())
    return f'## {row["device"]}: `{row["base"]}` with {factors}'


def _rms(values: Sequence[float] | NDArray[np.float64]) -> float:
    return math.sqrt(sum(v * v for v in values) / len(values)) if len(values) else 0.0


def _print_device(row: Mapping[str, Any]) -> None:
    print(f'{row["device"]}: {row["kicks"]} kicks ({row["undetermined"]} undetermined), '
          f'{row["wall_s"]:.0f} s '
          f'({row["simulated_kicks"]} kicks simulated), residual RMS '
          f'{row["residual_rms_start_rad"]:.3g} -> {row["residual_rms_fitted_rad"]:.3g} rad')
    for p in row['parameters']:
        print('  ' + _parameter_line(p))


def _parameter_line(p: Mapping[str, Any]) -> str:
    if p['interval']:
        got = f'{p["value"]:.4g} in {interval_text(p["interval"])}'
        if p['status'] != 'fitted':
            got += f' ({p["status"]})'
    else:
        got = f'{p["value"]:.4g} ({p["status"]}, held)'
    return (f'{p["path"]}: {got}, true {p["true"]:.4g}, start {p["start"]:.4g}: '
            f'{"within" if p["within"] else "OUTSIDE"}')


def _markdown(rows: Sequence[Mapping[str, Any]], args: argparse.Namespace, noise: float) -> str:
    only = ''.join(f' --device {name}' for name in args.devices or ())
    bases = ', '.join(f'`{base}`' for base in dict.fromkeys(r['base'] for r in rows))
    lines = ['# Identification of synthetic devices', '',
             f'Made by `sphere-twin synthetic study --kicks {args.kicks} --workers '
             f'{args.workers}{only}`: each device is a shipped set ({bases}) with two '
             f'physical parameters changed; {args.kicks} kicks recorded open loop by the '
             f'continuous twin (one a second, {PUBLISH_RATE_HZ:g} Hz samples, sensor noise '
             f'{noise:.3g} rad per axis: the noise study\'s 0.1 of the paper\'s kick), then '
             'identified from the bag alone. '
             'Intervals are 2 standard errors either side. See docs/identification.md.', '']
    for r in rows:
        lines += [_device_heading(r), '',
                  f'{r["kicks"]} kicks ({r["undetermined"]} left out: the model does not '
                  f'determine them), {r["wall_s"]:.0f} s wall on {args.workers} workers '
                  f'({r["simulated_kicks"]} kicks simulated, {r["evaluations"]} evaluations); '
                  f'per-kick residual RMS {r["residual_rms_start_rad"]:.3g} rad at the start, '
                  f'{r["residual_rms_fitted_rad"]:.3g} rad fitted (sum of squares '
                  f'{r["cost_ratio"]:.2f} x the noise\'s).', '',
                  '| parameter | true | start | identified | 2 s.e. interval | within |',
                  '|---|---|---|---|---|---|']
        for p in r['parameters']:
            if p['interval']:
                got, unc = f'{p["value"]:.4g}', interval_text(p['interval'])
                if p['status'] != 'fitted':
                    got += f' ({p["status"]})'
            else:
                got, unc = f'{p["value"]:.4g} ({p["status"]}, held)', '-'
            lines.append(f'| `{p["path"]}` | {p["true"]:.4g} | {p["start"]:.4g} | {got} | '
                         f'{unc} | {"yes" if p["within"] else "**no**"} |')
        notes = [f'- `{p["path"]}`: {p["note"]}' for p in r['parameters'] if p['note']]
        lines += [''] + notes + ([''] if notes else [])
    return '\n'.join(lines) + '\n'
