"""The rate limit of the simulator's rejection reports."""

from sphere_sim.twin.report_limit import ReportLimit


class FakeClock:
    def __init__(self):
        self.now_s = 0.0

    def __call__(self):
        return self.now_s


def test_at_most_n_reports_a_window_and_the_next_report_says_how_many_were_left_out():
    clock = FakeClock()
    limit = ReportLimit(per_window=3, window_s=1.0, clock=clock)
    assert [limit.allow() for _ in range(10)] == [True] * 3 + [False] * 7
    clock.now_s = 0.99
    assert not limit.allow()
    clock.now_s = 1.0
    assert limit.allow()
    assert limit.take_suppressed() == 8 and limit.take_suppressed() == 0
