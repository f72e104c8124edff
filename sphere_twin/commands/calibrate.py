"""``sphere-twin calibrate``: fit the declared-uncertain parameter to Fig. 4's threshold."""

import math

import yaml
from tqdm import tqdm

from sphere_sim.calibration import TARGET_THRESHOLD_V, evaluate, fit
from sphere_sim.parameters import PARAMS_DIR, load_parameter_set


def register(subparsers):
    parser = subparsers.add_parser(
        'calibrate', help="fit the calibrated set's uncertain parameter to Fig. 4",
        description='Fit the parameter that the calibrated set declares uncertain, within its '
                    'declared range, so that the dynamic pull-in threshold of 5 ms pulses with '
                    'the sphere on is the target; print several hypotheses side by side and '
                    'optionally rewrite sphere_sim/params/calibrated.yaml.')
    parser.add_argument('--target-v', type=float, default=TARGET_THRESHOLD_V,
                        help=f'target dynamic threshold in V (default {TARGET_THRESHOLD_V})')
    parser.add_argument('--write', action='store_true', help='rewrite calibrated.yaml')
    parser.set_defaults(func=run)


def run(args):
    calibrated = load_parameter_set('calibrated')
    base = load_parameter_set('table_a1')
    if len(calibrated.uncertain) != 1:
        raise SystemExit('calibrate fits exactly one declared uncertain parameter')
    spec = calibrated.uncertain[0]
    print(f'fitting {spec.path} in [{spec.low:g}, {spec.high:g}]: {spec.reason.strip()}')
    with tqdm(desc='fit', unit='run', leave=False) as bar:
        value, history = fit(base, spec.path, spec.low, spec.high, args.target_v,
                             progress=lambda v, t: bar.update())
    print(f'fitted {spec.path} = {value:.4g} after {len(history)} threshold runs')
    candidates = sorted({base.get(spec.path), spec.low, spec.high, value})
    print(f'{"value":>12} {"with sphere":>12} {"beams only":>11} {"tips on edge":>13} '
          f'{"sphere raises":>14}')
    for candidate in candidates:
        sphere_v, beams_v, on_edge = evaluate(base.replace(**{spec.path: candidate}))
        raises = sphere_v > beams_v if not math.isnan(beams_v) else False
        print(f'{candidate:>12.4g} {sphere_v:>10.2f} V {beams_v:>9.2f} V {on_edge!s:>13} '
              f'{raises!s:>14}')
    if args.write:
        path = PARAMS_DIR / 'calibrated.yaml'
        data = yaml.safe_load(path.read_text())
        data['overrides'][spec.path] = float(f'{value:.4g}')
        header = ''.join(line + '\n' for line in path.read_text().splitlines()
                         if line.startswith('#'))
        path.write_text(header + yaml.safe_dump(data, sort_keys=False, allow_unicode=True,
                                                width=96))
        print(f'wrote {path}')
    return 0
