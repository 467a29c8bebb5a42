"""Every lvws_msgs type imports, constructs, and survives a CDR round trip intact."""

from __future__ import annotations

import pytest
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import Pose2D
from lvws_msgs.msg import (
    Assignment,
    AssignmentArray,
    RobotState,
    Task,
    TaskGraph,
    TeamState,
)
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header


def roundtrip(msg):
    data = serialize_message(msg)
    assert isinstance(data, bytes) and len(data) > 0
    return deserialize_message(data, type(msg))


def make_robot(i: int) -> RobotState:
    return RobotState(
        id=f"jackal_{i}",
        kind="jackal",
        available=bool(i % 2),
        capabilities=[0, 1, i % 2],
        payload=2.5 + i,
        pose=Pose2D(x=1.5 * i, y=-2.0, theta=0.25),
        current_task="" if i % 2 else f"t{i}",
        busy_for=0.0 if i % 2 else 3.5,
    )


def make_task(i: int) -> Task:
    return Task(
        id=f"t{i}",
        status=Task.STATUS_ASSIGNED,
        capabilities=[1, 0, 1],
        payload=7.0,
        duration=12.25,
        prerequisites=[f"t{j}" for j in range(i)],
        assigned_robots=["jackal_1", "husky_1"],
        start_time=Time(sec=3, nanosec=500),
        end_time=Time(sec=0, nanosec=0),
    )


def test_robot_state_roundtrip():
    msg = make_robot(3)
    back = roundtrip(msg)
    assert back == msg
    assert list(back.capabilities) == [0, 1, 1]
    assert back.pose.x == 4.5 and back.kind == "jackal" and back.available


def test_team_state_roundtrip():
    msg = TeamState(
        header=Header(stamp=Time(sec=12, nanosec=34), frame_id="cell_map"),
        capability_names=["manipulation", "mobility", "sensing"],
        robots=[make_robot(i) for i in range(4)],
    )
    back = roundtrip(msg)
    assert back == msg
    assert [r.id for r in back.robots] == [f"jackal_{i}" for i in range(4)]
    assert back.header.frame_id == "cell_map"


def test_task_constants_and_roundtrip():
    assert [Task.STATUS_QUEUED, Task.STATUS_READY, Task.STATUS_ASSIGNED, Task.STATUS_DONE] == [0, 1, 2, 3]
    msg = make_task(3)
    back = roundtrip(msg)
    assert back == msg
    assert list(back.prerequisites) == ["t0", "t1", "t2"]
    assert back.start_time.sec == 3 and back.start_time.nanosec == 500


def test_task_graph_roundtrip():
    msg = TaskGraph(
        header=Header(frame_id="cell_map"),
        capability_names=["manipulation", "mobility"],
        tasks=[make_task(i) for i in range(5)],
    )
    back = roundtrip(msg)
    assert back == msg
    assert len(back.tasks) == 5 and back.tasks[4].payload == 7.0
    assert back.departure == ""  # not set: "together", as every graph before the field


def test_the_departure_crosses_cdr_and_converts_back_and_a_bad_one_is_refused():
    from lvws_ros.core.online import GraphSnapshot, check_graph
    from lvws_ros.errors import InstanceError
    from lvws_ros.ros import convert

    snap = GraphSnapshot(3.0, ("a",), (), departure="each")
    back = convert.graph_from_msg(roundtrip(convert.graph_to_msg(snap)))
    assert back.departure == "each" and back == snap
    with pytest.raises(InstanceError, match="TaskGraph departure: '', 'together' or 'each', got 'alone'"):
        check_graph(GraphSnapshot(3.0, ("a",), (), departure="alone"))


def test_assignment_array_roundtrip():
    msg = AssignmentArray(
        header=Header(stamp=Time(sec=1)),
        decision_step=42,
        policy="grp",
        assignments=[
            Assignment(task_id="t1", robot_ids=["jackal_1", "husky_1"]),
            Assignment(task_id="t2", robot_ids=["panda_2"]),
        ],
        waiting_robot_ids=["jackal_2"],
        decision_latency=Duration(sec=0, nanosec=1_500_000),
    )
    back = roundtrip(msg)
    assert back == msg
    assert back.assignments[0].robot_ids == ["jackal_1", "husky_1"]
    assert back.decision_latency.nanosec == 1_500_000
    assert back.decision_step == 42 and back.policy == "grp"


def test_travel_fields_cross_cdr_and_convert_back_to_the_same_snapshots():
    """The travel extension of TaskGraph/TeamState (issue #15): sites, distances, task and
    robot sites, speeds; the simulator's snapshots survive message conversion and CDR."""
    from lvws_ros.core.online import build_instance
    from lvws_ros.ros.convert import graph_from_msg, graph_to_msg, team_from_msg, team_to_msg
    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.sim.config import load_cell_config
    from lvws_ros.sim.world import CellSim

    sim = CellSim(load_cell_config(case_study_config()))
    graph, team = sim.graph_snapshot(), sim.team_snapshot()
    assert graph.sites and graph.distances
    g_back = graph_from_msg(roundtrip(graph_to_msg(graph)))
    t_back = team_from_msg(roundtrip(team_to_msg(team)))
    assert g_back == graph and t_back == team
    assert build_instance(t_back, g_back).travel == build_instance(team, graph).travel
    plain = TaskGraph(tasks=[make_task(1)])  # a graph without travel reads as zero travel
    assert graph_from_msg(roundtrip(plain)).sites == () and graph_from_msg(plain).tasks[0].site_from == ""
