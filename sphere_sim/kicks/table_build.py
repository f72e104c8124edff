"""Building the kick lookup table: independent kicks, a local process pool or Dask.

Every table entry is one simulated kick, independent of all others, computed by the pure
function :func:`run_kick_job`; the result does not depend on the engine or the worker count.
Finished entries are appended to a partial file as they arrive, so an interrupted build resumes
where it stopped.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import json
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from functools import lru_cache
from pathlib import Path
from typing import IO, TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray
from threadpoolctl import threadpool_limits

from sphere_sim.kicks.characteristics import offset_grid
from sphere_sim.kicks.design import KICK_RELAXATION, cardan_of_normal, simulate_kick
from sphere_sim.kicks.discrete import KickResult, normal_from_xy
from sphere_sim.kicks.engine import DaskEngine, PoolEngine, SerialEngine, engine_for
from sphere_sim.kicks.lookup_table import TABLE_FORMAT_VERSION, LookupTable, TableError, TableSpec
from sphere_sim.kicks.process_models import process_model
from sphere_sim.model.initial_state import rest_state
from sphere_sim.model.parameters import ParameterSet, load_parameter_set
from sphere_sim.model.rotations import angle_between

if TYPE_CHECKING:
    from distributed import Client

# A table entry as it is stored and sent between processes: JSON (``key``, ``dx``, ``dy``,
# ``peak_rad``, ``settle_s``).
Entry = dict[str, Any]
EntryKey = tuple[int, int, int]


@dataclasses.dataclass(frozen=True)
class KickJob:
    """One table entry: grid indices (i, j, k) and the state and intensity they stand for."""

    i: int
    j: int
    k: int
    x_sn: float
    y_sn: float
    intensity: float

    @property
    def key(self) -> EntryKey:
        return (self.i, self.j, self.k)


def jobs_of(spec: TableSpec) -> list[KickJob]:
    return [KickJob(i, j, k, x, y, float(u)) for i, j, x, y in spec.nodes()
            for k, u in enumerate(spec.intensities)]


def spec_to_dict(spec: TableSpec) -> dict[str, Any]:
    return spec.to_dict()


def spec_from_dict(data: Mapping[str, Any]) -> TableSpec:
    return TableSpec.from_dict(data)


@lru_cache(maxsize=256)
def _rest(params: ParameterSet, x_sn: float, y_sn: float) -> NDArray[np.float64]:
    model = process_model(params)
    return rest_state(model, cardan_of_normal(normal_from_xy(x_sn, y_sn)),
                      relaxation=KICK_RELAXATION)


# LAPACK's LU gives results that differ in the last bits with the BLAS thread count, and a kick
# through contacts amplifies them to ~1e-9 rad; Dask workers default to one thread, a local
# process to all cores. One thread everywhere makes a table bit-identical across engines.
BLAS_THREADS_PER_KICK = 1


def run_kick_job(spec_data: Mapping[str, Any], params: ParameterSet, job: KickJob,
                 x_rest: NDArray[np.float64] | None = None) -> Entry:
    """Simulate one entry; returns a JSON-able dict (pure: same inputs, same output).

    ``x_rest`` is the rest state of the job's node (:func:`node_rest`), computed here (and
    cached in this process) unless given.
    """
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        return _run_kick_job(spec_data, params, job, x_rest)


def node_rest(params: ParameterSet, x_sn: float, y_sn: float) -> NDArray[np.float64]:
    """The rest state at one grid node: a task of its own, shared by the node's kicks."""
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        return _rest(params, x_sn, y_sn)


def _run_kick_job(spec_data: Mapping[str, Any], params: ParameterSet, job: KickJob,
                  x_rest: NDArray[np.float64] | None) -> Entry:
    spec = spec_from_dict(spec_data)
    model = process_model(params)
    normal = normal_from_xy(job.x_sn, job.y_sn)
    x_rest = _rest(params, job.x_sn, job.y_sn) if x_rest is None else x_rest
    result, _ = simulate_kick(model, normal, spec.node_programme(job.x_sn, job.y_sn, job.intensity),
                              window_s=spec.window_s, rtol=spec.rtol, x_rest=x_rest)
    return {'key': list(job.key), 'dx': float(result.normal[0] - normal[0]),
            'dy': float(result.normal[1] - normal[1]), 'peak_rad': result.peak_deviation_rad,
            'settle_s': result.settle_time_s}


