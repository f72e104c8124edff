"""The publishing thread of a node (``sphere_twin.node_runtime.outbox``): order, overlap, a
bounded queue, errors that do not stop it, and a clean close. No ROS."""

import threading

import pytest

from sphere_twin.node_runtime.outbox import Outbox

# Generous: a call that should run at once runs within this (s); only a hang reaches it.
HANG_S = 10.0


def test_calls_run_in_order_on_a_thread_of_their_own_while_the_submitter_goes_on():
    box = Outbox(backlog=4)
    ran, threads = [], set()
    release = threading.Event()

    def first():
        threads.add(threading.get_ident())
        # Waits for the submitter: had submit() run the call itself, this would never end.
        assert release.wait(HANG_S)
        ran.append(0)

    box.submit(first)
    for k in range(1, 4):
        box.submit(lambda k=k: ran.append(k))
    release.set()
    assert box.flush(HANG_S)
    assert ran == [0, 1, 2, 3]
    assert threads and threading.get_ident() not in threads
    assert box.calls == 4 and box.errors == []
    assert box.close()


def test_a_full_queue_makes_the_submitter_wait_and_counts_the_wait():
    box = Outbox(backlog=1)
    started, release = threading.Event(), threading.Event()

    def blocking():
        started.set()
        release.wait(HANG_S)

    box.submit(blocking)
    assert started.wait(HANG_S)  # taken off the queue: running
    box.submit(lambda: None)  # fills the queue
    assert box.waiting_s == 0.0

    def late_release():
        release.set()

    timer = threading.Timer(0.05, late_release)
    timer.start()
    box.submit(lambda: None)  # waits until the first call ends
    timer.join()
    assert release.is_set() and box.waiting_s > 0.0
    assert box.flush(HANG_S) and box.calls == 3
    assert box.busy_s > 0.0
    assert box.close()


def test_a_failing_call_is_reported_and_the_next_ones_still_run():
    seen = []
    box = Outbox(on_error=seen.append)
    box.submit(lambda: 1 / 0)
    box.submit(lambda: seen.append('after'))
    assert box.flush(HANG_S)
    assert isinstance(seen[0], ZeroDivisionError) and seen[1] == 'after'
    assert box.close()
    kept = Outbox()
    kept.submit(lambda: [][1])
    assert kept.flush(HANG_S) and isinstance(kept.errors[0], IndexError)
    assert kept.close()


def test_close_runs_what_is_queued_then_stops_and_refuses_more():
    box = Outbox(backlog=8)
    ran = []
    release = threading.Event()
    box.submit(release.wait, HANG_S)
    for k in range(5):
        box.submit(ran.append, k)
    assert not box.flush(0.01)  # still blocked: flush says so instead of hanging
    release.set()
    assert box.close(HANG_S)
    assert ran == [0, 1, 2, 3, 4]
    assert box.close()  # again: nothing left to do
    with pytest.raises(RuntimeError, match='closed'):
        box.submit(ran.append, 5)


def test_the_compiled_integrator_releases_the_gil():
    """What lets the publishing thread run while the simulation thread integrates."""
    from sphere_sim.integrate import radau_compiled

    assert radau_compiled.integrate.targetoptions.get('nogil') is True
