"""Online scheduling from team and task-graph snapshots (the scheduler node's logic, ROS-free).

The scheduler node converts ``lvws_msgs/TeamState`` and ``lvws_msgs/TaskGraph`` into
the snapshots below and calls :class:`OnlineScheduler`; the simulator produces the
same snapshots directly, and ``lvws verify`` feeds recorded ones back. A decision step
happens whenever a robot becomes available or a task becomes ready (section III-A).

Robustness (the rules the scheduler node follows, whatever a message holds):

* A snapshot is checked before it is taken (:func:`check_team`, :func:`check_graph`):
  an out-of-range status, a non-finite or out-of-range number, a malformed vector or an
  unknown prerequisite id raises an InstanceError naming the message and the field, and
  the snapshot is ignored (the last good one stays).
* Order: a snapshot older than the newest one of its kind is dropped as out of order,
  unless it is more than ``restart_jump`` seconds older: then the world restarted (a
  simulator restart, or the newest stamp was bogus), the stamp order is reset, pending
  assignments are released, and a notice says so.
* Repeated snapshots trigger nothing (no new free robot, no new ready task).
* A robot is free only if the team says it is available, it has no ``current_task``,
  and no running or just-assigned task holds it; a busy robot whose ``busy_for`` is not
  a finite number is busy for as long as the longest task.
* A task is ready only if it is READY *and* all its prerequisites are DONE (checked
  here, not trusted).
* Assignments the world has not acknowledged within ``ack_timeout`` seconds of being sent
  (the decision's snapshots' time plus the time it took), or whose task or robots vanished
  from the latest snapshots, are released.

* Fallback: when the main policy cannot serve a step (it raises, e.g. a model that
  refuses the instance or gives non-finite rewards, or its decision breaks Eqs. 8-11),
  the ``fallback`` policy decides that step and a notice names both and the reason; the
  scheduler never stalls on its main policy. Without a fallback the error propagates.

What the node should report (restarts, releases, untrusted readiness, fallbacks)
collects in :attr:`OnlineScheduler.notices`.
"""

from __future__ import annotations

import functools
import graphlib
import math
import time
from collections.abc import Container, Mapping, Sequence, Set
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from lvws_ros.core.executor import Budgeted, Decision, Policy, State, TaskStatus, check_decision
from lvws_ros.core.problem import DEPARTURES, MAX_VALUE, OBJECTIVES, Instance, Robot, Task
from lvws_ros.core.subteams import covered, covers
from lvws_ros.core.travel import Travel, build_travel
from lvws_ros.errors import InstanceError

_STATUSES = frozenset(int(s) for s in TaskStatus)  # a plain set of ints: checked for every task of every graph
_READY, _ASSIGNED, _DONE, _QUEUED = (int(s) for s in (TaskStatus.READY, TaskStatus.ASSIGNED, TaskStatus.DONE,
                                                      TaskStatus.QUEUED))
BUSY_EPS = 1e-3  # a busy robot with an overdue estimate is still busy
RESTART_JUMP = 10.0  # seconds a stamp may go back before the world counts as restarted


@dataclass(frozen=True)
class RobotInfo:
    id: str
    kind: str
    available: bool
    capabilities: tuple[int, ...]
    payload: float
    current_task: str = ""
    busy_for: float = 0.0
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    site: str = ""  # travel: the site it is at when free ("": off every site, at its pose)
    speed: float = 0.0  # travel: > 0 mobile, 0 fixed at its site
    traits: tuple[float, ...] = ()  # amount of each of the snapshot's trait_names (formats.md, "Traits")
    home: str = ""  # return to base: the site it goes back to ("": its site)


@dataclass(frozen=True)
class TaskInfo:
    id: str
    status: int  # TaskStatus
    capabilities: tuple[int, ...]
    payload: float
    duration: float
    prerequisites: tuple[str, ...] = ()
    assigned_robots: tuple[str, ...] = ()
    start: float | None = None
    end: float | None = None
    site_from: str = ""  # travel: where its subteam meets
    site_to: str = ""  # travel: where its subteam is when it is done ("": site_from)
    requires: tuple[float, ...] = ()  # amount of each of the graph's trait_names its subteam adds up
    roles: int = 0  # 0: the graph's default, 1: no roles, 2: each member counts toward one trait


@dataclass(frozen=True)
class TeamSnapshot:
    stamp: float
    capability_names: tuple[str, ...]
    robots: tuple[RobotInfo, ...]
    trait_names: tuple[str, ...] = ()


@dataclass(frozen=True)
class GraphSnapshot:
    stamp: float
    capability_names: tuple[str, ...]
    tasks: tuple[TaskInfo, ...]
    # travel (none: zero travel): sites (name, x, y) and, optionally, the distance matrix
    # row-major over them (empty: straight lines between the coordinates)
    sites: tuple[tuple[str, float, float], ...] = ()
    distances: tuple[float, ...] = ()
    trait_names: tuple[str, ...] = ()  # traits, roles and the objective (formats.md, "Traits")
    roles: bool = False
    objective: str = ""  # "" or "makespan"; "return"
    # "" or "together": a subteam sets out together once its members are free; "each": a task
    # may be given to busy robots, each of whom sets out for it once free (formats.md, "departure")
    departure: str = ""


@dataclass(frozen=True)
class OnlineDecision:
    """A :class:`~lvws_ros.core.executor.Decision` by ids, as published on
    ``lvws/assignments`` and read back from bags."""

    step: int
    assignments: tuple[tuple[str, tuple[str, ...]], ...]
    waiting: tuple[str, ...]
    latency: float  # wall seconds spent deciding
    team_stamp: float
    graph_stamp: float
    policy: str = ""
    state_latency: float = 0.0  # wall seconds from the arrival of the state that made it due to its publication
    published: float = 0.0  # its stamp: when it went out on the node's clock, never before its inputs (0: unknown)


@dataclass(frozen=True)
class CellDelta:
    """What changed in a cell since the snapshot pair ``since`` (as a
    :class:`~lvws_ros.core.changes.LiveCell` that took numbered changes says it):
    :meth:`OnlineScheduler.offer_cell` takes the pair after it in time proportional to
    this, not to the cell, when ``since`` is the pair it holds. The snapshots it comes with
    were checked batch by batch; their robots' ``busy_for`` is as of the batch that last
    changed each, and ``until`` says when each busy robot is free (the cell's clock)."""

    since: tuple[TeamSnapshot, GraphSnapshot] | None  # None: the whole cell is new (a resync)
    tasks: frozenset[str]  # tasks added or changed (a prerequisite that left included)
    gone: Mapping[str, int]  # tasks that left -> their last status (DONE: retired, else cancelled)
    robots: frozenset[str]  # robots that joined or changed
    left: frozenset[str]  # robots that left
    watch: frozenset[str]  # tasks whose readiness may have changed: ``tasks`` and what waits on them
    by_id: Mapping[str, TaskInfo]  # the new graph's tasks by id
    until: Mapping[str, float]  # busy robots' end times
    checked: GraphSnapshot | None = None  # passed check_graph: its tasks (the same objects) are not checked again


