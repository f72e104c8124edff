"""Kicks per second of the kick workloads against the bare integration of the same kicks.

Three workloads run thousands of kicks: a table build, a kick optimisation and the calibration's
kick observations. Each runs on one worker (this process) and on n for every count asked (a
process pool, and a Dask LocalCluster of n single-threaded workers). The *bare* rate is that of
the same kicks' ``simulate`` calls alone, timed in this process during the one-worker run (no
set-up, no post-processing); a workload's rate is its kicks over its wall time and its workers
(kicks/s per core), and their ratio says how much of a core the integration gets. A workload's
1 -> n scaling is read against that of a pure CPU loop on n processes at the same time: the
scaling the machine itself offers (n up to its cores on an idle machine, less beyond them or
under other load).

Computes and returns; the CLI (``sphere-twin bench throughput``) prints and writes. Lives with
the kicks (not in ``studies``) because it drives the kick workloads, which sit in this room.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from sphere_sim.fitting.calibration import with_value
from sphere_sim.kicks import design as design_module
from sphere_sim.kicks import table_build
from sphere_sim.kicks.design import KickDesign, simulate_kick
from sphere_sim.kicks.engine import DaskEngine, PoolEngine, SerialEngine
from sphere_sim.kicks.lookup_table import TableSpec
from sphere_sim.kicks.optimization import optimise_kick
from sphere_sim.kicks.process_models import process_model
from sphere_sim.kicks.table_build import build_table, jobs_of
from sphere_sim.model.assembly import assemble
from sphere_sim.model.initial_state import explicit_state
from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_sim.model.scene import load_scene

if TYPE_CHECKING:
    from distributed import LocalCluster

    from sphere_sim.integrate.solve import Trajectory

ENGINES = ('serial', 'pool', 'dask')
# Worker counts of the pool and Dask runs unless asked otherwise (the serial run is 1).
DEFAULT_WORKER_COUNTS = (2,)
WORKLOADS = ('table', 'optimisation', 'calibration')
# The bench's Dask workers without their statistical profiler (a sample of every thread each
# 10 ms) and with the system monitor at 1 s: measured idle, the two workers then use 0.034
# instead of 0.07 CPU s per s, which a kick-bound worker would otherwise give up.
DASK_QUIET = {'distributed.worker.profile.enabled': False,
              'distributed.admin.system-monitor.interval': '1s'}
# The parameter whose range the calibration workload spans: an estimate of the calibrated set
# (the bristle's static coefficient), a kick optimised at each end of its range, as a
# sensitivity study of a declared estimate runs them.
CALIBRATION_PATH = 'friction.static_coefficient'


@dataclasses.dataclass(frozen=True)
class Plan:
    """How big each workload is: small enough for a few minutes in all (quick: one)."""

    table_spec: TableSpec
    popsize: int
    maxiter: int
    calibration_maxiter: int
    quick: bool

    @classmethod
    def of(cls, quick: bool) -> Plan:
        if quick:
            # 5 nodes within 23.6 deg x 1 intensity; DE of 12 per generation.
            return cls(TableSpec(grid_step=0.4, intensities=(1.0,),
                                 cone_half_angle_rad=math.radians(8.0)),
                       popsize=4, maxiter=1, calibration_maxiter=0, quick=True)
        # 9 nodes within 16.4 deg x 3 intensities: a small table with the real window and rtol.
        return cls(TableSpec(grid_step=0.2, intensities=(0.5, 0.9, 1.0),
                             cone_half_angle_rad=math.radians(10.0)),
                   popsize=4, maxiter=5, calibration_maxiter=2, quick=False)


@dataclasses.dataclass
class Run:
    """One workload on one engine."""

    workload: str
    engine: str
    workers: int
    kicks: int
    wall_s: float
    startup_s: float = 0.0  # the engine's start-up, not in wall_s
    integrated_kicks: int = 0  # kicks integrated in this process (all of them on one worker)
    cpu_s: float = 0.0  # CPU time of this process and the workers over wall_s

    @property
    def cpu_s_per_kick(self) -> float:
        return self.cpu_s / self.kicks

    @property
    def kicks_per_s_per_core(self) -> float:
        return self.kicks / (self.wall_s * self.workers)


class _IntegrationClock:
    """Counts and times the ``simulate`` calls of kicks made in this process."""

    def __init__(self) -> None:
        self.kicks = 0
        self.seconds = 0.0

    def wrap(self, simulate: Callable[..., Trajectory]) -> Callable[..., Trajectory]:
        def timed(*args: Any, **kwargs: Any) -> Trajectory:
            started = time.perf_counter()
            try:
                return simulate(*args, **kwargs)
            finally:
                self.seconds += time.perf_counter() - started
                self.kicks += 1
        return timed


@contextlib.contextmanager
def integration_clock() -> Iterator[_IntegrationClock]:
    """Times every kick's integration in this process while the block runs."""
    clock = _IntegrationClock()
    original = design_module.simulate
    design_module.simulate = clock.wrap(original)
    try:
        yield clock
    finally:
        design_module.simulate = original


