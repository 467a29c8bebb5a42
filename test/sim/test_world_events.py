"""A world that changes while it runs (no ROS): tasks added and cancelled, robots that
fail mid-transport (the object is put down where it is and picked up from there) and
come back, scripted events, and a run that ends with its reason when a task becomes
impossible."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from conftest import CASE_STUDY
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import ConfigError, WorldEventRejected, WorldStuck
from lvws_ros.registry import make_policy
from lvws_ros.sim.config import load_cell_config
from lvws_ros.sim.events import WorldEvent, load_events
from lvws_ros.sim.runner import run_offline
from lvws_ros.sim.world import ASSIGNED, DONE, FLOOR, QUEUED, READY, SLOT_RADIUS, CellSim
from samples import EVENTS


@pytest.fixture
def sim() -> CellSim:
    return CellSim(load_cell_config(CASE_STUDY))


def _until_carrying(sim: CellSim, assembly: str, transport: str, robot: str) -> None:
    """Run ``assembly`` (panda_1, at cell_1) to its end, then ``transport`` with ``robot``
    until the robot carries the object."""
    sim.assign(assembly, ["panda_1"])
    while sim.status[assembly] != DONE:
        sim.step()
    sim.assign(transport, [robot])
    while sim.jobs[transport].phase != "carry":
        sim.step()


def test_a_robot_failing_mid_transport_puts_the_object_down_and_the_task_comes_back(sim):
    _until_carrying(sim, "t01", "t04", "jackal_2")  # obj2 (3) from cell_1 to cell_2
    for _ in range(20):
        sim.step()
    where = sim.position("obj2")
    events = sim.fail("jackal_2")
    assert [e.kind for e in events] == ["interrupted", "failed"]
    assert sim.status["t04"] == READY and "t04" not in sim.team and sim.object_cell["obj2"] == FLOOR
    assert "jackal_2" not in {r.id for r in sim.team_snapshot().robots}
    with pytest.raises(Exception, match="has failed"):
        sim.assign("t04", ["jackal_2"])
    sim.assign("t04", ["husky_1"])  # picks obj2 up where it lies
    target = sim.jobs["t04"].targets["husky_1"]  # its place around obj2, where obj2 lies
    assert math.dist(target, where) == pytest.approx(SLOT_RADIUS)
    while sim.status["t04"] != DONE:
        sim.step()
    assert sim.object_cell["obj2"] == "cell_2" and sim.position("obj2") != where
    sim.repair("jackal_2")
    assert "jackal_2" in {r.id for r in sim.team_snapshot().robots if r.available}


def test_cancelling_a_transport_that_carries_its_object_leaves_it_to_the_next_transport(sim):
    _until_carrying(sim, "t02", "t05", "jackal_1")  # obj3 (2) from cell_1 to cell_3
    assert sim.object_cell["obj3"] is None  # on the robot
    sim.submit([{"id": "t20", "type": "transport", "object": "obj3", "from": "cell_3", "to": "cell_1",
                 "after": ["t05"]}])
    events = sim.cancel("t05")  # obj3 is put down where it is; t20 picks it up there
    assert [e.kind for e in events] == ["interrupted", "cancelled"]
    assert sim.object_cell["obj3"] == FLOOR and sim.status["t20"] == READY
    sim.assign("t20", ["jackal_1"])
    while sim.status["t20"] != DONE:
        sim.step()
    assert sim.object_cell["obj3"] == "cell_1"


def test_tasks_added_and_cancelled(sim):
    sim.cancel("t12")  # t14 waited for it
    assert "t12" not in sim.status and "t12" not in sim.inst.task_index
    assert all("t12" not in t.after for t in sim.cfg.tasks)
    hazard = {"id": "t15", "type": "assembly", "object": "obj4", "cell": "cell_3", "duration": 2.0}
    with pytest.raises(WorldEventRejected, match="t15 and t06 both work on obj4 and neither comes after the other"):
        sim.submit([hazard])  # if t06 took obj4 to cell_2 first, t15 would wait forever
    with pytest.raises(WorldEventRejected, match="task t15: obj4 is at cell_2 when it comes, not at cell_3"):
        sim.submit([{**hazard, "after": ["t09"]}])  # t12, which brought it back, is cancelled
    sim.submit([{**hazard, "cell": "cell_2", "after": ["t09"]}])  # where obj4 stays now
    assert sim.status["t15"] == QUEUED and sim.graph_snapshot().tasks[-1].id == "t15"
    sim.submit([{"id": "t16", "type": "transport", "object": "obj4", "from": "cell_2", "to": "cell_1",
                 "after": ["t15"]}])
    assert sim.status["t16"] == QUEUED
    for bad, words in (([{"id": "t15", "type": "assembly", "object": "obj4", "cell": "cell_3", "duration": 1}], "taken"),
                       ([{"id": "t17", "type": "assembly", "object": "objX", "cell": "cell_3", "duration": 1}],
                        "unknown object"),
                       ([{"id": "t17", "type": "assembly", "object": "obj4", "cell": "cell_3", "duration": 1,
                          "after": ["t99"]}], "unknown prerequisite"),
                       ([{"type": "assembly"}], "missing key")):
        with pytest.raises(WorldEventRejected, match=words):
            sim.submit(bad)
    assert "t17" not in sim.status  # all or nothing
    sim.assign("t01", ["panda_1"])
    assert sim.status["t01"] == ASSIGNED
    events = sim.cancel("t01")  # a running task: stopped first
    assert [e.kind for e in events] == ["interrupted", "cancelled"] and sim.robot_task["panda_1"] is None
    with pytest.raises(WorldEventRejected, match="unknown task"):
        sim.cancel("t01")
    with pytest.raises(WorldEventRejected, match="cancelling t04: task t08: obj2 is at cell_1 when it comes, not at "
                                                 "cell_2"):
        sim.cancel("t04")  # t08 and t11 work on obj2 after it: they would wait forever
    assert "t04" in sim.status


@pytest.mark.parametrize("policy", ["grp", "lvws", "lvws_sample", "auto"])
def test_scripted_events_run_to_a_valid_schedule_of_the_final_tasks(sim, policy, tmp_path: Path):
    path = tmp_path / "events.yaml"
    path.write_text(EVENTS)
    events = load_events(path)
    assert [e.kind for e in events] == ["cancel", "fail", "submit", "repair"]  # time order
    sched, _ = run_offline(sim, make_policy(policy), events=events)
    assert sim.failed == set()
    assert sorted(a.task for a in sched.assignments) == sorted({*(f"t{k:02d}" for k in range(1, 15)), "t15",
                                                                 "t16"} - {"t12"})
    assert check_schedule(sim.executed_instance(), sched) == []


def test_a_task_made_impossible_ends_the_run_with_the_reason(sim):
    with pytest.raises(WorldStuck, match=r"t10: obj1 weighs 7; the mobile robots left carry 5"):
        run_offline(sim, make_policy("grp"), events=[WorldEvent(5.0, "fail", "husky_1")])
    sim2 = CellSim(load_cell_config(CASE_STUDY))  # a later repair: not stuck
    sched, _ = run_offline(sim2, make_policy("grp"), events=[WorldEvent(5.0, "fail", "husky_1"),
                                                              WorldEvent(60.0, "repair", "husky_1")])
    assert check_schedule(sim2.executed_instance(), sched) == []


@pytest.mark.parametrize(("text", "words"), [
    ("- {at: -1, fail: r}", "'at' must be a sim time"),
    ("- {at: 1, fail: r, cancel: t}", "exactly one of"),
    ("- {at: 1, explode: r}", "exactly one of"),
    ("- {at: 1, submit: []}", "non-empty list"),
    ("- {at: 1, fail: 3}", "must name a robot"),
    ("events: 3", "expected a list"),
    ("[unclosed", "malformed YAML"),
])
def test_bad_event_files_name_the_file_and_the_event(tmp_path: Path, text: str, words: str):
    path = tmp_path / "events.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=words) as info:
        load_events(path)
    assert str(path) in str(info.value)
