"""The RBF net of eq. (12): its fit to the closed form of eq. (8), and how far it deviates.

    C = sum_ij a_ij exp(-(z_S - c_z,i)^2/sigma_z^2 - (phi - c_phi,j)^2/sigma_phi^2), with the
    weights a_ij fitted by linear least squares to the closed form
    (:mod:`sphere_sim.model.capacitance`), see :class:`RbfCapacitance`.

The scalar function the dynamics kernel calls (:func:`rbf_evaluate`) is compiled with numba and
returns ``(C in F, dC/dz_S in F/m, dC/dphi in F/rad)``.
"""

import dataclasses
import functools
import math
from collections.abc import Iterable
from typing import Any, TypedDict, Unpack

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.model.capacitance import DEFAULT_FRINGE_ANGLE_RAD, closed_form_array

# RBF net of eq. (12), the paper's values. The centres in z_S are z_G + gap for gaps in
# RBF_GAP_RANGE_M, i.e. c_z in [-9.9, 3.3] um for z_G = -10 um.
RBF_N_Z = 25
RBF_N_PHI = 25
RBF_GAP_RANGE_M = (0.1e-6, 13.3e-6)
RBF_PHI_RANGE_RAD = (-14.5e-3, 4.5e-3)
RBF_SIGMA_Z_M = 0.5e-6
RBF_SIGMA_PHI_RAD = 0.75e-3
# A Gaussian factor exp(-d^2) with d^2 above this (d > 7 sigma, factor < 2e-22) is taken as 0,
# both in the fit and in the evaluation, so both use the same function. This changes C by
# less than 1e-21 of the largest weight, and keeps the double sum from producing subnormal
# numbers, whose arithmetic is two orders of magnitude slower.
RBF_CUTOFF_EXPONENT = 50.0

# Least-squares samples per axis on the centre box (4x denser than the centres).
FIT_SAMPLES = 100
# The fit uses only samples where the gaps at both ends, g and h, are at least this (m). Part
# of the centre box has the far end under the ground plate (h < 0 for g < L_ES |sin phi|, up
# to 7.25 um at phi = -14.5 mrad), where eq. (8) does not hold; and C varies like 1/g and
# ln(h) near a zero gap, on a scale that Gaussians of width sigma_z cannot follow within about
# one sigma_z of it. Samples there spoil the fit elsewhere too: with those at g < sigma_z,
# the error in C reaches 6 % of its maximum even where both gaps are >= 2.5 um, against
# 1.3 % without. The contact model keeps both ends at least d_Iso = 1.5 um above the ground
# plate anyway.
FIT_MIN_GAP_M = RBF_SIGMA_Z_M
# Tikhonov term of the fit, relative to the largest singular value of the design matrix. The
# centres in the excluded region have no samples, so the plain least-squares problem is
# singular (and its minimum-norm solution has weights of ~1e-5 F, a wild net outside the
# fitted region). 1e-3 keeps the net there within the closed form's range and costs nothing
# measurable inside (1e-4 gives the same differences), while 1e-2 already raises the error in
# C over the box from 1.4 % to 3.7 % of its maximum.
FIT_RIDGE_RELATIVE = 1.0e-3

# Comparison (compare_models): evaluation points per axis, at the midpoints of a grid that
# never meets the fitting grid; pointwise relative differences are taken where the closed
# form's magnitude is at least this fraction of its maximum over the region.
COMPARE_POINTS = 201
POINTWISE_FLOOR = 1.0e-2

# The numba kernels below carry no annotations (numba reads their types from the arguments),
# hence the `type: ignore[no-untyped-def]` on their defs.


# --- RBF net (12) --------------------------------------------------------------------------