def _finite(value: float, where: str, low: float = 0.0, high: float = MAX_VALUE) -> None:
    if not (math.isfinite(value) and low <= value <= high):
        raise InstanceError(f"{where}: {value!r} is not a finite number in [{low:g}, {high:g}]")


def _bits(values: Sequence[int], k: int, where: str) -> None:
    if len(values) != k or any(v not in (0, 1) for v in values):
        raise InstanceError(f"{where}: expected {k} entries of 0 or 1 (one per capability), got {list(values)[:20]}")


def _amounts(values: Sequence[float], names: Sequence[str], where: str) -> None:
    """Trait amounts: none, or one finite amount >= 0 per trait name."""
    if values and len(values) != len(names):
        raise InstanceError(f"{where}: {len(values)} amounts for {len(names)} trait_names (one each, or none)")
    for n, v in enumerate(values):
        _finite(v, f"{where}[{n}]")


TEAM_NEEDS = "TeamState: needs capability_names (or trait_names) and at least one robot"


def check_team(snap: TeamSnapshot, checked: TeamSnapshot | None = None) -> None:
    """InstanceError naming the TeamState field when the snapshot cannot be used.
    ``checked``: a snapshot that passed before; its robots that ``snap`` holds at the same
    places (the very same objects, as an incremental reader keeps them) are not checked again."""
    _finite(snap.stamp, "TeamState header.stamp", high=math.inf)
    k = len(snap.capability_names)
    if (k < 1 and not snap.trait_names) or not snap.robots:
        raise InstanceError(TEAM_NEEDS)
    ids = [r.id for r in snap.robots]
    if len(set(ids)) != len(ids):
        raise InstanceError(f"TeamState robots: duplicate ids {sorted({i for i in ids if ids.count(i) > 1})}")
    same = checked is not None and (checked.capability_names, checked.trait_names) == (snap.capability_names,
                                                                                      snap.trait_names)
    for n in _changed(snap.robots, checked.robots if same and checked is not None else ()):
        check_robot(snap, n, snap.robots[n])


def check_robot(snap: TeamSnapshot, n: int, r: RobotInfo) -> None:
    """InstanceError naming the field when robot ``r`` (``robots[n]``) cannot be one of ``snap``'s."""
    where = f"TeamState robots[{n}] ({r.id!r})"
    if not r.id:
        raise InstanceError(f"TeamState robots[{n}].id: empty")
    _bits(r.capabilities, len(snap.capability_names), f"{where}.capabilities")
    _finite(r.payload, f"{where}.payload")
    if r.payload <= 0 and not snap.trait_names:
        raise InstanceError(f"{where}.payload: must be > 0, got {r.payload!r}")
    _amounts(r.traits, snap.trait_names, f"{where}.traits")
    _finite(r.speed, f"{where}.speed")
    if 0 < r.speed < 1 / MAX_VALUE:
        raise InstanceError(f"{where}.speed: 0 (fixed) or at least {1 / MAX_VALUE:g}, got {r.speed!r}")


def _changed(items: Sequence[Any], before: Sequence[Any]) -> list[int]:
    """The places of ``items`` that do not hold the very object ``before`` holds there."""
    if len(before) != len(items):
        return list(range(len(items)))
    return [n for n, (a, b) in enumerate(zip(items, before, strict=True)) if a is not b]


def check_graph(snap: GraphSnapshot, checked: GraphSnapshot | None = None) -> None:
    """InstanceError naming the TaskGraph field when the snapshot cannot be used.
    ``checked``: a snapshot that passed before; with the same traits and sites, its tasks
    that ``snap`` holds (the very same objects, wherever they are) are not checked again,
    and a cycle is looked for among the new tasks only unless a known task waits on more
    than it did (:func:`_unchanged`)."""
    _finite(snap.stamp, "TaskGraph header.stamp", high=math.inf)
    ids = {t.id for t in snap.tasks}
    if len(ids) != len(snap.tasks) or "" in ids:
        raise InstanceError("TaskGraph tasks: ids must be unique and non-empty")
    if checked is not None and (checked.capability_names, checked.trait_names, checked.sites, checked.distances) \
            == (snap.capability_names, snap.trait_names, snap.sites, snap.distances):
        changed, cycles_among = _unchanged(snap, checked, ids)
    else:
        changed, cycles_among = list(range(len(snap.tasks))), None
    for n in changed:
        check_task(snap, n, snap.tasks[n], ids)
    if snap.objective not in ("", *OBJECTIVES):
        raise InstanceError(f"TaskGraph objective: '', 'makespan' or 'return', got {snap.objective[:40]!r}")
    if snap.departure not in ("", *DEPARTURES):
        raise InstanceError(f"TaskGraph departure: '', 'together' or 'each', got {snap.departure[:40]!r}")
    _check_sites(snap, changed)
    if cycles_among is None:
        check_acyclic(tuple((t.id, tuple(t.prerequisites)) for t in snap.tasks))
    elif cycles_among:
        check_acyclic(tuple(sorted((t.id, tuple(p for p in t.prerequisites if p in cycles_among))
                                   for t in snap.tasks if t.id in cycles_among)))


def _unchanged(snap: GraphSnapshot, checked: GraphSnapshot, ids: set[str]) -> tuple[list[int], set[str] | None]:
    """For :func:`check_graph` against ``checked``: the places of ``snap``'s tasks to check
    (those ``checked`` does not hold as the very same object; with tasks gone, also those
    naming one), and the ids among which a cycle may be (the new ones; None: anywhere).
    A cycle through a known task whose prerequisites are among those it had goes on
    through known tasks only, by edges ``checked`` had: it would have been found there."""
    before = {t.id: t for t in checked.tasks}
    changed = [n for n, t in enumerate(snap.tasks) if before.get(t.id) is not t]
    if len(snap.tasks) - len(changed) < len(before):  # tasks gone: those that still name one are checked
        gone = {k for k in before if k not in ids}
        named = {n for n, t in enumerate(snap.tasks) if not gone.isdisjoint(t.prerequisites)}
        changed = sorted(named.union(changed))
    new: set[str] = set()
    for n in changed:
        t = snap.tasks[n]
        old = before.get(t.id)
        if old is None:
            new.add(t.id)
        elif not set(t.prerequisites) <= set(old.prerequisites):
            return changed, None
    return changed, new


