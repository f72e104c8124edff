"""``sphere-twin replay-check BAG``: the bag's commands replayed open loop through the twin."""

import json
import math
from pathlib import Path

from msg_defs.device import KICK_WINDOW_S
from sphere_twin.commands.bag import BAG_HELP
from sphere_twin.commands.options import CommandError, add_params_option


def register(subparsers):
    parser = subparsers.add_parser(
        'replay-check', help='replay a bag\'s commands open loop and compare the normals',
        description='Feed the recorded voltage commands and pulse programmes into the '
                    'simulator open loop, from the first recorded normal, and report the '
                    'simulated surface normal\'s error against the recorded one over time: the '
                    'way to hold the twin against recordings of the real device.')
    parser.add_argument('bag', help=BAG_HELP)
    parser.add_argument('--plant', choices=('discrete', 'continuous'), default='discrete')
    parser.add_argument('--tables', nargs='*', default=[],
                        help='kick tables of the discrete plant (default: the shipped one)')
    add_params_option(parser)
    parser.add_argument('--out', type=Path, default=None,
                        help='output directory (default: beside the bag)')
    parser.set_defaults(func=run)


def build_replay_plant(kind, normal0, time0_s, params, tables=()):
    """A plant of parameter set ``params`` resting at ``normal0`` at ``time0_s``."""
    from sphere_sim.kicks.design import cardan_of_normal
    from sphere_sim.kicks.discrete import kick_period_s
    from sphere_sim.model.scene import load_scene
    from sphere_sim.twin.plant_setup import discrete_plant, load_kick_model
    from sphere_sim.twin.plants import ContinuousPlant

    if kind == 'discrete':
        plant = discrete_plant(load_kick_model(tables, params), normal0)
    else:
        from sphere_sim.model.assembly import assemble
        from sphere_sim.model.initial_state import rest_state

        model = assemble(load_scene('rest'), params)
        plant = ContinuousPlant(model, rest_state(model, cardan_of_normal(normal0)),
                                kick_period_s=kick_period_s(load_kick_model(tables)))
    plant.time_s = time0_s
    return plant


def run(args):
    from sphere_twin.bag.locate import locate_bag
    from sphere_twin.plots import plot_lines
    from sphere_twin.run_analysis import load_run, replay, replay_start_index

    bag = locate_bag(args.bag)
    if bag.note:
        print(bag.note)
    recorded = load_run(bag.directory)
    start = replay_start_index(recorded, KICK_WINDOW_S)
    if start >= recorded.normal_t_s.size:
        raise CommandError(f'{args.bag}: the recording ends before a kick that began before '
                           'it settles')
    plant = build_replay_plant(args.plant, recorded.normals[start],
                               float(recorded.normal_t_s[start]), args.params, args.tables)
    result = replay(recorded, plant, start)
    out = args.out or bag.output_dir
    out.mkdir(parents=True, exist_ok=True)
    stem = out / f'{bag.name}_replay'
    plot_lines(result.times_s, [[max(math.degrees(e), 1e-12) for e in result.error_rad]],
               [f'{args.plant} plant'], 'time (s)', 'simulated vs recorded normal (deg)',
               stem.with_suffix('.png'), title=f'open-loop replay of {bag.name}',
               logy=True)
    data = {'bag': str(args.bag), 'plant': args.plant, 'samples': int(result.times_s.size),
            'kicks': len(recorded.kicks), 'max_error_rad': result.max_error_rad,
            'rms_error_rad': result.rms_error_rad}
    stem.with_suffix('.json').write_text(json.dumps(data, indent=2) + '\n')
    print(f'replayed {len(recorded.kicks)} programmes and {len(recorded.holds)} voltage '
          f'commands through the {args.plant} plant against {result.times_s.size} samples')
    print(f'wrote {stem.with_suffix(".png")} and {stem.with_suffix(".json")}')
    print(f'replay error: max {result.max_error_rad:.3g} rad, RMS {result.rms_error_rad:.3g} '
          'rad')
    return 0
