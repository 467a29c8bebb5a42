"""The one conversion between messages and the core's snapshots and decisions.

``*_from_msg`` read any object with the message's fields, so they serve rclpy
messages in the nodes and rosbags' deserialized messages in the bag reader alike.
"""

from __future__ import annotations

import array
import math
import operator
from typing import Any

from builtin_interfaces.msg import Duration, Time
from lvws_msgs.msg import (
    Assignment,
    AssignmentArray,
    CellChanges,
    CellTask,
    GoalEvent,
    InstanceTask,
    PlannedStart,
    RobotState,
    Site,
    Task,
    TaskGraph,
    TeamState,
)
from rclpy.serialization import deserialize_message

from lvws_ros.core.changes import CellChanges as Changes
from lvws_ros.core.dispatch import GoalNews, Moved
from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import GraphSnapshot, OnlineDecision, RobotInfo, TaskInfo, TeamSnapshot
from lvws_ros.errors import ConfigError, InstanceError
from lvws_ros.ros.serialized import Unreadable, layout_of
from lvws_ros.sim.config import PART_PAYLOAD

__all__ = [
    "GraphReader",
    "TeamReader",
    "cell_task_from_msg",
    "cell_task_to_msg",
    "changes_from_msg",
    "changes_to_msg",
    "decision_from_msg",
    "decision_to_msg",
    "from_time",
    "goal_event_to_msg",
    "graph_from_msg",
    "graph_to_msg",
    "instance_task_from_msg",
    "instance_task_to_msg",
    "planned_start_to_msg",
    "team_from_msg",
    "team_to_msg",
    "to_duration",
    "to_time",
]


def to_time(seconds: float) -> Time:
    if not math.isfinite(seconds) or seconds < 0:
        seconds = 0.0
    sec = int(seconds)
    return Time(sec=sec, nanosec=min(round((seconds - sec) * 1e9), 999_999_999))


def from_time(t: Any) -> float:
    """Seconds of a builtin_interfaces Time or Duration."""
    return _seconds(t.sec, t.nanosec)


def _seconds(sec: int, nanosec: int) -> float:
    return float(sec) + float(nanosec) * 1e-9


def to_duration(seconds: float) -> Duration:
    sec = int(seconds)
    return Duration(sec=sec, nanosec=min(round((seconds - sec) * 1e9), 999_999_999))


def _stamped(msg: Any, snap: TeamSnapshot | GraphSnapshot, frame_id: str) -> Any:
    msg.header.stamp = to_time(snap.stamp)
    msg.header.frame_id = frame_id
    msg.capability_names = list(snap.capability_names)
    msg.trait_names = list(snap.trait_names)
    return msg


def team_to_msg(snap: TeamSnapshot, frame_id: str = "map") -> TeamState:
    msg = _stamped(TeamState(), snap, frame_id)
    msg.robots = [_robot_msg(r) for r in snap.robots]
    return msg


def _robot_msg(r: RobotInfo) -> RobotState:
    rs = RobotState(id=r.id, kind=r.kind, available=r.available, capabilities=list(r.capabilities),
                    payload=float(r.payload), current_task=r.current_task, busy_for=float(r.busy_for),
                    site=r.site, speed=float(r.speed), traits=[float(a) for a in r.traits], home=r.home)
    rs.pose.x, rs.pose.y, rs.pose.theta = r.pose
    return rs


def team_from_msg(msg: Any) -> TeamSnapshot:
    """(Messages recorded before the travel fields read as zero travel, before the trait
    fields as no traits.)"""
    return TeamSnapshot(from_time(msg.header.stamp), tuple(msg.capability_names),
                        tuple(_robot_info(r) for r in msg.robots), tuple(getattr(msg, "trait_names", ())))


def _robot_info(r: Any) -> RobotInfo:
    if hasattr(r, "home"):
        return _robot_of_fields(r.id, _robot_fields(r))
    p = r.pose  # recorded before the travel or trait fields
    return RobotInfo(r.id, r.kind, bool(r.available), _numbers(r.capabilities, int), float(r.payload),
                     r.current_task, float(r.busy_for), (float(p.x), float(p.y), float(p.theta)),
                     str(getattr(r, "site", "")), float(getattr(r, "speed", 0.0)),
                     _numbers(getattr(r, "traits", ()), float), "")


