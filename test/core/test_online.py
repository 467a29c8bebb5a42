"""OnlineScheduler (the scheduler node's core) on snapshots: when it decides, and that it
never assigns a busy robot or an unready task whatever order messages come in."""

from __future__ import annotations

import dataclasses
import time

import pytest

from conftest import CASE_STUDY
from lvws_ros.core.executor import Budgeted, decision_deadline
from lvws_ros.core.online import OnlineScheduler, RobotInfo, TaskInfo, sent_at
from lvws_ros.errors import InstanceError, PolicyError
from lvws_ros.registry import make_policy
from lvws_ros.sim.config import load_cell_config
from lvws_ros.sim.world import CellSim


def fresh() -> tuple[CellSim, OnlineScheduler]:
    sim = CellSim(load_cell_config(CASE_STUDY))
    online = OnlineScheduler(make_policy("grp"))
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    return sim, online


def test_first_decision_and_no_repeat_on_duplicates():
    sim, online = fresh()
    d = online.decide()
    assert d is not None and d.step == 0
    assert {t for t, _ in d.assignments} == {"t01", "t03", "t07"}
    assert set(d.waiting) == {"jackal_1", "jackal_2", "husky_1"}
    # the same snapshots again (duplicates), before the world acknowledged: nothing new
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    assert online.decide() is None


def test_decides_again_when_a_robot_becomes_free():
    sim, online = fresh()
    d = online.decide()
    assert d is not None
    for t, robots in d.assignments:
        sim.assign(t, robots)
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    assert online.decide() is None and not online.pending  # acknowledged, nothing new
    while not sim.step():
        pass
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    d2 = online.decide()
    assert d2 is not None and d2.step == 1 and ("t02", ("panda_1",)) in d2.assignments


def test_out_of_order_snapshots_are_dropped():
    sim, online = fresh()
    old_team, old_graph = sim.team_snapshot(), sim.graph_snapshot()
    sim.assign("t01", ["panda_1"])
    for _ in range(10):
        sim.step()
    assert online.offer_team(sim.team_snapshot()) and online.offer_graph(sim.graph_snapshot())
    assert not online.offer_team(old_team) and not online.offer_graph(old_graph)
    assert online.dropped == 2
    d = online.decide()
    assert d is not None and all("panda_1" not in r for _, r in d.assignments)


def test_a_stale_team_message_cannot_free_a_busy_robot():
    sim, online = fresh()
    stale_team = sim.team_snapshot()  # says panda_1 is available
    sim.assign("t01", ["panda_1"])
    graph = sim.graph_snapshot()  # says t01 runs on panda_1
    online.offer_team(stale_team)
    online.offer_graph(graph)
    d = online.decide()
    assert d is not None
    assert all("panda_1" not in r for _, r in d.assignments)
    assert "panda_1" not in d.waiting


def test_unacknowledged_assignments_are_offered_again_after_the_timeout():
    sim, online = fresh()
    first = online.decide()
    assert first is not None
    later = sim.team_snapshot()
    # the world never executed it: 10 s later it still shows every task ready
    online.offer_team(dataclasses.replace(later, stamp=10.0))
    online.offer_graph(dataclasses.replace(sim.graph_snapshot(), stamp=10.0))
    again = online.decide()
    assert again is not None
    assert {t for t, _ in again.assignments} == {t for t, _ in first.assignments}


class _Slow:
    """GRP that takes ``seconds`` to decide (a first plan awaited)."""

    def __init__(self, seconds: float) -> None:
        self.grp, self.seconds, self.name = make_policy("grp"), seconds, "slow"

    def reset(self, instance):
        self.grp.reset(instance)

    def decide(self, state):
        time.sleep(self.seconds)
        return self.grp.decide(state)