def _read_partial(path: str | Path | None, digest: str) -> dict[EntryKey, Entry]:
    done: dict[EntryKey, Entry] = {}
    if path is None or not Path(path).exists():
        return done
    with open(path) as stream:
        header = json.loads(stream.readline() or '{}')
        if header.get('digest') != digest:
            return done  # built for something else: start afresh
        for line in stream:
            try:
                entry = json.loads(line)
            except json.JSONDecodeError:
                break  # a line cut short by the interruption
            done[tuple(entry['key'])] = entry
    return done


def _by_state(jobs: Iterable[KickJob]) -> list[list[KickJob]]:
    """Jobs grouped by grid node, whose rest state (the costly relaxation) is computed once."""
    groups: dict[tuple[int, int], list[KickJob]] = {}
    for job in jobs:
        groups.setdefault((job.i, job.j), []).append(job)
    return list(groups.values())


def _engine_map(jobs: Iterable[KickJob], spec_data: Mapping[str, Any], params: ParameterSet,
                engine: SerialEngine) -> Iterator[Entry]:
    """Yield results as they complete, from Dask, a process pool or this process.

    On a pool or Dask, each node's rest state is one task and each kick another, fed with it:
    the kicks of a node spread over all workers (a whole node per task left one worker idle
    for the last node's kicks) and no rest state is computed twice.
    """
    groups = _by_state(jobs)
    if isinstance(engine, DaskEngine):
        yield from _dask_map(groups, spec_data, params, engine.client)
    elif isinstance(engine, PoolEngine):
        yield from _pool_map(groups, spec_data, params, engine.pool)
    else:
        for group in groups:
            for job in group:
                yield run_kick_job(spec_data, params, job)


def _pool_map(groups: Iterable[list[KickJob]], spec_data: Mapping[str, Any],
              params: ParameterSet,
              pool: concurrent.futures.ProcessPoolExecutor) -> Iterator[Entry]:
    rests = {pool.submit(node_rest, params, group[0].x_sn, group[0].y_sn): group
             for group in groups}
    # Rest states and kicks alike.
    pending: set[concurrent.futures.Future[Any]] = set(rests)
    while pending:
        done, pending = concurrent.futures.wait(
            pending, return_when=concurrent.futures.FIRST_COMPLETED)
        for future in done:
            if future in rests:
                x_rest = future.result()
                pending |= {pool.submit(run_kick_job, spec_data, params, job, x_rest)
                            for job in rests[future]}
            else:
                yield future.result()


def _dask_map(groups: Iterable[list[KickJob]], spec_data: Mapping[str, Any],
              params: ParameterSet, client: Client) -> Iterator[Entry]:
    from distributed import as_completed

    futures = []
    for group in groups:
        rest = client.submit(node_rest, params, group[0].x_sn, group[0].y_sn, pure=False)
        futures += [client.submit(run_kick_job, spec_data, params, job, rest, pure=False)
                    for job in group]
    for future in as_completed(futures):
        yield future.result()


class ReuseError(TableError):
    """A table whose entries cannot stand for the ones a spec asks for."""


def reusable_entries(spec: TableSpec, params_digest: str,
                     table: LookupTable) -> dict[EntryKey, Entry]:
    """The entries of ``table`` that ``spec`` asks for too, keyed as its jobs.

    ``table`` must have been built for the same kick, grid, window, tolerance and parameters
    as ``spec``, which may differ in its intensities and its voltage offsets: an entry is one
    kick, fixed by those, its node's rest state and the programme simulated there, so it is
    the same whichever table holds it. An entry is taken only where both specs simulate the
    very same programme at its node and intensity (new offsets leave the nodes whose offset
    did not change to be reused).

    Raises
    ------
    ReuseError
        For a table built for something else.
    """
    same = dataclasses.replace(table.spec, intensities=spec.intensities, offsets=spec.offsets)
    if same.digest(params_digest) != spec.digest(params_digest):
        raise ReuseError('the table to reuse was built for another kick, grid, window or '
                         'tolerance; only its intensities and voltage offsets may differ')
    if table.meta['params_digest'] != params_digest:
        raise ReuseError('the table to reuse was built for other parameter values')
    old = {round(float(u), 12): k for k, u in enumerate(table.intensities)}
    entries: dict[EntryKey, Entry] = {}
    for job in jobs_of(spec):
        k = old.get(round(job.intensity, 12))
        if k is None or np.isnan(table.displacement[job.i, job.j, k, 0]):
            continue
        if (table.spec.node_programme(job.x_sn, job.y_sn, float(table.intensities[k]))
                != spec.node_programme(job.x_sn, job.y_sn, job.intensity)):
            continue
        dx, dy = table.displacement[job.i, job.j, k]
        entries[job.key] = {'key': list(job.key), 'dx': float(dx), 'dy': float(dy),
                            'peak_rad': float(table.peak_rad[job.i, job.j, k]),
                            'settle_s': float(table.settle_s[job.i, job.j, k])}
    return entries