def graph_to_msg(snap: GraphSnapshot, frame_id: str = "map") -> TaskGraph:
    msg = _stamped(TaskGraph(), snap, frame_id)
    msg.tasks = [_task_msg(t) for t in snap.tasks]
    msg.sites = [Site(id=name, x=float(x), y=float(y)) for name, x, y in snap.sites]
    msg.site_distances = [float(d) for d in snap.distances]
    msg.roles, msg.objective, msg.departure = bool(snap.roles), snap.objective, snap.departure
    return msg


def _task_msg(t: TaskInfo) -> Task:
    return Task(id=t.id, status=int(t.status), capabilities=list(t.capabilities), payload=float(t.payload),
                duration=float(t.duration), prerequisites=list(t.prerequisites), assigned_robots=list(t.assigned_robots),
                start_time=to_time(t.start or 0.0), end_time=to_time(t.end or 0.0), site_from=t.site_from,
                site_to=t.site_to, requires=[float(a) for a in t.requires], roles=int(t.roles))


def changes_to_msg(ch: Changes, frame_id: str = "map") -> CellChanges:
    msg = CellChanges(seq=ch.seq, tasks=[_task_msg(t) for t in ch.tasks], tasks_cancelled=list(ch.cancelled),
                      tasks_retired=list(ch.retired), robots=[_robot_msg(r) for r in ch.robots],
                      robots_left=list(ch.left))
    msg.header.stamp = to_time(ch.stamp)
    msg.header.frame_id = frame_id
    return msg


def changes_from_msg(msg: Any) -> Changes:
    """A CellChanges message as the core's batch (its tasks and robots read as the
    snapshot readers read them)."""
    return Changes(int(msg.seq), from_time(msg.header.stamp),
                   tuple(_task_of_fields(t.id, _task_fields(t)) for t in msg.tasks), tuple(msg.tasks_cancelled),
                   tuple(msg.tasks_retired), tuple(_robot_of_fields(r.id, _robot_fields(r)) for r in msg.robots),
                   tuple(msg.robots_left))


_ASSIGNED, _DONE = int(TaskStatus.ASSIGNED), int(TaskStatus.DONE)  # ints: compared for every task of every graph


def _numbers(values: Any, kind: type) -> tuple[Any, ...]:
    """A sequence field as a tuple of plain ints or floats (rclpy gives array.array, a bag
    reader numpy arrays: both have tolist, which is what makes this quick)."""
    out = values.tolist() if hasattr(values, "tolist") else values
    return tuple(out) if all(type(v) is kind for v in out) else tuple(kind(v) for v in out)


def graph_from_msg(msg: Any) -> GraphSnapshot:
    newer = bool(msg.tasks) and hasattr(msg.tasks[0], "requires")  # bags of the first format lack the travel/trait fields
    return _graph(msg, tuple(_task_info(t, newer) for t in msg.tasks))


def _graph(msg: Any, tasks: tuple[TaskInfo, ...]) -> GraphSnapshot:
    sites = tuple((str(s.id), float(s.x), float(s.y)) for s in getattr(msg, "sites", ()))
    return GraphSnapshot(from_time(msg.header.stamp), tuple(msg.capability_names), tasks, sites,
                         tuple(float(d) for d in getattr(msg, "site_distances", ())),
                         tuple(getattr(msg, "trait_names", ())), bool(getattr(msg, "roles", False)),
                         str(getattr(msg, "objective", "")), str(getattr(msg, "departure", "")))


def _task_info(t: Any, newer: bool) -> TaskInfo:
    if newer:
        return _task_of_fields(t.id, _task_fields(t))
    status = int(t.status)  # recorded before the travel and trait fields
    start = from_time(t.start_time) if status >= _ASSIGNED else None
    end = from_time(t.end_time) if status == _DONE else None
    return TaskInfo(t.id, status, _numbers(t.capabilities, int), float(t.payload), float(t.duration),
                    tuple(t.prerequisites), tuple(t.assigned_robots), start, end, str(getattr(t, "site_from", "")),
                    str(getattr(t, "site_to", "")), tuple(float(a) for a in getattr(t, "requires", ())),
                    int(getattr(t, "roles", 0)))


_SEQUENCES = (array.array, list, tuple)  # fields compared as they come (a bag reader's numpy arrays are not)


