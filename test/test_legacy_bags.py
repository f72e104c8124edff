"""Bags recorded before /beams/programme_status moved to action_msgs (their reports are
actionlib_msgs/GoalStatusArray) are still read, without the actionlib_msgs package, which
leaves ROS after Jazzy."""

import sys
from pathlib import Path

import pytest

from msg_defs.conversions import (
    LEGACY_PROGRAMME_STATUS_TYPE,
    legacy_programme_status_from_cdr,
    programme_events_from_msg,
)
from msg_defs.programme_events import ProgrammeState
from msg_defs.topics import PROGRAMME_STATUS
from sphere_twin.bag.reader import deserialize, read_messages

EXAMPLE = Path(__file__).resolve().parents[1] / 'bags' / 'example'
EXAMPLE_KICKS = 497  # bags/example_report.txt


@pytest.fixture
def no_actionlib(monkeypatch):
    """Make ``import actionlib_msgs`` fail, as it will after Jazzy."""
    for name in ('actionlib_msgs', 'actionlib_msgs.msg'):
        monkeypatch.setitem(sys.modules, name, None)


def _example_reports():
    raws = list(read_messages(EXAMPLE, [PROGRAMME_STATUS.name]))
    assert {raw.type_name for raw in raws} == {LEGACY_PROGRAMME_STATUS_TYPE}
    return raws


def test_the_example_bag_yields_its_programme_events_without_actionlib(no_actionlib):
    events = [e for raw in _example_reports()
              for e in programme_events_from_msg(legacy_programme_status_from_cdr(raw.data))]
    started = {e.number: e for e in events if e.state is ProgrammeState.STARTED}
    ended = {e.number: e for e in events if e.state is ProgrammeState.ENDED}
    assert len(started) == EXAMPLE_KICKS
    assert ended.keys() <= started.keys()
    # Each ends after it started, and names the same programme (the stamp it was sent with).
    assert all(started[n].time_s <= e.time_s and started[n].asked_s == e.asked_s
               for n, e in ended.items())
    assert all(e.text for e in events)  # an old bag keeps its lines for people


def test_the_legacy_decoder_agrees_with_the_recorded_package():
    pytest.importorskip('actionlib_msgs.msg')
    for raw in _example_reports():
        assert (programme_events_from_msg(legacy_programme_status_from_cdr(raw.data))
                == programme_events_from_msg(deserialize(raw)))


def test_the_example_bag_starts_its_kicks_where_reported_without_actionlib(no_actionlib):
    from sphere_twin.run_analysis import load_run

    run = load_run(EXAMPLE)
    starts = sorted(e.time_s for raw in _example_reports()
                    for e in programme_events_from_msg(legacy_programme_status_from_cdr(raw.data))
                    if e.state is ProgrammeState.STARTED)
    assert [start for start, _, _ in run.kicks] == starts


def test_a_player_republishes_old_reports_on_todays_type_with_the_same_events(no_actionlib):
    """What a player sends is what today's controller and tools subscribe to; only the lines
    for people stay behind (the topic carries none)."""
    from sphere_twin.bag.format import type_name_of
    from sphere_twin.bag.reader import in_current_contract

    for raw in _example_reports()[:50]:
        current = in_current_contract(raw)
        assert current.type_name == type_name_of(PROGRAMME_STATUS.msg_type)
        assert (current.topic, current.log_time_ns) == (raw.topic, raw.log_time_ns)
        old = programme_events_from_msg(legacy_programme_status_from_cdr(raw.data))
        assert programme_events_from_msg(deserialize(current)) == [
            e._replace(text='') for e in old]
        assert in_current_contract(current) is current
