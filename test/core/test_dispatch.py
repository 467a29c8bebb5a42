"""The dispatcher's bookkeeping: tasks, subteam goals and the failure rules, without ROS."""

from __future__ import annotations

import pytest

from lvws_ros.core.dispatch import Dispatch, GoalKind, Moved
from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.formats import instance_from_dict
from lvws_ros.errors import DispatchRefused

CELL = {
    "format": "lvws-instance/1", "name": "two-sites", "capabilities": ["lift", "weld"],
    "sites": {"a": [0, 0], "b": [4, 3]},
    "robots": [{"id": "r1", "capabilities": [1, 0], "payload": 2, "site": "a", "speed": 1.0},
               {"id": "r2", "capabilities": [1, 0], "payload": 2, "site": "a", "speed": 0.5},
               {"id": "arm", "capabilities": [0, 1], "payload": 1, "site": "b"}],
    "tasks": [{"id": "carry", "capabilities": [1, 0], "payload": 3, "duration": 2, "after": [], "from": "a", "to": "b"},
              {"id": "weld", "capabilities": [0, 1], "payload": 0, "duration": 3, "after": ["carry"], "site": "b"}],
}


def status(d: Dispatch, task: str) -> int:
    return next(t.status for t in d.graph_snapshot(0.0).tasks if t.id == task)


def test_a_subteam_task_is_done_when_every_member_succeeded_and_leaves_them_at_its_end_site():
    d = Dispatch(instance_from_dict(CELL))
    assert status(d, "carry") == TaskStatus.READY and status(d, "weld") == TaskStatus.QUEUED
    out = d.assign("carry", ["r1", "r2"], 10.0)
    goals = out.send
    assert [g.robot for g in goals] == ["r1", "r2"] and out.changed
    assert goals[0].site == "a" and goals[0].site_to == "b" and goals[0].planned_start == 10.0
    assert status(d, "carry") == TaskStatus.ASSIGNED
    team = {r.id: r for r in d.team_snapshot(11.0).robots}
    assert not team["r1"].available and team["r1"].current_task == "carry" and team["r1"].site == "b"
    assert team["r1"].busy_for == pytest.approx(1.0)
    d.accepted(goals[0].key, 10.1)
    d.feedback(goals[0].key, 12.0, "working", 0.5, "a")
    d.feedback(goals[1].key, 13.0, "working", 0.5, "a")
    d.succeeded(goals[0].key, 15.0, 2.0)
    assert status(d, "carry") == TaskStatus.ASSIGNED  # r2 is still at it
    assert d.busy_with("r1") == "carry"  # a member stays with the task until it is done
    d.succeeded(goals[1].key, 16.0, 2.0)
    task = next(t for t in d.graph_snapshot(16.0).tasks if t.id == "carry")
    assert task.status == TaskStatus.DONE and task.start == 13.0 and task.end == 16.0
    assert status(d, "weld") == TaskStatus.READY
    team = {r.id: r for r in d.team_snapshot(16.0).robots}
    assert team["r1"].available and team["r1"].site == "b" and team["arm"].site == "b"


def test_a_member_that_aborts_fails_the_task_the_others_are_cancelled_and_it_leaves_until_it_rejoins():
    d = Dispatch(instance_from_dict(CELL))
    goals = d.assign("carry", ["r1", "r2"], 0.0).send
    d.feedback(goals[1].key, 1.0, "travelling", 0.1, "")
    out = d.ended(goals[0].key, 2.0, GoalKind.ABORTED, "gripper jammed")
    assert out.cancel == [goals[1].key] and out.changed
    assert [n.kind for n in out.news] == [GoalKind.ABORTED]
    assert status(d, "carry") == TaskStatus.READY
    team = {r.id: r for r in d.team_snapshot(2.0).robots}
    assert "r1" not in team  # it vanishes from TeamState
    assert not team["r2"].available and team["r2"].site == ""  # until its goal ends, between sites
    with pytest.raises(DispatchRefused, match=r"r2.*busy"):
        d.assign("carry", ["r2"], 2.5)
    d.ended(goals[1].key, 3.0, GoalKind.CANCELED, "")
    assert d.team_snapshot(3.0).robots[0].available  # r2, cancelled on request, stays in the team
    late = d.succeeded(goals[0].key, 3.5, 2.0)  # a result for a goal already over
    assert not late.changed and "already aborted" in late.notes[0]
    d.rejoin("r1")
    assert {r.id for r in d.team_snapshot(4.0).robots} == {"r1", "r2", "arm"}