class _Reader:
    """What the incremental readers share: each item's fields as the last message had them
    (by id) and what they were converted to; an item whose fields are all as before keeps
    its converted object (the snapshot is equal to the whole conversion's, and an unchanged
    item is the very same object, which the core's checks and caches recognise)."""

    def __init__(self) -> None:
        self._raw: dict[str, tuple[Any, ...]] = {}
        self._info: dict[str, Any] = {}

    def forget(self) -> None:
        self._raw, self._info = {}, {}

    def _plain(self, items: Any, last_field: str, sequences: tuple[str, str]) -> bool:
        """Whether ``items`` can be read field by field: there are some, the first has the
        message's newest field ``last_field``, and its ``sequences`` are plain sequences
        (not a bag reader's arrays). If not, what was kept is forgotten."""
        if items and hasattr(items[0], last_field) and all(isinstance(getattr(items[0], f), _SEQUENCES)
                                                          for f in sequences):
            return True
        self.forget()
        return False

    def _items(self, items: Any, key_of: Any, fields: Any, convert: Any, copy: Any) -> tuple[Any, ...]:
        raw_of, info_of = self._raw, self._info
        raw: dict[str, tuple[Any, ...]] = {}
        info: dict[str, Any] = {}
        out = []
        for item in items:
            key = key_of(item)
            now = fields(item)
            old = raw_of.get(key)
            if old is not None and old == now:
                got = info_of[key]
            else:
                got = convert(key, now)
                now = copy(now)  # a message may be reused
            if key not in raw:  # a duplicate id: the core's check says so
                raw[key], info[key] = now, got
            out.append(got)
        self._raw, self._info = raw, info
        return tuple(out)


_TASK_FIELDS = ("status", "capabilities", "payload", "duration", "prerequisites", "assigned_robots", "start_time.sec",
                "start_time.nanosec", "end_time.sec", "end_time.nanosec", "site_from", "site_to", "requires", "roles")
_ROBOT_FIELDS = ("kind", "available", "capabilities", "payload", "current_task", "busy_for", "pose.x", "pose.y",
                 "pose.theta", "site", "speed", "traits", "home")
_task_fields = operator.attrgetter(*_TASK_FIELDS)  # every field of a Task (a C-level read of each)
_robot_fields = operator.attrgetter(*_ROBOT_FIELDS)  # every field of a RobotState


def _slot_getter(names: tuple[str, ...]) -> Any:
    """The getter of ``names`` (dotted paths) that reads an rclpy message's slots (``_status``
    for ``status``): the generated classes keep each field in the slot of its name with an
    underscore, and their properties return it as it is, so this reads the same values
    without a Python call per field."""
    return operator.attrgetter(*(".".join(f"_{part}" for part in name.split(".")) for name in names))


_task_slots, _robot_slots = _slot_getter(_TASK_FIELDS), _slot_getter(_ROBOT_FIELDS)


def _fields_of(item: Any, by_property: Any, by_slot: Any) -> Any:
    """``by_slot`` where ``item`` is a generated rclpy message whose slots (its nested
    messages' too) are its fields' names with an underscore, else ``by_property``."""
    try:
        if by_slot(item) == by_property(item):
            return by_slot
    except AttributeError:
        pass
    return by_property


def _task_copy(f: tuple[Any, ...]) -> tuple[Any, ...]:  # the fields with their sequences copied
    return f[0], f[1][:], f[2], f[3], f[4][:], f[5][:], *f[6:12], f[12][:], f[13]


def _robot_copy(f: tuple[Any, ...]) -> tuple[Any, ...]:
    return *f[:2], f[2][:], *f[3:11], f[11][:], f[12]


def _task_of_fields(key: str, f: tuple[Any, ...]) -> TaskInfo:
    """:func:`_task_info` of a Task whose fields :data:`_task_fields` read."""
    status = int(f[0])
    return TaskInfo(key, status, _numbers(f[1], int), float(f[2]), float(f[3]), tuple(f[4]), tuple(f[5]),
                    _seconds(f[6], f[7]) if status >= _ASSIGNED else None, _seconds(f[8], f[9]) if status == _DONE
                    else None, str(f[10]), str(f[11]), _numbers(f[12], float), int(f[13]))


