"""The planner's process: stopping it ends the child and its threads while the child is busy
with a large cell and states keep coming (the sender blocked on a full pipe to it, when it
gets there); plans are handed over newest first, prepared off the caller's thread; the child
runs below its parent's priority."""

from __future__ import annotations

import threading
import time

import numpy as np

from lvws_ros.core.datasets import subteam_heavy_instance
from lvws_ros.core.executor import State
from lvws_ros.planning.worker import PlannerProcess


def test_stop_ends_a_busy_child_and_its_threads_while_states_keep_coming() -> None:
    inst = subteam_heavy_instance(np.random.default_rng(0), 200, 1000, "full-pipes")  # plans and states of tens of KB
    proc = PlannerProcess(seed=0, workers=1, learned=False)
    proc.start()
    child = proc.process
    try:
        assert proc.wait_ready(60.0)
        state = State.initial(inst)
        deadline = time.monotonic() + 6.0
        while time.monotonic() < deadline:  # states while the child plans (the sender stuck, if it gets stuck)
            proc.send(state)
            time.sleep(0.05)
            if proc._pending is not None and time.monotonic() > deadline - 4.0:
                break
        stopper = threading.Thread(target=proc.stop, daemon=True)
        stopper.start()
        stopper.join(30.0)
        assert not stopper.is_alive(), "stop() hung"
        assert child is not None and not child.is_alive()
        assert proc.process is None and proc.inbox is None
    finally:
        if child is not None and child.is_alive():
            child.kill()


def test_latest_hands_over_the_newest_plan_of_those_that_arrived() -> None:
    # The child sends a plan for each state; the parent, reading late, gets only the plan of
    # the newest state (the older ones are dropped unread), and a valid one.
    from lvws_ros.core.schedule import check_schedule

    inst = subteam_heavy_instance(np.random.default_rng(1), 10, 30, "newest")
    proc = PlannerProcess(seed=0, workers=1, learned=False)
    proc.start()
    try:
        assert proc.wait_ready(60.0)
        state = State.initial(inst)
        proc.send(state)
        first = proc.latest(30.0)
        assert first is not None and first.seq == 1
        for _ in range(3):  # three more states, each answered with a plan, before the parent reads
            proc.send(state)
            time.sleep(1.0)
        update = proc.latest(30.0)
        deadline = time.monotonic() + 30.0
        while update is not None and update.seq < 4 and time.monotonic() < deadline:  # a slow child, still at it
            update = proc.latest(5.0) or update
        assert update is not None and update.seq == proc.sent == 4
        assert check_schedule(inst, update.schedule) == []
    finally:
        proc.stop()


class _FilledWhilePickled:
    """A cell whose lazy cache the decision thread fills while the sender pickles it: the
    first pickling attempts fail as a dict that changed size would make them."""

    def __init__(self, failures: int) -> None:
        self.failures = failures

    def __reduce__(self) -> tuple[object, tuple[int]]:
        if self.failures > 0:
            self.failures -= 1
            raise RuntimeError("dictionary changed size during iteration")
        return (_FilledWhilePickled, (0,))


def test_a_cell_pickled_while_its_cache_fills_is_sent_again_not_lost() -> None:
    from multiprocessing import Pipe

    from lvws_ros.planning.worker import _send_pickled

    reader, writer = Pipe(duplex=False)
    _send_pickled(writer, ("cell", _FilledWhilePickled(3)))
    assert reader.poll(1.0)
    kind, cell = reader.recv()
    assert kind == "cell" and isinstance(cell, _FilledWhilePickled)


def test_the_planner_runs_below_its_parent_s_priority_as_asked() -> None:
    # Decisions come first: the child lowers its own CPU priority (os.nice) by what it is
    # given, PLANNER_NICENESS unless told otherwise; 0 keeps the parent's.
    import os

    from lvws_ros.planning import PLANNER_NICENESS

    mine = os.getpriority(os.PRIO_PROCESS, 0)
    for asked, expected in ((None, min(19, mine + PLANNER_NICENESS)), (0, mine), (3, min(19, mine + 3))):
        proc = PlannerProcess(seed=0, workers=1, learned=False) if asked is None else \
            PlannerProcess(niceness=asked, seed=0, workers=1, learned=False)
        proc.start()
        try:
            assert proc.wait_ready(60.0) and proc.process is not None and proc.process.pid is not None
            threads = os.listdir(f"/proc/{proc.process.pid}/task")  # every thread (numpy's pool included)
            assert len(threads) > 1 and {os.getpriority(os.PRIO_PROCESS, int(t)) for t in threads} == {expected}
        finally:
            proc.stop()


def test_a_plan_arrives_unpickled_and_prepared_off_the_caller_s_thread() -> None:
    # What a decision would otherwise do when a plan arrives (unpickle it, map it onto the
    # cell) is done by the receiver thread: latest() hands over the prepared plan.
    inst = subteam_heavy_instance(np.random.default_rng(2), 10, 30, "prepared")
    threads: list[str] = []

    def prepare(update: object) -> str:
        threads.append(threading.current_thread().name)
        return "prepared"
    proc = PlannerProcess(prepare=prepare, seed=0, workers=1, learned=False)
    proc.start()
    try:
        assert proc.wait_ready(60.0)
        proc.send(State.initial(inst))
        update = proc.latest(30.0)
        assert update is not None and update.seq == 1 and update.prepared == "prepared"
        assert threads and all(name == "lvws-planner-receiver" for name in threads)
    finally:
        proc.stop()
    assert proc._receiver is None


def test_a_plan_that_cannot_be_prepared_is_handed_over_as_it_came() -> None:
    inst = subteam_heavy_instance(np.random.default_rng(2), 10, 30, "unprepared")

    def prepare(update: object) -> str:
        raise RuntimeError("cannot map it")
    proc = PlannerProcess(prepare=prepare, seed=0, workers=1, learned=False)
    proc.start()
    try:
        assert proc.wait_ready(60.0)
        proc.send(State.initial(inst))
        update = proc.latest(30.0)
        assert update is not None and update.prepared is None and update.schedule.assignments
        assert proc.alive() and not proc.failure  # the receiver reads on
    finally:
        proc.stop()
