"""A cell kept from numbered changes: the change-only protocol's core (ROS-free).

A world that speaks changes sends, after a snapshot of its team and task graph, batches
of what changed (:class:`CellChanges`), numbered 1, 2, 3, ... (``docs/ros.md``, "Changes
instead of snapshots"). :class:`LiveCell` holds the cell as of the last batch it took and
gives the same :class:`~lvws_ros.core.online.TeamSnapshot` and
:class:`~lvws_ros.core.online.GraphSnapshot` the world's snapshot would give, in time
proportional to the batch, not to the cell (a task or robot that did not change is the
very same object, which the core's checks and caches recognise). A batch that does not
follow the last one (:class:`ChangeGap`), or one that names what the cell does not hold
(:class:`ChangeRefused`), is not taken: nothing of it is applied, and the holder asks the
world for a snapshot (a resync).

Done work retires (:meth:`LiveCell.retire`): a DONE task whose dependents have all started
(or that has none) leaves the live cell once it ended ``horizon`` seconds ago; its
dependents no longer name it. A retired task never comes back: a batch or a snapshot that
holds it again has it left out. :func:`changes_between` gives the batch that turns one
pair of snapshots into the next (what a world that keeps snapshots sends).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Set
from dataclasses import dataclass, replace

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import (
    CellDelta,
    GraphSnapshot,
    RobotInfo,
    TaskInfo,
    TeamSnapshot,
    check_acyclic,
    check_graph,
    check_robot,
    check_task,
    check_task_sites,
    check_team,
)
from lvws_ros.errors import InstanceError

__all__ = ["CellChanges", "ChangeFollower", "ChangeGap", "ChangeRefused", "LiveCell", "changes_between",
           "without_retired"]

_QUEUED, _READY, _ASSIGNED, _DONE = (int(s) for s in (TaskStatus.QUEUED, TaskStatus.READY, TaskStatus.ASSIGNED,
                                                      TaskStatus.DONE))
UNTIL_EPS = 1e-9  # two "busy until" times closer than this are the same


@dataclass(frozen=True)
class CellChanges:
    """What changed in a cell at ``stamp`` (one ``lvws_msgs/CellChanges`` message).

    ``tasks``: tasks added (QUEUED or READY) or changed, each whole as it is now;
    ``cancelled``: tasks that left (their dependents no longer name them: the world sends
    the dependents in ``tasks``); ``retired``: DONE tasks that left the live cell;
    ``robots``: robots that joined or changed, each whole, ``busy_for`` counted from
    ``stamp``; ``left``: robots that left the team (failed, switched off)."""

    seq: int
    stamp: float
    tasks: tuple[TaskInfo, ...] = ()
    cancelled: tuple[str, ...] = ()
    retired: tuple[str, ...] = ()
    robots: tuple[RobotInfo, ...] = ()
    left: tuple[str, ...] = ()

    @property
    def size(self) -> int:
        return len(self.tasks) + len(self.cancelled) + len(self.retired) + len(self.robots) + len(self.left)


def without_retired(tasks: Iterable[TaskInfo], retired: Set[str]) -> Iterator[TaskInfo]:
    """``tasks`` less those in ``retired``, and none naming a retired task as a prerequisite
    (retired work is done: nothing waits on it). A task that names none is the very same object."""
    for t in tasks:
        if t.id not in retired:
            yield _unnamed(t, retired)


def _unnamed(t: TaskInfo, retired: Set[str]) -> TaskInfo:
    if retired.isdisjoint(t.prerequisites):
        return t
    return replace(t, prerequisites=tuple(p for p in t.prerequisites if p not in retired))


class ChangeGap(InstanceError):
    """A batch that does not follow the last one taken (a missed or repeated number)."""

    def __init__(self, expected: int, got: int) -> None:
        super().__init__(f"CellChanges seq {got}: expected {expected} (changes {expected}-{got - 1} missed)"
                         if got > expected else f"CellChanges seq {got}: already taken (expected {expected})")
        self.expected, self.got = expected, got


class ChangeRefused(InstanceError):
    """A batch that cannot apply to the cell (an unknown task or robot, a malformed item)."""


class _Ids:
    """The task ids a batch's prerequisites may name: the cell's, the batch's own and the
    retired ones (left out when applied), but not those it cancels."""

    def __init__(self, cell: dict[str, TaskInfo], added: set[str], retired: set[str], gone: set[str]) -> None:
        self.cell, self.added, self.retired, self.gone = cell, added, retired, gone  # looked up, never copied

    def __contains__(self, tid: object) -> bool:
        return (tid in self.cell or tid in self.added or tid in self.retired) and tid not in self.gone


class LiveCell:
    """A cell's team and task graph: a snapshot pair (:meth:`reset`) and the batches after it
    (:meth:`apply`); :meth:`snapshots` gives them as the world's snapshots would."""

    def __init__(self, team: TeamSnapshot, graph: GraphSnapshot, seq: int = 0, checked: bool = False) -> None:
        self.retired: set[str] = set()  # ids that left for good (kept: they never come back)
        self.retired_count = 0
        self.reset(team, graph, seq, checked)

    # -- taking a snapshot -------------------------------------------------------------
    def reset(self, team: TeamSnapshot, graph: GraphSnapshot, seq: int = 0, checked: bool = False) -> None:
        """Take a snapshot pair as the cell as of change ``seq`` (a resync); tasks retired
        before are left out of it, and its tasks no longer name them. ``checked``: both
        passed :func:`check_team` and :func:`check_graph` already (a scheduler took them)."""
        if self.retired & {t.id for t in graph.tasks}:
            graph = replace(graph, tasks=tuple(without_retired(graph.tasks, self.retired)))
        if not checked:
            check_team(team)
            check_graph(graph)
        self.seq = seq
        self.team_base, self.graph_base = team, graph  # names, sites, traits, objective: what changes never change
        self._restore(team, graph)

    def _restore(self, team: TeamSnapshot, graph: GraphSnapshot) -> None:
        """The cell as the snapshot pair says (O(cell): a snapshot, or a refused batch undone)."""
        self.stamp = max(team.stamp, graph.stamp)
        self.tasks: dict[str, TaskInfo] = {t.id: t for t in graph.tasks}
        self.robots: dict[str, RobotInfo] = {r.id: r for r in team.robots}
        self.until: dict[str, float] = {r.id: team.stamp + r.busy_for for r in team.robots if r.busy_for > 0}
        self.dependents: dict[str, set[str]] = {}
        for t in graph.tasks:
            for p in t.prerequisites:
                self.dependents.setdefault(p, set()).add(t.id)
        self.done: set[str] = {t.id for t in graph.tasks if t.status == _DONE}  # candidates to retire
        self._snaps: tuple[TeamSnapshot, GraphSnapshot] | None = (team, graph)
        self._viewed: tuple[TeamSnapshot, GraphSnapshot] | None = None  # the pair view() gave last (None: a new cell)
        self._tasks_changed: set[str] = set()  # since then (view())
        self._tasks_gone: dict[str, int] = {}
        self._robots_changed: set[str] = set()
        self._robots_left: set[str] = set()

    # -- taking a batch ----------------------------------------------------------------
    def apply(self, ch: CellChanges) -> None:
        """Take the next batch: ChangeGap when it is not number ``seq + 1``, ChangeRefused
        (naming the item) when it cannot apply; either way nothing of it is taken."""
        if ch.seq != self.seq + 1:
            raise ChangeGap(self.seq + 1, ch.seq)
        if not (math.isfinite(ch.stamp) and ch.stamp >= 0):
            raise ChangeRefused(f"CellChanges {ch.seq} header.stamp: {ch.stamp!r} is not a finite time")
        self._check_ids(ch)
        self._check_items(ch)
        self._apply(ch)
        self.seq = ch.seq

    def _check_ids(self, ch: CellChanges) -> None:
        """ChangeRefused for what names a task or robot the cell does not hold."""
        where = f"CellChanges {ch.seq}"
        for field, ids in (("tasks_cancelled", ch.cancelled), ("tasks_retired", ch.retired)):
            for n, tid in enumerate(ids):
                if tid not in self.tasks:
                    raise ChangeRefused(f"{where} {field}[{n}]: unknown task {tid!r}")
        for n, t in enumerate(ch.tasks):
            if t.id not in self.tasks and t.id not in self.retired and t.status not in (_QUEUED, _READY):
                raise ChangeRefused(f"{where} tasks[{n}] ({t.id!r}): unknown task (a new task comes QUEUED or "
                                    f"READY, got status {t.status})")
            if t.id in ch.cancelled or t.id in ch.retired:
                raise ChangeRefused(f"{where} tasks[{n}] ({t.id!r}): also cancelled or retired in the same batch")
        for n, tid in enumerate(ch.retired):
            t = next((u for u in ch.tasks if u.id == tid), self.tasks[tid])
            if t.status != _DONE:
                raise ChangeRefused(f"{where} tasks_retired[{n}]: task {tid!r} is not DONE")
        for n, rid in enumerate(ch.left):
            if rid not in self.robots:
                raise ChangeRefused(f"{where} robots_left[{n}]: unknown robot {rid!r}")

    def _check_items(self, ch: CellChanges) -> None:
        """ChangeRefused naming the item for a task or robot that cannot be the cell's: the
        snapshot checks, on the batch's items only (a cycle is looked for among the tasks it
        adds, in the whole graph only when it changes a known task's prerequisites)."""
        team, graph = self.team_base, self.graph_base
        ids = _Ids(self.tasks, {t.id for t in ch.tasks} | set(ch.retired), self.retired, set(ch.cancelled))
        known = {s[0] for s in graph.sites}
        try:
            for n, t in enumerate(ch.tasks):
                check_task(graph, n, t, ids)
                check_task_sites(n, t, known)
            for n, r in enumerate(ch.robots):
                old = self.robots.get(r.id)  # what check_robot checks, unchanged since it passed: not again
                if old is None or (r.capabilities, r.payload, r.traits, r.speed) != (old.capabilities, old.payload,
                                                                                    old.traits, old.speed):
                    check_robot(team, n, r)
                if not math.isfinite(r.busy_for):
                    raise InstanceError(f"TeamState robots[{n}] ({r.id!r}).busy_for: {r.busy_for!r} is not finite")
        except InstanceError as exc:
            raise ChangeRefused(f"CellChanges {ch.seq} {str(exc).replace('TeamState ', '').replace('TaskGraph ', '')}"
                                ) from None
        rewired = [t for t in ch.tasks if t.id in self.tasks and t.prerequisites != self.tasks[t.id].prerequisites]
        edges = {t.id: tuple(t.prerequisites) for t in ch.tasks if t.id not in self.tasks}  # a cycle needs a new
        if rewired:  # task, or a known one that waits on more than it did
            edges = {**{k: tuple(t.prerequisites) for k, t in self.tasks.items()},
                     **{t.id: tuple(t.prerequisites) for t in ch.tasks}}
        try:
            if edges:
                check_acyclic(tuple(sorted(edges.items())))
        except InstanceError as exc:
            raise ChangeRefused(f"CellChanges {ch.seq}: {exc}") from None

    def _apply(self, ch: CellChanges) -> None:
        for t in ch.tasks:
            if t.id in self.retired:
                continue  # never comes back
            self._put(_unnamed(t, self.retired))
        for tid in ch.cancelled:
            self._drop(tid)
        for tid in ch.retired:
            self._drop(tid)
            self.retired.add(tid)
            self.retired_count += 1
        for r in ch.robots:
            self.robots[r.id] = r
            self._robots_changed.add(r.id)
            self._robots_left.discard(r.id)
            if r.busy_for > 0:
                self.until[r.id] = ch.stamp + r.busy_for
            else:
                self.until.pop(r.id, None)
        for rid in ch.left:
            self.robots.pop(rid)
            self.until.pop(rid, None)
            self._robots_left.add(rid)
            self._robots_changed.discard(rid)
        self.stamp = max(self.stamp, ch.stamp)
        self._snaps = None

    def _put(self, t: TaskInfo) -> None:
        old = self.tasks.get(t.id)
        if old is not None and old.prerequisites != t.prerequisites:
            for p in old.prerequisites:
                self.dependents.get(p, set()).discard(t.id)
        if old is None or old.prerequisites != t.prerequisites:
            for p in t.prerequisites:
                self.dependents.setdefault(p, set()).add(t.id)
        self.tasks[t.id] = t
        self._tasks_changed.add(t.id)
        self._tasks_gone.pop(t.id, None)
        if t.status == _DONE:
            self.done.add(t.id)
        else:
            self.done.discard(t.id)

    def _drop(self, tid: str) -> None:
        """A task leaves; its dependents no longer name it."""
        t = self.tasks.pop(tid, None)
        if t is None:
            return
        self._tasks_changed.discard(tid)
        self._tasks_gone[tid] = t.status
        for p in t.prerequisites:
            self.dependents.get(p, set()).discard(tid)
        for d in self.dependents.pop(tid, set()):
            dep = self.tasks.get(d)
            if dep is not None:
                self.tasks[d] = replace(dep, prerequisites=tuple(p for p in dep.prerequisites if p != tid))
                self._tasks_changed.add(d)
        self.done.discard(tid)

    # -- what a decision reads ---------------------------------------------------------
    def snapshots(self) -> tuple[TeamSnapshot, GraphSnapshot]:
        """The cell as a world's snapshot pair stamped with the last batch's time (busy
        robots' ``busy_for`` counted from it)."""
        if self._snaps is None:
            now, until = self.stamp, self.until
            robots = tuple(r if r.id not in until or abs(r.busy_for - (until[r.id] - now)) < UNTIL_EPS
                           else replace(r, busy_for=max(0.0, until[r.id] - now)) for r in self.robots.values())
            self._snaps = (replace(self.team_base, stamp=now, robots=robots),
                           replace(self.graph_base, stamp=now, tasks=tuple(self.tasks.values())))
        return self._snaps

    def view(self) -> tuple[TeamSnapshot, GraphSnapshot, CellDelta]:
        """The cell as a snapshot pair with what changed since the pair the last call gave,
        for :meth:`~lvws_ros.core.online.OnlineScheduler.offer_cell`: in time proportional
        to the change (the robots as their batches gave them: ``busy_for`` as of each one's
        batch, the delta's ``until`` says when each busy robot is free)."""
        now = self.stamp
        team = replace(self.team_base, stamp=now, robots=tuple(self.robots.values()))
        graph = replace(self.graph_base, stamp=now, tasks=tuple(self.tasks.values()))
        changed = self._tasks_changed
        watch = set(changed)
        for tid in changed:
            watch.update(self.dependents.get(tid, ()))
        delta = CellDelta(self._viewed, frozenset(changed), dict(self._tasks_gone), frozenset(self._robots_changed),
                          frozenset(self._robots_left), frozenset(watch), dict(self.tasks), dict(self.until),
                          self.graph_base)
        self._viewed = (team, graph)
        self._tasks_changed, self._tasks_gone, self._robots_changed, self._robots_left = set(), {}, set(), set()
        return team, graph, delta

    # -- retiring done work ------------------------------------------------------------
    def retire(self, horizon: float) -> list[str]:
        """Retire the DONE tasks that ended ``horizon`` seconds or more before the cell's
        time and whose dependents have all started (or that have none): they leave the live
        cell, and their dependents no longer name them. Returns their ids."""
        out = []
        for tid in list(self.done):
            t = self.tasks[tid]
            if t.end is not None and t.end > self.stamp - horizon:
                continue
            if all(self.tasks[d].status >= _ASSIGNED for d in self.dependents.get(tid, ()) if d in self.tasks):
                out.append(tid)
        for tid in out:
            self._drop(tid)
            self.retired.add(tid)
        self.retired_count += len(out)
        if out:
            self._snaps = None
            self.snapshots()
        return out