@numba.njit(cache=True)
def rbf_evaluate(z_s_m, phi_rad, centres_z, centres_phi,  # type: ignore[no-untyped-def]
                 sigma_z, sigma_phi, weights):
    """Capacitance of the RBF net (12) and its analytic partial derivatives.

    The Gaussians are separable: the ``n_phi`` phi-factors are computed once, each z-factor
    once per row of the double sum.

    Parameters
    ----------
    z_s_m : float
        Suspension height z_S (m) (not the gap: the centres are in z_S).
    phi_rad : float
        Tilt (rad).
    centres_z : ndarray, shape (n_z,)
        c_z,i (m).
    centres_phi : ndarray, shape (n_phi,)
        c_phi,j (rad).
    sigma_z, sigma_phi : float
        Widths (m, rad).
    weights : ndarray, shape (n_z, n_phi)
        a_ij (F).

    Returns
    -------
    C_F, dC_dz_F_per_m, dC_dphi_F_per_rad : float
    """
    n_phi = centres_phi.shape[0]
    phi_factors = np.empty(n_phi)
    for j in range(n_phi):
        d = (phi_rad - centres_phi[j]) / sigma_phi
        phi_factors[j] = math.exp(-d * d) if d * d < RBF_CUTOFF_EXPONENT else 0.0
    c = 0.0
    dc_dz = 0.0
    dc_dphi = 0.0
    for i in range(centres_z.shape[0]):
        dz = (z_s_m - centres_z[i]) / sigma_z
        if not dz * dz < RBF_CUTOFF_EXPONENT:
            continue
        z_factor = math.exp(-dz * dz)
        row = 0.0
        row_phi = 0.0  # sum_j a_ij e_j (phi - c_phi,j)
        for j in range(n_phi):
            term = weights[i, j] * phi_factors[j]
            row += term
            row_phi += term * (phi_rad - centres_phi[j])
        c += z_factor * row
        dc_dz += z_factor * dz * row
        dc_dphi += z_factor * row_phi
    return c, -2.0 * dc_dz / sigma_z, -2.0 * dc_dphi / (sigma_phi * sigma_phi)


@numba.njit(cache=True)
def _rbf_many(z_s_m, phi_rad, centres_z, centres_phi,  # type: ignore[no-untyped-def]
              sigma_z, sigma_phi, weights, c, dc_dz, dc_dphi):
    for k in range(z_s_m.size):
        c[k], dc_dz[k], dc_dphi[k] = rbf_evaluate(z_s_m[k], phi_rad[k], centres_z, centres_phi,
                                                  sigma_z, sigma_phi, weights)


class FitOptions(TypedDict, total=False):
    """The keyword-only options of :func:`fit_rbf`, as :meth:`RbfCapacitance.fit` passes them."""

    gap_range_m: tuple[float, float]
    phi_range_rad: tuple[float, float]
    sigma_z_m: float
    sigma_phi_rad: float
    n_samples: int
    min_gap_m: float
    ridge: float


def _gaussians(x: NDArray[np.float64], centres: NDArray[np.float64],
               sigma: float) -> NDArray[np.float64]:
    """exp(-((x_k - c_i)/sigma)^2) cut off as in :func:`rbf_evaluate`, shape (x.size, c.size)."""
    d2 = ((x[:, None] - centres[None, :]) / sigma) ** 2
    return np.where(d2 < RBF_CUTOFF_EXPONENT, np.exp(-d2), 0.0)


