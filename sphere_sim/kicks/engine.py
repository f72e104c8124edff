"""Where many independent kicks run: this process, a local process pool, or a Dask cluster.

An engine is started once and handed to every workload that runs kicks (table builds, kick
optimisations, the calibration's many optimisations): its workers then keep, between tasks and
between workloads, the models and rest states they have built (each workload caches them per
process), where a pool started per call would build them again in every fresh process.

An engine is also a map-like callable, ``engine(func, iterable) -> list`` in order, which is
what scipy's ``differential_evolution(workers=...)`` takes.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import os
import time
from collections.abc import Callable, Iterable, Iterator
from typing import TYPE_CHECKING, Self, TypeVar, cast

if TYPE_CHECKING:
    from distributed import Client
    from typing_extensions import TypeIs

_Item = TypeVar('_Item')
_Result = TypeVar('_Result')

# Linux's clock ticks per second, in which /proc reports a process's CPU time.
CLOCK_TICKS_PER_S = os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 100


class SerialEngine:
    """Everything in this process."""

    workers = 1

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        pass

    def __call__(self, func: Callable[[_Item], _Result],
                 iterable: Iterable[_Item]) -> list[_Result]:
        return [func(item) for item in iterable]

    def worker_cpu_s(self) -> float:
        """CPU seconds its workers have used so far (this process's, here)."""
        return time.process_time()


class PoolEngine(SerialEngine):
    """A local pool of ``workers`` processes, started on first use and kept until closed."""

    def __init__(self, workers: int) -> None:
        self.workers = int(workers)
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None

    @property
    def pool(self) -> concurrent.futures.ProcessPoolExecutor:
        if self._pool is None:
            self._pool = concurrent.futures.ProcessPoolExecutor(max_workers=self.workers)
        return self._pool

    def start(self, warm: Callable[[], object] | None = None) -> Self:
        """Start every worker now (and run ``warm`` in each), not on the first task."""
        futures = [self.pool.submit(_warm, warm) for _ in range(self.workers)]
        for future in futures:
            future.result()
        return self

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __call__(self, func: Callable[[_Item], _Result],
                 iterable: Iterable[_Item]) -> list[_Result]:
        # One item per task: a generation of differential evolution is a dozen or so kicks of
        # unequal cost, and pickling the objective again (a few kB) costs far less than a
        # worker left idle at the generation's end while the other finishes a larger chunk.
        return list(self.pool.map(func, iterable))

    def worker_cpu_s(self) -> float:
        return sum(_process_cpu_s(pid) for pid in list(self.pool._processes))


class DaskEngine(SerialEngine):
    """The workers of a Dask scheduler (``tcp://host:port``) or of an existing Client."""

    def __init__(self, scheduler: str | Client) -> None:
        from distributed import Client

        self._own = not isinstance(scheduler, Client)
        self.client = Client(scheduler) if self._own else cast(Client, scheduler)
        self.workers = max(1, sum(w.get('nthreads', 1) for w in
                                  self.client.scheduler_info()['workers'].values()))

    def start(self, warm: Callable[[], object] | None = None) -> Self:
        if warm is not None:
            self.client.run(warm)
        return self

    def close(self) -> None:
        if self._own:
            self.client.close()

    def __call__(self, func: Callable[[_Item], _Result],
                 iterable: Iterable[_Item]) -> list[_Result]:
        return self.client.gather(self.client.map(func, list(iterable), pure=False))

    def worker_cpu_s(self) -> float:
        return sum(self.client.run(time.process_time).values())


def _process_cpu_s(pid: int) -> float:
    """User and system CPU seconds of a live process (0 where /proc cannot tell)."""
    try:
        with open(f'/proc/{pid}/stat') as stream:
            fields = stream.read().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_PER_S  # utime, stime


def _warm(warm: Callable[[], object] | None) -> None:
    if warm is not None:
        warm()


def engine_of(workers: int = 1, scheduler: str | Client | None = None) -> SerialEngine:
    """A new engine: Dask's at ``scheduler``, else ``workers`` local processes."""
    if scheduler is not None:
        return DaskEngine(scheduler)
    return PoolEngine(workers) if workers > 1 else SerialEngine()


@contextlib.contextmanager
def engine_for(workers: int | SerialEngine = 1,
               scheduler: str | Client | None = None) -> Iterator[SerialEngine]:
    """The engine ``workers`` is, left open for its owner; or a new one, closed on exit."""
    if is_engine(workers):
        yield workers
        return
    with engine_of(workers, scheduler) as engine:
        yield engine


def is_engine(obj: object) -> TypeIs[SerialEngine]:
    return isinstance(obj, SerialEngine)
