"""rosbag2 (MCAP) bags of runs, with rosbags: the type store, writing, and reading a run back.

ROS-free: the recorder node writes through :func:`open_writer`; ``lvws report`` and
``lvws verify`` read through :func:`read_run` (rosbags AnyReader, types from the bag).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from lvws_ros.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot

LVWS_TYPES = ("RobotState", "TeamState", "Task", "TaskGraph", "Assignment", "AssignmentArray")


class BagError(ValueError):
    """A bag that cannot be read as a run (missing, truncated, wrong topics)."""


def msg_dir() -> Path:
    """lvws_msgs' .msg files: the installed share directory, else msg_defs/ of the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory

        p = Path(get_package_share_directory("lvws_msgs")) / "msg"
        if p.is_dir():
            return p
    except Exception:
        pass
    return Path(__file__).resolve().parent.parent / "msg_defs" / "msg"


def typestore() -> Typestore:
    """ROS 2 Jazzy types plus lvws_msgs, registered from the .msg definitions."""
    store = get_typestore(Stores.ROS2_JAZZY)
    types: dict[str, Any] = {}
    for name in LVWS_TYPES:
        types.update(get_types_from_msg((msg_dir() / f"{name}.msg").read_text(), f"lvws_msgs/msg/{name}"))
    store.register(types)
    return store


def qos_to_bag(depth: int, reliable: bool, transient_local: bool) -> Qos:
    never = QosTime(sec=0x7FFFFFFF, nsec=0xFFFFFFFF)
    return Qos(
        history=QosHistory.KEEP_LAST, depth=depth,
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=never, lifespan=never, liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=never,
        avoid_ros_namespace_conventions=False)


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
class Decision:
    """One recorded AssignmentArray."""

    time_ns: int
    step: int
    policy: str
    assignments: list[tuple[str, tuple[str, ...]]]
    waiting: tuple[str, ...]
    latency: float
    team_stamp: float
    graph_stamp: float


@dataclass
class Run:
    """What a bag says about a run."""

    path: Path
    topics: dict[str, int]  # topic -> message count
    teams: list[TeamSnapshot] = field(default_factory=list)
    graphs: list[GraphSnapshot] = field(default_factory=list)
    decisions: list[Decision] = field(default_factory=list)
    diagnostics: list[dict[str, str]] = field(default_factory=list)
    duration_ns: int = 0


def _stamp(t: Any) -> float:
    return float(t.sec) + float(t.nanosec) * 1e-9


def team_from_bag(msg: Any) -> TeamSnapshot:
    return TeamSnapshot(_stamp(msg.header.stamp), tuple(msg.capability_names), tuple(
        RobotInfo(r.id, r.kind, bool(r.available), tuple(int(c) for c in r.capabilities), float(r.payload),
                  r.current_task, float(r.busy_for), (float(r.pose.x), float(r.pose.y), float(r.pose.theta)))
        for r in msg.robots))


def graph_from_bag(msg: Any) -> GraphSnapshot:
    tasks = []
    for t in msg.tasks:
        status = int(t.status)
        tasks.append(TaskInfo(t.id, status, tuple(int(c) for c in t.capabilities), float(t.payload),
                              float(t.duration), tuple(t.prerequisites), tuple(t.assigned_robots),
                              _stamp(t.start_time) if status >= 2 else None,
                              _stamp(t.end_time) if status == 3 else None))
    return GraphSnapshot(_stamp(msg.header.stamp), tuple(msg.capability_names), tuple(tasks))


def read_run(path: str | Path) -> Run:
    """Every team, graph, decision and diagnostics message of a bag (rosbags AnyReader)."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag")
    try:
        with AnyReader([p], default_typestore=typestore()) as reader:
            run = Run(p, {c.topic: c.msgcount for c in reader.connections}, duration_ns=reader.duration)
            for conn, t_ns, raw in reader.messages():
                if conn.topic not in ("/lvws/team_state", "/lvws/task_graph", "/lvws/assignments", "/diagnostics"):
                    continue
                msg: Any = reader.deserialize(raw, conn.msgtype)
                if conn.topic == "/lvws/team_state":
                    run.teams.append(team_from_bag(msg))
                elif conn.topic == "/lvws/task_graph":
                    run.graphs.append(graph_from_bag(msg))
                elif conn.topic == "/lvws/assignments":
                    run.decisions.append(Decision(
                        t_ns, int(msg.decision_step), msg.policy,
                        [(a.task_id, tuple(a.robot_ids)) for a in msg.assignments], tuple(msg.waiting_robot_ids),
                        _stamp(msg.decision_latency), _stamp(msg.team_stamp), _stamp(msg.graph_stamp)))
                else:
                    for s in msg.status:
                        run.diagnostics.append({"name": s.name, "level": str(s.level), "message": s.message,
                                                **{kv.key: kv.value for kv in s.values}})
    except BagError:
        raise
    except Exception as exc:
        raise BagError(f"{p}: not a readable rosbag2 bag ({type(exc).__name__}: {exc})") from None
    return run


def topics_in(paths: Iterable[str | Path]) -> set[str]:
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(p) for p in paths], default_typestore=typestore()) as reader:
        return {c.topic for c in reader.connections}