def check_task(snap: GraphSnapshot, n: int, t: TaskInfo, ids: Container[str]) -> None:
    """InstanceError naming the field when task ``t`` (``tasks[n]``) cannot be one of
    ``snap``'s (its sites aside: :func:`check_task_sites`); ``ids``: the graph's task ids."""
    k = len(snap.capability_names)
    where = f"TaskGraph tasks[{n}] ({t.id!r})"
    if t.status not in _STATUSES:
        raise InstanceError(f"{where}.status: {t.status} is not one of "
                            + ", ".join(f"{s.name}={s.value}" for s in TaskStatus))
    _bits(t.capabilities, k, f"{where}.capabilities")
    _amounts(t.requires, snap.trait_names, f"{where}.requires")
    if not any(t.capabilities) and not any(a > 0 for a in t.requires):
        raise InstanceError(f"{where}.capabilities: needs at least one capability"
                            + (" (or a trait in requires)" if snap.trait_names else ""))
    if t.roles not in (0, 1, 2):
        raise InstanceError(f"{where}.roles: 0 (the graph's), 1 (no) or 2 (yes), got {t.roles}")
    _finite(t.payload, f"{where}.payload")
    _finite(t.duration, f"{where}.duration")
    if t.duration <= 0:
        raise InstanceError(f"{where}.duration: must be > 0, got {t.duration!r}")
    unknown = [p for p in t.prerequisites if p not in ids]
    if unknown:
        raise InstanceError(f"{where}.prerequisites: unknown task id(s) {unknown}")
    if len(set(t.prerequisites)) != len(t.prerequisites):
        raise InstanceError(f"{where}.prerequisites: an id given twice")
    for name, value in (("start_time", t.start), ("end_time", t.end)):
        if value is not None:
            _finite(value, f"{where}.{name}", high=math.inf)


def _check_sites(snap: GraphSnapshot, tasks: Sequence[int] | None = None) -> None:
    """The travel part of a TaskGraph: unique named sites with finite coordinates, a
    distance matrix of |sites|^2 entries or none, every task (of ``tasks``, the places
    to check; None: all) at known sites."""
    names = [s[0] for s in snap.sites]
    if len(set(names)) != len(names) or "" in names:
        raise InstanceError("TaskGraph sites: ids must be unique and non-empty")
    taken = [n for n in names if n.startswith("@")]
    if taken:  # the sites of robots off every site (off_site)
        raise InstanceError(f"TaskGraph sites: id {taken[0]!r} starts with '@', which names robots' own sites")
    for n, (name, x, y) in enumerate(snap.sites):
        _finite(x, f"TaskGraph sites[{n}] ({name!r}).x", low=-MAX_VALUE)
        _finite(y, f"TaskGraph sites[{n}] ({name!r}).y", low=-MAX_VALUE)
    if snap.distances and len(snap.distances) != len(names) ** 2:
        raise InstanceError(f"TaskGraph site_distances: {len(snap.distances)} entries for {len(names)} sites "
                            f"(expected {len(names) ** 2}, row-major, or none)")
    for n, d in enumerate(snap.distances):
        _finite(d, f"TaskGraph site_distances[{n}]")
    known = set(names)
    for n in range(len(snap.tasks)) if tasks is None else tasks:
        check_task_sites(n, snap.tasks[n], known)


def check_task_sites(n: int, t: TaskInfo, known: Container[str]) -> None:
    """InstanceError naming the field when task ``t`` (``tasks[n]``) is not at the graph's
    sites ``known`` (none: a graph without sites)."""
    for field_, value in (("site_from", t.site_from), ("site_to", t.site_to)):
        if value and value not in known:
            raise InstanceError(f"TaskGraph tasks[{n}] ({t.id!r}).{field_}: unknown site {value!r}")
    if known and not t.site_from:
        raise InstanceError(f"TaskGraph tasks[{n}] ({t.id!r}).site_from: empty, but the graph has sites")


@functools.lru_cache(maxsize=4)
def check_acyclic(structure: tuple[tuple[str, tuple[str, ...]], ...]) -> None:
    """InstanceError on a cycle; memoised, since a world sends the same DAG step after step."""
    try:
        list(graphlib.TopologicalSorter(dict(structure)).static_order())
    except graphlib.CycleError as exc:
        raise InstanceError(f"TaskGraph prerequisites: cycle {' -> '.join(exc.args[1])}") from None


def trait_pairs(names: Sequence[str], amounts: Sequence[float]) -> tuple[tuple[str, float], ...]:
    """A snapshot's amounts (in the order of its trait names) as an instance's (trait,
    amount) pairs, the zeros left out."""
    if not names:  # a cell without traits: every item of it
        return ()
    return tuple((c, float(a)) for c, a in zip(names, amounts, strict=False) if a > 0)


def roles_of(code: int) -> bool | None:
    """``Task.roles`` of a message (0 the graph's, 1 no, 2 yes) as an instance task's."""
    return None if code == 0 else code == 2


def roles_code(roles: bool | None) -> int:
    """The inverse of :func:`roles_of`."""
    return 0 if roles is None else 1 + int(roles)


def build_instance(team: TeamSnapshot, graph: GraphSnapshot, name: str = "online", checked: bool = False) -> Instance:
    """The scheduling instance the snapshots describe (InstanceError on bad content).
    ``checked``: both passed :func:`check_team` and :func:`check_graph` (the graph, or
    the one it is a view of): each robot and task is not checked again."""
    if tuple(team.capability_names) != tuple(graph.capability_names):
        raise InstanceError(f"team capabilities {list(team.capability_names)} differ from the task graph's "
                            f"{list(graph.capability_names)}")
    if tuple(team.trait_names) != tuple(graph.trait_names):
        raise InstanceError(f"team traits {list(team.trait_names)} differ from the task graph's "
                            f"{list(graph.trait_names)}")
    traits = tuple(graph.trait_names)
    robots = tuple(Robot(r.id, tuple(map(int, r.capabilities)), float(r.payload),
                         traits=trait_pairs(traits, r.traits))
                   for r in team.robots)
    tasks = tuple(Task(t.id, tuple(map(int, t.capabilities)), float(t.payload), float(t.duration),
                       tuple(t.prerequisites),
                       requires=trait_pairs(traits, t.requires), roles=roles_of(t.roles))
                  for t in graph.tasks)
    travel = snapshot_travel(team, graph) if graph.sites else None
    homes = [r.id for r in team.robots if r.home]
    if homes and travel is None:
        raise InstanceError(f"TeamState robots ({homes[0]!r}).home: a home needs the TaskGraph's sites")
    return Instance(name, tuple(graph.capability_names), robots, tasks, travel=travel, traits=traits,
                    objective=graph.objective or "makespan", roles=bool(graph.roles),
                    departure=graph.departure or "together", prechecked=checked)


