"""The rate limits of the simulator's reports: rejections, and late programmes."""

from sphere_sim.twin.report_limit import CountedWarning, ReportLimit, Summary


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


def test_a_counted_warning_says_the_first_then_one_summary_a_period_with_the_count_since():
    clock = FakeClock()
    late = CountedWarning(period_s=10.0, clock=clock)
    assert late.due() is None  # nothing counted yet
    assert late.note()  # the first: said in full
    assert [late.note() for _ in range(46)] == [False] * 46
    clock.now_s = 9.99
    assert late.due() is None  # not yet: at most one line a period
    clock.now_s = 10.0
    assert late.due() == Summary(count=46, since_s=10.0, total=47)
    assert late.due() is None  # said: nothing more to say
    clock.now_s = 15.0
    late.note()
    late.note()
    clock.now_s = 19.0
    assert late.due() is None  # 9 s after the last line
    clock.now_s = 25.0
    assert late.due() == Summary(count=2, since_s=15.0, total=49)
    clock.now_s = 100.0
    assert late.due() is None and late.total == 49  # a quiet spell says nothing
