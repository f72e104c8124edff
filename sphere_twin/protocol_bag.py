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
    from sphere_twin.run_analysis import RecordedRun


@dataclasses.dataclass(frozen=True)
class ProtocolResults:
    brackets: tuple[ProbeBracket, ...]
    ramps: tuple[RampPullIn, ...]
    noise_std_rad: float  # per axis, from the resting stretches


def read_protocol(bag_dir: str | os.PathLike[str]) -> ProtocolResults:
    from sphere_twin.run_analysis import DEVICE_TOPICS, load_run

    return protocol_of(load_run(bag_dir, DEVICE_TOPICS))


def protocol_of(run: RecordedRun) -> ProtocolResults:
    """The protocol's brackets and ramps in a loaded recording of the device's topics."""
    from sphere_sim.fitting.protocol import probe_brackets, ramp_pull_in, resting_around

    t_s, normals = distinct_samples(run)
    observations, noise = resting_around(t_s, normals, run.kicks)
    ramps = [ramp_pull_in(t_s, normals, start, times, volts)
             for start, times, volts in run.kicks]
    return ProtocolResults(tuple(probe_brackets(observations, noise)),
                           tuple(r for r in ramps if r is not None), noise)


def distinct_samples(run: RecordedRun) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The measured normals' times and values, a sample published again with its stamp (a
    lockstep simulator repeats its last one while it waits for a command) counted once."""
    _, first = np.unique(run.normal_t_s, return_index=True)
    return run.normal_t_s[first], run.normals[first]
