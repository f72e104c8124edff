"""``sphere-twin calibrate``: fit the declared-uncertain parameters to Fig. 4 and Fig. 5."""

import math
import os
import textwrap

import yaml
from tqdm import tqdm

from sphere_sim.kicks.calibration import (
    CALIBRATED_SET,
    LITERAL_SET,
    calibrate,
    evaluate,
    kick_deg,
    threshold_v,
    with_value,
)
from sphere_sim.kicks.engine import engine_of
from sphere_sim.model.parameters import (
    CALIBRATION_TARGETS,
    ESTIMATE_TARGET,
    PARAMS_DIR,
    load_parameter_set,
)
from sphere_twin.commands.options import CommandError, positive_int


def register(subparsers):
    parser = subparsers.add_parser(
        'calibrate', help="fit the calibrated set's uncertain parameters to Fig. 4 and Fig. 5",
        description='Fit the parameters that the calibrated set declares uncertain, each within '
                    'its declared range and to its declared target: the dynamic pull-in '
                    'threshold of 5 ms pulses with the sphere on (Fig. 4) and the optimised '
                    'diagonal kick (Fig. 5, one kick optimisation per candidate). Prints the '
                    'evaluations and several hypotheses side by side, and optionally rewrites '
                    'sphere_sim/params/calibrated.yaml.')
    parser.add_argument('--target', choices=CALIBRATION_TARGETS, action='append',
                        help='fit only the parameters of this target (repeatable; default all)')
    parser.add_argument('--workers', type=positive_int, default=os.cpu_count() or 1,
                        help='parallel workers of the kick optimisations (default: all cores)')
    parser.add_argument('--write', action='store_true', help='rewrite calibrated.yaml')
    parser.set_defaults(func=run)


def run(args):
    calibrated = load_parameter_set(CALIBRATED_SET)
    base = load_parameter_set(LITERAL_SET)
    specs = [s for s in calibrated.uncertain if args.target is None or s.target in args.target]
    if not specs:
        raise CommandError('the calibrated set declares no uncertain parameter for that target')
    print_ranges(specs)
    with tqdm(desc='calibrate', unit='eval', leave=False) as bar:
        def progress(value, observed):
            bar.set_postfix_str(f'{value:.4g} -> {observed:.4g}')
            bar.update()

        # One pool for all the kick optimisations: its workers keep their models and rest states.
        with engine_of(args.workers) as engine:
            params, fits, checks = calibrate(calibrated, specs, engine, progress)
            print_fits(fits, checks)
            for spec in specs:
                if spec.target == 'fig4_threshold':
                    print_threshold_hypotheses(params, base, spec)
                if spec.target == ESTIMATE_TARGET:
                    print_estimate_sensitivity(params, spec, engine)
    if args.write:
        write_overrides(params, specs)
    return 0


def print_ranges(specs):
    """Each uncertain parameter's range and the physical reason for it."""
    for spec in specs:
        tied = f' (with {", ".join(spec.tied)})' if spec.tied else ''
        print(f'{spec.target}: {spec.path}{tied} in [{spec.low:g}, {spec.high:g}]')
        print(textwrap.fill(' '.join(spec.reason.split()), width=96, initial_indent='  ',
                            subsequent_indent='  '))


def print_fits(fits, checks):
    """Each fit's value, what it reached, and every evaluation on the way."""
    for result, (observed, target, tolerance) in zip(fits, checks, strict=True):
        print(f'fitted {result.spec.path} = {result.value:.4g} after {len(result.history)} '
              f'evaluations: {observed:.4g} {result.unit} (target {target:g} ± {tolerance:g})')
        if not result.reached:
            print(f'  target not reached inside the declared range [{result.spec.low:g}, '
                  f'{result.spec.high:g}]: missed by {abs(observed - target):.3g} {result.unit} '
                  f'at its end {result.value:g}; the range is not stretched to meet it')
        print(f'  {"value":>12} {"observed":>12}')
        for value, seen in sorted(result.history):
            print(f'  {value:>12.4g} {seen:>10.4g} {result.unit}')


def print_estimate_sensitivity(params, spec, workers):
    """What Fig. 4's threshold and Fig. 5's optimised kick do across an estimate's range."""
    print(f'{spec.path} (a physical estimate, not fitted):')
    print(f'{"value":>12} {"threshold":>10} {"optimised kick":>15}')
    for value in sorted({spec.low, params.get(spec.path), spec.high}):
        candidate = with_value(params, spec, value)
        print(f'{value:>12.4g} {threshold_v(candidate):>8.2f} V '
              f'{kick_deg(candidate, workers):>11.4f} deg')


def print_threshold_hypotheses(params, base, spec):
    """Thresholds with and without the sphere, and the rest contact, across the range."""
    candidates = sorted({base.get(spec.path), spec.low, spec.high, params.get(spec.path)})
    print(f'{spec.path}:')
    print(f'{"value":>12} {"with sphere":>12} {"beams only":>11} {"tips on edge":>13} '
          f'{"sphere raises":>14}')
    for candidate in candidates:
        sphere_v, beams_v, on_edge = evaluate(with_value(params, spec, candidate))
        raises = sphere_v > beams_v if not math.isnan(beams_v) else False
        print(f'{candidate:>12.4g} {sphere_v:>10.2f} V {beams_v:>9.2f} V {on_edge!s:>13} '
              f'{raises!s:>14}')


def write_overrides(params, specs):
    """Rewrite the fitted values in calibrated.yaml's ``overrides`` block, nothing else (the
    reasons and comments are written by hand)."""
    path = PARAMS_DIR / 'calibrated.yaml'
    lines = path.read_text().splitlines()
    overrides = dict(yaml.safe_load(path.read_text())['overrides'])
    for spec in specs:
        for dotted in spec.paths:
            overrides[dotted] = float(f'{params.get(dotted):.4g}')
    start = lines.index('overrides:') + 1
    end = start
    while end < len(lines) and lines[end].startswith('  '):
        end += 1
    block = [f'  {key}: {yaml.safe_dump(value).splitlines()[0]}'
             for key, value in overrides.items()]
    path.write_text('\n'.join(lines[:start] + block + lines[end:]) + '\n')
    print(f'wrote {path}')
