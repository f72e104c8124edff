"""How fast a node's simulated time ran against the wall clock, as the node saw it."""

import time


class PaceMeter:
    """Real-time factor between the first and the latest simulated instant a node handled.

    Each node notes the simulated times it acts on (a sample's stamp, a publication on the
    node's clock); the factor is their span over the wall time between the first and the
    latest note.
    """

    def __init__(self, clock=time.monotonic):
        self._clock = clock
        self._first = None  # (simulated s, wall s)
        self._latest = None

    def note(self, simulated_s):
        entry = (float(simulated_s), self._clock())
        if self._first is None:
            self._first = entry
        self._latest = entry

    def real_time_factor(self):
        """Simulated over wall seconds; NaN before two notes a wall instant apart."""
        if self._first is None or self._latest[1] <= self._first[1]:
            return float('nan')
        return (self._latest[0] - self._first[0]) / (self._latest[1] - self._first[1])

    def simulated_span_s(self):
        return 0.0 if self._first is None else self._latest[0] - self._first[0]
