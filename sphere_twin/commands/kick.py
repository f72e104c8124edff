"""``sphere-twin kick SCENE``: simulate one scene and print the sphere's final state."""

from __future__ import annotations

import argparse
import json

from sphere_sim.model.scene import load_scene
from sphere_sim.studies.runs import DEFAULT_RTOL, run_scene, summarize
from sphere_twin.commands.options import add_params_option, positive_float


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'kick', help='simulate one scene and print the final sphere state',
        description='Simulate a scene (a shipped name or a YAML path) from its initial state '
                    'for its duration and print the final Cardan angles (deg), surface normal '
                    'and rotation.')
    parser.add_argument('scene', help='scene name (see sphere_sim/scenes) or path to a YAML file')
    add_params_option(parser, default=None,
                      help="parameter set (name or YAML file) instead of the scene's own")
    parser.add_argument('--rtol', type=positive_float, default=DEFAULT_RTOL,
                        help='relative tolerance')
    parser.add_argument('--json', action='store_true', help='print the outcome as JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    # The scene's own set unless --params names another; the scene's perturbation either way.
    outcome = summarize(run_scene(scene, scene.parameters(args.params), rtol=args.rtol))
    if args.json:
        print(json.dumps(outcome.to_dict(), indent=2))
        return 0
    alpha, beta, gamma = outcome.cardan_deg
    nx, ny, nz = outcome.surface_normal
    print(f'scene: {outcome.scene} (parameters: {outcome.parameter_set}), '
          f'{outcome.duration_s * 1e3:.1f} ms simulated in {outcome.wall_time_s:.1f} s')
    print(f'cardan angles: alpha = {alpha:+.4f} deg, beta = {beta:+.4f} deg, '
          f'gamma = {gamma:+.4f} deg')
    print(f'surface normal: [{nx:+.6f}, {ny:+.6f}, {nz:.6f}]')
    print(f'rotation: {outcome.rotation_deg:.4f} deg towards {outcome.direction_deg:+.1f} deg '
          f'(largest excursion {outcome.max_tilt_change_deg:.4f} deg, airborne '
          f'{outcome.airborne_s * 1e3:.2f} ms)')
    return 0