def _robot_of_fields(key: str, f: tuple[Any, ...]) -> RobotInfo:
    """:func:`_robot_info` of a RobotState whose fields :data:`_robot_fields` read."""
    return RobotInfo(key, f[0], bool(f[1]), _numbers(f[2], int), float(f[3]), f[4], float(f[5]),
                     (float(f[6]), float(f[7]), float(f[8])), str(f[9]), float(f[10]), _numbers(f[11], float),
                     str(f[12]))


_item_id = operator.attrgetter("id")


class _Serialized:
    """How a snapshot message's serialized bytes read (:mod:`~lvws_ros.ros.serialized`):
    its flat fields by name (:attr:`names`), and the getters of an item's id (:attr:`key`)
    and of its other fields in the order the conversions take them (:attr:`fields`). Where
    the message class has fields that reader does not take, or its items lack one of these,
    every message is left to rclpy (:attr:`layout` None)."""

    def __init__(self, cls: Any, item_cls: Any, fields: tuple[str, ...]) -> None:
        self.cls = cls
        self.layout: Any = None
        try:
            layout, item_names = layout_of(cls), layout_of(item_cls).names
            positions = [item_names.index(name) for name in ("id", *fields)]
        except (Unreadable, ValueError):
            return
        self.layout = layout
        self.key, self.fields = operator.itemgetter(positions[0]), operator.itemgetter(*positions[1:])

    def values(self, data: bytes) -> dict[str, Any] | Any:
        """The message's flat fields by name, or where they do not read here, the message
        as rclpy reads it; InstanceError for bytes neither reads."""
        if self.layout is not None:
            try:
                flat = self.layout.read(data)
            except ValueError:
                flat = None  # rclpy decides (bytes it refuses too are refused below)
            if flat is not None:
                return dict(zip(self.layout.names, flat, strict=True))
        try:
            return deserialize_message(data, self.cls)
        except Exception as exc:  # rclpy's RMWError and what a bad buffer raises
            raise InstanceError(f"a {self.cls.__name__} whose bytes do not read: {exc}") from None


_GRAPH_BYTES = _Serialized(TaskGraph, Task, _TASK_FIELDS)
_TEAM_BYTES = _Serialized(TeamState, RobotState, _ROBOT_FIELDS)


def _same(fields: tuple[Any, ...]) -> tuple[Any, ...]:  # tuples read from bytes are not reused
    return fields


class GraphReader(_Reader):
    """:func:`graph_from_msg` for the messages of one stream (the scheduler node's): equal
    snapshots, the work of a message in proportion to the tasks that changed since the
    previous one (plus a pass reading the fields). Messages without the travel and trait
    fields, or whose sequences are not plain (a bag reader's), are converted whole.
    :meth:`read_serialized` takes the message's serialized bytes instead."""

    def read(self, msg: Any) -> GraphSnapshot:
        tasks = msg.tasks
        if not self._plain(tasks, "requires", ("capabilities", "requires")):
            return graph_from_msg(msg)
        fields = _fields_of(tasks[0], _task_fields, _task_slots)
        return _graph(msg, self._items(tasks, _item_id, fields, _task_of_fields, _task_copy))

    def read_serialized(self, data: bytes) -> GraphSnapshot:
        """:meth:`read` of a TaskGraph's serialized bytes (a raw subscription's), without a
        message object per task."""
        v = _GRAPH_BYTES.values(data)
        if not isinstance(v, dict):
            return self.read(v)
        tasks = self._items(v["tasks"], _GRAPH_BYTES.key, _GRAPH_BYTES.fields, _task_of_fields, _same)
        return GraphSnapshot(_seconds(v["header.stamp.sec"], v["header.stamp.nanosec"]), v["capability_names"],
                             tasks, tuple(v["sites"]), v["site_distances"], v["trait_names"], v["roles"],
                             v["objective"], v["departure"])


_CHANGES_BYTES = _Serialized(CellChanges, Task, _TASK_FIELDS)


