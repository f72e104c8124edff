"""``sphere-twin table build|check``: the discrete kick model as a lookup table."""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.lookup_table import DEFAULT_TABLE_PATH, LookupTable, TableSpec
from sphere_sim.kicks.offset_lookup import OffsetLookup
from sphere_sim.kicks.table_build import build_table, check_directions, check_table
from sphere_twin.commands.optimize import DEFAULT_OUTPUT as DEFAULT_DESIGN
from sphere_twin.commands.options import (
    GRID_STEP,
    add_params_option,
    number_in_range,
    output_file,
    positive_int,
    seed,
    unit_interval,
)
from sphere_twin.commands.primitives import DEFAULT_OFFSETS

# The kick window: the kicks' pulses last a few ms and they settle in about 50 ms (Fig. 5); a
# second is far past settling.
WINDOW_S = number_in_range(0.01, 1.0, 'seconds; the kicks settle in about 0.05 s')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser('table', help='build or check the discrete kick table',
                                   description='The discrete model x_{t+1} = f(x_t, a_t, u_K) '
                                               'as a linearly interpolated lookup table.')
    sub = parser.add_subparsers(dest='table_command', metavar='ACTION', required=True)
    build = sub.add_parser('build', help='simulate the table (resumable)',
                           description='Simulate every grid kick with a process pool or Dask; '
                                       'an interrupted build resumes from its partial file.')
    build.add_argument('--output', type=output_file('.npz'), default=Path('kick_table.npz'),
                       help='table .npz path')
    add_params_option(build)
    build.add_argument('--grid-step', type=GRID_STEP, default=TableSpec.grid_step,
                       help='grid step in x_sn and y_sn (0.01 to 1)')
    build.add_argument('--intensities', type=unit_interval, nargs='+',
                       default=list(TableSpec.intensities), help='u_K values')
    build.add_argument('--window-s', type=WINDOW_S, default=TableSpec.window_s,
                       help='kick window (s, 0.01 to 1)')
    build.add_argument('--design', default=DEFAULT_DESIGN,
                       help='kick optimisation JSON whose design to use')
    build.add_argument('--offsets', default=str(DEFAULT_OFFSETS),
                       help="the design's voltage offsets (§4.1), a JSON of `sphere-twin "
                            "primitives offsets`, or 'none'")
    build.add_argument('--workers', type=positive_int, default=2, help='local processes')
    build.add_argument('--reuse', type=Path, default=None,
                       help='a table of the same kick at other intensities or offsets: '
                            'its kicks whose programme is unchanged are taken instead of '
                            'simulated again')
    build.add_argument('--scheduler', default=None,
                       help='Dask scheduler address, e.g. tcp://host:8786')
    build.set_defaults(func=run_build)
    check = sub.add_parser('check', help='compare the table with direct simulation',
                           description='Interpolated against simulated kicks at random '
                                       'off-grid states, actions and intensities.')
    check.add_argument('--table', default=str(DEFAULT_TABLE_PATH))
    check.add_argument('--points', type=positive_int, default=8)
    check.add_argument('--seed', type=seed, default=0)
    check.add_argument('--grid', type=GRID_STEP, default=None, metavar='STEP',
                       help='the full kicks from the states of a STEP grid over the half cone '
                            'the table simulates (action 0), not from the random states')
    check.set_defaults(func=run_check)


def run_build(args: argparse.Namespace) -> int:
    spec = TableSpec(grid_step=args.grid_step, intensities=tuple(args.intensities),
                     window_s=args.window_s, parameter_set=args.params.name)
    if args.design:
        spec = dataclasses.replace(spec, design=KickDesign.load(args.design))
    if args.offsets != 'none':
        spec = dataclasses.replace(spec, offsets=OffsetLookup.load(args.offsets, spec.design,
                                                                   args.params.name))
    reuse = None
    if args.reuse is not None:
        reuse = LookupTable.load(args.reuse)
    output = Path(args.output)
    partial = output.with_suffix('.partial.jsonl')
    output.parent.mkdir(parents=True, exist_ok=True)  # the partial file is written from the start
    started = time.perf_counter()
    first_done: list[int] = []
    with tqdm(desc='kicks', unit='kick') as bar:
        def progress(done: int, total: int) -> None:
            if not first_done:
                first_done.append(done)
            bar.total = total
            bar.n = done
            bar.refresh()

        table = build_table(spec, args.params, workers=args.workers, scheduler=args.scheduler,
                            partial_path=partial, progress=progress, reuse=reuse)
    wall_s = time.perf_counter() - started
    table.save(output)
    partial.unlink(missing_ok=True)
    engine = f'Dask at {args.scheduler}' if args.scheduler else f'{args.workers} local workers'
    simulated = len(spec.nodes()) * len(spec.intensities) - first_done[0]
    print(f'wrote {output}: {len(spec.nodes())} states x {len(spec.intensities)} intensities, '
          f'parameters {args.params.name} (digest {table.meta["params_digest"]})')
    print(f'{simulated} kicks simulated in {wall_s:.1f} s with {engine} '
          f'({simulated / wall_s:.2f} kicks/s)')
    print_direction_errors(table)
    return 0


def print_direction_errors(table: LookupTable) -> None:
    """How far the full kicks stray from their nominal direction over the cone (§4.1)."""
    errors = np.degrees(table.direction_errors_rad(1.0))
    offsets = 'with' if table.spec.offsets else 'without'
    print(f'full kick direction error {offsets} voltage offsets: median {np.median(errors):.2f} '
          f'deg, max {errors.max():.2f} deg over {errors.size} states')


def run_check(args: argparse.Namespace) -> int:
    table = LookupTable.load_current(args.table)
    with tqdm(total=args.points, desc='direct kicks', unit='kick') as bar:
        worst, errors = check_table(table, args.points, args.seed,
                                    progress=lambda done, total: bar.update())
    print(f'median interpolation error: {math.degrees(float(np.median(errors))):.4f} deg; '
          f'95th percentile {math.degrees(float(np.percentile(errors, 95))):.4f} deg')
    print(f'max interpolation error: {math.degrees(worst):.4f} deg over {args.points} points')
    print_direction_errors(table)
    with tqdm(desc='full kicks', unit='kick') as bar:
        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update()

        full = check_directions(table, args.points, args.seed, progress=progress,
                                grid_step=args.grid)
    strays = np.degrees([abs(d.simulated_error_rad) for d in full])
    worst_state = full[int(np.argmax(strays))]
    where = (f'states of a {args.grid:g} grid over the half cone' if args.grid is not None
             else 'off-grid states')
    print(f'full kick direction error at the {len(full)} {where}: median '
          f'{np.median(strays):.2f} deg, 90th percentile {np.percentile(strays, 90):.2f} deg, '
          f'max {strays.max():.2f} deg (at ({worst_state.x_sn:.3f}, {worst_state.y_sn:.3f}), '
          f'action {worst_state.action}, {math.degrees(worst_state.simulated_width_rad):.3f} '
          f'deg wide); {int(np.sum(strays > 5.0))} more than 5 deg off; the table against it: '
          f'max {math.degrees(max(d.between_rad for d in full)):.2f} deg')
    return 0