def test_a_silent_goal_is_lost_and_a_free_robot_whose_server_is_gone_leaves():
    d = Dispatch(instance_from_dict(CELL))
    goals = d.assign("carry", ["r1", "r2"], 0.0).send
    d.feedback(goals[0].key, 4.0, "travelling", 0.2, "")
    out = d.silent(5.5, 5.0, {})
    assert out.cancel == [goals[1].key, goals[0].key]  # the lost goal too: a robot alive but silent stops
    assert [n.kind for n in out.news] == [GoalKind.LOST]
    assert d.failed_robots() == {"r2": ("lost", 5.5)}
    out = d.silent(6.0, 5.0, {"arm": False})
    assert "arm" in d.failed_robots() and out.changed
    assert d.feedback(goals[1].key, 6.0, "working", 0.5, "a").notes  # a stale goal's feedback: a note, no change
    assert not d.feedback(goals[1].key, 6.1, "working", 0.6, "a").notes  # once per goal
    back = d.ended(goals[1].key, 7.0, GoalKind.CANCELED, "")  # it was alive: its lost goal ends, it is free
    assert back.changed and "r2" not in d.failed_robots()


def test_bad_assignments_and_service_calls_are_refused_naming_the_item():
    d = Dispatch(instance_from_dict(CELL), present=["r1", "r2"])
    for task, team, match in (("nope", ["r1"], "unknown task 'nope'"), ("carry", ["ghost"], "unknown robot 'ghost'"),
                              ("weld", ["arm"], "'weld' is QUEUED"), ("carry", ["r1", "r1"], "twice")):
        with pytest.raises(DispatchRefused, match=match):
            d.assign(task, team, 0.0)
    with pytest.raises(DispatchRefused, match="'arm' is out"):
        d.assign("carry", ["arm"], 0.0)
    with pytest.raises(DispatchRefused, match=r"unknown task id\(s\) \[.nope.\]"):
        d.add_tasks([{"id": "x", "capabilities": [1, 0], "payload": 0, "duration": 1, "after": ["nope"], "site": "a"}])
    with pytest.raises(DispatchRefused, match="unknown site 'c'"):
        d.add_tasks([{"id": "x", "capabilities": [1, 0], "payload": 0, "duration": 1, "after": [], "site": "c"}])
    with pytest.raises(DispatchRefused, match="cancel: unknown task"):
        d.cancel("nope", 0.0)


def test_submitted_and_cancelled_tasks_change_the_graph_and_a_cancel_stops_the_running_goals():
    d = Dispatch(instance_from_dict(CELL))
    d.add_tasks([{"id": "polish", "capabilities": [0, 1], "payload": 0, "duration": 1, "after": ["weld"],
                  "site": "b"}])
    assert status(d, "polish") == TaskStatus.QUEUED
    goals = d.assign("carry", ["r1", "r2"], 0.0).send
    out = d.cancel("carry", 1.0)
    assert sorted(out.cancel) == sorted(g.key for g in goals)
    assert [t.id for t in d.graph_snapshot(1.0).tasks] == ["weld", "polish"]
    assert status(d, "weld") == TaskStatus.READY  # no longer waits for the cancelled task
    d.ended(goals[0].key, 1.5, GoalKind.CANCELED, "")
    assert "r1" in {r.id for r in d.team_snapshot(1.5).robots if r.available}


def test_the_snapshots_of_a_cell_of_traits_with_homes_and_of_a_cell_without_tasks_build_the_scheduler_instance():
    from pathlib import Path

    from lvws_ros.core.formats import load_instance
    from lvws_ros.core.online import build_instance, check_graph, check_team

    inst = load_instance(Path(__file__).resolve().parents[2] / "examples" / "weld_cell_traits.json")
    d = Dispatch(inst)
    team, graph = d.team_snapshot(3.0), d.graph_snapshot(3.0)
    check_team(team)
    check_graph(graph)
    again = build_instance(team, graph)
    assert again.traits == inst.traits and again.objective == "return" and again.travel is not None
    assert [r.home for r in team.robots] == ["dock", "dock", "b", "c"]
    empty = Dispatch(instance_from_dict({**CELL, "tasks": []}))
    assert empty.graph_snapshot(0.0).tasks == () and empty.done
    empty.add_tasks([CELL["tasks"][0]])
    assert status(empty, "carry") == TaskStatus.READY


EACH = {**CELL, "departure": "each",
        "tasks": [*CELL["tasks"], {"id": "fetch", "capabilities": [1, 0], "payload": 1, "duration": 1, "after": [],
                                   "site": "a"}]}