def off_site(robot: RobotInfo) -> str:
    """The site of a robot off every named site (a robot stopped between sites): its pose."""
    return f"@{robot.id}"


def robot_site(robot: RobotInfo, known: set[str] | frozenset[str], n: int = 0) -> str:
    """The site a robot of a snapshot with travel is at: the one it names, or, for a mobile
    robot off every site (site ""), one of its own at its pose (:func:`off_site`).
    InstanceError naming the field for an unknown site or a fixed robot without one."""
    if robot.site in known:
        return robot.site
    where = f"TeamState robots[{n}] ({robot.id!r}).site"
    if robot.site:
        raise InstanceError(f"{where}: unknown site {robot.site!r} (the TaskGraph's sites: "
                            f"{', '.join(sorted(known)[:10])})")
    if robot.speed <= 0:
        raise InstanceError(f"{where}: empty for a fixed robot (speed 0), but the TaskGraph has sites: a fixed "
                            "robot needs its site (a TeamState without travel fields cannot serve a graph with sites)")
    return off_site(robot)


def graph_sites(tr: Travel) -> tuple[tuple[tuple[str, float, float], ...], tuple[float, ...]]:
    """The TaskGraph's ``sites`` and ``distances`` (row-major) of a travel model: the
    inverse of :func:`snapshot_travel` for the sites."""
    return (tuple((name, x, y) for name, (x, y) in zip(tr.sites, tr.coordinates, strict=True)),
            tuple(float(d) for d in tr.distance.reshape(-1)))


def snapshot_travel(team: TeamSnapshot, graph: GraphSnapshot) -> Travel:
    """The travel of the snapshots: the graph's sites (plus one at the pose of each mobile
    robot off every site), each robot at its site, each task at its sites."""
    known = frozenset(s[0] for s in graph.sites)
    sites = {name: (x, y) for name, x, y in graph.sites}
    at = [robot_site(r, known, n) for n, r in enumerate(team.robots)]
    for r, name in zip(team.robots, at, strict=True):
        if name not in known:
            sites[name] = (r.pose[0], r.pose[1])
    names = [s[0] for s in graph.sites]
    distances: dict[str, dict[str, float]] = {}
    if graph.distances:
        for a, name in enumerate(names):
            distances[name] = {b: graph.distances[a * len(names) + k] for k, b in enumerate(names) if b != name}
    robots = [(r.id, name, r.speed if r.speed > 0 else None) for r, name in zip(team.robots, at, strict=True)]
    tasks = [(t.id, t.site_from, t.site_to or t.site_from) for t in graph.tasks]
    return build_travel(sites, distances, robots, tasks, [r.home or None for r in team.robots])


def schedulable(team: TeamSnapshot, graph: GraphSnapshot) -> tuple[GraphSnapshot, dict[str, str]]:
    """The part of ``graph`` the robots of ``team`` can schedule, and the tasks held back
    (id -> why). A task the whole present team cannot cover (Eqs. 10-11: robots failed or
    gone; with travel, the robots that can reach it) is held back with every task waiting
    on it, until the team can cover it again; a DONE task it cannot cover any more is left
    out and dropped from its dependents' prerequisites (they are satisfied). The rest is
    scheduled as usual."""
    k = len(graph.capability_names) + len(graph.trait_names)
    vectors = [(*r.capabilities, *(r.traits or (0.0,) * len(graph.trait_names))) for r in team.robots] + \
        [(*t.capabilities, *(t.requires or (0.0,) * len(graph.trait_names))) for t in graph.tasks]
    if not graph.tasks or any(len(v) != k for v in vectors) or team.trait_names != graph.trait_names:
        return graph, {}  # nothing to hold back, or malformed: build_instance says what is wrong
    caps = np.array(vectors[:len(team.robots)], dtype=np.float64).reshape(-1, k)  # amounts (0/1 capabilities)
    payloads = np.array([r.payload for r in team.robots], dtype=np.float64)
    team_caps: np.ndarray = caps.sum(axis=0)
    team_payload: np.ndarray | float = float(payloads.sum())
    able: np.ndarray | None = None
    if graph.sites:  # with travel, per task only the robots that can reach it at all
        try:
            tr = snapshot_travel(team, graph)
        except InstanceError:
            return graph, {}  # build_instance says what is wrong
        n, m = len(team.robots), len(graph.tasks)
        able = np.isfinite(tr.arrivals(range(n), tr.robot_site, range(m))).astype(np.float64)  # (N, M)
        team_caps, team_payload = able.T @ caps, able.T @ payloads
    need = np.array(vectors[len(team.robots):], dtype=np.float64).reshape(-1, k)
    ok = covered(team_caps, team_payload, need, np.array([t.payload for t in graph.tasks], dtype=np.float64))
    for j, t in enumerate(graph.tasks):  # with roles, the rule itself
        if ok[j] and (graph.roles if roles_of(t.roles) is None else roles_of(t.roles)):
            rows = slice(None) if able is None else able[:, j] > 0
            ok[j] = covers(caps[rows], payloads[rows], need[j], t.payload, roles=True)
    if ok.all():
        return graph, {}
    done_gone = {t.id for t, c in zip(graph.tasks, ok, strict=True) if not c and t.status == TaskStatus.DONE}
    held = {t.id: "the robots present cannot cover it" + (" (those that can reach it)" if graph.sites else "")
            for t, c in zip(graph.tasks, ok, strict=True)
            if not c and t.status != TaskStatus.DONE}
    children: dict[str, list[str]] = {}
    for t in graph.tasks:
        for p in t.prerequisites:
            children.setdefault(p, []).append(t.id)
    stack = list(held)
    while stack:
        for c in children.get(stack.pop(), []):
            if c not in held:
                held[c] = "waits on a task the robots present cannot cover"
                stack.append(c)
    kept = tuple(replace(t, prerequisites=tuple(p for p in t.prerequisites if p not in done_gone))
                 for t in graph.tasks if t.id not in held and t.id not in done_gone)
    return replace(graph, tasks=kept), held


def scheduling_view(team: TeamSnapshot, graph: GraphSnapshot) -> tuple[GraphSnapshot, tuple[Any, ...],
                                                                        dict[str, str]]:
    """What a decision is made on: the schedulable part of the snapshots
    (:func:`schedulable`), the key of its instance (:func:`snapshot_key`: build a new one
    when it changes) and the tasks held back."""
    view, held = schedulable(team, graph)
    return view, snapshot_key(team, view), held


