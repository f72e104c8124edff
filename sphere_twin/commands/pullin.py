"""``sphere-twin pullin``: the Fig. 4 pull-in threshold of the model, and its figure."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.scene import load_scene
from sphere_sim.studies.pullin import dynamic_threshold, pulse_sweep, quasi_static_threshold
from sphere_twin.commands.options import add_params_option, output_file
from sphere_twin.plots import plot_pulse_sweep

SWEEP_V = (30.0, 35.0, 40.0, 45.0, 50.0, 55.0, 60.0, 65.0, 70.0)  # Fig. 4's range


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'pullin', help='find the pull-in threshold of 5 ms pulses (Fig. 4)',
        description='Bisection to 0.1 V on the amplitude of a 5 ms pulse on all four beams that '
                    'pulls the beams in, beside the quasi-static estimate of the same model, and '
                    'a Fig. 4-like PNG of the 30-70 V sweep.')
    add_params_option(parser)
    parser.add_argument('--no-sphere', action='store_true', help='beams alone')
    parser.add_argument('--plot', type=output_file('.png'), default=None,
                        help='PNG file (default fig4_pullin_<params>.png in the working '
                             'directory); a directory is refused')
    parser.add_argument('--no-plot', action='store_true', help='skip the sweep and its figure')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    scene = load_scene('four_beam_pulse').replace(sphere=not args.no_sphere)
    model = assemble(scene, args.params)
    x_rest = rest_state(model)
    with tqdm(desc='bisection', unit='run', leave=False) as bar:
        dynamic, runs = dynamic_threshold(model, x_rest, progress=lambda lo, hi: bar.update())
    static = quasi_static_threshold(model, x_rest)
    print(f'parameters: {args.params.name}; sphere: {"off" if args.no_sphere else "on"}')
    print(f'dynamic threshold (5 ms pulse, {runs} runs): {dynamic:.2f} V')
    print(f'quasi-static threshold (end of the static branch): {static:.2f} V '
          f'({100 * (dynamic - static) / static:+.1f} %)')
    if not args.no_plot:
        path = Path(args.plot or f'fig4_pullin_{args.params.name}.png')
        path.parent.mkdir(parents=True, exist_ok=True)
        with tqdm(total=len(SWEEP_V), desc='Fig. 4 sweep', unit='pulse', leave=False) as bar:
            trajs = pulse_sweep(model, x_rest, SWEEP_V, progress=lambda v: bar.update())
        plot_pulse_sweep(trajs, SWEEP_V, dynamic, path)
        if model.has_sphere:
            o = model.sphere_offset
            lifts = [np.max(t.x[o + 2] - t.x[o + 2, 0]) * 1e6 for t in trajs]
            print('sphere lift (um): ' + ', '.join(f'{v:.0f} V: {h:.1f}'
                                                   for v, h in zip(SWEEP_V, lifts, strict=True)))
        print(f'figure: {path}')
    print(f'pull-in threshold: {dynamic:.1f} V')
    return 0
