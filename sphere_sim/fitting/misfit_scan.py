"""The misfit measured along the principal directions of an identification's covariance.

The curvature a Gauss-Newton fit reports comes from the Jacobian at its optimum: it says how
the misfit rises where the residuals are linear in the parameters. Where two parameters trade
against each other the misfit lies in a long valley that flattens or bends. The scan measures
the misfit itself where the interval is reported, two standard errors out along each principal
direction (where the sum of squares should have risen by 4), and rescales each direction by what
it finds. That reading needs a misfit smooth on this scale: the kicks are simulated at a
tolerance where the integrator's own jumps are worth well under one (identification.FIT_RTOL).
Pure arithmetic: the caller evaluates the points.
"""

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

# Points lie this many standard errors from the optimum: where the interval is reported.
SCAN_SIGMAS = 2.0
# Smallest standard error scanned along a direction (scaled coordinates, where a range is 1).
MIN_SCALE = 1e-3


def principal_scales(
        cov: NDArray[np.floating[Any]]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Standard errors along the principal directions of ``cov`` and the directions
    (columns): ``cov = vectors @ diag(scales**2) @ vectors.T``."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    return np.sqrt(np.clip(values, MIN_SCALE ** 2, None)), vectors


def covariance_of(scales: ArrayLike, vectors: NDArray[np.float64]) -> NDArray[np.float64]:
    return (vectors * np.asarray(scales) ** 2) @ vectors.T


def measured_curvature(t_plus: float, rise_plus: float, t_minus: float,
                       rise_minus: float) -> float | None:
    """The coefficient ``a`` of the parabola ``a t^2 + b t`` through the misfit's rise at
    ``t_plus`` and at ``-t_minus`` along a direction (``t`` in the standard errors that were
    scanned, both >= 0): 1 where the covariance scanned is right, below 1 where the misfit
    rises less (the direction's variance is ``1/a`` times larger). A side of zero length (the
    optimum on a bound) leaves the parabola to the other side, symmetric. None when neither
    side has length."""
    sides = [(t, r) for t, r in ((t_plus, rise_plus), (t_minus, rise_minus)) if t > 0.0]
    if not sides:
        return None
    if len(sides) == 1:
        t, r = sides[0]
        return r / t ** 2
    return (rise_plus / t_plus + rise_minus / t_minus) / (t_plus + t_minus)
