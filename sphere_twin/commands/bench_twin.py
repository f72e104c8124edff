"""``sphere-twin bench twin``: the live twin's real-time factor over DDS, where it goes, and
the node loop's kick cycle."""

from __future__ import annotations

import argparse
import json
import os
import sys

from tqdm import tqdm

from sphere_sim.twin.plant_setup import FIDELITIES, LIVE_FIDELITY, PLANT_KINDS
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    CommandError,
    non_negative_float,
    output_directory,
    simulated_seconds,
)
from sphere_twin.twin_bench import DEFAULT_DURATION_S, BenchError, run_twin_bench, summary_lines


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add ``twin`` to the ``bench`` subcommands."""
    parser = sub.add_parser(
        'twin', help='the live twin\'s real-time factor and kick cycle over DDS',
        description='Run simulator (unpaced unless --real-time-factor), reference and '
                    'controller as processes over DDS on the demo\'s scenario for a fixed '
                    'simulated time; report the simulator\'s real-time factor, the share of '
                    'its wall time spent integrating, publishing and in rclpy, the latency '
                    'from a pulse programme\'s arrival to its first effect, and the node '
                    'loop\'s kick cycle and its parts. Writes '
                    'twin_<plant>[_<fidelity>][_paced].{json,md} into --out (the fidelity '
                    'only where it is not the plant\'s own).')
    parser.add_argument('--plant', choices=PLANT_KINDS, default='continuous')
    parser.add_argument('--fidelity', choices=FIDELITIES[:-1], default=LIVE_FIDELITY,
                        help='the model rung the continuous plant integrates (docs/numerics.md, '
                             'the ladder of models); the discrete plant is the table')
    parser.add_argument('--duration-s', type=simulated_seconds, default=DEFAULT_DURATION_S,
                        help='simulated seconds to run, 0.001 to 3600')
    parser.add_argument('--real-time-factor', type=non_negative_float, default=0.0,
                        help='pace the simulator at this many simulated seconds per wall '
                             'second (default 0: unpaced)')
    parser.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                        help='output directory')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    # The machine's load beside the figures: an unpaced real-time factor moves with it.
    load_before = os.getloadavg()[0]
    with tqdm(total=args.duration_s, desc=f'bench twin ({args.plant})', unit='sim s',
              file=sys.stderr, bar_format='{l_bar}{bar}| {n:.1f}/{total:g} sim s') as bar:
        def progress(simulated_s: float) -> None:
            bar.update(min(simulated_s, args.duration_s) - bar.n)

        try:
            result, farewell = run_twin_bench(
                args.plant, args.duration_s, progress=progress,
                real_time_factor=args.real_time_factor,
                fidelity=args.fidelity if args.plant == 'continuous' else '')
        except BenchError as error:
            raise CommandError(str(error)) from None
    lines = summary_lines(result)
    load = (f'load average (1 min) {load_before:.2f} at the start, {os.getloadavg()[0]:.2f} '
            'at the end')
    args.out.mkdir(parents=True, exist_ok=True)
    paced = args.real_time_factor > 0.0
    reduced = args.plant == 'continuous' and args.fidelity != LIVE_FIDELITY
    stem = args.out / (f'twin_{args.plant}{f"_{args.fidelity}" if reduced else ""}'
                       f'{"_paced" if paced else ""}')
    stem.with_suffix('.json').write_text(json.dumps({**result.to_dict(), 'machine': load},
                                                   indent=2) + '\n')
    command = (f'--plant {args.plant}{f" --fidelity {args.fidelity}" if reduced else ""} '
               f'--duration-s {args.duration_s:g}'
               + (f' --real-time-factor {args.real_time_factor:g}' if paced else ''))
    stem.with_suffix('.md').write_text(
        f'# Live twin, {args.plant} plant, model {result.fidelity}, {result.pace_name}\n\n'
        f'Written by `sphere-twin bench twin {command}`.\n\n'
        + '\n'.join(f'- {line}' for line in lines)
        + f'\n- farewell: `{farewell}`\n- machine: {load}\n')
    print(load)
    print('\n'.join(lines))
    return 0
