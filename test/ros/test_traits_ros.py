"""Traits, roles and return to base over ROS: the optional message fields survive the one
conversion and a CDR round trip, bags recorded before them are read and reported as
before, and the scheduler node in its own process schedules a cell written in traits
(subteams that cover by the trait rule, roles included)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rclpy.serialization import deserialize_message, serialize_message

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.formats import load_instance
from lvws_ros.core.online import (
    GraphSnapshot,
    RobotInfo,
    TaskInfo,
    TeamSnapshot,
    build_instance,
    graph_sites,
    roles_code,
)
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import covers
from lvws_ros.ros.convert import graph_from_msg, graph_to_msg, team_from_msg, team_to_msg
from scheduler_probe import scheduler_probe

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "weld_cell_traits.json"


def snapshots(path: Path) -> tuple[TeamSnapshot, GraphSnapshot]:
    """The snapshots of an instance file at time 0: every robot free at its site."""
    inst = load_instance(path)
    tr = inst.travel
    assert tr is not None
    robots = tuple(RobotInfo(r.id, "robot", True, r.capabilities, r.payload, "", 0.0, (0.0, 0.0, 0.0),
                             tr.sites[tr.robot_site[i]], tr.robot_speed[i],
                             tuple(inst.robot_amounts[i, len(inst.capabilities):]), tr.sites[tr.home(i)])
                   for i, r in enumerate(inst.robots))
    tasks = tuple(TaskInfo(t.id, int(TaskStatus.QUEUED if t.after else TaskStatus.READY), t.capabilities, t.payload,
                           t.duration, t.after, (), None, None, tr.sites[tr.task_from[j]], tr.sites[tr.task_to[j]],
                           tuple(inst.task_needs[j, len(inst.capabilities):]), roles_code(t.roles))
                  for j, t in enumerate(inst.tasks))
    return (TeamSnapshot(0.0, inst.capabilities, robots, inst.traits),
            GraphSnapshot(0.0, inst.capabilities, tasks, *graph_sites(tr), inst.traits, inst.roles, inst.objective))


def test_trait_fields_survive_the_conversion_and_a_cdr_round_trip():
    team, graph = snapshots(EXAMPLE)
    team_msg, graph_msg = team_to_msg(team), graph_to_msg(graph)
    team_back = team_from_msg(deserialize_message(serialize_message(team_msg), type(team_msg)))
    graph_back = graph_from_msg(deserialize_message(serialize_message(graph_msg), type(graph_msg)))
    assert team_back.trait_names == ("welder", "gripper", "payload")
    assert team_back.robots == team.robots and graph_back.tasks == graph.tasks
    assert (graph_back.trait_names, graph_back.roles, graph_back.objective) == (graph.trait_names, False, "return")
    inst = build_instance(team_back, graph_back)
    original = load_instance(EXAMPLE)
    assert inst.traits == original.traits and inst.objective == "return"
    assert (inst.robot_amounts == original.robot_amounts).all() and (inst.task_needs == original.task_needs).all()
    assert list(inst.task_roles) == list(original.task_roles)
    assert inst.travel is not None and [inst.travel.home(i) for i in range(inst.num_robots)] == \
        [original.travel.home(i) for i in range(original.num_robots)]


@pytest.mark.parametrize("bag", [REPO / "bags" / "reference" / "case-study-lvws", REPO / "test" / "data" / "bag-before-travel"])
def test_a_bag_recorded_before_the_trait_fields_is_read_and_reported_as_before(bag):
    """Read with the bag's own (older) types: no traits, no roles, the usual objective;
    the executed schedule rebuilt from it is valid, as before."""
    from lvws_ros.cli.report import executed
    from lvws_ros.ros.bag import read_run

    run = read_run(bag)
    assert run.teams and run.graphs
    assert all(t.trait_names == () and all(r.traits == () and r.home == "" for r in t.robots) for t in run.teams)
    last = run.graphs[-1]
    assert last.trait_names == () and not last.roles and last.objective == ""
    assert all(t.requires == () and t.roles == 0 for t in last.tasks)
    inst, sched = executed(run.teams, last)
    assert inst.traits == () and check_schedule(inst, sched) == []


def test_the_scheduler_node_schedules_a_cell_written_in_traits(ros_context):
    team, graph = snapshots(EXAMPLE)
    inst = build_instance(team, graph)
    with scheduler_probe(ros_context, "lvws_traits_probe", ["-p", "policy:=grp"]) as probe:
        probe.wait_for_scheduler()
        probe.spin(60.0, lambda: bool(probe.got) or (probe.team_pub.publish(team_to_msg(team)) or
                                                      probe.graph_pub.publish(graph_to_msg(graph)) or False))
        assert probe.got, probe.diags[-5:]
    decision = probe.got[0]
    assert decision.assignments, decision
    for a in decision.assignments:
        j = inst.task_index[a.task_id]
        team_idx = [inst.robot_index[r] for r in a.robot_ids]
        assert covers(inst.robot_amounts[team_idx], inst.robot_payload[team_idx], inst.task_needs[j],
                      inst.tasks[j].payload, bool(inst.task_roles[j])), (a.task_id, list(a.robot_ids))


def test_a_submitted_task_carries_its_traits_through_a_cell_task_message():
    from lvws_msgs.msg import CellTask

    from lvws_ros.errors import ConfigError
    from lvws_ros.ros.convert import cell_task_from_msg, cell_task_to_msg

    entry = {"id": "t20", "type": "transport", "object": "obj3", "from": "cell_1", "to": "cell_3", "after": ["t14"],
             "requires": {"battery": 3.0, "gripper": 0.5}}
    msg = deserialize_message(serialize_message(cell_task_to_msg(entry)), CellTask)
    assert list(msg.require_names) == ["battery", "gripper"] and list(msg.requires) == [3.0, 0.5]
    back = cell_task_from_msg(msg)
    assert back["requires"] == entry["requires"] and back["from"] == "cell_1"
    plain = cell_task_from_msg(cell_task_to_msg({k: v for k, v in entry.items() if k != "requires"}))
    assert "requires" not in plain  # a task without traits is the entry it was
    msg.requires = [3.0]
    with pytest.raises(ConfigError, match="task 't20': 2 require_names but 1 requires"):
        cell_task_from_msg(msg)
    msg.requires = [3.0, 0.5]
    msg.require_names = ["battery", "battery"]
    with pytest.raises(ConfigError, match="task 't20': require_names names a trait twice"):
        cell_task_from_msg(msg)
    for bad in ([3], None):
        with pytest.raises(ConfigError, match="task 0: requires must map"):
            cell_task_to_msg({**entry, "requires": bad})