# --- engines -------------------------------------------------------------------------------
class _Engine:
    """A started engine of :mod:`sphere_sim.kicks.engine` for one run, with its start-up
    (processes, imports, the compiled kernels loaded by a warm-up kick) timed apart."""

    def __init__(self, name: str, workers: int) -> None:
        self.name = name
        self.workers = workers
        self.engine: SerialEngine | None = None
        self.startup_s = 0.0
        self._cluster: LocalCluster | None = None

    def __enter__(self) -> SerialEngine:
        started = time.perf_counter()
        if self.name == 'dask':
            import dask
            from distributed import LocalCluster

            with dask.config.set(DASK_QUIET):
                self._cluster = LocalCluster(n_workers=self.workers,
                                             threads_per_worker=1, processes=True,
                                             host='127.0.0.1', dashboard_address=None)
            self.engine = DaskEngine(self._cluster.scheduler_address).start(_warm_worker)
        elif self.name == 'pool':
            self.engine = PoolEngine(self.workers).start(_warm_worker)
        else:
            self.engine = SerialEngine()
        self.startup_s = time.perf_counter() - started
        return self.engine

    def __exit__(self, *exc: object) -> None:
        assert self.engine is not None  # set by __enter__
        self.engine.close()
        if self._cluster is not None:
            self._cluster.close()


def _warm_worker() -> None:
    """Load the compiled kernels in a fresh worker, as any long-running worker has."""
    warm_up()


def warm_up() -> None:
    """One short kick: the compiled kernels are then loaded (their compilation is cached)."""
    model = assemble(load_scene('rest'))
    simulate_kick(model, np.array([0.0, 0.0, 1.0]), KickDesign().programme(1.0),
                  window_s=1e-3, x_rest=explicit_state(model))


def clear_caches() -> None:
    """Forget the set-ups a previous run left in this process (models, rest states): each
    run pays for its own, and a pool forked afterwards starts without them."""
    process_model.cache_clear()
    table_build._rest.cache_clear()


# --- workloads -----------------------------------------------------------------------------
def _table(plan: Plan, params: ParameterSet, engine: SerialEngine) -> int:
    build_table(plan.table_spec, params, workers=engine)
    return len(jobs_of(plan.table_spec))


def _optimisation(plan: Plan, params: ParameterSet, engine: SerialEngine,
                  maxiter: int | None = None) -> int:
    kick = optimise_kick(params=params, popsize=plan.popsize,
                         maxiter=plan.maxiter if maxiter is None else maxiter, workers=engine)
    return kick.evaluations + 1  # and the best design's outcome, simulated once more


def _calibration(plan: Plan, params: ParameterSet, engine: SerialEngine) -> int:
    """A kick optimisation at each end of an estimate's range, on one engine."""
    spec = next(s for s in params.uncertain if s.path == CALIBRATION_PATH)
    return sum(_optimisation(plan, with_value(params, spec, value), engine,
                             plan.calibration_maxiter) for value in (spec.low, spec.high))