def unready(graph: GraphSnapshot) -> list[tuple[str, str]]:
    """(task, prerequisite) for each task the graph calls READY although a prerequisite
    is not DONE: such a task is not ready."""
    status = {t.id: t.status for t in graph.tasks}
    return [(t.id, p) for t in graph.tasks if t.status == _READY
            for p in t.prerequisites if status.get(p) != _DONE]


def build_state(inst: Instance, team: TeamSnapshot, graph: GraphSnapshot,
                pending: Mapping[str, Sequence[str]] = {}, until: Mapping[str, float] | None = None,
                columns: TaskColumns | None = None) -> State:
    """The executor state at the newer snapshot's time, with ``pending`` (task -> robots
    assigned but not yet acknowledged) counted as running (the rules of the module doc).
    ``inst`` is the instance of ``graph`` or of an earlier snapshot of the same cell (the
    same tasks in the same places, with the same prerequisites: :func:`same_cell`).
    With ``"departure": "each"`` a task the world took starts when it says (its members
    report themselves busy until their last task ends, at its site), and a pending one is
    given as the executor gives it, in the order it was sent (:meth:`State.start`).
    ``until``: busy robots' end times (a :class:`CellDelta`'s), in place of their
    ``busy_for``; ``columns``: what the last snapshot's tasks gave, kept (:class:`TaskColumns`)."""
    if inst.departure == "each":
        state = _build_state(inst, team, graph, {}, until, columns, ahead=True)
        for tid, robots in pending.items():
            j = inst.task_index.get(tid)
            if j is not None and state.task_status[j] == TaskStatus.READY and all(r in inst.robot_index for r in robots):
                state.start(j, [inst.robot_index[r] for r in robots])
        return state
    return _build_state(inst, team, graph, pending, until, columns)


class TaskColumns:
    """What a graph's tasks give an executor state, per task place: the status as the
    graph says it, the members' indices and the start time (NaN: none). Kept from one
    snapshot to the next of the same instance: a task that is the very same object as
    last time (an incremental reader or a live cell keeps them) is not read again."""

    def __init__(self) -> None:
        self.inst: Instance | None = None
        self.tasks: Sequence[TaskInfo] = ()
        self.status = np.zeros(0, dtype=np.int8)
        self.start = np.zeros(0)
        self.teams: list[tuple[int, ...]] = []

    def read(self, inst: Instance, tasks: Sequence[TaskInfo]) -> tuple[np.ndarray, list[tuple[int, ...]], np.ndarray]:
        """(status, teams, start) of ``tasks`` (copies the caller may change)."""
        m = len(tasks)
        if inst is not self.inst or len(self.tasks) != m:
            self.inst, self.status, self.start, self.teams = inst, np.zeros(m, dtype=np.int8), np.full(m, np.nan), [()] * m
            places: Sequence[int] = range(m)
        else:
            places = _changed(tasks, self.tasks)
        index = inst.robot_index
        for j in places:
            t = tasks[j]
            self.status[j] = t.status
            self.teams[j] = tuple(index[r] for r in t.assigned_robots if r in index) if t.assigned_robots else ()
            self.start[j] = np.nan if t.start is None else t.start
        self.tasks = tasks
        return self.status.copy(), list(self.teams), self.start


def _build_state(inst: Instance, team: TeamSnapshot, graph: GraphSnapshot, pending: Mapping[str, Sequence[str]],
                 until: Mapping[str, float] | None = None, columns: TaskColumns | None = None,
                 ahead: bool = False) -> State:
    now = max(team.stamp, graph.stamp)
    n = inst.num_robots
    tasks = graph.tasks
    status, teams, given = (columns or TaskColumns()).read(inst, tasks)
    places = inst.task_index
    task, pre = inst.prerequisite_edges  # ready only once every prerequisite is DONE
    status[task[(status[task] == _READY) & (status[pre] != _DONE)]] = _QUEUED
    for tid, robots in pending.items():
        j = places.get(tid)
        if j is not None and status[j] == TaskStatus.READY and all(r in inst.robot_index for r in robots):
            status[j] = TaskStatus.ASSIGNED
            teams[j] = tuple(inst.robot_index[r] for r in robots)
    free_at = np.full(n, now)
    unknown_busy = max(float(inst.durations.max(initial=0.0)), BUSY_EPS)
    for i, r in enumerate(team.robots):
        if not r.available or r.current_task:
            busy = r.busy_for if until is None else max(0.0, until[r.id] - now) if r.id in until else r.busy_for
            free_at[i] = now + max(busy if math.isfinite(busy) else unknown_busy, BUSY_EPS)
    start = np.full(len(tasks), np.nan)
    done = status == _DONE
    start[done] = np.where(np.isnan(given[done]), now - inst.durations[done], given[done])
    tr = inst.travel
    own = _robot_sites(inst, team)  # where each robot says it is
    site = None if own is None else own.copy()  # and where it will be when its task is done
    for j in np.flatnonzero(status == _ASSIGNED).tolist():
        t = tasks[j]
        idx = list(teams[j])
        if ahead and t.start is not None:  # the world says when it starts
            start[j] = t.start
            free_at[idx] = np.maximum(free_at[idx], t.start + inst.durations[j])
            continue
        busy_until = [free_at[i] for i in idx if free_at[i] > now]
        # just assigned, or unacknowledged: the subteam travels first (travel extension)
        go = tr.arrival(idx, [int(own[i]) for i in idx], j) if tr is not None and own is not None else 0.0
        end = max(busy_until) if busy_until else now + go + inst.durations[j]
        free_at[idx] = np.maximum(free_at[idx], end)
        start[j] = end - inst.durations[j]
        if tr is not None and site is not None and not ahead:  # ahead: each robot says where it ends
            site[idx] = tr.task_to[j]
    return State(inst, now, free_at, status, start, teams, robot_site=site)


def _robot_sites(inst: Instance, team: TeamSnapshot) -> np.ndarray | None:
    """With travel, the site index each robot of ``team`` says it is at (:func:`robot_site`)."""
    tr = inst.travel
    if tr is None:
        return None
    index = {name: k for k, name in enumerate(tr.sites)}
    known = frozenset(index)
    return np.array([index.get(robot_site(r, known, n), tr.robot_site[n]) for n, r in enumerate(team.robots)],
                    dtype=np.int64)


