"""How fast a node's simulated time ran against the wall clock, as the node saw it."""

import time
from collections.abc import Callable


class PaceMeter:
    """Real-time factor between the first and the latest simulated instant a node handled.

    Each node notes the simulated times it acts on (a sample's stamp, a publication on the
    node's clock); the factor is their span over the wall time between the first and the
    latest note.
    """

    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self._clock = clock
        self._first: tuple[float, float] | None = None  # (simulated s, wall s)
        self._latest: tuple[float, float] | None = None

    def note(self, simulated_s: float) -> None:
        entry = (float(simulated_s), self._clock())
        if self._first is None:
            self._first = entry
        self._latest = entry

    def real_time_factor(self) -> float:
        """Simulated over wall seconds; NaN before two notes a wall instant apart."""
        first, latest = self._first, self._latest
        if first is None or latest is None or latest[1] <= first[1]:
            return float('nan')
        return (latest[0] - first[0]) / (latest[1] - first[1])

    def simulated_span_s(self) -> float:
        first, latest = self._first, self._latest
        return 0.0 if first is None or latest is None else latest[0] - first[0]
