"""Reading an experiment protocol back from a bag: each threshold search's bracket and each
slow ramp's pull-in, from the device's topics alone (programmes and the measured normal), for
a recording of a synthetic device or of hardware alike (``sphere_sim.fitting.protocol``)."""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from numpy.typing import NDArray

    from sphere_sim.fitting.protocol import ProbeBracket, RampPullIn
    from sphere_sim.fitting.ramps import RampObservation
    from sphere_twin.run_analysis import RecordedRun


@dataclasses.dataclass(frozen=True)
class ProtocolResults:
    brackets: tuple[ProbeBracket, ...]
    ramps: tuple[RampPullIn, ...]
    noise_std_rad: float  # per axis, from the resting stretches
    # the ramps whose jump was seen and the sphere rested before, as observations to fit
    ramp_observations: tuple[RampObservation, ...] = ()


def read_protocol(bag_dir: str | os.PathLike[str]) -> ProtocolResults:
    from sphere_twin.run_analysis import DEVICE_TOPICS, load_run

    return protocol_of(load_run(bag_dir, DEVICE_TOPICS))


def protocol_of(run: RecordedRun) -> ProtocolResults:
    """The protocol's brackets and ramps in a loaded recording of the device's topics."""
    from sphere_sim.fitting.protocol import probe_brackets, ramp_pull_in, resting_around
    from sphere_sim.fitting.ramps import RampObservation

    t_s, normals = distinct_samples(run)
    observations, noise = resting_around(t_s, normals, run.kicks)
    rested = {o.time_s: o for o in observations}
    ramps, fitted = [], []
    for start, times, volts in run.kicks:
        ramp = ramp_pull_in(t_s, normals, start, times, volts)
        if ramp is None:
            continue
        ramps.append(ramp)
        before = rested.get(float(start))
        observation = None if before is None else RampObservation.from_pull_in(
            ramp, times, volts, before.normal_before, noise)
        if observation is not None:
            fitted.append(observation)
    return ProtocolResults(tuple(probe_brackets(observations, noise)), tuple(ramps), noise,
                           tuple(fitted))


def distinct_samples(run: RecordedRun) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The measured normals' times and values, a sample published again with its stamp (a
    lockstep simulator repeats its last one while it waits for a command) counted once."""
    _, first = np.unique(run.normal_t_s, return_index=True)
    return run.normal_t_s[first], run.normals[first]