def test_the_ack_timeout_counts_from_when_a_slow_decision_went_out_not_from_its_snapshots():
    sim = CellSim(load_cell_config(CASE_STUDY))
    online = OnlineScheduler(_Slow(0.3), ack_timeout=0.2)
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    first = online.decide()
    assert first is not None and first.latency >= 0.3
    # 0.35 s on, before the world took it (every task still READY): sent 0.05 s ago, still pending
    online.offer_team(dataclasses.replace(sim.team_snapshot(), stamp=0.35))
    online.offer_graph(dataclasses.replace(sim.graph_snapshot(), stamp=0.35))
    assert online.decide() is None and set(online.pending) == {t for t, _ in first.assignments}
    # 0.6 s on, still not taken: the timeout is over, they are offered again
    online.offer_team(dataclasses.replace(sim.team_snapshot(), stamp=0.6))
    online.offer_graph(dataclasses.replace(sim.graph_snapshot(), stamp=0.6))
    again = online.decide()
    assert again is not None and {t for t, _ in again.assignments} == {t for t, _ in first.assignments}


def test_a_decision_stamped_on_a_faster_world_clock_is_pending_from_its_stamp_not_from_another_clocks():
    """A node that follows a world's clock running ten times faster than the wall's: a
    decision of 1 wall second (its latency) went out 10 s of the world's clock after its
    snapshots (its stamp). States stamped before that (queued while it was decided) never
    time it out; a stamp on another clock altogether (a day off) does not count."""
    sim, online = fresh()
    first = online.decide()
    assert first is not None
    tasks = {t for t, _ in first.assignments}
    online.published(dataclasses.replace(first, latency=1.0, published=10.0))
    assert sent_at(dataclasses.replace(first, latency=1.0, published=10.0), 0.0) == 10.0
    assert sent_at(dataclasses.replace(first, latency=1.0, published=2e9), 0.0) == 1.0  # on a clock of its own
    online.offer_team(dataclasses.replace(sim.team_snapshot(), stamp=9.0))  # queued before it went out
    online.offer_graph(dataclasses.replace(sim.graph_snapshot(), stamp=9.0))
    assert online.decide() is None and set(online.pending) == tasks
    online.offer_team(dataclasses.replace(sim.team_snapshot(), stamp=16.0))  # 6 s after, never taken
    online.offer_graph(dataclasses.replace(sim.graph_snapshot(), stamp=16.0))
    again = online.decide()
    assert again is not None and {t for t, _ in again.assignments} == tasks


def test_capabilities_must_agree():
    sim, online = fresh()
    team = sim.team_snapshot()
    online.offer_team(dataclasses.replace(team, capability_names=("a", "b", "c", "d", "e")))
    with pytest.raises(InstanceError, match="differ"):
        online.decide()


def test_unknown_prerequisite_is_an_instance_error():
    _sim, online = fresh()
    graph = online.graph
    assert graph is not None
    bad = (dataclasses.replace(graph.tasks[0], prerequisites=("t99",)), *graph.tasks[1:])
    with pytest.raises(InstanceError, match=r"TaskGraph tasks\[0\] \('t01'\)\.prerequisites: unknown .*t99"):
        online.offer_graph(dataclasses.replace(graph, tasks=bad))  # refused before it is taken
    assert online.graph is graph


def test_hand_made_snapshots():
    """A two-robot team where only a subteam can do the task."""
    from lvws_ros.core.online import GraphSnapshot, TeamSnapshot

    team = TeamSnapshot(0.0, ("lift", "drive"), (
        RobotInfo("a", "x", True, (1, 0), 2.0), RobotInfo("b", "y", True, (0, 1), 2.0),
        RobotInfo("c", "y", False, (1, 1), 9.0, "t0", 3.0)))
    graph = GraphSnapshot(0.0, ("lift", "drive"), (
        TaskInfo("t0", 2, (1, 0), 1.0, 5.0, (), ("c",), 0.0),
        TaskInfo("t1", 1, (1, 1), 3.0, 2.0),
        TaskInfo("t2", 0, (0, 1), 1.0, 2.0, ("t0",))))
    online = OnlineScheduler(make_policy("grp"))
    online.offer_team(team)
    online.offer_graph(graph)
    d = online.decide()
    assert d is not None and d.assignments == (("t1", ("a", "b")),) and d.waiting == ()


