"""Compiling the physics ahead of time, and saying so when a start has to do it.

numba compiles each kernel on its first call and caches the machine code on disk
(:mod:`sphere_sim.twin.kernel_cache`), once per install location. :func:`compile_physics`
runs the smallest real workloads through every kernel, so that no later start compiles:

* a few milliseconds of the continuous plant from the rest scene with a kick of the shipped
  table, as the simulator runs it (the integrator, the dynamics, the Newton system), by the
  live twin's method and by the studies';
* the discrete plant executing the same kick (a table lookup; its rest pose runs the dynamics);
* what the commands call beyond that: the closed form and the RBF net on arrays, the
  mechanical energy, the library methods' contact-onset checks, the kernel replay.

The controller runs no kernel (its model is the kick table), so there is nothing of its own
to compile; and sphere_control sits above this package, so it could not be run from here.

:func:`announce_compile` is what a node wraps its loading of the physics in: on a cold cache
it says what it is doing, compiles, and says how long it took.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import sphere_sim
from sphere_sim.twin.kernel_cache import (
    cache_directories,
    cached_kernels,
    missing_kernels,
)

# How a user compiles ahead of time (sphere_twin.commands.compile; `ros2 run sphere_twin
# compile_physics` in a colcon workspace).
COMPILE_COMMAND = 'sphere-twin compile'
# The start of the two lines a start logs around a cold compile (the tests and the start-up
# benchmark look for them).
COMPILING_LINE = 'compiling the physics for this install location'
COMPILED_LINE = 'compiled the physics in'
# What a cold compile takes on a 2-core machine (bench/results/startup.md); said beforehand.
COLD_COMPILE_ESTIMATE_S = 60.0
# The workload's sample period and length: a few samples into the kick reach every kernel.
WORKLOAD_PERIOD_S = 1e-3
WORKLOAD_SAMPLES = 4
# Library-method runs of the commands' workload: short, but each takes a step or two.
LIBRARY_RUN_S = 2e-4


@dataclasses.dataclass(frozen=True)
class CompileReport:
    """What :func:`compile_physics` did.

    Attributes
    ----------
    kernels : int
        Cached kernels of the physics.
    elapsed_s : float
        Wall time of the workloads (compiling, or loading from the cache).
    already_compiled : bool
        Every kernel was in the cache before: nothing was compiled.
    missing : tuple of str
        Kernels still without machine code in the cache afterwards (a workload misses them,
        or numba could not write its cache); empty when all went well.
    cache_dirs : tuple of Path
        Where numba keeps them, in this environment.
    """

    kernels: int
    elapsed_s: float
    already_compiled: bool
    missing: tuple[str, ...]
    cache_dirs: tuple[Path, ...]


def install_location() -> Path:
    """The directory the physics is imported from (site-packages, or the source tree)."""
    return Path(sphere_sim.__file__).resolve().parent.parent


def physics_compiled() -> bool:
    """Whether every kernel of the physics has machine code in numba's cache for this install
    location and environment: a start then loads it instead of compiling (a fraction of a
    second, after the imports it needs anyway)."""
    return not missing_kernels(cached_kernels())


def compile_physics() -> CompileReport:
    """Compile every kernel of the physics into numba's cache, unless it is all there already.

    Returns
    -------
    CompileReport
    """
    kernels = cached_kernels()
    already = not missing_kernels(kernels)
    started = time.perf_counter()
    if not already:
        for workload in WORKLOADS:
            workload()
    elapsed_s = time.perf_counter() - started
    return CompileReport(len(kernels), elapsed_s, already, tuple(missing_kernels(kernels)),
                         tuple(cache_directories(kernels)))


@contextlib.contextmanager
def announce_compile(log_info: Callable[[str], Any]) -> Iterator[None]:
    """Around a node's loading of the physics: on a cold cache, say so and compile it all.

    On a cold cache, logs one line through ``log_info`` on entry (what, where, about how
    long), lets the body load the physics (building a plant compiles the kernels it calls),
    then compiles the rest (the integrator the first samples would otherwise compile
    silently) and logs one line with how long it all took. On a warm cache it logs nothing
    and costs the check (milliseconds, after imports the physics needs anyway). A body that
    raises (a bad scene or table) ends it at once, without compiling the rest.
    """
    if physics_compiled():
        yield
        return
    log_info(f'{COMPILING_LINE}, {install_location()} (once; about '
             f'{COLD_COMPILE_ESTIMATE_S:.0f} s on a 2-core machine; ahead of time: '
             f'{COMPILE_COMMAND}) ...')
    started = time.perf_counter()
    yield
    report = compile_physics()
    not_cached = (f'; {len(report.missing)} kernels could not be cached and will compile at '
                  f'every start: {", ".join(report.missing)}' if report.missing else '')
    log_info(f'{COMPILED_LINE} {time.perf_counter() - started:.1f} s; later starts load it '
             f'from {", ".join(map(str, report.cache_dirs))}{not_cached}')


# --- the workloads ---------------------------------------------------------------------------
def _kick_programme() -> Any:
    """The shipped table's first kick at full intensity, from the level rest."""
    import numpy as np

    from sphere_sim.kicks.lookup_table import load_kick_model

    return load_kick_model(()).programme(0, 1.0, np.array([0.0, 0.0, 1.0]))


