"""A Kalman filter on the x-y point of the resting surface normal (§6's proposal).

Between measurements the sphere rests, so the state only changes by kicks. The filter predicts
each kick's displacement with the controller's own model (learned direction and width) and
treats the model's error as process noise; measurements are the noisy normal's x-y point.
"""

import dataclasses

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.kicks.discrete import normal_from_xy

IDENTITY_2 = np.eye(2)


@dataclasses.dataclass(frozen=True)
class KalmanParams:
    """Noise model of the filter.

    Attributes
    ----------
    measurement_std_rad : float
        Std of each measured x-y component (rad).
    kick_std_rad : float
        Std of each x-y component of the kick's displacement the model cannot predict, added
        per kick (rad).
    kick_relative_std : float
        Further std per kick as a fraction of the predicted displacement's length (direction
        and width errors scale with the kick).
    initial_std_rad : float
        Std of the initial state (rad).
    """

    measurement_std_rad: float
    kick_std_rad: float
    kick_relative_std: float = 0.5
    initial_std_rad: float = 0.0


class NormalKalmanFilter:
    """Linear Kalman filter with state x = (x_sn, y_sn), x_{k+1} = x_k + d_k + w_k, y_k = x_k + v_k.

    Parameters
    ----------
    params : KalmanParams
    normal : ndarray, shape (3,)
        Initial estimate.
    """

    def __init__(self, params: KalmanParams, normal: ArrayLike) -> None:
        self.params = params
        self.xy = np.asarray(normal, dtype=float)[:2].copy()
        self.covariance = params.initial_std_rad ** 2 * IDENTITY_2

    @property
    def normal(self) -> NDArray[np.float64]:
        """Estimated unit normal, shape (3,)."""
        return normal_from_xy(*self.xy)

    def predict(self, displacement_xy: ArrayLike) -> None:
        """Time update over one kick predicted to move the normal by ``displacement_xy``."""
        d = np.asarray(displacement_xy, dtype=float)
        p = self.params
        q = p.kick_std_rad ** 2 + (p.kick_relative_std * float(np.hypot(*d))) ** 2
        self.xy = self.xy + d
        self.covariance = self.covariance + q * IDENTITY_2

    def update(self, measured_normal: ArrayLike) -> NDArray[np.float64]:
        """Measurement update with a measured normal (shape (3,)); returns the estimate."""
        r = self.params.measurement_std_rad ** 2 * IDENTITY_2
        gain = self.covariance @ np.linalg.inv(self.covariance + r)
        self.xy = self.xy + gain @ (np.asarray(measured_normal, dtype=float)[:2] - self.xy)
        self.covariance = (IDENTITY_2 - gain) @ self.covariance
        return self.normal
