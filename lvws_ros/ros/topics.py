"""Topic names and QoS profiles of a run: every topic once, with its type and QoS.

Every name is relative, so a node's namespace moves all of them: in the root namespace
``lvws/team_state`` is ``/lvws/team_state``; with ``--ros-args -r __ns:=/cellA`` it is
``/cellA/lvws/team_state``. Health goes to ``diagnostics`` (``/diagnostics`` in the root
namespace, as diagnostic_aggregator expects; ``/cellA/diagnostics`` in a cell, with the
node's fully qualified name as ``hardware_id``). The simulator publishes ``clock`` (so does a
dispatcher with ``publish_clock``, its cell's clock at a rate other than 1); nodes on
sim time in a namespace take it with ``-r /clock:=clock`` (``lvws launch --namespace``
passes it), so two cells on one domain keep two clocks.
"""

from __future__ import annotations

import importlib
from typing import Any

from rclpy.publisher import Publisher
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from lvws_ros.rosbase.goals import PLANNED_STARTS_QOS, PLANNED_STARTS_TOPIC

TEAM_TOPIC = "lvws/team_state"
GRAPH_TOPIC = "lvws/task_graph"
ASSIGNMENTS_TOPIC = "lvws/assignments"
MARKERS_TOPIC = "lvws/markers"
DIAGNOSTICS_TOPIC = "diagnostics"
CLOCK_TOPIC = "clock"
GOAL_EVENTS_TOPIC = "lvws/goal_events"
CHANGES_TOPIC = "lvws/changes"  # the change-only protocol (docs/ros.md): numbered CellChanges
RESYNC_SERVICE = "lvws/resync"  # its snapshots on request (lvws_msgs/srv/Resync)
CLOCK_REMAP = ("-r", "/clock:=clock")  # a namespaced node on sim time reads its cell's clock

TEAM_QOS = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
# latched: late joiners get the current graph
GRAPH_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
ASSIGNMENTS_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
MARKERS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
DIAGNOSTICS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
GOAL_EVENTS_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.VOLATILE)
CHANGES_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
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
    GOAL_EVENTS_TOPIC: ("lvws_msgs/msg/GoalEvent", GOAL_EVENTS_QOS),  # the dispatcher's (a world of real robots)
    CHANGES_TOPIC: ("lvws_msgs/msg/CellChanges", CHANGES_QOS),  # a world that speaks changes
    PLANNED_STARTS_TOPIC: ("lvws_msgs/msg/PlannedStart", PLANNED_STARTS_QOS),  # the dispatcher's, to the robots
}


def split_topic(name: str) -> tuple[str, str] | None:
    """(namespace, relative name of TOPICS) of a fully qualified topic name, e.g.
    ``/cellA/lvws/team_state`` -> (``/cellA``, ``lvws/team_state``); None for a topic
    that is not one of a run's."""
    for rel in TOPICS:
        if name == f"/{rel}":
            return "/", rel
        if name.endswith(f"/{rel}") and name.startswith("/"):
            return name[: -len(rel) - 1], rel
    return None


def message_class(type_name: str) -> Any:
    """The rclpy message class of 'pkg/msg/Name'."""
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def state_audience(team_pub: Publisher, graph_pub: Publisher) -> int:
    """How many nodes take a world's state: the fewer of the TeamState and TaskGraph
    subscribers (a recorder matched on one topic and not yet on the other would miss the
    first state on the other)."""
    return min(team_pub.get_subscription_count(), graph_pub.get_subscription_count())