def _robot_same(a: RobotInfo, b: RobotInfo, a_stamp: float, b_stamp: float) -> bool:
    """Whether robot ``b`` at ``b_stamp`` is robot ``a`` at ``a_stamp`` with only time gone by."""
    if a is b:
        return True
    if replace(a, busy_for=0.0) != replace(b, busy_for=0.0):
        return False
    if a.busy_for <= 0 and b.busy_for <= 0:
        return True
    return abs((a_stamp + a.busy_for) - (b_stamp + b.busy_for)) < UNTIL_EPS


def changes_between(before: tuple[TeamSnapshot, GraphSnapshot], after: tuple[TeamSnapshot, GraphSnapshot],
                    seq: int) -> CellChanges:
    """The batch number ``seq`` that turns the snapshot pair ``before`` into ``after`` (a
    task that left DONE retired, any other cancelled; a busy robot whose end did not move
    unchanged)."""
    (t0, g0), (t1, g1) = before, after
    old_tasks = {t.id: t for t in g0.tasks}
    new_ids = {t.id for t in g1.tasks}
    tasks = tuple(t for t in g1.tasks if old_tasks.get(t.id) != t)
    gone = [t for t in g0.tasks if t.id not in new_ids]
    old_robots = {r.id: r for r in t0.robots}
    new_robot_ids = {r.id for r in t1.robots}
    robots = tuple(r for r in t1.robots if r.id not in old_robots
                   or not _robot_same(old_robots[r.id], r, t0.stamp, t1.stamp))
    return CellChanges(seq, max(t1.stamp, g1.stamp), tasks,
                       tuple(t.id for t in gone if t.status != _DONE), tuple(t.id for t in gone if t.status == _DONE),
                       robots, tuple(r.id for r in t0.robots if r.id not in new_robot_ids))


