"""The cell truth of a world of real robots (the dispatcher's bookkeeping, ROS-free).

A cell is an ``lvws-instance/1`` instance: its robots (capabilities or traits, payloads,
sites, speeds, homes) and tasks. :class:`Dispatch` holds what happens to them while the
robots work: each task's status, subteam, start and end; each robot's site, pose, task
and failure; each goal (one robot's part of one task) from sent to its end. The
dispatcher node feeds it the scheduler's assignments and the robots' answers and
publishes its snapshots (:meth:`Dispatch.team_snapshot`, :meth:`Dispatch.graph_snapshot`)
as TeamState and TaskGraph.

Rules:

* A task is DONE when every member of its subteam succeeded: it starts when its last
  member starts working (its first ``working`` feedback, else its result's end minus its
  worked duration) and ends at the last success; a member that succeeded stays with the
  task until it is done.
* A member that rejects its goal, aborts it or goes silent (:meth:`Dispatch.silent`) fails
  the task: the other members' goals are cancelled (each member stays busy until its goal
  ends), the task returns READY (QUEUED if a prerequisite was cancelled meanwhile) with no
  subteam, and the robot leaves the team (it vanishes from the snapshots) until
  :meth:`Dispatch.rejoin`.
* ``"departure": "each"``: a task may be given to busy members. A busy member's goal is
  held in its queue and goes out (:attr:`Outcome.send`) the moment it is free (the task it
  serves is done, or its goal ended on a cancel), with ``planned_start`` re-timed to when
  it can be there; when that moves the task's start, :attr:`Outcome.moved` says so for the
  members already sent. A member that leaves the team (rejected, aborted, lost, set failed)
  also gives back the tasks it was given and had not set out for: each returns READY, its
  other members' goals cancelled or dropped from their queues. A robot never has two
  goals at once.
* Bad input never raises out of the answers of robots: a result, feedback or answer for a
  goal that is already over (cancelled, lost, or an older goal) is ignored and named in
  the returned notes. An assignment or a service call that cannot be carried out raises
  :class:`~lvws_ros.errors.DispatchRefused` naming the item.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.formats import instance_from_dict, instance_to_dict
from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot, graph_sites, roles_code
from lvws_ros.core.problem import Instance
from lvws_ros.errors import DispatchRefused, InstanceError

__all__ = ["RETIME_SECONDS", "Dispatch", "Goal", "GoalKind", "GoalNews", "GoalSpec", "Moved", "Outcome"]

RETIME_SECONDS = 0.5  # a start moved by less (the answers' own latency) is not announced to the members sent


class GoalKind(enum.IntEnum):
    """What happened to a goal (the values of lvws_msgs/GoalEvent's KIND_* constants)."""

    SENT = 0
    ACCEPTED = 1
    REJECTED = 2
    FEEDBACK = 3
    SUCCEEDED = 4
    ABORTED = 5
    CANCELED = 6
    LOST = 7


_ACTIVE = frozenset({GoalKind.SENT, GoalKind.ACCEPTED})
WORKING = "working"


@dataclass
class Goal:
    key: int
    task: str
    robot: str
    sent: float
    state: GoalKind = GoalKind.SENT
    heard: float = 0.0  # when the robot last answered (sent, at first)
    cancelling: bool = False  # the dispatcher asked the robot to stop
    stale_noted: bool = False  # an answer after its end was reported
    working_since: float | None = None  # its first ``working`` feedback
    done_at: float | None = None  # its success

    @property
    def active(self) -> bool:
        return self.state in _ACTIVE


@dataclass(frozen=True)
class GoalSpec:
    """A goal to send: an ExecuteTask goal to robot ``robot``."""

    key: int
    task: str
    robot: str
    subteam: tuple[str, ...]
    site: str
    site_to: str
    require_names: tuple[str, ...]
    requires: tuple[float, ...]
    planned_start: float
    planned_duration: float


@dataclass(frozen=True)
class GoalNews:
    """One event of one goal, as the dispatcher publishes it (lvws_msgs/GoalEvent)."""

    kind: GoalKind
    task: str
    robot: str
    phase: str = ""
    progress: float = 0.0
    site: str = ""
    duration: float = 0.0
    message: str = ""


@dataclass(frozen=True)
class Moved:
    """A task's planned start moved later after some of its goals went out (a member set out
    later than planned): the members already on their way wait for the new one."""

    task: str
    subteam: tuple[str, ...]
    planned_start: float


@dataclass
class Outcome:
    """What an input did: goal events to publish, goals to cancel (keys), notes for the
    log (warnings), whether the snapshots changed."""

    news: list[GoalNews] = field(default_factory=list)
    cancel: list[int] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    changed: bool = False
    send: list[GoalSpec] = field(default_factory=list)  # goals due now ("departure": "each": a member now free)
    moved: list[Moved] = field(default_factory=list)  # planned starts that moved after goals went out

    def add(self, other: Outcome) -> Outcome:
        self.send += other.send
        self.moved += other.moved
        self.news += other.news
        self.cancel += other.cancel
        self.notes += other.notes
        self.changed |= other.changed
        return self


@dataclass
class _Robot:
    index: int
    site: str  # where it is ("": between sites, at pose)
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
    goal: int = 0  # key of its latest goal (0: none)
    failed: str = ""  # why it left the team ("": present)
    failed_at: float = 0.0
    queue: list[str] = field(default_factory=list)  # "each": tasks given while busy, in order; each goal sent once free


@dataclass
class _Task:
    entry: dict[str, Any]  # as the instance file writes it
    status: int = TaskStatus.QUEUED
    team: tuple[str, ...] = ()
    assigned_at: float = 0.0
    expected_end: float = 0.0
    start: float | None = None
    end: float | None = None
    goals: dict[str, int] = field(default_factory=dict)  # robot -> goal key of the current attempt
    planned_start: float = 0.0  # when its last member should be there (re-timed as members set out)


class Dispatch:
    """The cell's tasks, robots and goals; see the module doc."""

    def __init__(self, inst: Instance, present: Iterable[str] | None = None) -> None:
        data = instance_to_dict(inst)
        self._base = {k: v for k, v in data.items() if k != "tasks"}
        self.inst = inst
        tr = inst.travel
        self.robots = {r.id: _Robot(i, tr.sites[tr.robot_site[i]] if tr is not None else "")
                       for i, r in enumerate(inst.robots)}
        self.tasks: dict[str, _Task] = {t["id"]: _Task(t) for t in data["tasks"]}
        self.goals: dict[int, Goal] = {}
        self._next_key = 1
        self._specs: dict[str, Any] = {}  # task id -> its Task of the current instance
        self._rebuild()
        self._refresh()
        for rid in set(self.robots) - set(self.robots if present is None else present):
            self.robots[rid].failed = "down"

    # -- the instance ----------------------------------------------------------------------
    def _rebuild(self, entries: Sequence[dict[str, Any]] | None = None) -> Instance:
        """The instance of the cell's robots and ``entries`` (the current tasks when None),
        checked: InstanceError naming the item."""
        tasks = [t.entry for t in self.tasks.values()] if entries is None else list(entries)
        inst = instance_from_dict({**self._base, "tasks": tasks})
        if entries is None:
            self.inst = inst
            self._specs = {t.id: t for t in inst.tasks}
        return inst

    def _refresh(self) -> None:
        done = {k for k, t in self.tasks.items() if t.status == TaskStatus.DONE}
        for t in self.tasks.values():
            if t.status in (TaskStatus.QUEUED, TaskStatus.READY):
                ready = all(p in done for p in t.entry.get("after", []))
                t.status = TaskStatus.READY if ready else TaskStatus.QUEUED

    @property
    def done(self) -> bool:
        return all(t.status == TaskStatus.DONE for t in self.tasks.values())

    def _sites(self, task: str) -> tuple[str, str]:
        e = self.tasks[task].entry
        if "site" in e:
            return str(e["site"]), str(e["site"])
        return str(e.get("from", "")), str(e.get("to", ""))

    def _travel_time(self, robot: str, site: str, start: str | None = None) -> float:
        """Seconds robot ``robot`` needs from where it is (or from site ``start``) to
        ``site`` (0 without travel)."""
        tr, r = self.inst.travel, self.robots[robot]
        at = r.site if start is None else start
        if tr is None or not site or at == site:
            return 0.0
        speed = tr.robot_speed[r.index]
        if speed <= 0:
            return 0.0
        b = tr.sites.index(site)
        if at in tr.sites:
            return float(tr.distance[tr.sites.index(at), b]) / speed
        x, y = tr.coordinates[b]
        return math.hypot(x - r.pose[0], y - r.pose[1]) / speed

    def busy_with(self, robot: str) -> str:
        """The task robot ``robot`` serves: the task of its goal while the goal is active,
        or while the task runs (a member that succeeded stays until the task is done)."""
        r = self.robots[robot]
        g = self.goals.get(r.goal)
        if g is None:
            return ""
        t = self.tasks.get(g.task)
        running = t is not None and t.status == TaskStatus.ASSIGNED and t.goals.get(robot) == g.key
        return g.task if g.active or running else ""

    # -- the scheduler's assignments -------------------------------------------------------
    def assign(self, task: str, team: Sequence[str], now: float) -> Outcome:
        """Give ``task`` to ``team``: the goals due now in :attr:`Outcome.send`, as every
        input gives them (DispatchRefused naming the item when the task is unknown or not
        READY, or a member unknown, out of the team, or busy while the cell sends subteams
        off together). With ``"departure": "each"`` a busy member's goal is held until it
        is free (and goes out in the outcome of what frees it)."""
        t = self.tasks.get(task)
        what = f"assignment {task} <- {'+'.join(team)}"
        if t is None:
            raise DispatchRefused(f"{what}: unknown task {task!r}")
        unknown = [rid for rid in team if rid not in self.robots]
        if unknown:
            raise DispatchRefused(f"{what}: unknown robot {unknown[0]!r}")
        if t.status != TaskStatus.READY:
            raise DispatchRefused(f"{what}: task {task!r} is {TaskStatus(t.status).name}, not READY")
        if not team or len(set(team)) != len(team):
            raise DispatchRefused(f"{what}: the subteam is empty or names a robot twice")
        for rid in team:
            r = self.robots[rid]
            if r.failed:
                raise DispatchRefused(f"{what}: robot {rid!r} is out of the team ({r.failed})")
            if self.engaged(rid) and not self.ahead:
                raise DispatchRefused(f"{what}: robot {rid!r} is busy with {self.busy_with(rid)}")
        site = self._sites(task)[0]
        # each member sets out once free ("each": when its tasks given before end), from where they leave it
        start = max(self._free_at(rid, now) + self._travel_time(rid, site, self._site_when_free(rid))
                    for rid in team)
        t.status, t.team, t.assigned_at, t.start, t.end = TaskStatus.ASSIGNED, tuple(team), now, None, None
        t.planned_start, t.expected_end, t.goals = start, start + self._specs[task].duration, {}
        out = Outcome(changed=True)
        for rid in team:
            if self.engaged(rid):
                self.robots[rid].queue.append(task)  # its goal goes out once it is free
            else:
                out.add(self._send(task, rid, now))
        return out

    @property
    def ahead(self) -> bool:
        """``"departure": "each"``: a task may be given to busy robots (formats.md)."""
        return self.inst.departure == "each"

    def engaged(self, robot: str) -> bool:
        """Whether the robot serves a task, or has tasks given that wait for it."""
        return bool(self.busy_with(robot) or self.robots[robot].queue)

    def _last_task(self, robot: str) -> _Task | None:
        """The last task the robot was given (queued, else the one it serves), if any."""
        r = self.robots[robot]
        last = r.queue[-1] if r.queue else self.busy_with(robot)
        return self.tasks.get(last) if last else None

    def _free_at(self, robot: str, now: float) -> float:
        """When the robot is expected free: the expected end of its last task given, or now."""
        t = self._last_task(robot)
        return max(now, t.expected_end) if t is not None and t.status == TaskStatus.ASSIGNED else now

    def _site_when_free(self, robot: str) -> str:
        """Where the robot will be once free: where its last task given leaves it."""
        r, t = self.robots[robot], self._last_task(robot)
        if t is None or self.inst.travel is None:
            return r.site
        site, site_to = self._sites(t.entry["id"])
        return site_to or site

    def _send(self, task: str, robot: str, now: float) -> Outcome:
        """The robot's goal on ``task`` (its part), due now (in ``Outcome.send``)."""
        t, spec = self.tasks[task], self._specs[task]
        site, site_to = self._sites(task)
        out = Outcome()
        # re-timed: a member that sets out later than expected moves the task's start (for those sent too)
        start = max(t.planned_start, now + self._travel_time(robot, site))
        if t.goals and start > t.planned_start + RETIME_SECONDS:
            out.moved.append(Moved(task, t.team, start))
        t.planned_start, t.expected_end = start, start + float(spec.duration)
        key = self._next_key
        self._next_key += 1
        self.goals[key] = Goal(key, task, robot, now, heard=now)
        t.goals[robot] = self.robots[robot].goal = key
        out.send.append(GoalSpec(key, task, robot, t.team, site, site_to or site,
                                 tuple(n for n, _ in spec.requires), tuple(float(a) for _, a in spec.requires),
                                 t.planned_start, float(spec.duration)))
        out.news.append(GoalNews(GoalKind.SENT, task, robot, site=site))
        return out

    def _next(self, robot: str, now: float) -> Outcome:
        """A robot free again: the goal of the next task it was given, if any."""
        r = self.robots[robot]
        if r.failed or self.busy_with(robot) or not r.queue:
            return Outcome()
        return self._send(r.queue.pop(0), robot, now)

    # -- the robots' answers ---------------------------------------------------------------
    def _goal(self, key: int, what: str, out: Outcome) -> Goal | None:
        """The active goal ``key``; None (and a note) for an unknown or finished one."""
        g = self.goals.get(key)
        if g is None:
            out.notes.append(f"{what} for unknown goal {key}: ignored")
        elif not g.active:
            if not g.stale_noted:  # once per goal: a robot may send feedback ten times a second
                g.stale_noted = True
                out.notes.append(f"{what} for the goal of {g.robot} on {g.task} that is already "
                                 f"{g.state.name.lower()}: ignored")
            if g.state == GoalKind.LOST and what.startswith(("success", "aborted", "canceled")) \
                    and self.robots[g.robot].failed == "lost":
                out.add(self.rejoin(g.robot))  # it was alive after all, and its goal is over: free again
            return None
        return g

    def accepted(self, key: int, now: float) -> Outcome:
        out = Outcome()
        g = self._goal(key, "acceptance", out)
        if g is not None and g.state == GoalKind.SENT:
            g.state, g.heard = GoalKind.ACCEPTED, now
            out.news.append(GoalNews(GoalKind.ACCEPTED, g.task, g.robot))
        return out

    def feedback(self, key: int, now: float, phase: str, progress: float, site: str,
                 pose: tuple[float, float, float] | None = None) -> Outcome:
        """A goal's feedback: the robot is alive, where it is, and when it starts working."""
        out = Outcome()
        g = self._goal(key, f"feedback ({phase})", out)
        if g is None:
            return out
        g.heard = now
        if g.state == GoalKind.SENT:
            g.state = GoalKind.ACCEPTED
        r, tr = self.robots[g.robot], self.inst.travel
        if tr is not None and tr.robot_speed[r.index] > 0 and (not site or site in tr.sites):
            r.site = site  # "": between sites, at its pose
        if pose is not None and any(pose):
            r.pose = pose
        t = self.tasks.get(g.task)
        if phase == WORKING and g.working_since is None and not g.cancelling:
            g.working_since = now
            if t is not None and t.status == TaskStatus.ASSIGNED:  # the plan's end, from the real start
                t.expected_end = max(t.expected_end, now + self._specs[g.task].duration)
        out.news.append(GoalNews(GoalKind.FEEDBACK, g.task, g.robot, phase, float(progress), site))
        return out

    def succeeded(self, key: int, now: float, duration: float, message: str = "") -> Outcome:
        """A member's success; the task is DONE when every member succeeded."""
        out = Outcome()
        g = self._goal(key, "success", out)
        if g is None:
            return out
        g.state, g.heard, g.done_at = GoalKind.SUCCEEDED, now, now
        out.news.append(GoalNews(GoalKind.SUCCEEDED, g.task, g.robot, duration=float(duration), message=message))
        t = self.tasks.get(g.task)
        out.changed = True
        if t is None or t.status != TaskStatus.ASSIGNED or t.goals.get(g.robot) != key:
            return out.add(self._next(g.robot, now))  # a stopped goal that finished anyway: the robot is free
        if g.working_since is None:
            g.working_since = max(g.sent, now - max(0.0, float(duration)))
        members = [self.goals[k] for k in t.goals.values()]
        if len(members) == len(t.team) and all(m.state == GoalKind.SUCCEEDED for m in members):
            t.status, t.end = TaskStatus.DONE, now
            t.start = min(now, max(m.working_since or m.sent for m in members))
            site_to = self._sites(g.task)[1]
            tr = self.inst.travel
            for m in members:
                r = self.robots[m.robot]
                if site_to and tr is not None and (tr.robot_speed[r.index] > 0 or r.site == site_to):
                    r.site = site_to
            self._refresh()
            for m in members:  # "each": a member free now sets out for its next task
                out.add(self._next(m.robot, now))
        return out

    def ended(self, key: int, now: float, kind: GoalKind, message: str) -> Outcome:
        """The goal was rejected, aborted, cancelled or lost (``kind``). Unless the
        dispatcher cancelled it, the robot failed the task: it leaves the team and the
        task is interrupted."""
        out = Outcome()
        g = self._goal(key, f"{kind.name.lower()} answer", out)
        if g is None:
            return out
        g.state, g.heard = kind, now
        out.news.append(GoalNews(kind, g.task, g.robot, message=message))
        out.changed = True
        if kind == GoalKind.CANCELED and g.cancelling:
            return out.add(self._next(g.robot, now))  # stopped on request: free, on to its next task
        if kind == GoalKind.LOST:
            out.cancel.append(key)  # best effort: a robot alive but silent stops, and answers (back then)
        r = self.robots[g.robot]
        r.failed, r.failed_at = kind.name.lower(), now
        out.notes.append(f"robot {g.robot}: goal on {g.task} {kind.name.lower()}"
                         f"{' (' + message + ')' if message else ''}; it leaves the team until its server "
                         "answers again")
        t = self.tasks.get(g.task)
        if t is not None and t.status == TaskStatus.ASSIGNED and t.goals.get(g.robot) == key:
            out.add(self._interrupt(g.task, f"{g.robot}'s goal {kind.name.lower()}", now))
        out.add(self._release_queue(g.robot, now))
        return out

    def _release_queue(self, robot: str, now: float) -> Outcome:
        """A robot out of the team: the tasks it was given and had not set out for go back
        to READY, their other members released (never double-booked)."""
        out, r = Outcome(), self.robots[robot]
        while r.queue:
            task = r.queue.pop(0)
            if self.tasks[task].status == TaskStatus.ASSIGNED:
                out.add(self._interrupt(task, f"{robot} left the team before it set out", now))
        return out

    def _interrupt(self, task: str, why: str, now: float) -> Outcome:
        """Cancel every other active goal of ``task`` and put it back to READY (QUEUED if
        a prerequisite is not done); members are free once their goal has ended. A member
        that was given it while busy ("each") forgets it; one that succeeded on it already
        sets out for its next task."""
        t, out = self.tasks[task], Outcome(changed=True)
        for key in t.goals.values():
            g = self.goals[key]
            if g.active and not g.cancelling:
                g.cancelling = True
                out.cancel.append(key)
        team = t.team
        for rid in team:
            if task in self.robots[rid].queue:
                self.robots[rid].queue.remove(task)
        t.status, t.team, t.goals, t.start, t.end = TaskStatus.READY, (), {}, None, None
        self._refresh()
        out.notes.append(f"task {task} interrupted ({why}): READY again, {len(out.cancel)} goal(s) cancelled")
        for rid in team:
            out.add(self._next(rid, now))
        return out

    def silent(self, now: float, timeout: float, available: Mapping[str, bool],
               quiet: Mapping[int, float] | None = None) -> Outcome:
        """Goals whose robot sent nothing for ``timeout`` seconds are lost; so is a free
        robot whose server is not ``available`` (robot -> server up for the last
        ``timeout`` seconds, as the caller judges it). ``quiet``: goal key -> seconds since
        its robot was last heard, on the caller's clock (the node: wall time, even on sim
        time); default: since :attr:`Goal.heard`, on ``now``'s clock."""
        out = Outcome()
        for g in list(self.goals.values()):
            if g.active and (now - g.heard if quiet is None else quiet.get(g.key, 0.0)) > timeout:
                out.add(self.ended(g.key, now, GoalKind.LOST, f"no answer for {timeout:g} s"))
        for rid, r in self.robots.items():
            if not r.failed and not self.busy_with(rid) and not available.get(rid, True):
                r.failed, r.failed_at = "lost", now
                out.changed = True
                out.notes.append(f"robot {rid}: its server is gone; it leaves the team until it answers again")
                out.add(self._release_queue(rid, now))
        return out

    def rejoin(self, robot: str) -> Outcome:
        """The robot is back in the team (its server answers again, or a repair)."""
        r, out = self.robots[robot], Outcome()
        if r.failed:
            out.notes.append(f"robot {robot} is back in the team (was {r.failed})")
            r.failed, out.changed = "", True
        return out

    # -- services --------------------------------------------------------------------------
    def add_tasks(self, entries: Sequence[dict[str, Any]]) -> Outcome:
        """Add tasks written as the instance format writes them (all or nothing;
        DispatchRefused naming the item)."""
        ids = [e.get("id") for e in entries if isinstance(e, dict)]
        clash = sorted(str(i) for i in ids if i in self.tasks)
        if clash:
            raise DispatchRefused(f"task id(s) already in the cell: {clash}")
        current = [t.entry for t in self.tasks.values()]
        try:
            inst = self._rebuild([*current, *entries])
        except InstanceError as exc:
            raise DispatchRefused(f"tasks refused: {exc}") from None
        fresh = instance_to_dict(inst)["tasks"][len(current):]
        for e in fresh:
            self.tasks[e["id"]] = _Task(e)
        self._rebuild()
        self._refresh()
        return Outcome(changed=True, notes=[f"task(s) {', '.join(e['id'] for e in fresh)} added"])

    def cancel(self, task: str, now: float) -> Outcome:
        """Cancel a task that is not done: its running goals are cancelled, it leaves the
        graph and its dependents no longer wait for it."""
        t = self.tasks.get(task)
        if t is None:
            raise DispatchRefused(f"cancel: unknown task {task!r}")
        if t.status == TaskStatus.DONE:
            raise DispatchRefused(f"cancel: task {task!r} is done")
        out = self._interrupt(task, "cancelled", now) if t.status == TaskStatus.ASSIGNED else Outcome(changed=True)
        out.notes = [f"task {task} cancelled ({len(out.cancel)} goal(s) cancelled)"]
        del self.tasks[task]
        for other in self.tasks.values():
            after = other.entry.get("after", [])
            if task in after:
                other.entry = {**other.entry, "after": [a for a in after if a != task]}
        self._rebuild()
        self._refresh()
        return out

    def fault(self, robot: str, failed: bool, now: float) -> Outcome:
        r = self.robots.get(robot)
        if r is None:
            raise DispatchRefused(f"set_robot_fault: unknown robot {robot!r}")
        if not failed:
            return self.rejoin(robot)
        out = Outcome(changed=True)
        task = self.busy_with(robot)
        r.failed, r.failed_at = "fault", now  # first: the interrupt sends it nothing more
        if task and self.tasks[task].status == TaskStatus.ASSIGNED:
            out.add(self._interrupt(task, f"{robot} set failed", now))
        out.add(self._release_queue(robot, now))
        out.notes.append(f"robot {robot} set failed")
        return out

    # -- snapshots -------------------------------------------------------------------------
    def team_snapshot(self, now: float) -> TeamSnapshot:
        inst, tr = self.inst, self.inst.travel
        k = len(inst.capabilities)
        robots = []
        for rid, r in self.robots.items():
            if r.failed:
                continue  # a failed robot vanishes from TeamState
            i, task = r.index, self.busy_with(rid)
            t = self.tasks.get(task)
            running = t is not None and t.status == TaskStatus.ASSIGNED
            # busy until its last task given ends, where that task leaves it ("each": tasks queued)
            site = self._site_when_free(rid) if running or r.queue else r.site
            busy = self._free_at(rid, now) - now if running or r.queue else 0.0
            robots.append(RobotInfo(rid, str(inst.robots[i].extra.get("kind", "robot")), not self.engaged(rid),
                                    inst.robots[i].capabilities, inst.robots[i].payload,
                                    task if running else "", busy, r.pose, site,
                                    0.0 if tr is None else tr.robot_speed[i],
                                    tuple(float(a) for a in inst.robot_amounts[i, k:]),
                                    "" if tr is None else tr.sites[tr.home(i)]))
        return TeamSnapshot(now, inst.capabilities, tuple(robots), inst.traits)

    def graph_snapshot(self, now: float) -> GraphSnapshot:
        inst, tr = self.inst, self.inst.travel
        k = len(inst.capabilities)
        tasks = []
        for j, spec in enumerate(inst.tasks):
            t = self.tasks[spec.id]
            # not started: when the subteam was sent off, or ("each") when its last member should be there
            start = t.start if t.start is not None else t.planned_start if self.ahead else t.assigned_at
            sites = self._sites(spec.id) if tr is not None else ("", "")
            tasks.append(TaskInfo(spec.id, int(t.status), spec.capabilities, spec.payload, spec.duration, spec.after,
                                  t.team, start if t.status >= TaskStatus.ASSIGNED else None, t.end,
                                  sites[0], sites[1], tuple(float(a) for a in inst.task_needs[j, k:]),
                                  roles_code(spec.roles)))
        where = ((), ()) if tr is None else graph_sites(tr)
        return GraphSnapshot(now, inst.capabilities, tuple(tasks), *where, inst.traits, inst.roles, inst.objective,
                             inst.departure)

    def counts(self) -> dict[str, int]:
        """Tasks by status name, for progress lines."""
        out: dict[str, int] = {}
        for t in self.tasks.values():
            name = TaskStatus(t.status).name.lower()
            out[name] = out.get(name, 0) + 1
        return out

    def failed_robots(self) -> dict[str, tuple[str, float]]:
        """Robots out of the team: id -> (why, since when)."""
        return {rid: (r.failed, r.failed_at) for rid, r in self.robots.items() if r.failed}

