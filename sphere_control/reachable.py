"""How fast the plant can follow a moving reference, from the kicks it knows.

One kick per period moves the normal's x-y point by one of the kick vectors ``w_a d_a`` (width
``w_a`` along direction ``sigma_a``) scaled by an intensity in [0, 1], or leaves it. Over several
kicks the mean displacement per kick can be any point of the convex hull of ``{0, w_a d_a}``, so
the fastest the plant can move along a unit direction ``e`` is where the ray along ``e`` leaves
that hull. A reference that moves further per kick period than that outruns the plant, whatever
the controller does; the evaluation reports where on eq. (64) that happens and the controller
node warns about it.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Collection
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_control import reference as ref

if TYPE_CHECKING:
    from sphere_control.command import Controller

# Below this |det| two hull points are collinear with the ray; such a pair is an edge through 0.
COLLINEAR_TOLERANCE = 1e-15


def kick_vectors(directions_rad: ArrayLike, widths_rad: ArrayLike) -> NDArray[np.float64]:
    """x-y displacement of each full kick, shape (n_actions, 2), from its direction and width
    (small angles: a rotation of w rad moves the x-y point by w)."""
    directions = np.asarray(directions_rad, dtype=float)
    widths = np.broadcast_to(np.asarray(widths_rad, dtype=float), directions.shape)
    return np.column_stack([widths * np.cos(directions), widths * np.sin(directions)])


def model_kicks(controller: Controller) -> NDArray[np.float64]:
    """The kick vectors a controller believes in: its (learned) directions and full-intensity
    widths (:meth:`~sphere_control.command.Controller.believed_kicks`)."""
    belief = controller.believed_kicks()
    return kick_vectors(belief.directions_rad, belief.full_widths_rad)


def reach_per_kick(kicks_xy: NDArray[np.float64], direction_rad: float) -> float:
    """Largest mean x-y displacement per kick along ``direction_rad`` (the ray's exit from the
    convex hull of 0 and the kick vectors ``kicks_xy``, shape (n, 2)); 0 if no kick has a
    component along it."""
    e = np.array([math.cos(direction_rad), math.sin(direction_rad)])
    points = [np.asarray(p, dtype=float) for p in kicks_xy]
    best = 0.0
    for p in points:  # a kick straight along the direction
        if abs(e[0] * p[1] - e[1] * p[0]) <= COLLINEAR_TOLERANCE and p @ e > best:
            best = float(p @ e)
    for p, q in itertools.combinations(points, 2):
        # lambda e = alpha p + (1 - alpha) q with alpha in [0, 1], lambda >= 0
        a = p - q
        det = -e[0] * a[1] + e[1] * a[0]
        if abs(det) <= COLLINEAR_TOLERANCE:
            continue
        lam = (-q[0] * a[1] + q[1] * a[0]) / det
        alpha = (e[0] * q[1] - e[1] * q[0]) / det
        if 0.0 <= alpha <= 1.0 and lam > best:
            best = float(lam)
    return best


def best_single_kick(kicks_xy: NDArray[np.float64], direction_rad: float) -> float:
    """The largest component along ``direction_rad`` of one kick (what a kick towards the
    path gives when its sideways part is not taken back by the next)."""
    e = np.array([math.cos(direction_rad), math.sin(direction_rad)])
    return max(0.0, float(np.max(np.asarray(kicks_xy, dtype=float) @ e)))


def reference_steps(reference: ref.Reference, times_s: Collection[float], period_s: float,
                    cone_half_angle_rad: float) -> NDArray[np.float64]:
    """x-y displacement of the reference over one kick period from each time, shape (n, 2)."""
    now = np.array([ref.sample(reference, t, cone_half_angle_rad).normal[:2] for t in times_s])
    ahead = np.array([ref.sample(reference, t + period_s, cone_half_angle_rad).normal[:2]
                      for t in times_s])
    return ahead - now


def speed_ratios(steps_xy: Collection[NDArray[np.float64]],
                 kicks_at: Callable[[int], NDArray[np.float64]],
                 reach: Callable[[NDArray[np.float64], float], float] = reach_per_kick,
                 ) -> NDArray[np.float64]:
    """Needed over reachable displacement per kick for each reference step.

    ``kicks_at(i)`` gives the kick vectors that apply at step ``i`` (they may change over the
    cone). A ratio above 1 means the reference outruns the plant there; a step of zero length
    needs nothing (ratio 0). ``reach`` is :func:`reach_per_kick` (kicks combined over
    periods) or :func:`best_single_kick`.
    """
    ratios = np.zeros(len(steps_xy))
    for i, step in enumerate(steps_xy):
        needed = math.hypot(*step)
        if needed == 0.0:
            continue
        furthest = reach(kicks_at(i), math.atan2(step[1], step[0]))
        ratios[i] = math.inf if furthest == 0.0 else needed / furthest
    return ratios