def changes_from_serialized(data: bytes) -> Changes:
    """:func:`changes_from_msg` of a CellChanges message's serialized bytes (a raw
    subscription's), without a message object per task or robot; InstanceError for bytes
    that do not read."""
    v = _CHANGES_BYTES.values(data)
    if not isinstance(v, dict) or _TEAM_BYTES.layout is None:
        return changes_from_msg(v if not isinstance(v, dict) else deserialize_message(data, CellChanges))
    task_key, task_fields = _GRAPH_BYTES.key, _GRAPH_BYTES.fields
    robot_key, robot_fields = _TEAM_BYTES.key, _TEAM_BYTES.fields
    return Changes(int(v["seq"]), _seconds(v["header.stamp.sec"], v["header.stamp.nanosec"]),
                   tuple(_task_of_fields(task_key(t), task_fields(t)) for t in v["tasks"]), tuple(v["tasks_cancelled"]),
                   tuple(v["tasks_retired"]), tuple(_robot_of_fields(robot_key(r), robot_fields(r)) for r in v["robots"]),
                   tuple(v["robots_left"]))


class TeamReader(_Reader):
    """:func:`team_from_msg` for the messages of one stream, as :class:`GraphReader`."""

    def read(self, msg: Any) -> TeamSnapshot:
        robots = msg.robots
        if not self._plain(robots, "home", ("capabilities", "traits")):
            return team_from_msg(msg)
        fields = _fields_of(robots[0], _robot_fields, _robot_slots)
        return TeamSnapshot(from_time(msg.header.stamp), tuple(msg.capability_names),
                            self._items(robots, _item_id, fields, _robot_of_fields, _robot_copy),
                            tuple(msg.trait_names))

    def read_serialized(self, data: bytes) -> TeamSnapshot:
        """:meth:`read` of a TeamState's serialized bytes, as :meth:`GraphReader.read_serialized`."""
        v = _TEAM_BYTES.values(data)
        if not isinstance(v, dict):
            return self.read(v)
        robots = self._items(v["robots"], _TEAM_BYTES.key, _TEAM_BYTES.fields, _robot_of_fields, _same)
        return TeamSnapshot(_seconds(v["header.stamp.sec"], v["header.stamp.nanosec"]), v["capability_names"],
                            robots, v["trait_names"])


def decision_to_msg(d: OnlineDecision, stamp: Time) -> AssignmentArray:
    msg = AssignmentArray()
    msg.header.stamp = stamp
    msg.decision_step = d.step
    msg.policy = d.policy
    msg.assignments = [Assignment(task_id=t, robot_ids=list(robots)) for t, robots in d.assignments]
    msg.waiting_robot_ids = list(d.waiting)
    msg.decision_latency = to_duration(d.latency)
    msg.team_stamp = to_time(d.team_stamp)
    msg.graph_stamp = to_time(d.graph_stamp)
    msg.state_latency = to_duration(d.state_latency)
    return msg


def decision_from_msg(msg: Any) -> OnlineDecision:
    return OnlineDecision(int(msg.decision_step), tuple((a.task_id, tuple(a.robot_ids)) for a in msg.assignments),
                          tuple(msg.waiting_robot_ids), from_time(msg.decision_latency), from_time(msg.team_stamp),
                          from_time(msg.graph_stamp), msg.policy,
                          from_time(msg.state_latency) if hasattr(msg, "state_latency") else 0.0,
                          from_time(msg.header.stamp))


def diagnostics_from_msg(msg: Any) -> list[dict[str, str]]:
    """A DiagnosticArray's statuses as flat dicts: name, level, message, hardware_id and
    each key-value pair."""
    return [{"name": s.name, "level": str(s.level), "message": s.message, "hardware_id": s.hardware_id,
             **{kv.key: kv.value for kv in s.values}} for s in msg.status]