def build_table(spec: TableSpec, params: ParameterSet | None = None,
                workers: int | SerialEngine = 1, scheduler: str | None = None,
                partial_path: str | Path | None = None,
                progress: Callable[[int, int], object] | None = None,
                reuse: LookupTable | None = None) -> LookupTable:
    """Simulate every entry of ``spec`` (resuming from ``partial_path``) into a LookupTable.

    Parameters
    ----------
    spec : TableSpec
    params : ParameterSet, optional
        The set named by ``spec.parameter_set`` unless given (the workers receive it whole).
    workers : int or engine
        Local processes (ignored with ``scheduler``), or a started engine of
        :mod:`sphere_sim.kicks.engine`, which is left open.
    scheduler : str, optional
        Address of a Dask scheduler, e.g. ``tcp://127.0.0.1:8786``.
    partial_path : path, optional
        File of finished entries, appended as they arrive.
    progress : callable, optional
        Called with the number of entries finished so far and the total.
    reuse : LookupTable, optional
        A table of the same kick at other intensities: its entries are taken, not simulated
        again (:func:`reusable_entries`).
    """
    params = load_parameter_set(spec.parameter_set) if params is None else params
    digest = spec.digest(params.digest())
    spec_data = spec_to_dict(spec)
    jobs = jobs_of(spec)
    done = _read_partial(partial_path, digest)
    reused = {} if reuse is None else reusable_entries(spec, params.digest(), reuse)
    reused = {key: entry for key, entry in reused.items() if key not in done}
    todo = [job for job in jobs if job.key not in done and job.key not in reused]
    stream: IO[str] | None = None
    if partial_path is not None:
        fresh = not done
        stream = open(partial_path, 'w' if fresh else 'a')  # noqa: SIM115 - closed below
        if fresh:
            stream.write(json.dumps({'digest': digest}) + '\n')
    for entry in reused.values():
        _record(entry, done, stream)
    try:
        if progress is not None:
            progress(len(done), len(jobs))
        with engine_for(workers, scheduler) as engine:
            for entry in _engine_map(todo, spec_data, params, engine):
                _record(entry, done, stream)
                if progress is not None:
                    progress(len(done), len(jobs))
    finally:
        if stream is not None:
            stream.close()
    return _assemble(spec, params, digest, done)


def _record(entry: Entry, done: dict[EntryKey, Entry], stream: IO[str] | None) -> None:
    done[tuple(entry['key'])] = entry
    if stream is not None:
        stream.write(json.dumps(entry) + '\n')
        stream.flush()


def _assemble(spec: TableSpec, params: ParameterSet, digest: str,
              entries: Mapping[EntryKey, Entry]) -> LookupTable:
    axis = spec.axis()
    n, m = axis.size, len(spec.intensities)
    displacement = np.full((n, n, m, 2), np.nan)
    peak = np.full((n, n, m), np.nan)
    settle = np.full((n, n, m), np.nan)
    for (i, j, k), entry in entries.items():
        displacement[i, j, k] = (entry['dx'], entry['dy'])
        peak[i, j, k] = entry['peak_rad']
        settle[i, j, k] = entry['settle_s']
    meta = {'format_version': TABLE_FORMAT_VERSION, 'params_digest': params.digest(),
            'parameter_set': params.name, 'table_digest': digest, 'spec': spec_to_dict(spec),
            'reference_direction_deg': math.degrees(spec.design.direction_rad)}
    return LookupTable(axis, np.array(spec.intensities, dtype=float), displacement, peak, settle,
                       meta)


