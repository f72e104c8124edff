"""``sphere-twin validate``: the continuous model's rest, symmetry and energy figures."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from sphere_sim.kicks import holding
from sphere_sim.kicks.design import DesignError, KickDesign
from sphere_sim.kicks.offset_lookup import OffsetError, OffsetLookup
from sphere_sim.model.parameters import ParameterError, ParameterSet, load_parameter_set
from sphere_sim.studies import validation
from sphere_twin.commands.options import CommandError, add_params_option

DEFAULT_DESIGN = Path('bench/results/kick_optimization.json')
# The shipped voltage offsets (§4.1) of the shipped design on `calibrated`: the widths at tilt are
# printed with them too where they belong to the design and set validated.
DEFAULT_OFFSETS = Path('bench/results/voltage_offsets.json')


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    parser = subparsers.add_parser(
        'validate', help='print the rest, symmetry and energy figures of the physics model',
        description='Rest equilibrium (§4.1), symmetry of equal and mirrored pulses, and the '
                    'energy balance with and without losses, and how a sphere that landed from a '
                    'kick holds (creep, ratchet) and how the kick narrows with tilt (with the '
                    'shipped voltage offsets too, where they fit the design and set); the same '
                    'functions the tests use.')
    add_params_option(parser)
    parser.add_argument('--design', type=Path, default=None,
                        help=f'kick design JSON of `sphere-twin optimize-kick` (default '
                             f'{DEFAULT_DESIGN} where it exists, else the paper\'s template)')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    rest = validation.rest_report(args.params)
    on_edge = 'yes' if (rest.front_gaps_m < 0).all() else 'no'
    front_nm = rest.front_gaps_m.min() * 1e9
    rear_um = rest.rear_gaps_m.min() * 1e6
    print(f'rest ({args.params.name}): largest force imbalance {rest.force_imbalance:.2e} of the '
          f'weight per tip; tips on the front edge: {on_edge} (front gap {front_nm:+.2f} nm, '
          f'rear gap {rear_um:.2f} um)')
    print(f'rest drift over {rest.duration_s:.0f} s: tilt {rest.tilt_drift_rad:.2e} rad, '
          f'position {rest.position_drift_m:.2e} m')
    params = args.params
    tilt, lift = validation.symmetric_pulse_tilt(params=params)
    print(f'equal 50 V pulses: largest tilt {tilt:.2e} rad (sphere lifted {lift * 1e6:.1f} um)')
    mismatch, excursion = validation.mirror_mismatch(params=params)
    print(f'mirrored programme: normals differ by {mismatch:.2e} (largest x-y excursion '
          f'{excursion:.2e})')
    surplus, impacts = validation.lossless_drop(params=params)
    print(f'lossless drop: {impacts} impacts, energy error {surplus:.2e} of m g h')
    surplus, work = validation.lossless_pulse(params=params)
    print(f'lossless pulse: energy error {surplus:.2e} of the electrical work ({work:.3e} J)')
    peak, final = validation.lossy_kick(params=params)
    print(f'kick with losses: energy surplus at most {peak:+.2e}, finally {final:+.2e} of the '
          'electrical work')
    rests = validation.tilted_rests(params=params)
    print('tilted rest (solved) at ' + ', '.join(f'{t:.0f}' for t, _, _ in rests)
          + f' deg: largest force imbalance {max(r for _, r, _ in rests):.2e} of the weight per '
          f'tip, normal within {max(e for _, _, e in rests):.1e} rad of the tilt asked for')
    design = _design(args.design)
    for tilt_deg in (20.0, 35.0):
        rate = holding.landed_creep_rate(tilt_deg, params=params, design=design)
        print(f'tilted rest at {tilt_deg:.0f} deg creeps back at {math.degrees(rate):.2g} deg/s '
              f'(landed from a kick, over {holding.HOLD_DURATION_S:.0f} s)')
    moved = holding.ratchet_rad(35.0, params=params, design=design)
    print(f'ratchet at 35 deg: {math.degrees(moved):.2g} deg after '
          f'{holding.RATCHET_PULSES} pulses')
    offsets = _offsets(design, params)
    for tilt_deg in (20.0, 35.0):
        ratio = holding.width_ratio(tilt_deg, params=params, design=design)
        line = f'width at {tilt_deg:.0f} deg: {ratio:.2f} of level'
        if offsets is not None:
            ratio = holding.width_ratio(tilt_deg, params=params, design=design, offsets=offsets)
            line += f' ({ratio:.2f} with the shipped voltage offsets)'
        print(line)
    return 0


def _design(path: Path | None) -> KickDesign:
    """The kick the hold and width figures use: ``path``, the committed optimised kick, or the
    paper's template."""
    if path is None:
        if not DEFAULT_DESIGN.exists():
            return KickDesign()
        path = DEFAULT_DESIGN
    try:
        return KickDesign.load(path)
    except (OSError, DesignError) as exc:
        raise CommandError(str(exc)) from exc


def _offsets(design: KickDesign, params: ParameterSet) -> OffsetLookup | None:
    """The shipped voltage offsets where they were searched for ``design`` on this very set (a
    file that overrides the named set's values has none: it is another device)."""
    try:
        lookup = OffsetLookup.load(DEFAULT_OFFSETS, design, params.name)
        searched_on = load_parameter_set(params.name)
    except (OSError, OffsetError, ParameterError):
        return None
    return lookup if searched_on.digest() == params.digest() else None
