"""The motion of a reference known only by its samples (``/sphere/reference`` in the node).

The x-y point's velocity is the slope of a least-squares line through the recent samples. A
sample that leaves that line by more than a jump tolerance starts the history afresh (a new
setpoint, a jump of the trajectory), so a jump is never extrapolated: until a few samples after
it the reference counts as standing still, and a controller previewing it aims at it as it is.
"""

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_control.reference import clamp_to_cone
from sphere_sim.kicks.discrete import CONE_HALF_ANGLE_RAD, normal_from_xy

# The line is fitted to the samples of this last stretch: five of the reference node's 10 Hz,
# short enough that eq. (64)'s circle is still a line (its arc leaves the chord by 8e-4 in x-y
# over 0.5 s).
HISTORY_S = 0.5
MIN_SAMPLES = 3
# Off the line by more than this (x-y units, 0.11 deg): a jump, not motion.
JUMP_TOLERANCE = 2e-3


class ReferenceMotion:
    """Velocity of a sampled reference, robust to jumps.

    Parameters
    ----------
    history_s : float
        Samples older than this (before the newest) are dropped.
    jump_tolerance : float
        Distance (x-y units) from the fitted line's prediction that counts as a jump.
    """

    def __init__(self, history_s: float = HISTORY_S,
                 jump_tolerance: float = JUMP_TOLERANCE) -> None:
        self.history_s = history_s
        self.jump_tolerance = jump_tolerance
        self.times_s: list[float] = []
        self.xys: list[NDArray[np.float64]] = []
        self.jumps = 0

    def add(self, time_s: float, normal: ArrayLike) -> bool:
        """Record a sample; returns True if it was a jump (the history restarted there)."""
        time_s = float(time_s)
        xy = np.asarray(normal, dtype=float)[:2]
        if self.times_s and time_s <= self.times_s[-1]:
            return False  # a repeat or an old sample says nothing new about the motion
        # With fewer samples a jump cannot be told from motion; the next ones will tell.
        jump = (len(self.times_s) >= MIN_SAMPLES
                and math.hypot(*(xy - self.predict_xy(time_s))) > self.jump_tolerance)
        if jump:
            self.times_s, self.xys = [], []
            self.jumps += 1
        self.times_s.append(time_s)
        self.xys.append(xy)
        keep = [i for i, t in enumerate(self.times_s) if t >= time_s - self.history_s]
        self.times_s = [self.times_s[i] for i in keep]
        self.xys = [self.xys[i] for i in keep]
        return jump

    def velocity_xy(self) -> NDArray[np.float64]:
        """x-y velocity (1/s) of the fitted line; zero with fewer than MIN_SAMPLES samples."""
        if len(self.times_s) < MIN_SAMPLES:
            return np.zeros(2)
        t = np.asarray(self.times_s) - self.times_s[-1]
        xy = np.asarray(self.xys)
        t_mean = t.mean()
        spread = float(np.sum((t - t_mean) ** 2))
        if spread == 0.0:
            return np.zeros(2)
        return ((t - t_mean) @ (xy - xy.mean(axis=0))) / spread

    def predict_xy(self, time_s: float) -> NDArray[np.float64]:
        """The fitted line's x-y point at ``time_s`` (the newest sample moved on by the
        velocity)."""
        return self.xys[-1] + self.velocity_xy() * (float(time_s) - self.times_s[-1])

    def ahead(self, horizon_s: float, cone_half_angle_rad: float = CONE_HALF_ANGLE_RAD,
              ) -> NDArray[np.float64] | None:
        """The unit normal the reference will have ``horizon_s`` after its newest sample,
        clamped into the cone; None before any sample."""
        if not self.times_s:
            return None
        xy, _ = clamp_to_cone(self.xys[-1] + self.velocity_xy() * horizon_s,
                              cone_half_angle_rad)
        return normal_from_xy(*xy)
