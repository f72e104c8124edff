"""A thread that runs a node's publications in the order they were handed over.

The simulator integrates on the executor's thread (its compiled kernel releases the GIL) and
hands each sample's messages here, so that building and publishing sample k overlaps the
integration of sample k+1: one core integrates while the other talks. Order is kept, because a
controller needs a programme's report before the sample it decides on. The queue is bounded: a
publisher that falls behind makes the integrating thread wait (and the wait is counted) instead
of letting samples pile up in memory and in latency.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

# Samples handed over but not yet published, beyond which the integrating thread waits. Two
# keep the overlap (one being published, one queued); more would only add latency.
DEFAULT_BACKLOG = 2
# How long close() waits for the thread to publish what is queued (s).
CLOSE_TIMEOUT_S = 2.0
# flush() looks again this often (s): a sample's messages take about a millisecond.
FLUSH_POLL_S = 5e-4

_STOP = object()


class Outbox:
    """Runs submitted calls one after another on a thread of its own.

    Parameters
    ----------
    backlog : int
        Most calls waiting at once; ``submit`` blocks beyond it.
    on_error : callable, optional
        ``on_error(exception)`` for a call that raised; by default the error is kept in
        ``errors`` (at most the first ten) and the thread goes on.
    name : str
        The thread's name.
    """

    def __init__(self, backlog: int = DEFAULT_BACKLOG,
                 on_error: Callable[[BaseException], None] | None = None,
                 name: str = 'outbox') -> None:
        if backlog < 1:
            raise ValueError(f'backlog must be >= 1, got {backlog}')
        self._queue: queue.Queue = queue.Queue(maxsize=backlog)
        self._on_error = on_error
        self.errors: list[BaseException] = []
        # Written by one thread each, read by anyone (a float read is atomic in CPython).
        self.busy_s = 0.0  # the outbox's thread running calls
        self.waiting_s = 0.0  # submitters blocked on a full queue
        self.calls = 0
        self._closed = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, call: Callable[..., object], *args: object) -> None:
        """Queue ``call(*args)``; waits while ``backlog`` calls are already queued.

        Raises
        ------
        RuntimeError
            After :meth:`close`.
        """
        if self._closed:
            raise RuntimeError('the outbox is closed')
        item = (call, args)
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            started = time.perf_counter()
            self._queue.put(item)
            self.waiting_s += time.perf_counter() - started

    def flush(self, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
        """Wait until every call submitted so far has run; False if that took longer than
        ``timeout_s``."""
        deadline = time.perf_counter() + timeout_s
        while self._queue.unfinished_tasks:
            if time.perf_counter() > deadline:
                return False
            time.sleep(FLUSH_POLL_S)
        return True

    def close(self, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
        """Run what is queued, then stop the thread; True if it stopped within ``timeout_s``.
        Idempotent."""
        if not self._closed:
            self._closed = True
            try:
                self._queue.put(_STOP, timeout=timeout_s)
            except queue.Full:
                return False
        self._thread.join(timeout_s)
        return not self._thread.is_alive()

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            try:
                if item is _STOP:
                    return
                call, args = item
                started = time.perf_counter()
                try:
                    call(*args)
                except Exception as error:  # reported; the thread goes on
                    if self._on_error is not None:
                        self._on_error(error)
                    elif len(self.errors) < 10:
                        self.errors.append(error)
                self.busy_s += time.perf_counter() - started
                self.calls += 1
            finally:
                self._queue.task_done()
