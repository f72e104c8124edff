"""``sphere-twin primitives width|offsets``: the kick's characteristics of §4 (Fig. 8 and 10)."""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sphere_sim.kicks.characteristics import (
    OFFSET_DIRECTION_TOL_RAD,
    OFFSET_GRID_STEP,
    OffsetSolution,
    rotation_width_curves,
    voltage_offsets,
)
from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD
from sphere_twin.commands.optimize import DEFAULT_OUTPUT as DEFAULT_DESIGN
from sphere_twin.commands.options import (
    DEFAULT_OUT_DIR,
    GRID_STEP,
    CommandError,
    add_params_option,
    number_in_range,
    output_directory,
    positive_int,
)

# The committed results, read as inputs (the offsets a table build applies).
RESULTS = Path('bench/results')
# The shipped offsets of the shipped design (§4.1), which the default table is built with.
DEFAULT_OFFSETS = RESULTS / 'voltage_offsets.json'
# Initial tilts of the width curves: inside the cone the paper investigates (§4).
CONE_HALF_ANGLE_DEG = math.degrees(CONE_HALF_ANGLE_RAD)
TILT_DEG = number_in_range(-CONE_HALF_ANGLE_DEG, CONE_HALF_ANGLE_DEG,
                           'degrees of tilt inside the cone of the paper')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'primitives', help="a kick's rotation width and voltage offsets (Fig. 10, Fig. 8)",
        description="Characteristics of the optimised kick: the resting normal's displacement "
                    'over the kick window.')
    sub = parser.add_subparsers(dest='primitives_command', metavar='ACTION', required=True)
    width = sub.add_parser('width', help='rotation width against intensity u_K (Fig. 10)',
                           description='Rotation width against u_K in [0, 1] for initial '
                                       'tilts alpha; writes a PNG and JSON.')
    width.add_argument('--alphas-deg', type=TILT_DEG, nargs='+', default=[0.0, 20.0, 35.0],
                       help=f'initial tilts about x (deg, within +-{CONE_HALF_ANGLE_DEG:g})')
    width.add_argument('--intensities', type=positive_int, default=11, help='points in [0, 1]')
    offsets = sub.add_parser('offsets', help='voltage offsets over the cone (Fig. 8)',
                             description='For each grid state, the offset on the compensating '
                                         'beam that puts the kick on its nominal direction.')
    offsets.add_argument('--grid-step', type=GRID_STEP, default=OFFSET_GRID_STEP,
                         help=f"step in x_sn and y_sn, 0.01 to 1 (default {OFFSET_GRID_STEP:g}, "
                              "half the table's)")
    offsets.add_argument('--workers', type=positive_int, default=2, help='local processes')
    offsets.add_argument('--reuse', type=Path, default=None,
                         help='an earlier offsets JSON of the same design, parameters and '
                              'grid: its states that ended within the direction tolerance are '
                              'taken unless a lower zero crossing lies below them, the others '
                              'searched again')
    for p in (width, offsets):
        add_params_option(p)
        p.add_argument('--design', default=DEFAULT_DESIGN,
                       help='kick optimisation JSON whose design to use')
        p.add_argument('--out', type=output_directory, default=DEFAULT_OUT_DIR,
                       help='output directory')
    width.set_defaults(func=run_width)
    offsets.set_defaults(func=run_offsets)