def _hand_made(stamp: float = 1.0):
    from lvws_ros.core.online import GraphSnapshot, TeamSnapshot

    team = TeamSnapshot(stamp, ("lift", "drive"), (
        RobotInfo("a", "x", True, (1, 1), 5.0), RobotInfo("b", "y", True, (1, 1), 5.0)))
    graph = GraphSnapshot(stamp, ("lift", "drive"), (
        TaskInfo("t0", 1, (1, 0), 1.0, 5.0), TaskInfo("t1", 1, (0, 1), 1.0, 2.0)))
    return team, graph


def _fed(team, graph) -> OnlineScheduler:
    online = OnlineScheduler(make_policy("grp"))
    online.offer_team(team)
    online.offer_graph(graph)
    return online


@pytest.mark.parametrize(("field", "value", "words"), [
    ("status", 200, r"tasks\[0\] \('t0'\)\.status: 200 is not one of QUEUED=0"),
    ("duration", float("nan"), r"tasks\[0\] \('t0'\)\.duration: nan is not a finite number"),
    ("payload", float("inf"), r"tasks\[0\] \('t0'\)\.payload: inf"),
    ("capabilities", (1, 0, 1), r"tasks\[0\] \('t0'\)\.capabilities: expected 2 entries"),
])
def test_a_malformed_task_is_refused_naming_the_field(field, value, words):
    team, graph = _hand_made()
    online = _fed(team, graph)
    bad = dataclasses.replace(graph, stamp=2.0, tasks=(dataclasses.replace(graph.tasks[0], **{field: value}),
                                                       graph.tasks[1]))
    with pytest.raises(InstanceError, match="TaskGraph " + words):
        online.offer_graph(bad)
    assert online.graph is graph  # ignored: the last good graph stays


def test_a_robot_with_nan_payload_is_refused_and_nan_busy_for_means_busy():
    team, graph = _hand_made()
    online = _fed(team, graph)
    bad = dataclasses.replace(team, stamp=2.0, robots=(dataclasses.replace(team.robots[0], payload=float("nan")),
                                                       team.robots[1]))
    with pytest.raises(InstanceError, match=r"TeamState robots\[0\] \('a'\)\.payload"):
        online.offer_team(bad)
    busy = dataclasses.replace(team, robots=(dataclasses.replace(team.robots[0], available=False,
                                                                 busy_for=float("nan")), team.robots[1]))
    d = _fed(busy, graph).decide()
    assert d is not None and all(r == ("b",) for _, r in d.assignments) and d.assignments


def test_a_robot_with_a_current_task_is_busy_whatever_available_says():
    team, graph = _hand_made()
    claims = dataclasses.replace(team, robots=(dataclasses.replace(team.robots[0], current_task="t9"),
                                               team.robots[1]))
    d = _fed(claims, graph).decide()
    assert d is not None and all("a" not in r for _, r in d.assignments)


def test_readiness_is_checked_not_trusted():
    team, graph = _hand_made()
    liar = dataclasses.replace(graph, tasks=(graph.tasks[0], dataclasses.replace(graph.tasks[1], prerequisites=("t0",))))
    online = _fed(team, liar)
    d = online.decide()
    assert d is not None and [t for t, _ in d.assignments] == ["t0"]
    assert any("t1 is READY but its prerequisite t0 is not DONE" in n for n in online.notices)


def test_a_stamp_far_ahead_does_not_deafen_the_scheduler():
    team, graph = _hand_made(stamp=1.0)
    online = _fed(team, graph)
    assert online.offer_team(dataclasses.replace(team, stamp=2147483647.0))
    assert not online.offer_team(dataclasses.replace(team, stamp=2147483646.0))  # slightly older: out of order
    assert online.offer_team(dataclasses.replace(team, stamp=3.0))  # far back: a restart
    assert online.offer_graph(dataclasses.replace(graph, stamp=3.0))
    assert online.restarts == 1 and any("world restart" in n for n in online.notices)
    d = online.decide()
    assert d is not None and d.assignments and d.team_stamp == 3.0


