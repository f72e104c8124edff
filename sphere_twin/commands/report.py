"""``sphere-twin report BAG``: error against run time, kicks and statistics of a recorded run."""

from __future__ import annotations

import argparse
import json
import math
import sys

from sphere_twin.commands.bag import BAG_HELP
from sphere_twin.commands.options import DEFAULT_OUT_DIR, output_directory, positive_float


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'report', help='error against run time and statistics of a recorded bag',
        description='Surface-normal error against time with the kicks marked, the path in the '
                    'x-y plane beside the reference (PNG), and kicks, settle times, final, RMS '
                    'and max error (text and JSON). Works on any bag of the topic contract.')
    parser.add_argument('bag', help=BAG_HELP)
    parser.add_argument('--out', type=output_directory, default=None,
                        help='output directory (default: the working directory)')
    parser.add_argument('--band-deg', type=positive_float, default=0.05,
                        help='settling band around a setpoint (deg)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.run_analysis import load_run, plot_report, statistics, unclosed_bag_warning

    bag = locate_bag(args.bag)
    if bag.note:
        print(bag.note)
    recorded = load_run(bag.directory)
    warning = unclosed_bag_warning(bag.directory, recorded)
    if warning:
        print(f'sphere-twin report: warning: {warning}', file=sys.stderr, flush=True)
    stats = statistics(recorded, math.radians(args.band_deg))
    out = args.out or DEFAULT_OUT_DIR
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f'{bag.name}_report'
    png = plot_report(recorded, stem.with_suffix('.png'), title=bag.name)
    data = {'bag': str(args.bag), **stats.to_dict(), **({'warning': warning} if warning else {})}
    stem.with_suffix('.json').write_text(json.dumps(data, indent=2) + '\n')
    settle = ', '.join('never' if s is None else f'{s:.2f} s' for s in stats.settle_times_s)
    lines = [f'bag: {args.bag}',
             f'duration: {stats.duration_s:.2f} s, kicks: {stats.kicks}',
             f'settle times (band {args.band_deg:g} deg): {settle or "no setpoint"}',
             f'error: final {math.degrees(stats.final_error_rad):.4f} deg, RMS '
             f'{math.degrees(stats.rms_error_rad):.4f} deg, max '
             f'{math.degrees(stats.max_error_rad):.4f} deg',
             *([f'error where the controller decided (settled states): RMS '
                f'{math.degrees(stats.rms_decided_error_rad):.4f} deg']
               if math.isfinite(stats.rms_decided_error_rad) else []),
             f'wrote {png} and {stem.with_suffix(".json")}']
    stem.with_suffix('.txt').write_text('\n'.join(lines[:-1]) + '\n')
    print('\n'.join(lines))
    return 0
