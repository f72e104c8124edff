"""``sphere-twin optimize-kick``: the optimised hind-left kick of §4.1, saved as JSON."""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
from pathlib import Path

from tqdm import tqdm

from sphere_sim.kicks.design import KickDesign
from sphere_sim.kicks.discrete import PAPER_FULL_KICK_RAD
from sphere_sim.kicks.optimization import optimise_kick
from sphere_twin.commands.options import add_params_option, output_file, positive_int, seed

DEFAULT_OUTPUT = 'kick_optimization.json'
AXIS_OUTPUT = 'kick_optimization_axis.json'
# Templates: the paper's hind-left kick, and an axis-parallel one (§6's future work): the
# right beam (3, at +x) at the high voltage, the other three at the low one, mirror-symmetric
# about the x axis, so that its rotation can only go along x. Like the diagonal kick it moves
# the normal towards its high beams; the mirror layout (beam 1 low, 2-4 high) reaches only
# 0.08 deg with the same search (docs/motion_primitives.md).
TEMPLATES = {
    'diagonal': KickDesign(),
    'axis': KickDesign(direction_rad=0.0, low_beams=(1, 2, 4), high_beams=(3,)),
}
# The paper's layout, or its low and high beams exchanged: the layout that turns the dry
# contact (`dry_contact`) towards the kick's direction, its own finding (docs/parameters.md).
LAYOUTS = ('paper', 'swapped')


def template(kick: str, layout: str = 'paper') -> KickDesign:
    """The design the search starts from: ``kick``'s template in ``layout``."""
    design = TEMPLATES[kick]
    if layout == 'swapped':
        design = dataclasses.replace(design, low_beams=design.high_beams,
                                     high_beams=design.low_beams)
    return design


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'optimize-kick', help='optimise the hind-left kick by differential evolution',
        description='Maximise the rotation of the hind-left kick (35 V on beams 1-2, 80 V on '
                    'beams 3-4, as §4.1; free widths and delay) towards -45 deg with scipy '
                    'differential evolution, seeded, with parallel workers; writes the result '
                    'as JSON.')
    parser.add_argument('--kick', choices=sorted(TEMPLATES), default='diagonal',
                        help='diagonal (hind-left, towards -45 deg) or axis (towards +x)')
    parser.add_argument('--layout', choices=LAYOUTS, default='paper',
                        help='paper (35 V on the low beams, 80 V on the high ones, as §4.1) or '
                             'swapped (low and high beams exchanged: the dry contact\'s own)')
    add_params_option(parser)
    parser.add_argument('--seed', type=seed, default=1)
    parser.add_argument('--popsize', type=positive_int, default=8, help='population per parameter')
    parser.add_argument('--maxiter', type=positive_int, default=12, help='generations')
    parser.add_argument('--workers', type=positive_int, default=2, help='parallel processes')
    parser.add_argument('--output', type=output_file('.json'), default=None,
                        help=f'JSON path (default {DEFAULT_OUTPUT}, or {AXIS_OUTPUT} for axis)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    with tqdm(total=args.maxiter, desc='generations', unit='gen') as bar:
        def progress(best: float) -> None:
            bar.set_postfix(best_deg=f'{math.degrees(best):.4f}')
            bar.update()

        best = optimise_kick(template(args.kick, args.layout), args.params, seed=args.seed,
                             popsize=args.popsize, maxiter=args.maxiter, workers=args.workers,
                             progress=progress)
    data = best.to_dict()
    data['parameter_set'] = args.params.name
    # Which values the design was optimised for: a later recalibration makes it stale.
    data['parameter_digest'] = args.params.digest()
    path = Path(args.output or (AXIS_OUTPUT if args.kick == 'axis' else DEFAULT_OUTPUT))
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=2) + '\n')
    d = best.design
    print(f'widths: beams {d.low_beams} {d.width_low_s * 1e3:.3f} ms at {d.low_v:.0f} V, '
          f'beams {d.high_beams} {d.width_high_s * 1e3:.3f} ms at {d.high_v:.0f} V; '
          f'delay {d.delay_s * 1e3:+.3f} ms ({best.evaluations} simulations)')
    print(f'rotation {best.rotation_deg:.4f} deg towards {best.direction_deg:+.1f} deg '
          f'({best.along_deg:+.4f} deg along {math.degrees(d.direction_rad):+.0f} deg; '
          f'paper, diagonal: {math.degrees(PAPER_FULL_KICK_RAD):.2f} deg), '
          f'settled after {best.settle_time_s * 1e3:.1f} ms')
    print(f'wrote {path}')
    return 0