def test_departing_each_a_busy_member_is_given_its_next_task_and_its_goal_goes_out_once_it_is_free():
    d = Dispatch(instance_from_dict(EACH))
    goals = d.assign("carry", ["r1", "r2"], 0.0).send  # both at a: carry takes them to b (5 m away)
    out = d.assign("fetch", ["r1"], 1.0)  # r1 busy with carry: it will go back to a for it
    assert out.send == [] and out.changed and status(d, "fetch") == TaskStatus.ASSIGNED
    team = {r.id: r for r in d.team_snapshot(1.0).robots}
    # busy until fetch ends: carry ends at 2, back from b to a (5 m at 1 m/s), 1 s of work; then at a
    assert not team["r1"].available and team["r1"].current_task == "carry" and team["r1"].site == "a"
    assert team["r1"].busy_for == pytest.approx(2.0 + 5.0 + 1.0 - 1.0)
    fetch = next(t for t in d.graph_snapshot(1.0).tasks if t.id == "fetch")
    assert fetch.start == pytest.approx(7.0) and fetch.assigned_robots == ("r1",)
    d.succeeded(goals[0].key, 2.0, 2.0)
    assert not d.succeeded(goals[0].key, 2.0, 2.0).send  # a repeated answer sends nothing
    out = d.succeeded(goals[1].key, 2.5, 2.0)
    assert [(g.robot, g.task, g.site) for g in out.send] == [("r1", "fetch", "a")]  # free: it sets out now
    assert out.send[0].planned_start == pytest.approx(7.5)  # re-timed from when it is really free
    assert d.busy_with("r1") == "fetch" and not d.robots["r1"].queue


@pytest.mark.parametrize(("fetch_done", "moved"), [(1.0, []), (1.2, []),  # on time, or within the answers' latency
                                                   (3.0, [Moved("pair", ("r1", "r2"), 3.0)])])
def test_departing_each_a_member_later_than_planned_moves_the_start_for_the_members_already_sent(fetch_done, moved):
    pair = {"id": "pair", "capabilities": [1, 0], "payload": 4, "duration": 1, "after": [], "site": "a"}
    d = Dispatch(instance_from_dict({**EACH, "tasks": [*EACH["tasks"], pair]}))
    fetch = d.assign("fetch", ["r1"], 0.0).send  # r1 at a until 1.0, as planned
    out = d.assign("pair", ["r1", "r2"], 0.5)  # r2 sent now, r1 once fetch is done
    assert [(g.robot, g.planned_start) for g in out.send] == [("r2", 1.0)] and not out.moved
    out = d.succeeded(fetch[0].key, fetch_done, 1.0)  # r1 sets out then
    assert [(g.robot, g.planned_start) for g in out.send] == [("r1", max(1.0, fetch_done))]
    assert out.moved == moved  # r2, waiting at a, is told the new start


def test_departing_each_a_member_lost_releases_the_tasks_it_was_given_and_nothing_is_double_booked():
    d = Dispatch(instance_from_dict(EACH))
    goals = d.assign("carry", ["r1", "r2"], 0.0).send
    assert d.assign("fetch", ["r2"], 0.5).send == []  # queued behind carry
    out = d.ended(goals[1].key, 1.0, GoalKind.ABORTED, "wheel slip")  # r2 fails carry, and leaves
    assert out.cancel == [goals[0].key]
    assert status(d, "carry") == TaskStatus.READY and status(d, "fetch") == TaskStatus.READY  # both given again
    assert not d.robots["r2"].queue and not out.send
    with pytest.raises(DispatchRefused, match="out of the team"):
        d.assign("fetch", ["r2"], 1.5)
    again = d.assign("fetch", ["r1"], 1.5).send  # r1 still busy (its carry goal is being cancelled): queued
    assert again == [] and d.robots["r1"].queue == ["fetch"]
    out = d.ended(goals[0].key, 2.0, GoalKind.CANCELED, "")  # stopped on request: on to fetch
    assert [(g.robot, g.task) for g in out.send] == [("r1", "fetch")]
    assert d.engaged("r1") and {r.id for r in d.team_snapshot(2.0).robots} == {"r1", "arm"}


def test_departing_each_a_robot_set_failed_after_its_part_is_sent_nothing_and_gives_back_its_queue():
    d = Dispatch(instance_from_dict(EACH))
    goals = d.assign("carry", ["r1", "r2"], 0.0).send
    d.assign("fetch", ["r1"], 0.5)  # queued behind carry
    d.succeeded(goals[0].key, 2.0, 2.0)  # r1 did its part; it stays with carry until r2 is done
    out = d.fault("r1", True, 2.5)
    assert not out.send and d.robots["r1"].failed == "fault" and not d.robots["r1"].queue
    assert status(d, "carry") == TaskStatus.READY and status(d, "fetch") == TaskStatus.READY
    assert out.cancel == [goals[1].key]
