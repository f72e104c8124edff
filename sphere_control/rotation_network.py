"""The piecewise-linear network h_a(u_K) of eqs. (59)-(60), its inverse and its learning rule.

h(u) = b + sum_i w_i zeta_i(u) with zeta_i(u) = max(0, u - u_i): a continuous function, linear
between the knots u_i, giving the rotation width (rad) of a kick of intensity u in [0, 1]. While
it is being learned it need not be monotone, so the inverse follows the paper's rules (§4.2):
above the maximum, the intensity of the maximum; below the minimum, that of the minimum; of
several solutions, the one needing least voltage, i.e. the smallest intensity (the voltage rises
with u_K).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray

INTENSITY_RANGE = (0.0, 1.0)


@dataclasses.dataclass(frozen=True)
class NetworkShape:
    """Knots of the network.

    Attributes
    ----------
    n_segments : int
        n_K, the number of activation functions; knots equally spaced from u = 0.
    """

    n_segments: int = 5

    def knots(self) -> NDArray[np.float64]:
        """u_K,i of eq. (60), shape (n_segments,), starting at 0."""
        return np.linspace(INTENSITY_RANGE[0], INTENSITY_RANGE[1], self.n_segments,
                           endpoint=False)


class RotationWidthNetwork:
    """One action's h_a(u_K) with its learnable bias and weights.

    Parameters
    ----------
    bias_rad : float
        b_a (rad).
    weights_rad : ndarray, shape (n,)
        w_a (rad per unit intensity).
    knots : ndarray, shape (n,)
        u_K,i, increasing, in [0, 1).
    """

    def __init__(self, bias_rad: float, weights_rad: ArrayLike, knots: ArrayLike) -> None:
        self.bias_rad = float(bias_rad)
        self.weights_rad = np.array(weights_rad, dtype=float)
        self.knots = np.array(knots, dtype=float)
        if self.weights_rad.shape != self.knots.shape or np.any(np.diff(self.knots) <= 0.0):
            raise ValueError('weights and increasing knots must have the same length')

    @classmethod
    def linear(cls, full_width_rad: float,
               shape: NetworkShape = NetworkShape()) -> RotationWidthNetwork:
        """The prior before learning: h(u) = full_width * u (zero bias, one active slope)."""
        weights = np.zeros(shape.n_segments)
        weights[0] = full_width_rad
        return cls(0.0, weights, shape.knots())

    def copy(self) -> RotationWidthNetwork:
        return RotationWidthNetwork(self.bias_rad, self.weights_rad, self.knots)

    def features(self, intensity: float) -> NDArray[np.float64]:
        """zeta(u) of eq. (60), shape (n,)."""
        return np.maximum(0.0, float(intensity) - self.knots)

    def __call__(self, intensity: float) -> float:
        """h(u) (rad)."""
        return self.bias_rad + float(self.weights_rad @ self.features(intensity))

    def vertices(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Intensities (shape (n+1,)) where h may change slope, with the values there (rad)."""
        u = np.append(self.knots, INTENSITY_RANGE[1])
        u[0] = max(u[0], INTENSITY_RANGE[0])
        return u, np.array([self(x) for x in u])

    def inverse(self, width_rad: float) -> float:
        """u_K = h^-1(Psi) by the paper's rules; always a value in [0, 1].

        Parameters
        ----------
        width_rad : float
            The desired rotation width Psi* (rad).
        """
        u, h = self.vertices()
        if width_rad >= h.max():
            return float(u[np.argmax(h)])  # argmax returns the first, i.e. least voltage
        if width_rad <= h.min():
            return float(u[np.argmin(h)])
        for (u0, h0), (u1, h1) in zip(zip(u[:-1], h[:-1], strict=True),
                                      zip(u[1:], h[1:], strict=True), strict=True):
            if min(h0, h1) <= width_rad <= max(h0, h1):
                if h1 == h0:
                    return float(u0)
                return float(u0 + (width_rad - h0) * (u1 - u0) / (h1 - h0))
        raise AssertionError('a continuous function takes every value between its extremes')

    def update(self, intensity: float, achieved_width_rad: float, bias_rate: float,
               weight_rate: float) -> float:
        """Eqs. (62)-(63) after a kick of ``intensity`` achieved ``achieved_width_rad``.

        The error Psi - Psi~ of the prediction is fed back to the bias and, through the
        gradient dh/dw = zeta(u_K) of the kick's own intensity, to the weights (our reading of
        the paper's dh^-1/dw, which is not defined for a non-injective h).

        Returns
        -------
        float
            The prediction error Psi - Psi~ before the update (rad).
        """
        error = self(intensity) - achieved_width_rad
        zeta = self.features(intensity)
        self.bias_rad -= bias_rate * error
        self.weights_rad -= weight_rate * error * zeta
        return error