@dataclasses.dataclass(frozen=True, eq=False)
class RbfCapacitance:
    """A fitted RBF net (12); arrays are read-only (fits are cached and shared).

    Attributes
    ----------
    centres_z_m : ndarray, shape (n_z,)
        c_z,i in z_S (m).
    centres_phi_rad : ndarray, shape (n_phi,)
        c_phi,j (rad).
    sigma_z_m, sigma_phi_rad : float
        Gaussian widths (m, rad).
    weights : ndarray, shape (n_z, n_phi)
        a_ij (F).
    condition_number : float
        2-norm condition number of the regularised least-squares problem, i.e. of the design
        matrix stacked on lambda I (the square root of that of its normal equations).
    ridge : float
        Tikhonov factor used, relative to the design matrix's largest singular value.
    """

    centres_z_m: NDArray[np.float64]
    centres_phi_rad: NDArray[np.float64]
    sigma_z_m: float
    sigma_phi_rad: float
    weights: NDArray[np.float64]
    condition_number: float = math.nan
    ridge: float = 0.0

    @classmethod
    def fit(cls, length_m: float, width_m: float, z_ground_m: float,
            fringe_angle_rad: float = DEFAULT_FRINGE_ANGLE_RAD, include_fringe: bool = True,
            n_z: int = RBF_N_Z, n_phi: int = RBF_N_PHI,
            **options: Unpack[FitOptions]) -> 'RbfCapacitance':
        """The net fitted to :func:`closed_form`, cached on all arguments.

        Parameters
        ----------
        length_m, width_m : float
            Electrode length and width (m).
        z_ground_m : float
            Ground plate height z_G (m); the centres are z_G + gaps in ``RBF_GAP_RANGE_M``.
        fringe_angle_rad : float
            theta_f of the closed form's fringe term (rad).
        include_fringe : bool
            Whether the target includes the fringe term.
        n_z, n_phi : int
            Number of centres along z_S and phi.
        **options
            Passed to :func:`fit_rbf` (ranges, widths, samples, floors, ridge).

        Returns
        -------
        RbfCapacitance
            One shared instance per distinct argument set.
        """
        return _fit_cached(float(length_m), float(width_m), float(z_ground_m),
                           float(fringe_angle_rad), bool(include_fringe), int(n_z), int(n_phi),
                           tuple(sorted(options.items())))

    @property
    def centre_box(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """((z_min, z_max) in m, (phi_min, phi_max) in rad) spanned by the centres."""
        return ((float(self.centres_z_m[0]), float(self.centres_z_m[-1])),
                (float(self.centres_phi_rad[0]), float(self.centres_phi_rad[-1])))

    def evaluate(self, z_s_m: ArrayLike, phi_rad: ArrayLike) -> tuple[NDArray[np.float64], ...]:
        """:func:`rbf_evaluate` on arrays.

        Parameters
        ----------
        z_s_m, phi_rad : array_like
            Suspension heights z_S (m) and tilts (rad), broadcast to a shape S.

        Returns
        -------
        C_F, dC_dz_F_per_m, dC_dphi_F_per_rad : ndarray, shape S
        """
        z, phi = np.broadcast_arrays(np.asarray(z_s_m, dtype=float),
                                     np.asarray(phi_rad, dtype=float))
        out = [np.empty(z.shape) for _ in range(3)]
        _rbf_many(np.ascontiguousarray(z).ravel(), np.ascontiguousarray(phi).ravel(),
                  self.centres_z_m, self.centres_phi_rad, self.sigma_z_m, self.sigma_phi_rad,
                  self.weights, *(o.reshape(-1) for o in out))
        return tuple(out)


def fit_rbf(length_m: float, width_m: float, z_ground_m: float,
            fringe_angle_rad: float = DEFAULT_FRINGE_ANGLE_RAD, include_fringe: bool = True,
            n_z: int = RBF_N_Z, n_phi: int = RBF_N_PHI, *,
            gap_range_m: tuple[float, float] = RBF_GAP_RANGE_M,
            phi_range_rad: tuple[float, float] = RBF_PHI_RANGE_RAD,
            sigma_z_m: float = RBF_SIGMA_Z_M, sigma_phi_rad: float = RBF_SIGMA_PHI_RAD,
            n_samples: int = FIT_SAMPLES, min_gap_m: float = FIT_MIN_GAP_M,
            ridge: float = FIT_RIDGE_RELATIVE) -> RbfCapacitance:
    """Fit the weights of the RBF net (12) to :func:`closed_form` (uncached).

    The samples are an ``n_samples`` x ``n_samples`` grid on the centre box, restricted to
    states with both gaps (g and the far-end gap h) >= ``min_gap_m`` (see ``FIT_MIN_GAP_M``).
    The Gaussians are dimensionless and the target is scaled by its largest sample, so the
    problem is equally well conditioned in any units.
    The least squares is Tikhonov-regularised, min |A a - C|^2 + lambda^2 |a|^2 with lambda =
    ``ridge`` times the largest singular value of the design matrix A (bounded by the product
    of the 1-D factors' norms), solved by ``numpy.linalg.lstsq`` (rcond=None) on its normal
    equations (A^T A + lambda^2 I) a = A^T C.

    Parameters
    ----------
    length_m, width_m, z_ground_m, fringe_angle_rad, include_fringe, n_z, n_phi
        As for :meth:`RbfCapacitance.fit`.
    gap_range_m : (float, float)
        Gaps (m) of the first and last z-centre.
    phi_range_rad : (float, float)
        First and last phi-centre (rad).
    sigma_z_m, sigma_phi_rad : float
        Gaussian widths (m, rad).
    n_samples : int
        Samples per axis.
    min_gap_m : float
        Samples with a smaller gap at either end are left out (m).
    ridge : float
        Relative Tikhonov factor (0 for plain least squares).

    Returns
    -------
    RbfCapacitance
    """
    gaps = np.linspace(gap_range_m[0], gap_range_m[1], n_z)
    centres_phi = np.linspace(phi_range_rad[0], phi_range_rad[1], n_phi)
    sample_gaps = np.linspace(gap_range_m[0], gap_range_m[1], n_samples)
    sample_phis = np.linspace(phi_range_rad[0], phi_range_rad[1], n_samples)
    grid_gap, grid_phi = np.meshgrid(sample_gaps, sample_phis, indexing='ij')
    target = closed_form_array(grid_gap, grid_phi, length_m, width_m, fringe_angle_rad,
                               include_fringe)[0]
    far_gap = grid_gap + length_m * np.sin(grid_phi)
    keep = ((grid_gap >= min_gap_m) & (far_gap >= min_gap_m)).astype(float)
    scale_f = np.max(np.abs(keep * target))
    target = keep * target / scale_f  # scaled to 1 (F), 0 where left out

    # The design matrix A has rows (gap sample s, phi sample t), columns (i, j) and entries
    # keep[s, t] gz[s, i] gp[t, j]. Its normal equations are built from the separable
    # factors (O(n_samples n^4), no n_samples^2 x n^2 matrix):
    # (A^T A)[ij, kl] = sum_s gz[s, i] gz[s, k] sum_t keep[s, t] gp[t, j] gp[t, l],
    # (A^T C)[ij] = (gz^T (keep C) gp)[i, j].
    g_z = _gaussians(sample_gaps, gaps, sigma_z_m)
    g_phi = _gaussians(sample_phis, centres_phi, sigma_phi_rad)
    n_weights = n_z * n_phi
    z_pairs = np.einsum('si,sk->sik', g_z, g_z).reshape(n_samples, n_z * n_z)
    phi_pairs = np.einsum('st,tj,tl->sjl', keep, g_phi, g_phi).reshape(n_samples, -1)
    gram = (z_pairs.T @ phi_pairs).reshape(n_z, n_z, n_phi, n_phi)
    gram = gram.transpose(0, 2, 1, 3).reshape(n_weights, n_weights)
    # Tikhonov: min |A a - C|^2 + lam^2 |a|^2. Solving the normal equations squares the
    # condition (to ~1e6 with the default ridge), which costs 6 of 16 digits: far below the
    # fit's own error.
    lam = ridge * np.linalg.norm(g_z, 2) * np.linalg.norm(g_phi, 2)
    normal = gram + lam * lam * np.eye(n_weights)
    solution, _, _, singular = np.linalg.lstsq(normal, (g_z.T @ target @ g_phi).ravel(),
                                               rcond=None)
    condition = math.sqrt(singular[0] / singular[-1]) if singular[-1] > 0.0 else math.inf

    def frozen(a: ArrayLike) -> NDArray[np.float64]:
        a = np.ascontiguousarray(a, dtype=float)
        a.flags.writeable = False
        return a

    return RbfCapacitance(centres_z_m=frozen(z_ground_m + gaps),
                          centres_phi_rad=frozen(centres_phi), sigma_z_m=float(sigma_z_m),
                          sigma_phi_rad=float(sigma_phi_rad),
                          weights=frozen(scale_f * solution.reshape(n_z, n_phi)),
                          condition_number=condition, ridge=float(ridge))


@functools.lru_cache(maxsize=16)
def _fit_cached(length_m: float, width_m: float, z_ground_m: float, fringe_angle_rad: float,
                include_fringe: bool, n_z: int, n_phi: int,
                options: tuple[tuple[str, Any], ...],
                ) -> RbfCapacitance:
    return fit_rbf(length_m, width_m, z_ground_m, fringe_angle_rad, include_fringe, n_z, n_phi,
                   **dict(options))


# --- comparison ----------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Difference:
    """Largest difference between the RBF net and the closed form for one quantity.

    Attributes
    ----------
    region : str
        ``'box'`` or ``'interior'`` (see :func:`compare_models`).
    quantity : str
        ``'C'`` (F), ``'dC_dz'`` (F/m) or ``'dC_dphi'`` (F/rad).
    relative_to_max : float
        max |RBF - closed| / max |closed| over the region.
    relative_pointwise : float
        max |RBF - closed| / |closed| over the points of the region where |closed| >=
        ``POINTWISE_FLOOR`` max |closed|.
    reference_max : float
        max |closed| over the region (SI units of the quantity).
    n_points : int
        Evaluation points in the region.
    """

    region: str
    quantity: str
    relative_to_max: float
    relative_pointwise: float
    reference_max: float
    n_points: int


def compare_models(length_m: float, width_m: float, z_ground_m: float,
                   fringe_angle_rad: float = DEFAULT_FRINGE_ANGLE_RAD,
                   include_fringe: bool = True, *, fit: RbfCapacitance | None = None,
                   n_points: int = COMPARE_POINTS,
                   min_gap_m: float = FIT_MIN_GAP_M) -> tuple[Difference, ...]:
    """Largest relative differences between the RBF net and the closed form.

    The evaluation points are the midpoints of an ``n_points`` x ``n_points`` cell grid on the
    centre box, which never coincide with the fitting samples. Regions:

    ``box``
        The centre box where both gaps, g and the far-end gap h, are >= ``min_gap_m``: the
        region the net is fitted to (see ``FIT_MIN_GAP_M``).
    ``interior``
        The box shrunk by one sigma on every side, with both gaps >= ``min_gap_m`` +
        sigma_z: the Gaussians fall off at the edges of the fitted region, so the net is
        weakest within about one sigma of them.

    Parameters
    ----------
    length_m, width_m, z_ground_m, fringe_angle_rad, include_fringe
        As for :meth:`RbfCapacitance.fit`.
    fit : RbfCapacitance, optional
        The net to compare; by default the cached :meth:`RbfCapacitance.fit` of these
        arguments.
    n_points : int
        Evaluation cells per axis.
    min_gap_m : float
        Points with a smaller gap at either end are not compared (m).

    Returns
    -------
    tuple of Difference
        For each region in (box, interior), quantities C, dC_dz, dC_dphi.
    """
    if fit is None:
        fit = RbfCapacitance.fit(length_m, width_m, z_ground_m, fringe_angle_rad,
                                 include_fringe)
    (z_lo, z_hi), (phi_lo, phi_hi) = fit.centre_box
    z_edges = np.linspace(z_lo, z_hi, n_points + 1)
    phi_edges = np.linspace(phi_lo, phi_hi, n_points + 1)
    z, phi = np.meshgrid(0.5 * (z_edges[1:] + z_edges[:-1]),
                         0.5 * (phi_edges[1:] + phi_edges[:-1]), indexing='ij')
    gap = z - z_ground_m
    closed = closed_form_array(gap, phi, length_m, width_m, fringe_angle_rad, include_fringe)
    net = fit.evaluate(z, phi)
    far_gap = gap + length_m * np.sin(phi)
    sz, sp = fit.sigma_z_m, fit.sigma_phi_rad
    regions = {
        'box': (gap >= min_gap_m) & (far_gap >= min_gap_m),
        'interior': ((gap >= min_gap_m + sz) & (far_gap >= min_gap_m + sz)
                     & (z >= z_lo + sz) & (z <= z_hi - sz)
                     & (phi >= phi_lo + sp) & (phi <= phi_hi - sp)),
    }
    result = []
    for region, inside in regions.items():
        for quantity, ref, got in zip(('C', 'dC_dz', 'dC_dphi'), closed, net, strict=True):
            ref, got = ref[inside], got[inside]
            error = np.abs(got - ref)
            ref_max = float(np.max(np.abs(ref)))
            large = np.abs(ref) >= POINTWISE_FLOOR * ref_max
            result.append(Difference(
                region=region, quantity=quantity,
                relative_to_max=float(np.max(error) / ref_max),
                relative_pointwise=float(np.max(error[large] / np.abs(ref[large]))),
                reference_max=ref_max, n_points=int(inside.sum())))
    return tuple(result)


def format_comparison(differences: Iterable[Difference]) -> str:
    """The differences of :func:`compare_models` as a plain-text table (str)."""
    lines = [f'{"region":<9} {"quantity":<8} {"rel. to max":>11} {"pointwise":>10} '
             f'{"max |closed|":>13} {"points":>7}']
    for d in differences:
        lines.append(f'{d.region:<9} {d.quantity:<8} {d.relative_to_max:>11.2e} '
                     f'{d.relative_pointwise:>10.2e} {d.reference_max:>13.4e} {d.n_points:>7d}')
    return '\n'.join(lines)
