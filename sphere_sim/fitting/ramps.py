"""The model side of the protocol's slow ramps: where a staircase of voltage on one beam pulls
it in, for a parameter set, and a recorded ramp's jump as a residual.

A probe's threshold is dynamic (a short pulse: the beams' inertia and damping), a slow ramp's
is static (the stiffness and the gap): with the threshold searches alone, the beams' four
parameters trade along a valley that a ramp cuts across (docs/identification.md, "The slow
ramps"). On the shipped example the thresholds of paper_b's truth and of a point 16 % low in
k_z and 46 % low in d_B,phi fit equally well; the ramps of the two points pull in 0.7 V apart.

The recorded jump (:func:`~sphere_sim.fitting.protocol.ramp_pull_in`) lies between two samples
of the normal sensor; the ramp's voltage at a time is read as the ramp's rate says it, from the
programme's first level (the staircase holds each level for one step), so that a jump's time
and a ramp's voltage are one number. The model simulates the recorded programme from rest at
the recorded normal and reports the instant its normal moves
:data:`~sphere_sim.fitting.protocol.RAMP_JUMP_RAD` within :data:`JUMP_LAG_S`, interpolated
between output samples: a continuous function of the parameters wherever the jump is a jump,
so the misfit has no steps from it.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from sphere_sim.fitting.protocol import RAMP_JUMP_RAD, RampPullIn, moved_rad
from sphere_sim.fitting.thresholds import ThresholdObservation
from sphere_sim.integrate.solve import simulate
from sphere_sim.integrate.tolerances import FIT_RTOL
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal
from sphere_sim.kicks.discrete import NOISE_STUDY_STD_RAD
from sphere_sim.kicks.process_models import process_model
from sphere_sim.kicks.table_build import BLAS_THREADS_PER_KICK
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet
from sphere_sim.model.programme import PulseProgramme

# The model's jump: the normal moving the recorder's threshold for a jump (RAMP_JUMP_RAD, about
# half of the jumps seen, 2.7e-3 to 4.3e-3 rad on the shipped example: the detector's largest
# step of window means falls on the first sample past the jump's middle) within one sample
# period of the 100 Hz sensor.
JUMP_LAG_S = 0.01
# The simulated normal's output spacing (s): the jump rises over some 2.5 ms (2.6e-3 to 9.8e-3
# rad on paper_b's truth, beam 3), resolved by five samples.
OUTPUT_PERIOD_S = 5e-4
# Simulated past the recorded jump before a longer run is tried (s of ramp): 2 V at 20 V/s.
MARGIN_S = 0.1
# Where the recorder's detector puts the jump, its spread under the sensor's noise (V of ramp,
# one standard deviation, at the noise study's sensor, NOISE_STUDY_STD_RAD): measured on the
# model at paper_b's truth, each of the shipped example's four ramps sampled at 100 Hz with 40
# draws of that noise, 0.14, 0.14, 0.29 and 0.24 V (beams 1-4; the sphere rings after the
# jump, so a noisy window mean may take a sample on either side for it). The largest, scaled
# with the recording's noise.
DETECTION_SD_V = 0.3
# The model's own error (V, one standard deviation): where in its 2.5 ms rise the jump is put,
# at 20 V/s 0.05 V, and the detector's bias on the noiseless model (its bracket's middle
# 0.045 V from the model's jump on paper_b's truth, beams 1 and 2).
MODEL_ERROR_V = 0.05


@dataclasses.dataclass(frozen=True)
class RampObservation:
    """A recorded ramp's jump: between the ramp's voltages ``low_v`` and ``high_v`` (read at
    the two samples either side of it, as the ramp's rate says), from the sphere resting at
    ``normal_before``, under the programme ``times_s``, ``voltages_v`` (zero-order hold)."""

    beams: tuple[int, ...]
    rate_v_per_s: float
    start_v: float  # the staircase's first level
    low_v: float
    high_v: float
    normal_before: tuple[float, float, float]
    times_s: tuple[float, ...]
    voltages_v: tuple[tuple[float, ...], ...]
    noise_std_rad: float  # the recording's sensor noise, per axis

    @classmethod
    def from_pull_in(cls, pull_in: RampPullIn, times_s: NDArray[np.float64],
                     voltages_v: NDArray[np.float64], normal_before: NDArray[np.float64],
                     noise_std_rad: float) -> RampObservation | None:
        """The recorded ramp as an observation, or None where no jump was seen."""
        if pull_in.below_s is None or pull_in.above_s is None:
            return None
        start_v = float(np.max(np.asarray(voltages_v, dtype=float)[0]))
        n = np.asarray(normal_before, dtype=float)
        return cls(pull_in.beams, pull_in.rate_v_per_s, start_v,
                   start_v + pull_in.rate_v_per_s * pull_in.below_s,
                   start_v + pull_in.rate_v_per_s * pull_in.above_s,
                   (float(n[0]), float(n[1]), float(n[2])),
                   tuple(float(t) for t in times_s),
                   tuple(tuple(float(v) for v in row) for row in voltages_v),
                   float(noise_std_rad))

    @property
    def label(self) -> str:
        beams = '+'.join(str(b) for b in self.beams)
        return f'ramp of beam{"s" if len(self.beams) > 1 else ""} {beams} at ' \
               f'{self.rate_v_per_s:g} V/s'

    @property
    def middle_v(self) -> float:
        return 0.5 * (self.low_v + self.high_v)

    @property
    def std_v(self) -> float:
        """The residual's standard deviation (V): the jump uniform between the two samples,
        the detector's spread under the recording's noise (:data:`DETECTION_SD_V`) and the
        model's error (:data:`MODEL_ERROR_V`), in quadrature."""
        detection = DETECTION_SD_V * self.noise_std_rad / NOISE_STUDY_STD_RAD
        return math.sqrt((self.high_v - self.low_v) ** 2 / 12.0 + detection ** 2
                         + MODEL_ERROR_V ** 2)

    def voltage_at(self, t_s: float) -> float:
        """The ramp's voltage ``t_s`` after its start, as its rate says."""
        return self.start_v + self.rate_v_per_s * t_s

    def time_at(self, voltage_v: float) -> float:
        return (voltage_v - self.start_v) / self.rate_v_per_s

    def programme(self) -> PulseProgramme:
        return PulseProgramme.from_segments(list(self.times_s),
                                            [list(row) for row in self.voltages_v])


# What the protocol's pull-in experiments give a fit: a threshold search's bracket (dynamic) or
# a slow ramp's jump (static), each a voltage with a standard deviation.
PullInObservation = ThresholdObservation | RampObservation


def jump_time_s(t_s: NDArray[np.float64], normals: NDArray[np.float64]) -> float | None:
    """The first instant at which the normal (samples ``normals`` at ``t_s``) lies
    :data:`~sphere_sim.fitting.protocol.RAMP_JUMP_RAD` from where it was :data:`JUMP_LAG_S`
    before, interpolated linearly between samples; None if it never does."""
    t, first = np.unique(np.asarray(t_s, dtype=float), return_index=True)
    n = np.asarray(normals, dtype=float)[first]
    lagged = np.column_stack([np.interp(t - JUMP_LAG_S, t, n[:, k]) for k in range(3)])
    moved = np.array([moved_rad(a, b) for a, b in zip(lagged, n, strict=True)])
    moved[t < t[0] + JUMP_LAG_S] = 0.0
    over = np.flatnonzero(moved > RAMP_JUMP_RAD)
    if not over.size:
        return None
    i = int(over[0])  # at least 1: moved is zero for the first lag
    share = (RAMP_JUMP_RAD - moved[i - 1]) / (moved[i] - moved[i - 1])
    return float(t[i - 1] + share * (t[i] - t[i - 1]))


def model_ramp_pull_in_v(params: ParameterSet, observation: RampObservation,
                         rtol: float = FIT_RTOL) -> float:
    """The ramp's voltage at the model's jump (:func:`jump_time_s`), the recorded programme
    simulated from rest at the recorded normal: first to :data:`MARGIN_S` past the recorded
    jump, then to the programme's end if the model has not jumped by then. A model that does
    not jump within the programme returns the ramp's voltage at its end (the residual is then
    a bound)."""
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        model = process_model(params)
        normal = np.asarray(observation.normal_before, dtype=float)
        x = rest_state(model, cardan_of_normal(normal / np.linalg.norm(normal)),
                       relaxation=KICK_RELAXATION)
        programme = observation.programme()
        end_s = observation.times_s[-1]
        t_parts: list[NDArray[np.float64]] = []
        n_parts: list[NDArray[np.float64]] = []
        start_s = 0.0
        for stop_s in (min(observation.time_at(observation.high_v) + MARGIN_S, end_s), end_s):
            if stop_s <= start_s:
                continue
            traj = simulate(model, x, stop_s, programme, rtol=rtol,
                            sample_period_s=OUTPUT_PERIOD_S, t_start_s=start_s)
            t_parts.append(traj.t)
            n_parts.append(np.array([model.surface_normal(traj.x[:, i])
                                     for i in range(traj.x.shape[1])]))
            jumped = jump_time_s(np.concatenate(t_parts), np.concatenate(n_parts))
            if jumped is not None:
                return observation.voltage_at(jumped)
            x, start_s = traj.x[:, -1], stop_s
    return observation.voltage_at(end_s)