RUNNERS: dict[str, Callable[[Plan, ParameterSet, SerialEngine], int]] = {
    'table': _table, 'optimisation': _optimisation, 'calibration': _calibration}


def run_workload(workload: str, engine_name: str, plan: Plan, params: ParameterSet,
                 workers: int = 1) -> tuple[Run, _IntegrationClock | None]:
    """Time one workload on an engine of ``workers`` (1 for 'serial'); returns (Run, bare
    clock or None)."""
    clear_caches()
    runner = _Engine(engine_name, 1 if engine_name == 'serial' else workers)
    with runner as engine, integration_clock() as clock:
        cpu_started = _cpu_s(engine)
        started = time.perf_counter()
        kicks = RUNNERS[workload](plan, params, engine)
        wall_s = time.perf_counter() - started
        cpu_s = _cpu_s(engine) - cpu_started
    bare = clock if engine_name == 'serial' else None
    return Run(workload, engine_name, engine.workers, kicks, wall_s, runner.startup_s,
               clock.kicks, cpu_s), bare


def _cpu_s(engine: SerialEngine) -> float:
    """CPU seconds used so far by this process and, on a pool or Dask, by the workers: a
    machine busy with other work slows a run's wall time, much less its CPU time."""
    own = time.process_time()
    return own + engine.worker_cpu_s() if isinstance(engine, (PoolEngine, DaskEngine)) else own


# A pure-Python loop of about 0.3 s: n of them, one after the other and then on an n-process
# pool, give the 1 -> n scaling the machine itself offers at that moment (n on an idle machine
# with n cores or more; less while other work shares them), against which the workloads' is
# read.
PROBE_ITERATIONS = 3_000_000


def _probe(n: int) -> int:
    total = 0
    for i in range(n):
        total += i * i
    return total


def machine_scaling(workers: int = 2) -> float:
    """1 -> ``workers`` process scaling of a pure CPU loop on this machine now."""
    started = time.perf_counter()
    for _ in range(workers):
        _probe(PROBE_ITERATIONS)
    serial_s = time.perf_counter() - started
    with PoolEngine(workers) as pool:
        pool.start()
        started = time.perf_counter()
        pool(_probe, [PROBE_ITERATIONS] * workers)
        return serial_s / (time.perf_counter() - started)