def still_pending(pending: Mapping[str, tuple[tuple[str, ...], float]], graph: GraphSnapshot | Mapping[str, TaskInfo],
                  now: float, ack_timeout: float, team: TeamSnapshot | Set[str] | None = None
                  ) -> dict[str, tuple[tuple[str, ...], float]]:
    """The assignments (task -> (robots, since)) the world has not acknowledged yet: a
    task no longer READY was acknowledged (or is gone); one not taken ``ack_timeout``
    seconds after ``since`` (:func:`sent_at`) is offered again; one whose robots left
    ``team`` is released. ``graph`` and ``team`` may be given as the tasks by id and the
    robots' ids."""
    tasks = {t.id: t for t in graph.tasks} if isinstance(graph, GraphSnapshot) else graph
    robots = {r.id for r in team.robots} if isinstance(team, TeamSnapshot) else team
    return {k: v for k, v in pending.items() if k in tasks and tasks[k].status == _READY
            and now - v[1] <= ack_timeout and (robots is None or set(v[0]) <= robots)}


PUBLISHED_WITHIN = 86_400.0  # a decision stamped further than this after its inputs' time is on another clock


def sent_at(decision: OnlineDecision, now: float) -> float:
    """When a decision made on the snapshots of time ``now`` went out: ``now`` plus the time
    it took (its ``latency``: a first plan awaited can take longer than ``ack_timeout``, and
    the world cannot take what it has not been sent), or its ``published`` stamp when later:
    a node that follows a world's clock running faster than the wall's stamps it on that
    clock. A stamp more than PUBLISHED_WITHIN after ``now`` is on a clock of its own (a node
    on wall time beside a simulated world) and does not count."""
    late = decision.published - now
    return now + max(decision.latency, late if late <= PUBLISHED_WITHIN else 0.0)


def snapshot_key(team: TeamSnapshot, graph: GraphSnapshot) -> tuple[Any, ...]:
    """What the scheduling instance of two snapshots depends on: equal keys, same instance
    (a new one when tasks or robots come or go, or change)."""
    known = {s[0] for s in graph.sites}
    return (team.capability_names, tuple(_robot_part(r) for r in team.robots), tuple(_task_part(t) for t in graph.tasks),
            (graph.trait_names, graph.roles, graph.objective, graph.departure),
            # travel: the sites, speeds and task sites; where a robot is only when it is off
            # every site (a new site at its pose); the state follows the robots (build_state)
            graph.sites, graph.distances, tuple((t.site_from, t.site_to) for t in graph.tasks),
            tuple((r.speed, bool(graph.sites) and r.site not in known,  # off every site: a site of its own,
                   r.pose[:2] if graph.sites and r.site not in known  # at its pose while it stands free
                   and r.available and not r.current_task else None) for r in team.robots))


def _robot_part(r: RobotInfo) -> tuple[Any, ...]:
    """What of a robot the instance holds (travel aside)."""
    return r.id, r.capabilities, r.payload, r.traits, r.home


def _task_part(t: TaskInfo) -> tuple[Any, ...]:
    """What of a task the instance holds (travel aside)."""
    return t.id, t.capabilities, t.payload, t.duration, t.prerequisites, t.requires, t.roles


def same_cell(before: tuple[TeamSnapshot, GraphSnapshot], now: tuple[TeamSnapshot, GraphSnapshot]) -> bool:
    """Whether two pairs of snapshots without travel describe the same cell: they differ at
    most in what changes as the world runs (stamps, statuses, subteams, times, availability,
    busy times, poses), so that their schedulable parts (:func:`schedulable`) and instances
    are the same. Robots and tasks that are the very same objects (an incremental reader
    keeps them) cost a look each."""
    (t0, g0), (t1, g1) = before, now
    if g0.sites or g1.sites or len(t0.robots) != len(t1.robots) or len(g0.tasks) != len(g1.tasks):
        return False
    if (t0.capability_names, t0.trait_names, g0.capability_names, g0.trait_names, g0.roles, g0.objective,
            g0.departure) != (t1.capability_names, t1.trait_names, g1.capability_names, g1.trait_names, g1.roles,
                              g1.objective, g1.departure):
        return False
    return all(a is b or (_robot_part(a), a.speed) == (_robot_part(b), b.speed)
               for a, b in zip(t0.robots, t1.robots, strict=True)) and \
        all(a is b or (_task_part(a), a.site_from, a.site_to) == (_task_part(b), b.site_from, b.site_to)
            for a, b in zip(g0.tasks, g1.tasks, strict=True))


def is_due(free: Set[Any], ready: Set[Any], seen_free: Set[Any], seen_ready: Set[Any], running: bool,
           ahead: bool = False) -> bool:
    """When a decision is due: a robot free or a task ready that is new since the last look,
    or nothing running (waiting would stall); and a ready task with a free robot, or with
    any robot when ``ahead`` (departure each: busy robots may be given tasks)."""
    new = bool(free - seen_free) or bool(ready - seen_ready) or not running
    return new and bool(free or ahead) and bool(ready)


def close_policy(policy: Policy | None) -> None:
    """Call the policy's ``close`` when it has one (a policy that runs a process)."""
    close = getattr(policy, "close", None)
    if callable(close):
        close()


