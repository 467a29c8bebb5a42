"""rosbag2 (MCAP) bags of runs, with rosbags: the type store, the one QoS <-> bag
conversion, writing, and reading a run back (``lvws report``/``verify``).

Messages read back go through :mod:`lvws_ros.ros.convert`, the same conversion the
nodes use.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability, QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from lvws_ros.core.changes import CellChanges, ChangeRefused, LiveCell
from lvws_ros.core.online import GraphSnapshot, OnlineDecision, TaskInfo, TeamSnapshot
from lvws_ros.errors import BagError
from lvws_ros.ros.convert import (
    changes_from_msg,
    decision_from_msg,
    diagnostics_from_msg,
    graph_from_msg,
    team_from_msg,
)
from lvws_ros.ros.resources import msg_dir
from lvws_ros.ros.topics import (
    ASSIGNMENTS_TOPIC,
    CHANGES_TOPIC,
    DIAGNOSTICS_TOPIC,
    GOAL_EVENTS_TOPIC,
    GRAPH_TOPIC,
    TEAM_TOPIC,
    split_topic,
)

__all__ = ["Run", "flush", "open_writer", "qos_from_bag", "qos_to_bag", "read_run", "reindex", "typestore"]

LVWS_TYPES = ("RobotState", "TeamState", "Site", "Task", "TaskGraph", "Assignment", "AssignmentArray", "GoalEvent",
              "CellChanges", "PlannedStart")


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


def flush(writer: Writer) -> None:
    """Put every message written so far on disk: the pending MCAP chunk is closed (rosbags'
    own ``close_chunk``) and the file flushed. A recorder calls this about once a second,
    so a killed recording loses at most that second (:func:`reindex` opens it again)."""
    storage = writer.storage
    if isinstance(storage, McapWriter):
        if any(storage.chunk.msgs.values()):
            storage.close_chunk()
        storage.bio.flush()


def _recover(mcap_file: Path) -> tuple[dict[int, Any], dict[int, Any], list[Any], bool]:
    """Schemas, channels and messages of every complete record of an MCAP file, however
    it ends (a killed writer leaves no summary and maybe half a chunk); and whether it was
    cut short."""
    from mcap.records import Channel, Message, Schema
    from mcap.stream_reader import StreamReader

    schemas: dict[int, Any] = {}
    channels: dict[int, Any] = {}
    messages: list[Any] = []
    truncated = False
    with mcap_file.open("rb") as f:
        try:
            for record in StreamReader(f, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
        except Exception:  # the cut-off end of a killed recording, whatever mcap calls it
            truncated = True
    return schemas, channels, messages, truncated


def reindex(path: str | Path) -> tuple[int, int]:
    """``lvws reindex BAG`` (``ros2 bag reindex``): rebuild a bag whose recorder was killed.

    Every complete message of the bag's MCAP file is written again with rosbags into a
    proper MCAP file (chunk indexes, summary) with a new ``metadata.yaml``, so rosbags'
    AnyReader and the ``mcap`` reader open it. The original file is kept beside it as
    ``<name>.mcap.orig``. Returns (messages kept, connections)."""
    from rosbags.rosbag2.metadata import parse_qos

    bag = Path(path)
    files = sorted(bag.glob("*.mcap")) if bag.is_dir() else []
    if len(files) != 1:
        raise BagError(f"{bag}: expected a bag folder with one .mcap file, found {[f.name for f in files]}")
    orig = files[0].with_name(files[0].name + ".orig")
    if orig.exists():
        raise BagError(f"{orig}: exists (the bag was reindexed already); move it away to reindex again")
    schemas, channels, messages, _ = _recover(files[0])
    if not channels:
        raise BagError(f"{files[0]}: no complete channel record: nothing to recover")
    tmp = bag.with_name(bag.name + ".reindex")
    if tmp.exists():
        raise BagError(f"{tmp}: exists (a previous reindex was interrupted); remove it first")
    store = typestore()
    writer = open_writer(tmp)
    try:
        conns = {}
        for cid, ch in sorted(channels.items()):
            qos = parse_qos(ch.metadata.get("offered_qos_profiles", "")) if ch.metadata.get("offered_qos_profiles") else []
            conns[cid] = writer.add_connection(ch.topic, schemas[ch.schema_id].name, typestore=store,
                                               offered_qos_profiles=qos)
        for m in sorted(messages, key=lambda m: (m.log_time, m.sequence)):
            writer.write(conns[m.channel_id], m.log_time, m.data)
    except Exception as exc:
        writer.close()
        shutil.rmtree(tmp, ignore_errors=True)
        raise BagError(f"{bag}: cannot rebuild ({type(exc).__name__}: {exc})") from None
    writer.close()
    files[0].rename(orig)
    (tmp / f"{tmp.name}.mcap").rename(bag / files[0].name)
    (bag / "metadata.yaml").write_text((tmp / "metadata.yaml").read_text().replace(f"{tmp.name}.mcap", files[0].name))
    shutil.rmtree(tmp)
    return len(messages), len(conns)


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
    goal_events: list[tuple[int, str, str]] = field(default_factory=list)  # (kind, task, robot): a dispatcher's
    duration_ns: int = 0
    namespace: str = "/"  # the cell's namespace (its topics' prefix)
    changes: list[CellChanges] = field(default_factory=list)  # a world that speaks changes (CellChanges)
    retired: list[TaskInfo] = field(default_factory=list)  # done work that left the live cell, as last said
    said_prerequisites: dict[str, tuple[str, ...]] = field(default_factory=dict)  # before retirement stripped them

    def whole_graph(self) -> GraphSnapshot:
        """The last task graph with the tasks that retired before it (their prerequisites as
        the world said them): every task the run ever held."""
        last = self.graphs[-1]
        if not self.retired:
            return last
        live = tuple(replace(t, prerequisites=self.said_prerequisites.get(t.id, t.prerequisites)) for t in last.tasks)
        return replace(last, tasks=tuple(self.retired) + live)


def _replay_changes(run: Run) -> None:
    """A bag of a world that speaks changes: its first snapshots and the changes after them
    become the snapshots each change gives (``teams``/``graphs`` as a snapshot world's); the
    tasks that retired are kept aside (:meth:`Run.whole_graph`)."""
    if not run.changes or not run.teams or not run.graphs:
        return
    # the first snapshot pair (a world may have sent a TaskGraph alone before its first robot
    # was up: the pair is the graph stamped as the first TeamState); what was recorded stays
    team0 = run.teams[0]
    graph0 = next((g for g in run.graphs if abs(g.stamp - team0.stamp) < 1e-9), run.graphs[0])
    cell = LiveCell(team0, graph0)
    teams, graphs = list(run.teams), list(run.graphs)
    said = {t.id: t for t in graph0.tasks}  # each task as the world last sent it
    for ch in sorted(run.changes, key=lambda c: c.seq):
        if ch.seq <= cell.seq:
            continue
        if ch.seq != cell.seq + 1:
            raise BagError(f"{run.path}: CellChanges {cell.seq + 1}-{ch.seq - 1} are not in the bag")
        try:
            cell.apply(ch)
        except ChangeRefused as exc:
            raise BagError(f"{run.path}: {exc}") from None
        said.update((t.id, t) for t in ch.tasks)
        for tid in ch.retired:
            run.retired.append(said.pop(tid))
        for tid in ch.cancelled:
            said.pop(tid, None)
        team, graph = cell.snapshots()
        teams.append(team)
        graphs.append(graph)
    run.teams, run.graphs = teams, graphs
    run.said_prerequisites = {t.id: said[t.id].prerequisites for t in graphs[-1].tasks
                              if t.id in said and said[t.id].prerequisites != t.prerequisites}


def _add(run: Run, topic: str, msg: Any) -> None:
    if topic == TEAM_TOPIC:
        run.teams.append(team_from_msg(msg))
    elif topic == GRAPH_TOPIC:
        run.graphs.append(graph_from_msg(msg))
    elif topic == ASSIGNMENTS_TOPIC:
        run.decisions.append(decision_from_msg(msg))
    elif topic == GOAL_EVENTS_TOPIC:
        run.goal_events.append((int(msg.kind), str(msg.task_id), str(msg.robot_id)))
    elif topic == CHANGES_TOPIC:
        run.changes.append(changes_from_msg(msg))
    else:
        run.diagnostics.extend(diagnostics_from_msg(msg))


def read_run(path: str | Path) -> Run:
    """Every team, graph, decision and diagnostics message of a bag (rosbags AnyReader),
    whatever the namespace of its cell; a bag that holds several cells is refused."""
    from rosbags.highlevel import AnyReader

    p = Path(path)
    if not p.exists():
        raise BagError(f"{p}: no such bag")
    wanted = (TEAM_TOPIC, GRAPH_TOPIC, ASSIGNMENTS_TOPIC, DIAGNOSTICS_TOPIC, GOAL_EVENTS_TOPIC, CHANGES_TOPIC)
    try:
        with AnyReader([p], default_typestore=typestore()) as reader:
            run = Run(p, {c.topic: c.msgcount for c in reader.connections}, duration_ns=reader.duration)
            names = {c.topic: split_topic(c.topic) for c in reader.connections}
            cells = sorted({n[0] for n in names.values() if n is not None and n[1] in wanted[:3]})
            if len(cells) > 1:
                raise BagError(f"{p}: holds the topics of several cells ({', '.join(cells)}); record one cell per bag")
            run.namespace = cells[0] if cells else "/"
            for conn, _t_ns, raw in reader.messages():
                name = names[conn.topic]
                if name is not None and name[1] in wanted and (name[1] != DIAGNOSTICS_TOPIC or name[0] == run.namespace):
                    _add(run, name[1], reader.deserialize(raw, conn.msgtype))
        _replay_changes(run)
    except BagError:
        raise
    except Exception as exc:  # rosbags raises many kinds on a broken bag
        raise BagError(f"{p}: not a readable rosbag2 bag ({type(exc).__name__}: {exc})") from None
    return run