MAX_HELD = 100_000  # batches held while a resync is awaited (beyond: the oldest are dropped; the resync covers them)


class ChangeFollower:
    """What a node does with numbered batches: take them in order into a :class:`LiveCell`,
    hold those that come early, and say when a snapshot is needed (:attr:`needs_resync`):
    before the first snapshot, after a gap, after a batch it refused. ``retire_after``
    (seconds, < 0: never): done work retires from the cell that long after it ended,
    whatever the world does (:meth:`LiveCell.retire`)."""

    def __init__(self, retire_after: float = -1.0) -> None:
        self.cell: LiveCell | None = None
        self.retire_after = retire_after
        self.held: dict[int, CellChanges] = {}
        self.needs_resync = False
        self.notices: list[str] = []  # for the node's diagnostics (WARN)
        self.gaps = self.refused = self.repeated = self.resyncs = self.restarts = 0
        self.restarted = False  # a world started again since the last snapshot

    def take(self, ch: CellChanges) -> bool:
        """Take one batch; whether the cell changed."""
        if self.cell is None:
            self._hold(ch)
            self.needs_resync = True
            return False
        if ch.seq == 1 < self.cell.seq and not self.restarted:  # numbers are never reused while a world runs
            self.held.clear()
            self.notices.append(f"CellChanges 1 after {self.cell.seq}: the world started again; asking for its "
                                "snapshot")
            self.restarts += 1
            self.restarted = self.needs_resync = True
        if self.needs_resync:  # until the world's snapshot says which batches it covers
            self._hold(ch)
            return False
        if ch.seq <= self.cell.seq:
            self.repeated += 1
            return False
        self._hold(ch)
        return self._drain()

    def start_from(self, team: TeamSnapshot, graph: GraphSnapshot, first: CellChanges, checked: bool = False) -> bool:
        """Before ``first``, the first batch taken, when it is number 1 and nothing was
        taken yet: the world's first snapshots (change 0, which a world that speaks changes
        publishes once, latched) as the cell, so that batch 1 needs no resync. Whether they
        were taken. ``checked``: both passed the snapshot checks already (a scheduler took
        them); else InstanceError for snapshots that cannot be used (nothing taken)."""
        if self.cell is not None or first.seq != 1 or abs(team.stamp - graph.stamp) > UNTIL_EPS \
                or first.stamp < team.stamp:
            return False
        self.cell = LiveCell(team, graph, 0, checked)
        return True

    def resync(self, team: TeamSnapshot, graph: GraphSnapshot, seq: int) -> None:
        """Take the world's snapshots as of batch ``seq``, then the held batches after it
        (InstanceError, nothing taken, for snapshots that cannot be used)."""
        if self.cell is None or self.restarted:  # a world started again: its ids owe nothing to the last one's
            self.cell = LiveCell(team, graph, seq)
        else:
            self.cell.reset(team, graph, seq)
        self.restarted = False
        self.resyncs += 1
        self.needs_resync = False
        self._drain()

    def _hold(self, ch: CellChanges) -> None:
        self.held[ch.seq] = ch
        while len(self.held) > MAX_HELD:
            del self.held[min(self.held)]

    def _drain(self) -> bool:
        cell = self.cell
        assert cell is not None
        changed = False
        for seq in [s for s in self.held if s <= cell.seq]:
            del self.held[seq]
        while (ch := self.held.pop(cell.seq + 1, None)) is not None:
            try:
                cell.apply(ch)
                changed = True
            except ChangeRefused as exc:
                self.refused += 1
                self.notices.append(f"{exc}: not taken; asking the world for its snapshot")
                self.needs_resync = True
                break
        if self.held and not self.needs_resync:
            self.gaps += 1
            self.notices.append(f"CellChanges {cell.seq + 1}-{min(self.held) - 1} missed: asking the world for its "
                                "snapshot")
            self.needs_resync = True
        if self.retire_after >= 0 and cell.retire(self.retire_after):
            changed = True
        return changed