def run_width(args: argparse.Namespace) -> int:
    from sphere_twin.plots import plot_lines

    design = KickDesign.load(args.design)
    intensities = np.linspace(0.0, 1.0, args.intensities)
    total = len(args.alphas_deg) * intensities.size
    with tqdm(total=total, desc='kicks', unit='kick') as bar:
        curves = rotation_width_curves(design, args.alphas_deg, intensities, args.params,
                                       progress=bar.update)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = out / 'rotation_width.png'
    plot_lines(intensities, [np.degrees(c.width_rad) for c in curves],
               [f'alpha = {c.alpha_deg:.0f} deg' for c in curves], 'intensity $u_K$',
               'rotation width (deg)', png,
               title='Rotation width of the optimised kick, cf. Fig. 10')
    data = {'parameter_set': args.params.name, 'design': design.to_dict(),
            'curves': [{'alpha_deg': c.alpha_deg, 'intensities': c.intensities.tolist(),
                        'width_deg': np.degrees(c.width_rad).tolist(),
                        'direction_deg': np.degrees(c.direction_rad).tolist()}
                       for c in curves]}
    (out / 'rotation_width.json').write_text(json.dumps(data, indent=2) + '\n')
    print(f'{"u_K":>5} ' + ' '.join(f'{f"alpha {c.alpha_deg:.0f}":>10}' for c in curves))
    for i, u in enumerate(intensities):
        print(f'{u:5.2f} ' + ' '.join(f'{math.degrees(c.width_rad[i]):10.4f}' for c in curves))
    full = curves[0].width_rad[-1]
    print('full kick against the first tilt: ' + ', '.join(
        f'alpha {c.alpha_deg:.0f}: {c.width_rad[-1] / full:.2f}' for c in curves[1:]))
    print(f'wrote {png}')
    return 0


def run_offsets(args: argparse.Namespace) -> int:
    from sphere_twin.plots import plot_offsets

    design = KickDesign.load(args.design)
    reuse = [] if args.reuse is None else reusable_offsets(args.reuse, design, args.params.name,
                                                           args.grid_step)
    with tqdm(desc='states', unit='state') as bar:
        solutions = voltage_offsets(design, args.grid_step, params=args.params,
                                    workers=args.workers, progress=bar.update, reuse=reuse)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    png = plot_offsets(solutions, out / 'voltage_offsets.png')
    (out / 'voltage_offsets.json').write_text(json.dumps(
        {'parameter_set': args.params.name, 'design': design.to_dict(),
         'grid_step': args.grid_step,
         'direction_tolerance_deg': math.degrees(OFFSET_DIRECTION_TOL_RAD),
         'states': [s.__dict__ for s in solutions]}, indent=2) + '\n')
    before = np.degrees([abs(s.direction_error_without_rad) for s in solutions])
    after = np.degrees([abs(s.direction_error_rad) for s in solutions])
    print(f'{len(solutions)} states; direction error without offset: median {np.median(before):.2f}'
          f' deg, max {before.max():.2f} deg')
    print(f'wrote {png}')
    print(f'residual direction error: median {np.median(after):.2f} deg, '
          f'max {after.max():.2f} deg over {len(solutions)} states')
    if args.reuse is not None:
        kept = sum(s in reuse for s in solutions)
        print(f'{kept} states taken from {args.reuse}, {len(solutions) - kept} searched '
              f'(or moved to a lower zero crossing)')
    return 0


def reusable_offsets(path: Path, design: KickDesign, parameter_set: str,
                     grid_step: float) -> list[OffsetSolution]:
    """The states of an earlier ``primitives offsets`` JSON, refused (SystemExit) unless it was
    searched for the same design, parameter set, grid step and direction tolerance."""
    try:
        data = json.loads(path.read_text())
        same = (data['design'] == json.loads(json.dumps(design.to_dict()))
                and data['parameter_set'] == parameter_set
                and math.isclose(data['grid_step'], grid_step)
                and math.isclose(data['direction_tolerance_deg'],
                                 math.degrees(OFFSET_DIRECTION_TOL_RAD)))
        states = [OffsetSolution(**s) for s in data['states']]
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
        raise CommandError(f'{path} holds no voltage offsets saved by `sphere-twin primitives '
                         f'offsets`: {type(exc).__name__}: {exc}') from exc
    if not same:
        raise CommandError(f'{path} was searched for another design, parameter set, grid step '
                         f'or tolerance; it cannot be reused')
    return states
