"""rosbag2 (MCAP) bags of runs, with rosbags: the type store, the one QoS <-> bag
conversion, writing, and reading a run back (``lvws report``/``verify``).

Messages read back go through :mod:`lvws_ros.ros.convert`, the same conversion the
nodes use.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from lvws_ros.core.online import GraphSnapshot, OnlineDecision, TeamSnapshot
from lvws_ros.errors import BagError
from lvws_ros.ros.convert import decision_from_msg, graph_from_msg, team_from_msg
from lvws_ros.ros.resources import msg_dir
from lvws_ros.ros.topics import ASSIGNMENTS_TOPIC, DIAGNOSTICS_TOPIC, GRAPH_TOPIC, TEAM_TOPIC

__all__ = ["Run", "open_writer", "qos_from_bag", "qos_to_bag", "read_run", "typestore"]

LVWS_TYPES = ("RobotState", "TeamState", "Task", "TaskGraph", "Assignment", "AssignmentArray")


def typestore() -> Typestore:
    """ROS 2 Jazzy types plus lvws_msgs, registered from the .msg definitions."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for name in LVWS_TYPES:
        types.update(get_types_from_msg((msg_dir() / f"{name}.msg").read_text(), f"lvws_msgs/msg/{name}"))
    store.register(types)
    return store


def qos_to_bag(qos: QoSProfile) -> Qos:
    """A topic's rclpy QoS as the bag records it (rosbags' offered QoS profile)."""
    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
    return Qos(
        history=QosHistory.KEEP_LAST, depth=qos.depth,
        reliability=QosReliability.RELIABLE if qos.reliability == ReliabilityPolicy.RELIABLE
        else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
        else QosDurability.VOLATILE,
        deadline=never, lifespan=never, liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False)


def qos_from_bag(conn: Any, min_depth: int = 1) -> QoSProfile:
    """The QoS a recorded connection offered (its first profile, depth at least
    ``min_depth``), else reliable and volatile."""
    profiles = getattr(conn.ext, "offered_qos_profiles", None) or []
    if not profiles:
        return QoSProfile(depth=min_depth, reliability=ReliabilityPolicy.RELIABLE)
    q = profiles[0]
    return QoSProfile(
        depth=max(int(q.depth), min_depth),
        reliability=ReliabilityPolicy.BEST_EFFORT if q.reliability == QosReliability.BEST_EFFORT
        else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if q.durability == QosDurability.TRANSIENT_LOCAL
        else DurabilityPolicy.VOLATILE)


def open_writer(path: str | Path) -> Writer:
    """An open rosbag2 writer (MCAP storage, metadata version 9). Close it in ``finally``."""
    p = Path(path)
    if p.exists():
        raise BagError(f"{p}: already exists (a bag is never overwritten)")
    p.parent.mkdir(parents=True, exist_ok=True)
    writer = Writer(p, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.open()
    return writer


@dataclass
class Run:
    """What a bag says about a run."""

    path: Path
    topics: dict[str, int]  # topic -> message count
    teams: list[TeamSnapshot] = field(default_factory=list)
    graphs: list[GraphSnapshot] = field(default_factory=list)
    decisions: list[OnlineDecision] = field(default_factory=list)
    diagnostics: list[dict[str, str]] = field(default_factory=list)
    duration_ns: int = 0


def _add(run: Run, topic: str, msg: Any) -> None:
    if topic == TEAM_TOPIC:
        run.teams.append(team_from_msg(msg))
    elif topic == GRAPH_TOPIC:
        run.graphs.append(graph_from_msg(msg))
    elif topic == ASSIGNMENTS_TOPIC:
        run.decisions.append(decision_from_msg(msg))
    else:
        for s in msg.status:
            run.diagnostics.append({"name": s.name, "level": str(s.level), "message": s.message,
                                    **{kv.key: kv.value for kv in s.values}})


def read_run(path: str | Path) -> Run:
    """Every team, graph, decision and diagnostics message of a bag (rosbags AnyReader)."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag")
    wanted = (TEAM_TOPIC, GRAPH_TOPIC, ASSIGNMENTS_TOPIC, DIAGNOSTICS_TOPIC)
    try:
        with AnyReader([p], default_typestore=typestore()) as reader:
            run = Run(p, {c.topic: c.msgcount for c in reader.connections}, duration_ns=reader.duration)
            for conn, _t_ns, raw in reader.messages():
                if conn.topic in wanted:
                    _add(run, conn.topic, reader.deserialize(raw, conn.msgtype))
    except Exception as exc:  # rosbags raises many kinds on a broken bag
        raise BagError(f"{p}: not a readable rosbag2 bag ({type(exc).__name__}: {exc})") from None
    return run
