"""Rate limit for the simulator's reports of rejected commands.

A burst of bad commands (a runaway publisher) must not turn into a burst of log lines and
``/diagnostics`` messages: the first few in each wall-clock window are reported one by one,
the rest only counted, and the next report says how many were left out. Every one is
counted in the periodic status all the same.
"""

import time
from collections.abc import Callable

REPORTS_PER_WINDOW = 10
WINDOW_S = 1.0


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