@dataclasses.dataclass
class Summary:
    runs: list[Run]
    bare_kicks_per_s: dict[str, float]  # workload -> kicks/s of the bare integration, one core
    quick: bool
    # Worker count -> the CPU loop's 1 -> n scaling, before and after the runs.
    machine_scaling: dict[int, tuple[float, ...]] = dataclasses.field(default_factory=dict)
    load_average: tuple[float, ...] = ()  # the 1-minute load average, before and after the runs

    def run(self, workload: str, engine: str, workers: int | None = None) -> Run:
        """The run of ``workload`` on ``engine`` (with ``workers``, if given)."""
        return next(r for r in self.runs if r.workload == workload and r.engine == engine
                    and (workers is None or r.workers == workers))

    def ratio(self, workload: str, engine: str = 'serial', workers: int | None = None) -> float:
        """Kicks/s per core of the workload over the bare integration rate of its kicks."""
        return (self.run(workload, engine, workers).kicks_per_s_per_core
                / self.bare_kicks_per_s[workload])

    def cpu_efficiency(self, workload: str, engine: str, workers: int | None = None) -> float:
        """CPU per kick on one worker over that on ``engine``: 1 when the workers do no more
        work per kick than one process does (what the 1 -> n scaling over n is on an idle
        machine, but for a worker waiting)."""
        return (self.run(workload, 'serial').cpu_s_per_kick
                / self.run(workload, engine, workers).cpu_s_per_kick)

    def scaling(self, workload: str, engine: str, workers: int | None = None) -> float:
        """Total kicks/s on ``engine``'s workers over that on one."""
        one, many = self.run(workload, 'serial'), self.run(workload, engine, workers)
        return (many.kicks / many.wall_s) / (one.kicks / one.wall_s)

    def loop_scaling(self, workers: int) -> float:
        """The CPU loop's 1 -> ``workers`` scaling, the mean of before and after the runs."""
        return float(np.mean(self.machine_scaling[workers]))

    def of_loop(self, workload: str, engine: str, workers: int) -> float:
        """The workload's 1 -> n scaling over the CPU loop's on as many processes: 1 when
        it scales as well as the machine lets any work scale."""
        return self.scaling(workload, engine, workers) / self.loop_scaling(workers)

    def worker_counts(self) -> list[int]:
        return sorted({r.workers for r in self.runs if r.engine != 'serial'})

    def parallel_runs(self) -> list[Run]:
        return [r for r in self.runs if r.engine != 'serial']

    def to_dict(self) -> dict[str, Any]:
        return {'quick': self.quick, 'bare_kicks_per_s': self.bare_kicks_per_s,
                'machine_scaling': {str(n): list(v) for n, v in self.machine_scaling.items()},
                'load_average': list(self.load_average),
                'runs': [{**dataclasses.asdict(r),
                          'kicks_per_s_per_core': r.kicks_per_s_per_core,
                          'ratio_to_bare': self.ratio(r.workload, r.engine, r.workers),
                          'cpu_efficiency': self.cpu_efficiency(r.workload, r.engine,
                                                                r.workers)}
                         for r in self.runs],
                'scaling': {w: {f'{r.engine} {r.workers}': {
                    'scaling': self.scaling(w, r.engine, r.workers),
                    'of_loop': self.of_loop(w, r.engine, r.workers)}
                    for r in self.parallel_runs() if r.workload == w}
                    for w in self.workloads()}}

    def engines(self) -> list[str]:
        return list(dict.fromkeys(r.engine for r in self.runs))

    def workloads(self) -> list[str]:
        return list(self.bare_kicks_per_s)


def throughput(quick: bool = False, workloads: Iterable[str] = WORKLOADS,
               engines: Sequence[str] = ENGINES,
               worker_counts: Sequence[int] = DEFAULT_WORKER_COUNTS,
               progress: Callable[[str, str, int], object] | None = None) -> Summary:
    """Every workload on one worker and on every other engine with each of ``worker_counts``;
    returns a :class:`Summary`.

    ``progress`` is called with (workload, engine label, runs done so far) before each run.
    ``engines`` starts with 'serial': it times the bare integration of each workload's kicks.
    """
    if engines[0] != 'serial':
        raise ValueError("the engines must start with 'serial'")
    counts = sorted({int(n) for n in worker_counts})
    if not counts or counts[0] < 2:
        raise ValueError(f'worker counts must be 2 or more (one worker always runs), got '
                         f'{list(worker_counts)}')
    plan = Plan.of(quick)
    params = load_parameter_set(plan.table_spec.parameter_set)
    warm_up()
    probes = {n: [machine_scaling(n)] for n in counts}
    loads = [_load_average()]
    runs: list[Run]
    bare: dict[str, float]
    runs, bare = [], {}
    for workload in workloads:
        for engine, workers in [('serial', 1)] + [(e, n) for n in counts for e in engines[1:]]:
            if progress is not None:
                progress(workload, f'{engine} {workers}', len(runs))
            run, clock = run_workload(workload, engine, plan, params, workers)
            runs.append(run)
            if clock is not None:
                bare[workload] = clock.kicks / clock.seconds
    for n in counts:
        probes[n].append(machine_scaling(n))
    loads.append(_load_average())
    return Summary(runs, bare, quick, {n: tuple(v) for n, v in probes.items()}, tuple(loads))


def _load_average() -> float:
    return os.getloadavg()[0] if hasattr(os, 'getloadavg') else math.nan
