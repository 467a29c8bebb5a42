"""Topic names, QoS profiles and message <-> snapshot conversions shared by the nodes."""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from typing import Any

from builtin_interfaces.msg import Duration, Time
from lvws_msgs.msg import Assignment, AssignmentArray, RobotState, Task, TaskGraph, TeamState
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from lvws_ros.online import GraphSnapshot, OnlineDecision, RobotInfo, TaskInfo, TeamSnapshot

TEAM_TOPIC = "/lvws/team_state"
GRAPH_TOPIC = "/lvws/task_graph"
ASSIGNMENTS_TOPIC = "/lvws/assignments"
MARKERS_TOPIC = "/lvws/markers"
DIAGNOSTICS_TOPIC = "/diagnostics"
CLOCK_TOPIC = "/clock"

TEAM_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
# latched: late joiners get the current graph
GRAPH_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
ASSIGNMENTS_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
MARKERS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
CLOCK_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE,
                       history=HistoryPolicy.KEEP_LAST)

# Every topic of a run: name -> (ROS type name, QoS).
TOPICS: dict[str, tuple[str, QoSProfile]] = {
    TEAM_TOPIC: ("lvws_msgs/msg/TeamState", TEAM_QOS),
    GRAPH_TOPIC: ("lvws_msgs/msg/TaskGraph", GRAPH_QOS),
    ASSIGNMENTS_TOPIC: ("lvws_msgs/msg/AssignmentArray", ASSIGNMENTS_QOS),
    MARKERS_TOPIC: ("visualization_msgs/msg/MarkerArray", MARKERS_QOS),
    DIAGNOSTICS_TOPIC: ("diagnostic_msgs/msg/DiagnosticArray", DIAGNOSTICS_QOS),
    CLOCK_TOPIC: ("rosgraph_msgs/msg/Clock", CLOCK_QOS),
}


def message_class(type_name: str) -> Any:
    """The rclpy message class of 'pkg/msg/Name'."""
    import importlib

    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def user_args(argv: Sequence[str]) -> list[str]:
    """Command-line arguments before --ros-args (those are rclpy's)."""
    argv = list(argv)
    return argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv


def to_time(seconds: float) -> Time:
    if not math.isfinite(seconds) or seconds < 0:
        seconds = 0.0
    sec = int(seconds)
    return Time(sec=sec, nanosec=min(round((seconds - sec) * 1e9), 999_999_999))


def from_time(t: Any) -> float:
    return float(t.sec) + float(t.nanosec) * 1e-9


def to_duration(seconds: float) -> Duration:
    sec = int(seconds)
    return Duration(sec=sec, nanosec=min(round((seconds - sec) * 1e9), 999_999_999))


def _stamped(msg: Any, snap: TeamSnapshot | GraphSnapshot, frame_id: str) -> Any:
    msg.header.stamp = to_time(snap.stamp)
    msg.header.frame_id = frame_id
    msg.capability_names = list(snap.capability_names)
    return msg


def team_to_msg(snap: TeamSnapshot, frame_id: str = "map") -> TeamState:
    msg = _stamped(TeamState(), snap, frame_id)
    for r in snap.robots:
        rs = RobotState(id=r.id, kind=r.kind, available=r.available, capabilities=list(r.capabilities),
                        payload=float(r.payload), current_task=r.current_task, busy_for=float(r.busy_for))
        rs.pose.x, rs.pose.y, rs.pose.theta = r.pose
        msg.robots.append(rs)
    return msg


def team_from_msg(msg: Any) -> TeamSnapshot:
    return TeamSnapshot(
        from_time(msg.header.stamp), tuple(msg.capability_names),
        tuple(RobotInfo(r.id, r.kind, bool(r.available), tuple(int(c) for c in r.capabilities), float(r.payload),
                        r.current_task, float(r.busy_for), (float(r.pose.x), float(r.pose.y), float(r.pose.theta)))
              for r in msg.robots))


def graph_to_msg(snap: GraphSnapshot, frame_id: str = "map") -> TaskGraph:
    msg = _stamped(TaskGraph(), snap, frame_id)
    for t in snap.tasks:
        msg.tasks.append(Task(id=t.id, status=int(t.status), capabilities=list(t.capabilities),
                              payload=float(t.payload), duration=float(t.duration),
                              prerequisites=list(t.prerequisites), assigned_robots=list(t.assigned_robots),
                              start_time=to_time(t.start or 0.0), end_time=to_time(t.end or 0.0)))
    return msg


def graph_from_msg(msg: Any) -> GraphSnapshot:
    tasks = []
    for t in msg.tasks:
        status = int(t.status)
        start = from_time(t.start_time) if status >= Task.STATUS_ASSIGNED else None
        end = from_time(t.end_time) if status == Task.STATUS_DONE else None
        tasks.append(TaskInfo(t.id, status, tuple(int(c) for c in t.capabilities), float(t.payload),
                              float(t.duration), tuple(t.prerequisites), tuple(t.assigned_robots), start, end))
    return GraphSnapshot(from_time(msg.header.stamp), tuple(msg.capability_names), tuple(tasks))


def decision_to_msg(d: OnlineDecision, policy: str, stamp: Time) -> AssignmentArray:
    msg = AssignmentArray()
    msg.header.stamp = stamp
    msg.decision_step = d.step
    msg.policy = policy
    msg.assignments = [Assignment(task_id=t, robot_ids=list(robots)) for t, robots in d.assignments]
    msg.waiting_robot_ids = list(d.waiting)
    msg.decision_latency = to_duration(d.latency)
    msg.team_stamp = to_time(d.team_stamp)
    msg.graph_stamp = to_time(d.graph_stamp)
    return msg


def log(node_name: str, text: str) -> None:
    sys.stderr.write(f"[{node_name}] {text}\n")
    sys.stderr.flush()