def test_a_robot_that_vanishes_releases_its_pending_assignment():
    team, graph = _hand_made()
    online = _fed(team, graph)
    d = online.decide()
    assert d is not None and len(d.assignments) == 2
    gone = dataclasses.replace(team, stamp=2.0, robots=(team.robots[1],))
    online.offer_team(gone)
    online.offer_graph(dataclasses.replace(graph, stamp=2.0))
    d2 = online.decide()  # no KeyError: the assignment of the robot that left is released
    assert any("left the latest snapshots" in n for n in online.notices)
    assert all("a" not in robots for robots, _ in online.pending.values())
    assert d2 is None or all("a" not in r for _, r in d2.assignments)


def test_a_team_the_instance_would_refuse_is_refused_when_offered():
    team, graph = _hand_made()
    online = _fed(team, graph)
    zero = dataclasses.replace(team, stamp=2.0, robots=(dataclasses.replace(team.robots[0], payload=0.0),
                                                        team.robots[1]))
    with pytest.raises(InstanceError, match=r"robots\[0\] \('a'\)\.payload: must be > 0"):
        online.offer_team(zero)
    twins = dataclasses.replace(team, stamp=2.0, robots=(team.robots[0], team.robots[0]))
    with pytest.raises(InstanceError, match="duplicate ids"):
        online.offer_team(twins)
    assert online.team is team and online.decide() is not None


def test_a_world_restart_drops_the_old_worlds_snapshots():
    team, graph = _hand_made(stamp=500.0)
    online = _fed(team, graph)
    assert online.decide() is not None
    assert online.offer_team(dataclasses.replace(team, stamp=1.0))
    assert online.graph is None and online.decide() is None  # waits for the new world's graph
    assert online.offer_graph(dataclasses.replace(graph, stamp=1.0))
    d = online.decide()
    assert d is not None and d.graph_stamp == 1.0


class Refusing:
    """A policy that cannot serve anything (as a model past its limits would)."""

    name = "refusing"

    def __init__(self, at: str) -> None:
        self.at = at

    def reset(self, instance):
        if self.at == "reset":
            raise PolicyError("this model handles at most 3 capabilities")

    def decide(self, state):
        raise PolicyError("non-finite rewards")


@pytest.mark.parametrize("at", ["reset", "decide"])
def test_the_fallback_decides_when_the_main_policy_cannot_and_says_so(at):
    sim = CellSim(load_cell_config(CASE_STUDY))
    online = OnlineScheduler(Refusing(at), fallback=make_policy("grp"))
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    d = online.decide()
    assert d is not None and d.policy == "grp" and d.assignments
    assert online.fallbacks == 1 and any("fallback grp" in n and "refusing" in n for n in online.notices)
    bare = OnlineScheduler(Refusing(at))
    bare.offer_team(sim.team_snapshot())
    bare.offer_graph(sim.graph_snapshot())
    with pytest.raises(PolicyError):
        bare.decide()


def test_tasks_the_robots_present_cannot_cover_are_held_back_and_come_back():
    """The only lifter leaves: the lifting task and the one waiting on it are held back
    (WARN), the driving task is still scheduled; when the lifter is back, so are they. A
    DONE task nobody present could do again does not block its dependents."""
    from lvws_ros.core.online import GraphSnapshot, TeamSnapshot

    caps = ("lift", "drive")
    lifter, driver = RobotInfo("l", "x", True, (1, 0), 5.0), RobotInfo("d", "y", True, (0, 1), 5.0)
    graph = GraphSnapshot(1.0, caps, (
        TaskInfo("lift0", 1, (1, 0), 1.0, 5.0), TaskInfo("after_lift", 0, (0, 1), 1.0, 2.0, ("lift0",)),
        TaskInfo("drive0", 1, (0, 1), 1.0, 2.0), TaskInfo("old", 3, (1, 0), 1.0, 1.0, (), ("l",), 0.0, 1.0),
        TaskInfo("after_old", 1, (0, 1), 1.0, 2.0, ("old",))))
    online = OnlineScheduler(make_policy("grp"))
    online.offer_team(TeamSnapshot(1.0, caps, (driver,)))
    online.offer_graph(graph)
    d = online.decide()
    assert d is not None and {t for t, _ in d.assignments} <= {"drive0", "after_old"} and d.assignments
    assert any("lift0 cannot be covered by the robots present" in n and "1 task(s) waiting" in n
               for n in online.notices)
    online.offer_team(TeamSnapshot(2.0, caps, (lifter, dataclasses.replace(driver, available=False,
                                                                          current_task=d.assignments[0][0],
                                                                          busy_for=1.0))))
    online.offer_graph(dataclasses.replace(graph, stamp=2.0))
    d2 = online.decide()
    assert d2 is not None and ("lift0", ("l",)) in d2.assignments
    assert any("robot(s) l joined the team" in c for c in online.changes)


