"""``sphere-twin capacitance``: the closed form of eq. (8) against the RBF net of eq. (12).

Fits the net the model would use for a parameter set, prints the largest differences between
the two over the net's centre box (see :func:`sphere_sim.model.capacitance_rbf.compare_models`) and
optionally plots both along a few slices.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from sphere_sim.model import capacitance as cap
from sphere_sim.model import capacitance_rbf as rbf
from sphere_twin.commands.options import add_params_option, output_file, positive_float

# Gaps g = z_S - z_G of the plotted slices (m): from near the contact (d_Iso = 1.5 um) to the
# rest gap (10 um), all inside the fitted region for phi >= 0.
PLOT_GAPS_M = (2.0e-6, 5.0e-6, 10.0e-6)
PLOT_POINTS = 400  # per slice


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Add the ``capacitance`` subcommand to an argparse ``subparsers`` object."""
    parser = subparsers.add_parser(
        'capacitance',
        help='compare the closed-form capacitance (eq. 8) with the RBF net (eq. 12)',
        description=__doc__.splitlines()[0].replace('``', ''),
    )
    add_params_option(parser, help='parameter set giving the electrode geometry and fringe '
                                   'settings: a name or a YAML file')
    parser.add_argument('--no-fringe', action='store_true',
                        help='leave out the fringe (second) term of eq. (8)')
    parser.add_argument('--fringe-angle-rad', type=positive_float, default=None,
                        metavar='RAD',
                        help="theta_f regularising the fringe term (default: the parameter "
                             "set's)")
    parser.add_argument('--plot', metavar='PATH', type=output_file('.png'), default=None,
                        help='also write a PNG of C and dC/dphi, closed form and RBF, along '
                             'slices of constant gap')
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print the comparison table (and write the plot); returns the exit status 0."""
    params = args.params
    beam = params.beam
    include_fringe = params.electrostatics.fringe and not args.no_fringe
    angle = (params.electrostatics.fringe_angle_rad if args.fringe_angle_rad is None
             else args.fringe_angle_rad)
    geometry = (beam.electrode_length_m, beam.electrode_width_m, beam.ground_z_m)

    start = time.perf_counter()
    fit = rbf.RbfCapacitance.fit(*geometry, angle, include_fringe)
    fit_s = time.perf_counter() - start
    differences = rbf.compare_models(*geometry, angle, include_fringe, fit=fit)

    (z_lo, z_hi), (phi_lo, phi_hi) = fit.centre_box
    fringe = f'on, theta_f = {angle:g} rad' if include_fringe else 'off'
    print(f'parameter set {params.name}: L_ES = {beam.electrode_length_m:g} m, '
          f'w_ES = {beam.electrode_width_m:g} m, z_G = {beam.ground_z_m:g} m; fringe {fringe}')
    print(f'RBF net: {fit.weights.shape[0]} x {fit.weights.shape[1]} centres, '
          f'z_S in [{z_lo:.4g}, {z_hi:.4g}] m, phi in [{phi_lo:.4g}, {phi_hi:.4g}] rad, '
          f'sigma_z = {fit.sigma_z_m:g} m, sigma_phi = {fit.sigma_phi_rad:g} rad')
    print(f'fit: both gaps >= {rbf.FIT_MIN_GAP_M:g} m, ridge {fit.ridge:g}, '
          f'condition number {fit.condition_number:.3g}, {fit_s:.2f} s')
    print()
    print(rbf.format_comparison(differences))
    print()
    print("rel. to max = max |RBF - closed| / max |closed| over the region; pointwise = max "
          f"|RBF - closed| / |closed| where |closed| >= {rbf.POINTWISE_FLOOR:g} max |closed|.")
    print('box = centre box with both gaps >= the fit floor; interior = one sigma inside it.')
    if args.plot:
        _plot(args.plot, fit, geometry, angle, include_fringe)
        print(f'wrote {args.plot}')
    return 0


def _plot(path: Path, fit: rbf.RbfCapacitance, geometry: tuple[float, float, float],
          fringe_angle_rad: float, include_fringe: bool) -> None:
    """C and dC/dphi along phi at the gaps PLOT_GAPS_M, closed form (solid) and RBF (dashed)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    length_m, width_m, z_ground_m = geometry
    (_, _), (phi_lo, phi_hi) = fit.centre_box
    phi = np.linspace(phi_lo, phi_hi, PLOT_POINTS)
    fig = Figure(figsize=(10.0, 4.0), layout='constrained')
    FigureCanvasAgg(fig)
    ax_c, ax_d = fig.subplots(1, 2)
    for k, gap in enumerate(PLOT_GAPS_M):
        closed = cap.closed_form_array(gap, phi, length_m, width_m, fringe_angle_rad,
                                       include_fringe)
        net = fit.evaluate(z_ground_m + gap, phi)
        fitted = np.minimum(gap, gap + length_m * np.sin(phi)) >= rbf.FIT_MIN_GAP_M
        colour = f'C{k}'
        for ax, index, scale in ((ax_c, 0, 1e12), (ax_d, 2, 1e9)):
            ax.plot(phi * 1e3, np.where(fitted, closed[index], np.nan) * scale, color=colour,
                    label=f'closed form, g = {gap * 1e6:g} um')
            ax.plot(phi * 1e3, np.where(fitted, net[index], np.nan) * scale, '--',
                    color=colour, label=f'RBF, g = {gap * 1e6:g} um')
    ax_c.set(xlabel='phi (mrad)', ylabel='C (pF)', title='capacitance')
    ax_d.set(xlabel='phi (mrad)', ylabel='dC/dphi (nF/rad)', title='dC/dphi')
    ax_c.legend(fontsize='small')
    path.parent.mkdir(parents=True, exist_ok=True)  # checked creatable before the fit
    fig.savefig(path, dpi=120)