def random_check_points(n_points: int, seed: int, cone_half_angle_rad: float,
                        n_actions: int = 4) -> list[tuple[NDArray[np.float64], int, float]]:
    """Seeded random (normal, action, intensity) inside the cone."""
    rng = np.random.default_rng(seed)
    points: list[tuple[NDArray[np.float64], int, float]] = []
    while len(points) < n_points:
        x, y = rng.uniform(-1, 1, 2) * math.sin(cone_half_angle_rad)
        if math.hypot(x, y) <= math.sin(cone_half_angle_rad):
            points.append((normal_from_xy(float(x), float(y)), int(rng.integers(n_actions)),
                           float(rng.uniform(0.0, 1.0))))
    return points


def direct_kick(spec: TableSpec, params: ParameterSet, normal: NDArray[np.float64], action: int,
                intensity: float) -> KickResult:
    """The continuous model's outcome for the same kick the table interpolates."""
    model = process_model(params)
    programme = spec.programme(action, intensity, normal)
    with threadpool_limits(limits=BLAS_THREADS_PER_KICK):
        x_rest = rest_state(model, cardan_of_normal(normal), relaxation=KICK_RELAXATION)
        result, _ = simulate_kick(model, normal, programme, window_s=spec.window_s,
                                  rtol=spec.rtol, x_rest=x_rest)
    return result


def check_table(table: LookupTable, n_points: int = 8, seed: int = 0,
                progress: Callable[[int, int], object] | None = None
                ) -> tuple[float, list[float]]:
    """Largest angle (rad) between interpolated and simulated final normals, and all errors.

    The simulations use the parameter set the table names; a set whose values changed since
    the build is refused (:meth:`LookupTable.load_current`'s rule).
    """
    spec = spec_from_dict(table.meta['spec'])
    params = table.parameters()
    errors = []
    for normal, action, intensity in random_check_points(n_points, seed,
                                                         spec.cone_half_angle_rad):
        predicted = table.kick(normal, action, intensity).normal
        simulated = direct_kick(spec, params, normal, action, intensity).normal
        errors.append(angle_between(predicted, simulated))
        if progress is not None:
            progress(len(errors), n_points)
    return max(errors), errors


@dataclasses.dataclass(frozen=True)
class OffGridDirection:
    """The full kick (u_K = 1) from one off-grid check state: how far the continuous model's
    kick strays from its action's nominal direction, and how far the table's from it (rad)."""

    x_sn: float
    y_sn: float
    action: int
    simulated_error_rad: float
    table_error_rad: float
    simulated_width_rad: float

    @property
    def between_rad(self) -> float:
        return abs(math.remainder(self.simulated_error_rad - self.table_error_rad,
                                  2.0 * math.pi))


def grid_check_states(step: float, spec: TableSpec) -> list[tuple[NDArray[np.float64], int]]:
    """(normal, action 0) at the states of a square ``step`` grid inside the cone on the half
    the table simulates (:meth:`TableSpec.side` >= 0): every other state and action is an image
    of one of these under the device's symmetry."""
    return [(normal_from_xy(x, y), 0) for x, y in offset_grid(step, spec.cone_half_angle_rad)
            if spec.side(x, y) >= 0.0]


def check_directions(table: LookupTable, n_points: int = 8, seed: int = 0,
                     progress: Callable[[int, int], object] | None = None,
                     grid_step: float | None = None) -> list[OffGridDirection]:
    """The full kick's direction at the states and actions of :func:`check_table` (the same
    seed gives the same states), or with ``grid_step`` at those of :func:`grid_check_states`,
    each with the offset the table's spec interpolates there: between the nodes, where the
    offsets' nodes do not reach (docs/motion_primitives.md)."""
    spec = spec_from_dict(table.meta['spec'])
    params = table.parameters()
    states = (grid_check_states(grid_step, spec) if grid_step is not None else
              [(normal, action) for normal, action, _ in
               random_check_points(n_points, seed, spec.cone_half_angle_rad)])
    out: list[OffGridDirection] = []
    for normal, action in states:
        nominal = table.directions_rad[action]
        predicted = table.kick(normal, action, 1.0).normal[:2] - normal[:2]
        simulated = direct_kick(spec, params, normal, action, 1.0).normal[:2] - normal[:2]
        out.append(OffGridDirection(
            float(normal[0]), float(normal[1]), action,
            math.remainder(math.atan2(simulated[1], simulated[0]) - nominal, 2.0 * math.pi),
            math.remainder(math.atan2(predicted[1], predicted[0]) - nominal, 2.0 * math.pi),
            float(np.hypot(*simulated))))
        if progress is not None:
            progress(len(out), len(states))
    return out
