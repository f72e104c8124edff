"""Rate limits for the simulator's reports: of rejected commands, and of late programmes.

A burst of bad commands (a runaway publisher) must not turn into a burst of log lines and
``/diagnostics`` messages: the first few in each wall-clock window are reported one by one,
the rest only counted, and the next report says how many were left out. Every one is
counted in the periodic status all the same.

A late programme is no error of its sender but the pace slipping, and at some paces it is
most programmes: the first is said with its times, the rest are counted and summarised at
most once per :data:`SUMMARY_PERIOD_S` of wall time (:class:`CountedWarning`). The status
and the final line count every one.
"""

import dataclasses
import time
from collections.abc import Callable

REPORTS_PER_WINDOW = 10
WINDOW_S = 1.0
# A warning that may come with every command is summarised at most this often (wall s).
SUMMARY_PERIOD_S = 10.0


class ReportLimit:
    """Decides which events to report: at most ``per_window`` per ``window_s`` of wall time."""

    def __init__(self, per_window: int = REPORTS_PER_WINDOW, window_s: float = WINDOW_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.per_window = per_window
        self.window_s = window_s
        self._clock = clock
        self._window_start: float | None = None
        self._reported = 0
        self.suppressed = 0  # left out since the last report

    def allow(self) -> bool:
        """True if this event is to be reported; else it is counted as left out."""
        now = self._clock()
        if self._window_start is None or now - self._window_start >= self.window_s:
            self._window_start, self._reported = now, 0
        if self._reported < self.per_window:
            self._reported += 1
            return True
        self.suppressed += 1
        return False

    def take_suppressed(self) -> int:
        """How many were left out since the last report (and reset that count)."""
        count, self.suppressed = self.suppressed, 0
        return count


@dataclasses.dataclass(frozen=True)
class Summary:
    """What a :class:`CountedWarning` has to say: ``count`` more since its last line,
    ``since_s`` of wall time ago, ``total`` in all."""

    count: int
    since_s: float
    total: int


class CountedWarning:
    """A warning that may come with every command (a late programme): the first is said at
    once, the others counted and summarised at most once per ``period_s`` of wall time, each
    summary with the count since the line before.

    Call :meth:`note` for each occurrence (it says whether to log this one in full) and
    :meth:`due` from a periodic timer (a summary, or None).
    """

    def __init__(self, period_s: float = SUMMARY_PERIOD_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.period_s = period_s
        self._clock = clock
        self._said_at: float | None = None  # wall time of the last line
        self.unsaid = 0  # counted since the last line
        self.total = 0  # counted in all

    def note(self) -> bool:
        """Count one; True if it is the first, to be said in full now."""
        self.total += 1
        if self._said_at is None:
            self._said_at = self._clock()
            return True
        self.unsaid += 1
        return False

    def due(self) -> Summary | None:
        """The summary of those counted since the last line, once ``period_s`` has passed
        since it (it is then the last line); None if there is none or it is not yet time."""
        now = self._clock()
        if not self.unsaid or self._said_at is None or now - self._said_at < self.period_s:
            return None
        summary = Summary(self.unsaid, now - self._said_at, self.total)
        self._said_at, self.unsaid = now, 0
        return summary
