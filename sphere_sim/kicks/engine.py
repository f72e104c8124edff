"""Where many independent kicks run: this process, a local process pool, or a Dask cluster.

An engine is started once and handed to every workload that runs kicks (table builds, kick
optimisations, the calibration's many optimisations): its workers then keep, between tasks and
between workloads, the models and rest states they have built (each workload caches them per
process), where a pool started per call would build them again in every fresh process.

An engine is also a map-like callable, ``engine(func, iterable) -> list`` in order, which is
what scipy's ``differential_evolution(workers=...)`` takes.
"""

import concurrent.futures
import contextlib
import os
import time

# Linux's clock ticks per second, in which /proc reports a process's CPU time.
CLOCK_TICKS_PER_S = os.sysconf('SC_CLK_TCK') if hasattr(os, 'sysconf') else 100


class SerialEngine:
    """Everything in this process."""

    workers = 1

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        pass

    def __call__(self, func, iterable):
        return [func(item) for item in iterable]

    def worker_cpu_s(self):
        """CPU seconds its workers have used so far (this process's, here)."""
        return time.process_time()


class PoolEngine(SerialEngine):
    """A local pool of ``workers`` processes, started on first use and kept until closed."""

    def __init__(self, workers):
        self.workers = int(workers)
        self._pool = None

    @property
    def pool(self):
        if self._pool is None:
            self._pool = concurrent.futures.ProcessPoolExecutor(max_workers=self.workers)
        return self._pool

    def start(self, warm=None):
        """Start every worker now (and run ``warm`` in each), not on the first task."""
        futures = [self.pool.submit(_warm, warm) for _ in range(self.workers)]
        for future in futures:
            future.result()
        return self

    def close(self):
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __call__(self, func, iterable):
        # One item per task: a generation of differential evolution is a dozen or so kicks of
        # unequal cost, and pickling the objective again (a few kB) costs far less than a
        # worker left idle at the generation's end while the other finishes a larger chunk.
        return list(self.pool.map(func, iterable))

    def worker_cpu_s(self):
        return sum(_process_cpu_s(pid) for pid in list(self.pool._processes))


class DaskEngine(SerialEngine):
    """The workers of a Dask scheduler (``tcp://host:port``) or of an existing Client."""

    def __init__(self, scheduler):
        from distributed import Client

        self._own = not isinstance(scheduler, Client)
        self.client = Client(scheduler) if self._own else scheduler
        self.workers = max(1, sum(w.get('nthreads', 1) for w in
                                  self.client.scheduler_info()['workers'].values()))

    def start(self, warm=None):
        if warm is not None:
            self.client.run(warm)
        return self

    def close(self):
        if self._own:
            self.client.close()

    def __call__(self, func, iterable):
        return self.client.gather(self.client.map(func, list(iterable), pure=False))

    def worker_cpu_s(self):
        return sum(self.client.run(time.process_time).values())


def _process_cpu_s(pid):
    """User and system CPU seconds of a live process (0 where /proc cannot tell)."""
    try:
        with open(f'/proc/{pid}/stat') as stream:
            fields = stream.read().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_PER_S  # utime, stime


def _warm(warm):
    if warm is not None:
        warm()


def engine_of(workers=1, scheduler=None):
    """A new engine: Dask's at ``scheduler``, else ``workers`` local processes."""
    if scheduler is not None:
        return DaskEngine(scheduler)
    return PoolEngine(workers) if workers > 1 else SerialEngine()


@contextlib.contextmanager
def engine_for(workers=1, scheduler=None):
    """The engine ``workers`` is, left open for its owner; or a new one, closed on exit."""
    if is_engine(workers):
        yield workers
        return
    with engine_of(workers, scheduler) as engine:
        yield engine


def is_engine(obj):
    return isinstance(obj, SerialEngine)