class OnlineScheduler:
    """Decides when a robot became available or a task became ready; see the module doc."""

    def __init__(self, policy: Policy, ack_timeout: float = 5.0, restart_jump: float = RESTART_JUMP,
                 fallback: Policy | None = None) -> None:
        self.policy = policy
        self.fallback = fallback
        self.fallbacks = 0  # steps the fallback decided
        self._main_refused = ""  # why the main policy refused the current instance (reset)
        self.ack_timeout = ack_timeout
        self.restart_jump = restart_jump
        self.team: TeamSnapshot | None = None
        self.graph: GraphSnapshot | None = None
        self.pending: dict[str, tuple[tuple[str, ...], float]] = {}  # task -> (robots, since: still_pending)
        self.step = 0
        self.dropped = 0  # out-of-order snapshots
        self.restarts = 0
        self.notices: list[str] = []  # for the node's diagnostics (WARN); it clears them once reported
        self.changes: list[str] = []  # the world's announced changes (tasks, robots), for diagnostics (OK)
        self._inst: Instance | None = None
        self._key: object = None
        self._view: GraphSnapshot | None = None  # the schedulable part of self.graph
        self._basis: tuple[TeamSnapshot, GraphSnapshot] | None = None  # the snapshots self._view is of
        self._held: list[str] = []  # tasks held back (no present subteam can cover them)
        self._seen_free: frozenset[str] = frozenset()
        self._seen_ready: frozenset[str] = frozenset()
        self._until: Mapping[str, float] | None = None  # busy robots' end times (offer_cell), else their busy_for
        self._by_id: Mapping[str, TaskInfo] | None = None  # self.graph's tasks by id (made when needed)
        self._robot_ids: frozenset[str] | None = None  # self.team's robots' ids (made when needed)
        self._columns = TaskColumns()

    def set_policies(self, policy: Policy, fallback: Policy | None) -> None:
        """Switch policies (a runtime parameter change): the next decision resets them on
        the current instance; pending assignments stay."""
        old = (self.policy, self.fallback)
        self.policy, self.fallback = policy, fallback
        self._inst, self._key, self._main_refused, self._basis = None, None, "", None
        for p in old:
            if p is not policy and p is not fallback:
                close_policy(p)

    def close(self) -> None:
        """Release what the policies hold beyond this object (the planner's process of
        ``auto``): the node's cleanup and shutdown."""
        close_policy(self.policy)
        close_policy(self.fallback)

    def _in_order(self, kind: str, last: float | None, stamp: float) -> bool:
        """False for an out-of-order snapshot; a big jump back restarts the world."""
        if last is None or stamp >= last:
            return True
        if last - stamp <= self.restart_jump:
            self.dropped += 1
            return False
        self.restarts += 1
        self.notices.append(f"{kind} stamp went back from {last:.3f} to {stamp:.3f} s: world restart assumed, "
                            f"stamp order reset, {len(self.pending)} pending assignment(s) released")
        self.pending.clear()
        self.team, self.graph = None, None  # both are of the old world: wait for the new world's
        self._until = self._by_id = self._robot_ids = None
        self._seen_free, self._seen_ready = frozenset(), frozenset()
        return True

    def offer_team(self, snap: TeamSnapshot) -> bool:
        """Take a team snapshot (InstanceError, snapshot ignored, when malformed)."""
        check_team(snap, self.team)
        if not self._in_order("TeamState", self.team.stamp if self.team else None, snap.stamp):
            return False
        if self.team is not None:
            before, now = {r.id for r in self.team.robots}, {r.id for r in snap.robots}
            if before - now:
                self.notices.append(f"robot(s) {', '.join(sorted(before - now))} left the team (failed?): "
                                    "not scheduled until they come back")
            if now - before:
                self.changes.append(f"robot(s) {', '.join(sorted(now - before))} joined the team")
        self.team, self._until, self._robot_ids = snap, None, None
        return True

    def offer_graph(self, snap: GraphSnapshot, checked: GraphSnapshot | None = None) -> bool:
        """Take a task-graph snapshot (InstanceError, snapshot ignored, when malformed).
        ``checked``: one that passed :func:`check_graph` elsewhere (a ChangeFollower's),
        for the first snapshot: its tasks are not checked again."""
        check_graph(snap, self.graph if self.graph is not None else checked)
        if not self._in_order("TaskGraph", self.graph.stamp if self.graph else None, snap.stamp):
            return False
        if self.graph is not None:
            before = {t.id: t for t in self.graph.tasks}
            now = {t.id: t for t in snap.tasks}
            if set(now) - set(before):
                self.changes.append(f"task(s) {', '.join(sorted(set(now) - set(before)))} added")
            gone = sorted(k for k in set(before) - set(now) if before[k].status != TaskStatus.DONE)
            if gone:  # a DONE task that leaves retired: not news
                self.changes.append(f"task(s) {', '.join(gone)} removed (cancelled)")
            back = sorted(k for k, t in now.items() if t.status == _READY and not t.assigned_robots
                          and k in before and before[k].status == _ASSIGNED)
            if back:
                self.notices.append(f"task(s) {', '.join(back)} interrupted: READY again, replanned")
        self.graph, self._by_id = snap, None
        for task, pre in unready(snap):
            self.notices.append(f"TaskGraph says {task} is READY but its prerequisite {pre} is not DONE: not ready")
        return True

    def offer_cell(self, team: TeamSnapshot, graph: GraphSnapshot, delta: CellDelta) -> bool:
        """Take a live cell's snapshot pair (:class:`CellDelta`; checked where its changes
        were taken): in time proportional to ``delta`` when it is of the pair held, else as
        :meth:`offer_team` and :meth:`offer_graph` take them (InstanceError, pair ignored,
        when it cannot be used). Whether it was taken. A READY task whose prerequisite is
        not DONE is reported when it or the prerequisite changes."""
        held = (self.team, self.graph)
        if delta.since is None or held[0] is None or held[1] is None or delta.since[0] is not held[0] \
                or delta.since[1] is not held[1] or team.stamp < held[0].stamp or graph.stamp < held[1].stamp:
            if not self.offer_team(team):
                return False
            self._until = delta.until  # the team's busy robots, whatever becomes of the graph
            if not self.offer_graph(graph, delta.checked):
                return False
            self._by_id = delta.by_id
            return True
        if not team.robots:
            raise InstanceError(TEAM_NEEDS)
        ids = self._team_ids()
        if delta.left & ids:
            self.notices.append(f"robot(s) {', '.join(sorted(delta.left & ids))} left the team (failed?): "
                                "not scheduled until they come back")
        joined = sorted(delta.robots - ids)
        if joined:
            self.changes.append(f"robot(s) {', '.join(joined)} joined the team")
        self._news(self._tasks_by_id(), delta)
        self.team, self.graph = team, graph
        self._until, self._by_id, self._robot_ids = delta.until, delta.by_id, (ids - delta.left) | delta.robots
        by_id = delta.by_id
        for tid in sorted(delta.watch):
            t = by_id.get(tid)
            for p in t.prerequisites if t is not None and t.status == _READY else ():
                if p not in by_id or by_id[p].status != _DONE:
                    self.notices.append(f"TaskGraph says {tid} is READY but its prerequisite {p} is not DONE: "
                                        "not ready")
        return True

    def _news(self, before: Mapping[str, TaskInfo], delta: CellDelta) -> None:
        """What a live cell's tasks did since ``before`` (tasks by id), for diagnostics."""
        added = sorted(k for k in delta.tasks if k not in before)
        if added:
            self.changes.append(f"task(s) {', '.join(added)} added")
        gone = sorted(k for k, status in delta.gone.items() if k in before and status != _DONE)
        if gone:
            self.changes.append(f"task(s) {', '.join(gone)} removed (cancelled)")
        now = delta.by_id
        back = sorted(k for k in delta.tasks if k in before and k in now and now[k].status == _READY
                      and not now[k].assigned_robots and before[k].status == _ASSIGNED)
        if back:
            self.notices.append(f"task(s) {', '.join(back)} interrupted: READY again, replanned")

    def _tasks_by_id(self) -> Mapping[str, TaskInfo]:
        assert self.graph is not None
        if self._by_id is None:
            self._by_id = {t.id: t for t in self.graph.tasks}
        return self._by_id

    def _team_ids(self) -> frozenset[str]:
        assert self.team is not None
        if self._robot_ids is None:
            self._robot_ids = frozenset(r.id for r in self.team.robots)
        return self._robot_ids

    def _release(self, now: float) -> None:
        """Drop pending assignments that were acknowledged, timed out, or lost their task
        or robots; report the last two kinds."""
        assert self.team is not None and self.graph is not None
        if not self.pending:
            return
        tasks, robots = self._tasks_by_id(), self._team_ids()
        kept = still_pending(self.pending, tasks, now, self.ack_timeout, robots)
        for task, (team, _) in self.pending.items():
            if task not in kept and (task not in tasks or not set(team) <= robots):
                gone = [task] if task not in tasks else sorted(set(team) - robots)
                self.notices.append(f"pending assignment {task} <- {'+'.join(team)} released: {', '.join(gone)} "
                                    "left the latest snapshots")
        self.pending = kept

    def instance(self) -> Instance:
        """The instance of the schedulable part of the latest snapshots (:func:`schedulable`)."""
        assert self.team is not None and self.graph is not None
        now = (self.team, self.graph)
        if self._inst is not None and not self._held and self._basis is not None and self._view is self._basis[1] \
                and same_cell(self._basis, now):  # the view was the whole graph (nothing held back or left out)
            self._basis, self._view = now, self.graph  # nothing held back, nothing but the run changed
            return self._inst
        view, key, held = scheduling_view(self.team, self.graph)
        self._basis = None
        if sorted(held) != self._held:
            self._held = sorted(held)
            if held:
                first = [t for t, why in held.items() if why.startswith("the robots")]
                self.notices.append(f"task(s) {', '.join(first)} cannot be covered by the robots present: held back "
                                    f"with {len(held) - len(first)} task(s) waiting on them until robots come back")
        self._view = view
        if key != self._key or self._inst is None:
            self._inst = build_instance(self.team, view, checked=True)  # both were checked when offered
            self._key = key
            self._main_refused = ""
            try:
                self.policy.reset(self._inst)
            except Exception as exc:  # a policy that cannot serve this instance: the fallback will
                if self.fallback is None:
                    raise
                self._main_refused = f"{type(exc).__name__}: {exc}"
            if self.fallback is not None:
                self.fallback.reset(self._inst)
        self._basis = now
        return self._inst

    def decide(self, started: float | None = None) -> OnlineDecision | None:
        """A decision if one is due (a new free robot or a new ready task), else None.
        ``started``: the perf_counter time the decision's work began (the scheduler node:
        when the message that made it due arrived, before its conversion); a policy with a
        budget (:class:`~lvws_ros.core.executor.Budgeted`) counts it from then."""
        if self.team is None or self.graph is None:
            return None
        inst = self.instance()
        now = max(self.team.stamp, self.graph.stamp)
        self._release(now)
        assert self._view is not None
        state = build_state(inst, self.team, self._view, {k: v[0] for k, v in self.pending.items()}, self._until,
                            self._columns)
        free = frozenset(inst.robots[i].id for i in state.free_robots())
        ready = frozenset(inst.tasks[j].id for j in state.ready_tasks())
        running = bool((state.task_status == TaskStatus.ASSIGNED).any())
        if not is_due(free, ready, self._seen_free, self._seen_ready, running, ahead=inst.departure == "each"):
            self._seen_free, self._seen_ready = free, ready
            return None
        decision = self.decide_state(state, started)  # if it raises, the same state is due again
        for task, robots in decision.assignments:
            self.pending[task] = (robots, sent_at(decision, now))
        self._seen_free = free - {r for _, team in decision.assignments for r in team}
        self._seen_ready = ready - {t for t, _ in decision.assignments}
        return decision

    def published(self, decision: OnlineDecision) -> None:
        """The decision went out (its ``published`` stamp set): its assignments are pending
        from :func:`sent_at` on."""
        now = max(decision.team_stamp, decision.graph_stamp)
        for task, _robots in decision.assignments:
            if task in self.pending:
                robots, since = self.pending[task]
                self.pending[task] = (robots, max(since, sent_at(decision, now)))

    def forget(self, decision: OnlineDecision) -> None:
        """Undo :meth:`decide`'s bookkeeping for a decision that was never sent: its tasks
        are not pending, and its robots and tasks are new to the next decision."""
        for task, _robots in decision.assignments:
            self.pending.pop(task, None)
        self._seen_free, self._seen_ready = frozenset(), frozenset()

    def pure_instance(self) -> Instance:
        """The instance :meth:`instance` would give, built without touching the scheduler
        (a policy can be checked against it while another thread decides)."""
        assert self.team is not None and self.graph is not None
        return build_instance(self.team, scheduling_view(self.team, self.graph)[0], checked=True)

    def decide_state(self, state: State, started: float | None = None) -> OnlineDecision:
        """Run the policy on ``state`` (checked against Eqs. 8-11) and name the result
        (``started``: as for :meth:`decide`)."""
        inst = state.instance
        t0 = time.perf_counter()
        budgeted = self.policy if isinstance(self.policy, Budgeted) else None
        if budgeted is not None:
            budgeted.clock = started  # None: from when it decides
        try:
            decision, used = self._decide_with(state)
        finally:
            if budgeted is not None:  # for this decision only, whether or not the policy read it
                budgeted.clock = None
        latency = time.perf_counter() - t0
        said: list[str] | None = getattr(self.policy, "notices", None)  # what the policy has to report (WARN)
        while said:
            self.notices.append(f"{self.policy.name}: {said.pop(0)}")
        assigned = {r for _, team in decision.assignments for r in team}
        out = OnlineDecision(
            self.step,
            tuple((inst.tasks[j].id, tuple(inst.robots[r].id for r in team)) for j, team in decision.assignments),
            tuple(inst.robots[r].id for r in state.free_robots() if r not in assigned),
            latency,
            self.team.stamp if self.team else state.time,
            self.graph.stamp if self.graph else state.time,
            used,
        )
        self.step += 1
        return out

    def _decide_with(self, state: State) -> tuple[Decision, str]:
        """(decision, name of the policy that made it): the main policy, or the fallback
        when the main one cannot serve this step (module doc)."""
        reason = self._main_refused
        if not reason:
            try:
                decision: Decision = self.policy.decide(state)
                check_decision(state, decision, self.policy.name)
                return decision, self.policy.name
            except Exception as exc:  # whatever the main policy raises, the fallback serves the step
                if self.fallback is None:
                    raise
                reason = f"{type(exc).__name__}: {exc}"
        assert self.fallback is not None
        decision = self.fallback.decide(state)
        check_decision(state, decision, self.fallback.name)
        self.fallbacks += 1
        self.notices.append(f"step {self.step}: {self.policy.name} could not decide ({reason[:200]}); "
                            f"decided with the fallback {self.fallback.name}")
        return decision, self.fallback.name