def cell_task_to_msg(item: dict[str, Any], k: int = 0) -> CellTask:
    """A task entry of the cell config (``from``/``to`` or ``cell``) as a CellTask
    (ConfigError naming entry ``k``)."""
    try:
        requires = item.get("requires", {})
        if not isinstance(requires, dict):
            raise ConfigError(f"task {k}: requires must map trait names to amounts, got {requires!r}")
        return CellTask(id=str(item["id"]), type=str(item["type"]), object=str(item.get("object", "")),
                        source=str(item.get("from", "")), cell=str(item.get("to", item.get("cell", ""))),
                        duration=float(item.get("duration", 0.0)), payload=float(item.get("payload", PART_PAYLOAD)),
                        after=[str(a) for a in item.get("after", [])],
                        require_names=[str(n) for n in requires], requires=[float(v) for v in requires.values()])
    except KeyError as exc:
        raise ConfigError(f"task {k}: missing key {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"task {k}: {exc}") from None


def _requires_from_msg(msg: Any) -> dict[str, float]:
    """A task message's ``require_names`` and ``requires`` as the files' ``requires`` map
    (ConfigError naming the task when they do not pair up)."""
    names, amounts = list(msg.require_names), [float(v) for v in msg.requires]
    if len(names) != len(amounts):
        raise ConfigError(f"task {msg.id!r}: {len(names)} require_names but {len(amounts)} requires")
    if len(set(names)) != len(names):
        raise ConfigError(f"task {msg.id!r}: require_names names a trait twice: {names}")
    return dict(zip(names, amounts, strict=True))


def cell_task_from_msg(msg: Any) -> dict[str, Any]:
    """A CellTask as a task entry of the cell config (the inverse of :func:`cell_task_to_msg`)."""
    entry: dict[str, Any] = {"id": msg.id, "type": msg.type, "object": msg.object, "duration": msg.duration,
                             "payload": msg.payload, "after": list(msg.after)}
    if requires := _requires_from_msg(msg):
        entry["requires"] = requires
    if msg.type == "transport":
        entry.update({"from": msg.source, "to": msg.cell})
    else:
        entry["cell"] = msg.cell
    return entry


def goal_event_to_msg(news: GoalNews, stamp: float) -> GoalEvent:
    return GoalEvent(stamp=to_time(stamp), kind=int(news.kind), task_id=news.task, robot_id=news.robot,
                     phase=news.phase, progress=float(news.progress), site=news.site, duration=float(news.duration),
                     message=news.message)


def planned_start_to_msg(moved: Moved, planned_start: float, stamp: float) -> PlannedStart:
    """A start that moved: ``planned_start`` on the robots' clock (the dispatcher node's ROS
    time), stamped ``stamp`` (the cell's clock)."""
    msg = PlannedStart(task_id=moved.task, subteam=list(moved.subteam), planned_start=float(planned_start))
    msg.header.stamp = to_time(stamp)
    return msg


_ROLES = {None: InstanceTask.ROLES_DEFAULT, False: InstanceTask.ROLES_NO, True: InstanceTask.ROLES_YES}


def instance_task_to_msg(item: dict[str, Any], k: int = 0) -> InstanceTask:
    """A task object of an instance file (``capabilities``, ``payload``, ``requires``,
    ``duration``, ``after``, ``site`` or ``from``/``to``, ``roles``) as an InstanceTask
    (ConfigError naming entry ``k``)."""
    try:
        requires = item.get("requires", {})
        if not isinstance(requires, dict):
            raise ConfigError(f"task {k}: requires must map trait names to amounts, got {requires!r}")
        if item.get("roles") not in _ROLES:
            raise ConfigError(f"task {k}: roles must be true or false, got {item.get('roles')!r}")
        return InstanceTask(id=str(item["id"]), capabilities=[int(c) for c in item.get("capabilities", [])],
                            payload=float(item.get("payload", 0.0)), require_names=[str(n) for n in requires],
                            requires=[float(v) for v in requires.values()], duration=float(item["duration"]),
                            prerequisites=[str(a) for a in item.get("after", [])],
                            site=str(item.get("site", item.get("from", ""))), site_to=str(item.get("to", "")),
                            roles=_ROLES[item.get("roles")])
    except KeyError as exc:
        raise ConfigError(f"task {k}: missing key {exc}") from None
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"task {k}: {exc}") from None


def instance_task_from_msg(msg: Any) -> dict[str, Any]:
    """An InstanceTask as the instance file writes a task (the inverse of
    :func:`instance_task_to_msg`); the cell checks it."""
    entry: dict[str, Any] = {"id": msg.id, "payload": float(msg.payload), "duration": float(msg.duration),
                             "after": list(msg.prerequisites)}
    if len(msg.capabilities):
        entry["capabilities"] = [int(c) for c in msg.capabilities]
    if requires := _requires_from_msg(msg):
        entry["requires"] = requires
    if msg.site and msg.site_to and msg.site_to != msg.site:
        entry.update({"from": msg.site, "to": msg.site_to})
    elif msg.site:
        entry["site"] = msg.site
    roles = {InstanceTask.ROLES_NO: False, InstanceTask.ROLES_YES: True}.get(int(msg.roles))
    if roles is not None:
        entry["roles"] = roles
    return entry