def _run_plant(kind: str, method: str | None = None) -> None:
    """A few samples of the plant ``kind`` from the rest scene into a kick, through the
    simulator's own runner (so the kernels see the simulator's argument types); the continuous
    plant integrated by ``method`` where given, else as the live twin does."""
    from sphere_sim.twin.plant_setup import build_plant
    from sphere_sim.twin.plants import ContinuousPlant
    from sphere_sim.twin.runner import TwinRunner

    plant = build_plant(kind, 'rest')
    if method is not None and isinstance(plant, ContinuousPlant):
        plant.method = method
    runner = TwinRunner(plant, WORKLOAD_PERIOD_S)
    runner.tick()
    times_s, volts_v = _kick_programme().segments()
    runner.command_programme(times_s, volts_v)
    for _ in range(WORKLOAD_SAMPLES):
        runner.tick()


def compile_continuous_plant() -> None:
    """The simulator's continuous plant: every kernel of a kick from rest, by the live
    twin's method and by the studies' (check_fidelity's reference, a replay of a bag recorded
    by Radau)."""
    from sphere_sim.integrate.solve import DEFAULT_METHOD

    _run_plant('continuous')
    _run_plant('continuous', DEFAULT_METHOD)


def load_discrete_plant() -> None:
    """The simulator's discrete plant: the table lookup of a kick (no kernel of its own; its
    rest pose runs the dynamics with the continuous plant's signatures, checked here)."""
    _run_plant('discrete')


def compile_command_kernels() -> None:
    """The kernels only commands call: the capacitance models on arrays (the capacitance and
    pull-in studies), the mechanical energy (validation), the contact-onset checks of the
    library methods (``--method Radau``, ``odeint``) and the kernel replay (the benches)."""
    from sphere_sim.integrate.kernel_replay import RecordingModel, replay
    from sphere_sim.integrate.solve import simulate
    from sphere_sim.model.assembly import assemble
    from sphere_sim.model.capacitance import closed_form_array
    from sphere_sim.model.capacitance_rbf import RbfCapacitance
    from sphere_sim.model.initial_state import initial_state
    from sphere_sim.model.scene import load_scene

    model = assemble(load_scene('rest'))
    beam = model.params.beam
    closed_form_array([2e-6, 3e-6], [0.0, 1e-3], beam.electrode_length_m,
                      beam.electrode_width_m)
    RbfCapacitance.fit(beam.electrode_length_m, beam.electrode_width_m,
                       beam.ground_z_m).evaluate([0.0, 1e-6], [0.0, 1e-3])
    x0 = initial_state(model)
    model.mechanical_energy(x0)
    programme = _kick_programme()
    recording = RecordingModel(model)
    simulate(recording, x0, LIBRARY_RUN_S, programme, method='Radau')
    simulate(model, x0, LIBRARY_RUN_S, programme, method='odeint')
    replay(model, recording.rhs_calls[:1])
    replay(model, recording.jac_calls[:1], jacobian=True)


# In this order: the simulator's own kernels first, so that an interrupted compile has done
# the part a start needs most.
WORKLOADS: tuple[Callable[[], None], ...] = (
    compile_continuous_plant,
    load_discrete_plant,
    compile_command_kernels,
)
