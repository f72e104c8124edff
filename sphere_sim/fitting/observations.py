"""What a device's recordings tell the identification: kicks observed between resting
stretches, and the sensor noise their residuals carry.

What a device records is the commands it was sent (pulse programmes, voltages held) and its
measured surface normal (§6's magnetic sensor, with its noise), nothing more. Between kicks the
friction holds the sphere still, so every stretch of settled samples measures one resting
normal; their mean beats the sensor noise by the square root of their number. A kick is then an
observation: the programme, the resting normal before it and the resting normal after it.

The residuals are weighed by the sensor noise they carry, correlations included: the stretch
after one kick is the stretch before the next, so one noise draw enters both. The fit itself is
:mod:`sphere_sim.fitting.identification`.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sphere_sim.model.programme import PulseProgramme

# A kick counts as over, and the model is compared with the recording, this long after its
# programme's start (or at the programme's end, if later). The kick window of the controllers
# (KICK_WINDOW_S, 60 ms) is where a kick is within a small angle of its end; at 60 ms the sphere
# still moves by a few 1e-6 rad, which the whitened fit reads (measured over 16 noiseless kicks
# of device_a at its true parameters: model against recording 4.5e-6 rad median at 60 ms,
# 1.7e-6 at 100, 200 and 500 ms alike). Four samples of a second's pause are the price.
SETTLE_S = 0.1
# Noiseless recordings: the integrator's own error sets the residuals' scale.
NOISELESS_STD_RAD = 1e-9
# The restart's own error, per axis: a kick simulated from the relaxed rest state at the
# recorded normal ends this far (RMS) from the same kick in the continuous run that recorded it
# (measured over 40 noiseless kicks of device_a at its true parameters, compared at SETTLE_S:
# 8e-6 rad per axis, most kicks within 2e-6 and one 6.8e-5 off; carrying the friction
# bristles' strain over from the kick before changes it little). It enters every residual,
# independent from kick to kick, beside the sensor's noise: without it the whitened fit reads
# it as a parameter change.
RESTART_STD_RAD = 1e-5


class IdentificationError(ValueError):
    """Recordings or a request the identification cannot work with."""


@dataclasses.dataclass(frozen=True)
class KickObservation:
    """One recorded kick: its programme and the resting normals around it.

    Attributes
    ----------
    time_s : float
        Start of the programme.
    times_s : ndarray, shape (k,)
    voltages_v : ndarray, shape (k, 4)
        The programme's zero-order-hold segments.
    normal_before, normal_after : ndarray, shape (3,)
        Means of the settled samples before and after the kick (unit vectors).
    samples_before, samples_after : int
        How many samples each mean is of.
    """

    time_s: float
    times_s: NDArray[np.float64]
    voltages_v: NDArray[np.float64]
    normal_before: NDArray[np.float64]
    normal_after: NDArray[np.float64]
    samples_before: int
    samples_after: int

    def programme(self) -> PulseProgramme:
        return PulseProgramme.from_segments(self.times_s, self.voltages_v)

    def to_dict(self) -> dict[str, Any]:
        return {'time_s': self.time_s, 'times_s': np.asarray(self.times_s).tolist(),
                'voltages_v': np.asarray(self.voltages_v).tolist(),
                'normal_before': np.asarray(self.normal_before).tolist(),
                'normal_after': np.asarray(self.normal_after).tolist(),
                'samples_before': self.samples_before, 'samples_after': self.samples_after}


@dataclasses.dataclass(frozen=True)
class Observations:
    """The kicks of one or more recordings and the sensor noise measured in them."""

    kicks: tuple[KickObservation, ...]
    noise_std_rad: float  # per tangential axis, from the scatter within settled stretches
    dropped: int = 0  # programmes that could not be used (no settled samples around them)
    # Indices i whose settled stretch after kick i is the one before kick i + 1: one noise
    # draw enters both kicks' residuals, with opposite signs.
    shared: tuple[int, ...] = ()

    def without(self, left_out: Iterable[int]) -> Observations:
        """These observations less the kicks ``left_out`` (indices into ``kicks``). A stretch
        stays shared only between two kicks that both remain."""
        gone = set(left_out)
        keep = [i for i in range(len(self.kicks)) if i not in gone]
        index = {old: new for new, old in enumerate(keep)}
        return dataclasses.replace(
            self, kicks=tuple(self.kicks[i] for i in keep),
            shared=tuple(index[i] for i in self.shared if i in index and i + 1 in index))

    def residual_std_rad(self, i: int) -> float:
        """Standard deviation (rad, per axis) of kick ``i``'s residual: the sensor noise of
        its two means and the restart's error."""
        k = self.kicks[i]
        var = (self.noise_std_rad or NOISELESS_STD_RAD) ** 2
        return math.sqrt(var * (1.0 / k.samples_before + 1.0 / k.samples_after)
                         + RESTART_STD_RAD ** 2)

    def digest(self) -> str:
        text = json.dumps([k.to_dict() for k in self.kicks], sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def residual_covariance(self) -> NDArray[np.float64]:
        """Covariance (rad^2) of the residual vector (x and y of each kick) from the sensor
        noise alone. A residual is the model's end, started from the mean before the kick,
        minus the mean after it: it carries the noise of both means, and consecutive kicks
        that share a stretch are anticorrelated through it."""
        var = (self.noise_std_rad or NOISELESS_STD_RAD) ** 2
        n = len(self.kicks)
        cov = np.zeros((2 * n, 2 * n))
        for i in range(n):
            cov[2 * i, 2 * i] = cov[2 * i + 1, 2 * i + 1] = self.residual_std_rad(i) ** 2
        for i in self.shared:
            for axis in (0, 1):
                a, b = 2 * i + axis, 2 * i + 2 + axis
                cov[a, b] = cov[b, a] = -var / self.kicks[i].samples_after
        return cov

    def whitener(self) -> NDArray[np.float64]:
        """``W`` with ``W C W^T = I`` for the residuals' covariance ``C``: ``W r`` are residuals
        in units of their noise, uncorrelated, whose sum of squares is the misfit."""
        from scipy.linalg import solve_triangular

        chol = np.linalg.cholesky(self.residual_covariance())
        return solve_triangular(chol, np.eye(chol.shape[0]), lower=True)


def _unit_mean(normals: NDArray[np.float64]) -> NDArray[np.float64]:
    mean = np.mean(normals, axis=0)
    return mean / np.linalg.norm(mean)


def _tangential_scatter(normals: NDArray[np.float64],
                        mean: NDArray[np.float64]) -> tuple[float, int]:
    """Squared tangential deviations (rad^2) of unit normals from their mean, summed, and
    the number of degrees of freedom they carry (two per sample, less two for the mean)."""
    d = normals - mean
    d -= np.outer(d @ mean, mean)
    return float(np.sum(d * d)), 2 * (len(normals) - 1)


def observations_from_samples(
        normal_t_s: ArrayLike, normals: ArrayLike,
        programmes: Iterable[tuple[float, ArrayLike, ArrayLike]],
        holds: Iterable[tuple[float, ArrayLike]] = (), window_s: float | None = None,
        min_samples: int = 2) -> Observations:
    """Cut a recording into kick observations.

    Parameters
    ----------
    normal_t_s : ndarray, shape (n,)
        Sample times of the measured normals.
    normals : ndarray, shape (n, 3)
    programmes : sequence of (start_s, times_s, voltages_v)
        The recorded pulse programmes, in any order.
    holds : sequence of (time_s, voltages_v)
        Recorded voltage commands. 0 V on every beam is the rest the kicks start from; a kick
        whose stretch before or after contains another hold is dropped (the model starts each
        kick at rest with the beams unpowered).
    window_s : float, optional
        A programme's effect counts as over this long after its start (or at its end, if
        later); samples from then until the next programme are settled. ``SETTLE_S`` unless
        given.
    min_samples : int
        Fewest settled samples before and after a kick for it to count.

    Raises
    ------
    IdentificationError
        When no kick has settled samples on both sides.
    """
    window_s = SETTLE_S if window_s is None else window_s
    t = np.asarray(normal_t_s, dtype=float)
    n = np.asarray(normals, dtype=float)
    progs = sorted(((float(s), np.asarray(ts, dtype=float), np.asarray(vs, dtype=float))
                    for s, ts, vs in programmes), key=lambda p: p[0])
    powered = [float(ht) for ht, volts in holds if np.any(np.asarray(volts) != 0.0)]
    kicks: list[KickObservation]
    shared: list[int]
    last_after: NDArray[np.bool_] | None
    kicks, dropped, ss, dof, shared, last_after = [], 0, 0.0, 0, [], None
    for i, (start, times, volts) in enumerate(progs):
        settled_from = start + max(window_s, float(times[-1]))
        prev_end = (progs[i - 1][0] + max(window_s, float(progs[i - 1][1][-1]))
                    if i else -math.inf)
        next_start = progs[i + 1][0] if i + 1 < len(progs) else math.inf
        before = (t >= prev_end - 1e-9) & (t < start - 1e-9)
        after = (t >= settled_from - 1e-9) & (t < next_start - 1e-9)
        interrupted = any(prev_end - 1e-9 <= h < next_start for h in powered)
        if before.sum() < min_samples or after.sum() < min_samples or interrupted:
            dropped += 1
            continue
        n_before, n_after = _unit_mean(n[before]), _unit_mean(n[after])
        if kicks and last_after is not None and np.array_equal(before, last_after):
            shared.append(len(kicks) - 1)
        last_after = after
        kicks.append(KickObservation(start, times, volts, n_before, n_after,
                                     int(before.sum()), int(after.sum())))
        # Each settled stretch counted once for the noise (the one after each kick, and the
        # one before the first).
        for mask, mean in ([(before, n_before)] if not kicks[:-1] else []) + [(after, n_after)]:
            s, d = _tangential_scatter(n[mask], mean)
            ss, dof = ss + s, dof + d
    if not kicks:
        raise IdentificationError('no kick with settled samples before and after it: the '
                                  'recording needs pauses between programmes')
    noise = math.sqrt(ss / dof) if dof else 0.0  # per axis
    return Observations(tuple(kicks), noise, dropped, tuple(shared))


def merge_observations(parts: Sequence[Observations]) -> Observations:
    """Observations of several recordings as one set (noise pooled by kick count). One
    recording is returned as it is: pooling would round its noise by an ulp, and the fit's end
    in a flat valley follows such a difference."""
    if len(parts) == 1:
        return parts[0]
    kicks = tuple(k for part in parts for k in part.kicks)
    weights = [len(part.kicks) for part in parts]
    noise = math.sqrt(np.average([p.noise_std_rad ** 2 for p in parts], weights=weights))
    offsets = np.cumsum([0, *weights[:-1]])
    shared = tuple(int(o + i) for o, part in zip(offsets, parts, strict=True)
                   for i in part.shared)
    return Observations(kicks, noise, sum(p.dropped for p in parts), shared)