def test_a_budget_counts_from_when_the_decision_began():
    # lvws_sample with 200 ms per decision: told that the decision's work began 10 s ago
    # (the node: the message's arrival), its budget is spent and it decides as LVWS alone;
    # told nothing, it samples; the clock holds for one decision only.
    sim = CellSim(load_cell_config(CASE_STUDY))
    policy = make_policy("lvws_sample", budget_ms=200.0)
    assert isinstance(policy, Budgeted)
    online = OnlineScheduler(policy)
    online.offer_team(sim.team_snapshot())
    online.offer_graph(sim.graph_snapshot())
    t0 = time.perf_counter()
    d = online.decide(started=t0 - 10.0)
    assert d is not None and policy.fallbacks == 1 and time.perf_counter() - t0 < 0.2
    assert policy.clock is None
    policy.clock = later = time.perf_counter() + 5.0  # counted from a later time
    assert decision_deadline(policy) == pytest.approx(later + 0.2)
    assert policy.clock is None
    policy.budget_ms = None
    assert decision_deadline(policy) is None


@pytest.mark.parametrize(("free", "ready", "seen_free", "seen_ready", "running", "ahead", "due"), [
    ({"r1"}, {"t1"}, set(), set(), True, False, True),  # both new
    ({"r1"}, {"t1"}, {"r1"}, {"t1"}, True, False, False),  # nothing new, something runs: wait
    ({"r1"}, {"t1"}, {"r1"}, {"t1"}, False, False, True),  # nothing runs: waiting would stall
    (set(), {"t1"}, set(), set(), True, False, False),  # a new task, every robot busy
    (set(), {"t1"}, set(), set(), True, True, True),  # departing each: busy robots may be given it
    ({"r1"}, set(), set(), set(), False, True, False),  # nothing ready
])
def test_a_decision_is_due_by_one_rule(free, ready, seen_free, seen_ready, running, ahead, due):
    from lvws_ros.core.online import is_due

    assert is_due(free, ready, seen_free, seen_ready, running, ahead) is due


def test_a_done_task_no_robot_present_covers_leaves_the_state_aligned_with_its_instance() -> None:
    # The only lifter failed after its task was done: that task leaves the view (its
    # dependents' prerequisite is met); the next decision, with nothing else new about the
    # cell, still reads the state from the view the instance was built of.
    from lvws_ros.core.online import GraphSnapshot, TeamSnapshot
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    caps = ("arm", "lift")
    r0 = RobotInfo("r0", "x", True, (1, 0), 2.0)
    done = TaskInfo("d", 3, (0, 1), 1.0, 2.0, start=0.0, end=2.0)
    a, b = TaskInfo("a", 1, (1, 0), 1.0, 2.0), TaskInfo("b", 1, (1, 0), 1.0, 2.0)
    core = OnlineScheduler(GreedyPayloadPolicy(), ack_timeout=1e9)
    core.offer_team(TeamSnapshot(3.0, caps, (r0,)))
    core.offer_graph(GraphSnapshot(3.0, caps, (done, a, b)))
    first = core.decide()
    assert first is not None and first.assignments == (("a", ("r0",)),)
    core.offer_team(TeamSnapshot(5.0, caps, (r0,)))
    core.offer_graph(GraphSnapshot(5.0, caps, (done, dataclasses.replace(a, status=3, assigned_robots=("r0",),
                                                                           start=3.0, end=5.0), b)))
    second = core.decide()
    assert second is not None and second.assignments == (("b", ("r0",)),)
