"""Topic names and QoS profiles of a run: every topic once, with its type and QoS."""

from __future__ import annotations

import importlib
from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

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
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)
