"""``sphere-twin kick SCENE``: simulate one scene and print the sphere's final state."""

from __future__ import annotations

import argparse
import json

from sphere_sim.integrate.segment import SolverError, SolverStatus
from sphere_sim.integrate.solve import Trajectory
from sphere_sim.integrate.tolerances import DEFAULT_RTOL
from sphere_sim.model.scene import Scene, available_scenes, load_scene
from sphere_sim.studies.runs import (
    BeamsOutcome,
    KickOutcome,
    run_scene,
    summarize,
    summarize_beams,
)
from sphere_twin.commands.options import CommandError, add_params_option, tolerance

# How a run fails when the tolerance is the fix; other failures name their own cause.
TOLERANCE_FAILURES = (SolverStatus.STEP_TOO_SMALL, SolverStatus.BUDGET_EXCEEDED)


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'kick', help='simulate one scene and print the final sphere state',
        description='Simulate a scene (a shipped name or a YAML path) from its initial state '
                    'for its duration and print the final Cardan angles (deg), surface normal '
                    'and rotation.')
    parser.add_argument('scene', help='a shipped scene (' + ', '.join(available_scenes())
                        + ') or the path of a scene YAML file')
    add_params_option(parser, default=None,
                      help="parameter set (name or YAML file) instead of the scene's own")
    parser.add_argument('--rtol', type=tolerance, default=DEFAULT_RTOL,
                        help='relative tolerance, 1e-12 to 1e-2 (default %(default)g)')
    parser.add_argument('--json', action='store_true', help='print the outcome as JSON')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scene = load_scene(args.scene)
    trajectory = _simulate(scene, args)
    # A scene without a sphere still shows what its beams did.
    outcome = (summarize(trajectory) if trajectory.model.has_sphere
               else summarize_beams(trajectory))
    if args.json:
        print(json.dumps(outcome.to_dict(), indent=2))
    elif isinstance(outcome, KickOutcome):
        print_sphere(outcome)
    else:
        print_beams(outcome)
    return 0


def _simulate(scene: Scene, args: argparse.Namespace) -> Trajectory:
    """The scene's run; a failed integration is the user's to fix, so it names the option."""
    try:
        # The scene's own set unless --params names another; its perturbation either way.
        return run_scene(scene, scene.parameters(args.params), rtol=args.rtol)
    except SolverError as error:
        if error.status not in TOLERANCE_FAILURES:
            raise
        raise CommandError(f'{error}: the integration of scene {scene.name!r} at --rtol '
                           f'{args.rtol:g} gave up; try another --rtol from 1e-12 to 1e-2 '
                           f'(default {DEFAULT_RTOL:g})') from error


def print_sphere(outcome: KickOutcome) -> None:
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


def print_beams(outcome: BeamsOutcome) -> None:
    print(f'scene: {outcome.scene} (parameters: {outcome.parameter_set}), '
          f'{outcome.duration_s * 1e3:.1f} ms simulated in {outcome.wall_time_s:.1f} s; '
          'no sphere, the beams alone')
    print('tip height change at the end (um): ' + ', '.join(
        f'beam {b}: {c * 1e6:+.3f}'
        for b, c in zip(outcome.beams, outcome.final_tip_change_m, strict=True)))
    print('largest tip excursion (um): ' + ', '.join(
        f'beam {b}: {c * 1e6:.3f}'
        for b, c in zip(outcome.beams, outcome.max_tip_excursion_m, strict=True)))
    print('smallest electrode gap (um): ' + ', '.join(
        f'beam {b}: {g * 1e6:.3f}'
        for b, g in zip(outcome.beams, outcome.min_electrode_gap_m, strict=True)))
