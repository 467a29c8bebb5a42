"""The assembly-cell case study (paper section IV-B) as a pymunk 2D kinematic world.

No ROS here: :class:`CellSim` takes a :class:`~lvws_ros.sim.config.CellConfig`,
executes subteam assignments and reports what happened; the ``cell_sim`` node, the
offline runner and the tests drive it.

* Panda arms are static bodies at their cell; an arm works only on an object at its cell.
* Jackals and the Husky are kinematic bodies driven at bounded speed (travel takes
  time, nothing teleports). A transport task drives every member to the object, loads
  it (handling time), carries it at the slowest member's speed, and unloads it. The
  members' payloads must add up to the object's weight (Eq. 11), so only a Jackal +
  Husky subteam can carry Obj1 (7 units).
* The world changes while it runs (the dynamic protocol of docs/ros.md): :meth:`CellSim.submit`
  adds tasks, :meth:`CellSim.cancel` removes one (its dependents stop waiting for it),
  :meth:`CellSim.fail` stops a robot where it is and takes it out of the team (its task
  returns READY; a carried object is put down where it is, and a transport picks it up
  from there), :meth:`CellSim.repair` brings it back. :meth:`CellSim.impossible` names the
  tasks the team left can never do. Refusals are :class:`~lvws_ros.errors.WorldEventRejected`.
* With ``plan_travel`` (the shipped config), the instance has the travel extension of
  formats.md (:func:`build_instance`: cells and start points as sites, distances that
  bound the drive to a member's slot); members pace their approach to arrive when the plan
  says (the task starts when the last one is there), a member already at the object stays
  where it stands, and a transport carries at ``nominal_speed`` keeping its formation, so
  the world executes a plan on time. ``share_travel=False`` keeps the travel out of the
  snapshots (a travel-blind scheduler in the same world).
* The scheduling instance (:attr:`CellSim.inst`) carries nominal durations; the
  executed schedule (:meth:`CellSim.schedule`) carries what really happened, approach
  drives and real speeds included, and is valid by the rules of formats.md for the
  executed instance (:meth:`CellSim.executed_instance`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pymunk

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot, graph_sites
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.subteams import shortfall
from lvws_ros.core.travel import Travel, build_travel
from lvws_ros.errors import AssignmentRejected, ConfigError, InstanceError, WorldEventRejected
from lvws_ros.sim.config import (
    ARM_KINDS,
    FLOOR,
    MOBILE_KINDS,
    CellConfig,
    RobotSpec,
    TaskSpec,
    check_object_flow,
    parse_task,
    start_site,
)
from lvws_ros.sim.instance_world import check_noise, duration_factor

__all__ = ["CellSim", "Event", "Frame", "build_instance"]

QUEUED, READY, ASSIGNED, DONE = TaskStatus.QUEUED, TaskStatus.READY, TaskStatus.ASSIGNED, TaskStatus.DONE


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


SLOT_RADIUS = 0.8  # members stand this far from the object they work on (_slot)


def _travel(cfg: CellConfig) -> Travel:
    """The cell's travel (``plan_travel``): the cells and each mobile robot's start point
    as sites. A distance includes SLOT_RADIUS at each cell end (a member stands at a slot
    around the object, not at the cell's centre), so it bounds the drive between any two
    slots and robots can arrive when the plan says."""
    sites = {c.id: c.position for c in cfg.cells.values()}
    sites.update({start_site(r.id): r.start for r in cfg.robots if r.kind in MOBILE_KINDS})
    offset = {name: SLOT_RADIUS if name in cfg.cells else 0.0 for name in sites}
    distances = {a: {b: round(_dist(pa, pb) + offset[a] + offset[b], 6) for b, pb in sites.items() if b != a}
                 for a, pa in sites.items()}
    robots = [(r.id, str(r.cell), None) if r.kind in ARM_KINDS else (r.id, start_site(r.id), r.speed)
              for r in cfg.robots]
    tasks = [(t.id, t.source or t.cell, t.cell) for t in cfg.tasks]
    return build_travel({k: list(v) for k, v in sites.items()}, distances, robots, tasks)


def build_instance(cfg: CellConfig) -> Instance:
    """The scheduling problem of the case study, with nominal durations (and, with
    ``plan_travel``, the travel between cells)."""
    caps = cfg.capabilities

    def vec(*names: str) -> tuple[int, ...]:
        return tuple(int(c in names) for c in caps)

    robots = tuple(
        Robot(r.id, vec("manipulation", f"@{r.cell}") if r.kind in ARM_KINDS else vec("mobility"), r.payload,
              {"kind": r.kind}, traits=r.traits) for r in cfg.robots)
    tasks = []
    for t in cfg.tasks:
        weight = cfg.objects[t.object].weight
        if t.type == "transport":
            assert t.source is not None
            travel = _dist(cfg.cells[t.source].position, cfg.cells[t.cell].position) / cfg.nominal_speed
            tasks.append(Task(t.id, vec("mobility"), weight, round(2 * cfg.handling_time + travel, 3), t.after,
                              {"type": t.type, "object": t.object, "from": t.source, "to": t.cell},
                              requires=t.requires))
        else:
            tasks.append(Task(t.id, vec("manipulation", f"@{t.cell}"), t.payload, t.duration, t.after,
                              {"type": t.type, "object": t.object, "cell": t.cell}, requires=t.requires))
    return Instance(cfg.name, caps, robots, tuple(tasks), travel=_travel(cfg) if cfg.plan_travel else None,
                    traits=cfg.traits)


@dataclass
class _Job:
    """A task being executed: its subteam and the phase it is in."""

    task: TaskSpec
    team: tuple[str, ...]
    phase: str  # transport: approach, load, carry, unload; assembly: work
    timer: float = 0.0
    targets: dict[str, tuple[float, float]] = field(default_factory=dict)
    due: dict[str, float] = field(default_factory=dict)  # plan_travel: when each member arrives
    pickup: tuple[float, float] = (0.0, 0.0)  # transport: where the object is picked up


@dataclass(frozen=True)
class Frame:
    """Positions and work at one instant, for rendering."""

    time: float
    positions: dict[str, tuple[float, float]]
    robot_task: dict[str, str | None]
    done: int
    total: int = 0  # tasks in the world at that instant (0: unknown)
    failed: frozenset[str] = frozenset()
    task_object: dict[str, str] = field(default_factory=dict)  # running task -> the object it works on


@dataclass
class Event:
    time: float
    kind: str  # finished | submitted | cancelled | interrupted | failed | repaired
    task: str
    robots: tuple[str, ...]


class CellSim:
    """The case-study world. ``assign`` starts tasks, ``step`` advances sim time by dt."""

    def __init__(self, cfg: CellConfig, share_travel: bool = True, noise: float = 0.0, noise_seed: int = 0) -> None:
        # duration noise: each task takes its duration times a seeded factor in [1 - noise, 1 + noise]
        self.noise, self.noise_seed = check_noise(noise), int(noise_seed)
        self.cfg = cfg
        # False: the snapshots leave the travel out (a travel-blind scheduler in the same
        # world, for comparison); the world still moves by the plan's travel
        self.share_travel = share_travel
        self.inst = build_instance(self.cfg)
        self.space = pymunk.Space()
        self.time = 0.0
        self.bodies: dict[str, pymunk.Body] = {}
        for cell in self.cfg.cells.values():  # cell floors: sensors, robots drive over them
            floor = pymunk.Body(body_type=pymunk.Body.STATIC)
            floor.position = cell.position
            shape = pymunk.Poly.create_box(floor, cell.size)
            shape.sensor = True
            self.space.add(floor, shape)
        self.robot_spec = {r.id: r for r in self.cfg.robots}
        for r in self.cfg.robots:
            kind = pymunk.Body.STATIC if r.kind in ARM_KINDS else pymunk.Body.KINEMATIC
            body = pymunk.Body(body_type=kind)
            body.position = self._arm_base(r) if r.kind in ARM_KINDS else r.start
            self.space.add(body, pymunk.Circle(body, 0.35 if r.kind == "jackal" else 0.5))
            self.bodies[r.id] = body
        self.object_cell: dict[str, str | None] = {}
        for o in self.cfg.objects.values():
            body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
            body.position = self.cfg.cells[o.cell].position
            self.space.add(body, pymunk.Poly.create_box(body, (0.4 + 0.08 * o.weight,) * 2))
            self.bodies[o.id] = body
            self.object_cell[o.id] = o.cell
        self.status = {t.id: QUEUED for t in self.cfg.tasks}
        self.start: dict[str, float] = {}
        self.end: dict[str, float] = {}
        self.team: dict[str, tuple[str, ...]] = {}
        self.robot_task: dict[str, str | None] = {r.id: None for r in self.cfg.robots}
        # where each robot is when free (plan_travel): a cell, its start, or "" off every site
        self.robot_site = {r.id: str(r.cell) if r.kind in ARM_KINDS else start_site(r.id) for r in self.cfg.robots}
        self.failed: set[str] = set()
        self.jobs: dict[str, _Job] = {}
        self.trace: list[Frame] = []
        self._task_spec = {t.id: t for t in self.cfg.tasks}
        self._refresh_ready()

    # -- geometry ---------------------------------------------------------------------
    def _arm_base(self, r: RobotSpec) -> tuple[float, float]:
        x, y = self.cfg.cells[str(r.cell)].position
        return (x, y - 1.0)

    def position(self, body_id: str) -> tuple[float, float]:
        p = self.bodies[body_id].position
        return (float(p.x), float(p.y))

    def _slot(self, cell: str | tuple[float, float], k: int, n: int) -> tuple[float, float]:
        """Where member k of n stands around an object at ``cell`` (or at a point: an object
        on the floor) (fixed offsets, so a team carrying together keeps its formation)."""
        x, y = self.cfg.cells[cell].position if isinstance(cell, str) else cell
        ang = math.pi / 2 + 2 * math.pi * k / max(n, 1)
        return (x + SLOT_RADIUS * math.cos(ang), y + SLOT_RADIUS * math.sin(ang))

    def _stand(self, rid: str, at: tuple[float, float], k: int, n: int) -> tuple[float, float]:
        """Where member k of n stands to pick up an object at ``at``. Without plan_travel,
        slot k of n. With it: where it is, if it is at the object already (the plan's zero
        travel); for a robot off every site, short of the object on its straight line
        there (the plan's drive); else its own place around the object."""
        if not self.cfg.plan_travel:
            return self._slot(at, k, n)
        here = self.position(rid)
        gap = _dist(here, at)
        if gap <= SLOT_RADIUS + self.cfg.arrive_tolerance:
            return here
        if not self.robot_site[rid]:  # off every site: the plan drives it straight, so stop short on that line
            return (at[0] + (here[0] - at[0]) * SLOT_RADIUS / gap, at[1] + (here[1] - at[1]) * SLOT_RADIUS / gap)
        # its own place around any object (the mobile robots spread evenly), so robots
        # that stay where they stand never share one
        mobile = [r.id for r in self.cfg.robots if r.kind in MOBILE_KINDS]
        return self._slot(at, mobile.index(rid), len(mobile))

    # -- state ------------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return all(s == DONE for s in self.status.values())

    @property
    def makespan(self) -> float | None:
        return max(self.end.values()) if self.done and self.end else None

    def _refresh_ready(self) -> None:
        for t in self.cfg.tasks:
            if self.status[t.id] == QUEUED and all(self.status[a] == DONE for a in t.after):
                self.status[t.id] = READY

    def check_assignment(self, task_id: str, robot_ids: Sequence[str]) -> None:
        """Raise AssignmentRejected unless the world can execute this assignment now."""
        if task_id not in self.status:
            raise AssignmentRejected(f"unknown task {task_id!r}")
        if self.status[task_id] != READY:
            names = {QUEUED: "queued", ASSIGNED: "already assigned", DONE: "done"}
            raise AssignmentRejected(f"task {task_id} is {names[self.status[task_id]]}, not ready")
        if not robot_ids or len(set(robot_ids)) != len(robot_ids):
            raise AssignmentRejected(f"task {task_id}: empty or repeated robot list {list(robot_ids)}")
        for rid in robot_ids:
            if rid not in self.robot_task:
                raise AssignmentRejected(f"task {task_id}: unknown robot {rid!r}")
            if rid in self.failed:
                raise AssignmentRejected(f"task {task_id}: robot {rid} has failed")
            if self.robot_task[rid] is not None:
                raise AssignmentRejected(f"task {task_id}: robot {rid} is busy with {self.robot_task[rid]}")
        spec = self._task_spec[task_id]
        obj = self.cfg.objects[spec.object]
        kinds = [self.robot_spec[r].kind for r in robot_ids]
        if spec.type == "transport":
            if any(k not in MOBILE_KINDS for k in kinds):
                raise AssignmentRejected(f"task {task_id}: only mobile robots can transport, got {kinds}")
            if self.object_cell[obj.id] not in (spec.source, FLOOR):
                raise AssignmentRejected(f"task {task_id}: {obj.id} is not at {spec.source}")
            total = sum(self.robot_spec[r].payload for r in robot_ids)
            if shortfall(True, total, True, obj.weight)[1] > 0:  # Eq. 11, with the one tolerance
                raise AssignmentRejected(f"task {task_id}: {obj.id} weighs {obj.weight:g}, subteam "
                                         f"{list(robot_ids)} carries only {total:g}")
        else:
            if len(robot_ids) != 1 or kinds[0] not in ARM_KINDS:
                raise AssignmentRejected(f"task {task_id}: assembly needs one arm, got {list(robot_ids)}")
            arm = self.robot_spec[robot_ids[0]]
            if arm.cell != spec.cell:
                raise AssignmentRejected(f"task {task_id}: {arm.id} is at {arm.cell}, the work is at {spec.cell}")
            if self.object_cell[obj.id] != spec.cell:
                at = self.object_cell[obj.id]
                where = "on a robot" if at is None else "on the floor" if at == FLOOR else f"at {at}"
                raise AssignmentRejected(f"task {task_id}: {obj.id} is not at {spec.cell} (it is {where})")
            if shortfall(True, arm.payload, True, spec.payload)[1] > 0:
                raise AssignmentRejected(f"task {task_id}: {arm.id} handles {arm.payload:g}, the part weighs "
                                         f"{spec.payload:g}")

    def assign(self, task_id: str, robot_ids: Sequence[str]) -> None:
        """Start ``task_id`` with the subteam ``robot_ids`` now (raises AssignmentRejected)."""
        self.check_assignment(task_id, robot_ids)
        team = tuple(robot_ids)
        spec = self._task_spec[task_id]
        self.status[task_id] = ASSIGNED
        self.start[task_id] = self.time
        self.team[task_id] = team
        for rid in team:
            self.robot_task[rid] = task_id
        if spec.type == "transport":
            assert spec.source is not None
            pickup: str | tuple[float, float] = spec.source
            if self.object_cell[spec.object] == FLOOR:  # put down by an interrupted transport
                pickup = self.position(spec.object)
            at = self.cfg.cells[pickup].position if isinstance(pickup, str) else pickup
            job = _Job(spec, team, "approach", pickup=at,
                       targets={r: self._stand(r, at, k, len(team)) for k, r in enumerate(team)})
            if self.cfg.plan_travel:  # each member arrives when the plan says; the task starts then
                job.due = {r: self.time + self._travel_time(r, spec.source) for r in team}
                self.start[task_id] = max(job.due.values())
        else:
            job = _Job(spec, team, "work", timer=spec.duration * self.duration_factor(task_id))
        self.jobs[task_id] = job

    def duration_factor(self, task_id: str) -> float:
        """How much longer (or shorter) than its duration task ``task_id`` takes here: 1
        without noise, else 1 + noise x U(-1, 1) drawn from the noise seed and the task's
        id (the same factor for the same task in every run; tasks added later get theirs)."""
        return duration_factor(self.noise, self.noise_seed, task_id)

    def _travel_time(self, rid: str, site: str) -> float:
        """Seconds the plan gives robot ``rid`` from where it is to ``site`` (plan_travel):
        the instance's travel from its site, or straight from its pose when it is off
        every site (the snapshots' rule: lvws_ros.core.online.snapshot_travel)."""
        tr = self.inst.travel
        assert tr is not None
        spec = self.robot_spec[rid]
        here = self.robot_site[rid]
        if here == site:
            return 0.0
        if not here:
            return _dist(self.position(rid), self.cfg.cells[site].position) / spec.speed
        return tr.time(self.inst.robot_index[rid], tr.sites.index(here), tr.sites.index(site))

    # -- a changing world ------------------------------------------------------------------
    def _rebuild(self, tasks: Sequence[TaskSpec]) -> None:
        """The world's task set is ``tasks``; WorldEventRejected (nothing changed) when the
        scheduling instance refuses it (a task the team can never cover, a trait the cell
        does not name)."""
        cfg = replace(self.cfg, tasks=tuple(tasks))
        try:
            inst = build_instance(cfg)
        except InstanceError as exc:
            raise WorldEventRejected(str(exc)) from None
        self.cfg, self.inst = cfg, inst
        self._task_spec = {t.id: t for t in self.cfg.tasks}

    @staticmethod
    def _carrying(job: _Job) -> bool:
        """The job's subteam has its object (a transport past its approach)."""
        return job.task.type == "transport" and job.phase != "approach"

    def _interrupt(self, task_id: str) -> tuple[str, ...]:
        """Stop a running task: its subteam is released, a carried object is put down
        where it is, the task is READY again with no subteam. Returns the subteam."""
        job = self.jobs.pop(task_id)
        if self._carrying(job):
            self.object_cell[job.task.object] = FLOOR
            self.bodies[job.task.object].velocity = (0.0, 0.0)
        for rid in job.team:
            self.robot_task[rid] = None
            if self.robot_spec[rid].kind in MOBILE_KINDS:
                self.robot_site[rid] = ""  # stopped between sites
        self.status[task_id] = READY
        self.start.pop(task_id, None)
        self.team.pop(task_id, None)
        return job.team

    def submit(self, items: Sequence[dict[str, Any]]) -> list[Event]:
        """Add tasks (entries of the config's task list); all or nothing."""
        known = set(self.status)
        new: list[TaskSpec] = []
        for k, item in enumerate(items):
            try:
                spec = parse_task(item, self.cfg.cells, self.cfg.objects)
            except KeyError as exc:
                raise WorldEventRejected(f"task {k}: missing key {exc}") from None
            except ConfigError as exc:
                raise WorldEventRejected(str(exc)) from None
            if spec.id in known:
                raise WorldEventRejected(f"task {spec.id}: the id is taken")
            strange = [name for name, _ in spec.requires if name not in self.cfg.traits]
            if strange:
                raise WorldEventRejected(f"task {spec.id}: unknown trait {strange[0]!r} (the cell's traits: "
                                         f"{list(self.cfg.traits)})")
            unknown = [a for a in spec.after if a not in known]
            if unknown:
                raise WorldEventRejected(f"task {spec.id}: unknown prerequisite(s) {unknown}")
            known.add(spec.id)
            new.append(spec)
        if not new:
            raise WorldEventRejected("no task to add")
        self._check_object_flow([*self.cfg.tasks, *new])
        self._rebuild([*self.cfg.tasks, *new])
        for spec in new:
            self.status[spec.id] = QUEUED
        self._refresh_ready()
        return [Event(self.time, "submitted", spec.id, ()) for spec in new]

    def cancel(self, task_id: str) -> list[Event]:
        """Remove a task that is not done; its dependents no longer wait for it."""
        if task_id not in self.status:
            raise WorldEventRejected(f"unknown task {task_id!r}")
        if self.status[task_id] == DONE:
            raise WorldEventRejected(f"task {task_id} is done; only tasks not done can be cancelled")
        at = dict(self.object_cell)
        job = self.jobs.get(task_id)
        if job is not None and self._carrying(job):
            at[job.task.object] = FLOOR  # where _interrupt puts it down
        self._check_object_flow([t for t in self.cfg.tasks if t.id != task_id], f"cancelling {task_id}: ", at)
        events = []
        if task_id in self.jobs:
            events.append(Event(self.time, "interrupted", task_id, self._interrupt(task_id)))
        del self.status[task_id]
        self._rebuild([replace(t, after=tuple(a for a in t.after if a != task_id))
                       for t in self.cfg.tasks if t.id != task_id])
        self._refresh_ready()
        return [*events, Event(self.time, "cancelled", task_id, ())]

    def _check_object_flow(self, tasks: Sequence[TaskSpec], context: str = "",
                           at: dict[str, str | None] | None = None) -> None:
        """WorldEventRejected if, with ``tasks``, a task not done could wait forever for its
        object (:func:`~lvws_ros.sim.config.check_object_flow`; ``at``: where the objects
        are, default now)."""
        try:
            check_object_flow([t for t in tasks if self.status.get(t.id) != DONE],
                              self.object_cell if at is None else at, started=set(self.jobs))
        except ConfigError as exc:
            raise WorldEventRejected(f"{context}{exc}") from None

    def fail(self, robot_id: str) -> list[Event]:
        """The robot stops where it is and leaves the team; its task returns READY."""
        if robot_id not in self.robot_task:
            raise WorldEventRejected(f"unknown robot {robot_id!r}")
        if robot_id in self.failed:
            raise WorldEventRejected(f"robot {robot_id} has failed already")
        events = []
        task = self.robot_task[robot_id]
        if task is not None:
            events.append(Event(self.time, "interrupted", task, self._interrupt(task)))
        self.failed.add(robot_id)
        if self.robot_spec[robot_id].kind in MOBILE_KINDS:
            self.robot_site[robot_id] = ""
        return [*events, Event(self.time, "failed", "", (robot_id,))]

    def repair(self, robot_id: str) -> list[Event]:
        """A failed robot comes back, available where it stopped."""
        if robot_id not in self.robot_task:
            raise WorldEventRejected(f"unknown robot {robot_id!r}")
        if robot_id not in self.failed:
            raise WorldEventRejected(f"robot {robot_id} has not failed")
        self.failed.discard(robot_id)
        return [Event(self.time, "repaired", "", (robot_id,))]

    def impossible(self) -> dict[str, str]:
        """Tasks not done that the robots left (all but the failed ones) can never do, by
        this world's rules (a transport needs mobile robots carrying the object's weight
        together, Eq. 11; an assembly one arm at its cell handling the part), each with why."""
        alive = [r for r in self.cfg.robots if r.id not in self.failed]
        mobile = sum(r.payload for r in alive if r.kind in MOBILE_KINDS)
        out = {}
        for t in self.cfg.tasks:
            if self.status[t.id] == DONE:
                continue
            if t.type == "transport":
                weight = self.cfg.objects[t.object].weight
                if shortfall(True, mobile, True, weight)[1] > 0:
                    out[t.id] = f"{t.object} weighs {weight:g}; the mobile robots left carry {mobile:g} together"
            elif not any(r.kind in ARM_KINDS and r.cell == t.cell and shortfall(True, r.payload, True, t.payload)[1] == 0
                         for r in alive):
                out[t.id] = f"no arm left at {t.cell} handling {t.payload:g}"
        return out

    # -- dynamics ---------------------------------------------------------------------
    def _drive(self, rid: str, target: tuple[float, float], speed: float, dt: float) -> bool:
        """Set a velocity toward ``target`` (no overshoot); True when already there."""
        body = self.bodies[rid]
        dx, dy = target[0] - body.position.x, target[1] - body.position.y
        d = math.hypot(dx, dy)
        if d <= self.cfg.arrive_tolerance:
            body.velocity = (0.0, 0.0)
            return True
        v = min(speed, d / dt)
        body.velocity = (v * dx / d, v * dy / d)
        return False

    def _pace(self, rid: str, job: _Job) -> float:
        """The speed that brings ``rid`` to its slot when the plan says (plan_travel; at
        most its own speed), else its own speed."""
        speed = self.robot_spec[rid].speed
        if rid not in job.due:
            return speed
        body = self.bodies[rid]
        left = math.hypot(job.targets[rid][0] - body.position.x, job.targets[rid][1] - body.position.y)
        return min(speed, left / max(job.due[rid] - self.time, self.cfg.dt))

    def step(self) -> list[Event]:
        """Advance the world by one dt; returns the tasks that finished."""
        dt = self.cfg.dt
        for body in self.bodies.values():
            if body.body_type == pymunk.Body.KINEMATIC:
                body.velocity = (0.0, 0.0)
        finished: list[str] = []
        for tid, job in self.jobs.items():
            spec = job.task
            if job.phase == "work":
                job.timer -= dt
                if job.timer <= 1e-9:
                    finished.append(tid)
            elif job.phase == "approach":
                arrived = [self._drive(r, job.targets[r], self._pace(r, job), dt)
                           and self.time >= job.due.get(r, 0.0) - 1e-9 for r in job.team]
                if all(arrived):
                    job.phase, job.timer = "load", self.cfg.handling_time * self.duration_factor(tid)
                    self.object_cell[spec.object] = None
                    if self.cfg.plan_travel:
                        self.start[tid] = self.time  # the task starts when the last member is there
            elif job.phase == "load":
                job.timer -= dt
                if job.timer <= 1e-9:
                    job.phase = "carry"
                    if self.cfg.plan_travel:  # each member moves by the object's move: the plan's distance
                        dx, dy = np.subtract(self.cfg.cells[spec.cell].position, job.pickup)
                        job.targets = {r: (self.position(r)[0] + dx, self.position(r)[1] + dy) for r in job.team}
                    else:
                        job.targets = {r: self._slot(spec.cell, k, len(job.team)) for k, r in enumerate(job.team)}
            elif job.phase == "carry":
                speed = min(self.robot_spec[r].speed for r in job.team)
                if self.cfg.plan_travel:  # the plan's duration: carried at nominal_speed
                    speed = min(speed, self.cfg.nominal_speed)
                speed /= self.duration_factor(tid)  # a transport's noise: slower or faster carrying
                arrived = [self._drive(r, job.targets[r], speed, dt) for r in job.team]
                self.bodies[spec.object].velocity = self.bodies[job.team[0]].velocity
                if all(arrived):
                    job.phase, job.timer = "unload", self.cfg.handling_time * self.duration_factor(tid)
            elif job.phase == "unload":
                job.timer -= dt
                if job.timer <= 1e-9:
                    finished.append(tid)
        self.space.step(dt)
        self.time = round(self.time + dt, 9)
        out = []
        for tid in finished:
            job = self.jobs.pop(tid)
            if job.task.type == "transport":
                self.object_cell[job.task.object] = job.task.cell
                self.bodies[job.task.object].position = self.cfg.cells[job.task.cell].position
            self.status[tid] = DONE
            self.end[tid] = self.time
            for rid in job.team:
                self.robot_task[rid] = None
                if job.task.type == "transport":
                    self.robot_site[rid] = job.task.cell
            out.append(Event(self.time, "finished", tid, job.team))
        if out:
            self._refresh_ready()
        return out

    def record_frame(self) -> None:
        """Keep the current positions for rendering (see lvws_ros.sim.render)."""
        self.trace.append(Frame(self.time, {k: self.position(k) for k in self.bodies}, dict(self.robot_task),
                                sum(s == DONE for s in self.status.values()), len(self.status),
                                frozenset(self.failed), {t: j.task.object for t, j in self.jobs.items()}))

    # -- views for the scheduler --------------------------------------------------------
    def team_snapshot(self) -> TeamSnapshot:
        robots = []
        for r, caps in zip(self.cfg.robots, (rb.capabilities for rb in self.inst.robots), strict=True):
            if r.id in self.failed:  # a failed robot leaves the team until repaired
                continue
            task = self.robot_task[r.id]
            busy = 0.0
            if task is not None:
                busy = max(0.0, self.start[task] + self.inst.tasks[self.inst.task_index[task]].duration - self.time)
            x, y = self.position(r.id)
            site, speed = "", 0.0
            if self.cfg.plan_travel and self.share_travel:  # busy: where its task leaves it
                site = self._task_spec[task].cell if task is not None else self.robot_site[r.id]
                speed = r.speed if r.kind in MOBILE_KINDS else 0.0
            robots.append(RobotInfo(r.id, r.kind, task is None, caps, r.payload, task or "", busy, (x, y, 0.0),
                                    site, speed, self._amounts(r.traits)))
        return TeamSnapshot(self.time, self.cfg.capabilities, tuple(robots), self.inst.traits)

    def _amounts(self, pairs: Sequence[tuple[str, float]]) -> tuple[float, ...]:
        """Trait amounts in the order of the instance's trait names (none without traits)."""
        given = dict(pairs)
        return tuple(float(given.get(name, 0.0)) for name in self.inst.traits)

    def graph_snapshot(self) -> GraphSnapshot:
        tasks = []
        tr = self.inst.travel if self.share_travel else None
        for j, t in enumerate(self.inst.tasks):
            sites = ("", "") if tr is None else (tr.sites[tr.task_from[j]], tr.sites[tr.task_to[j]])
            tasks.append(TaskInfo(t.id, self.status[t.id], t.capabilities, t.payload, t.duration, t.after,
                                  self.team.get(t.id, ()), self.start.get(t.id), self.end.get(t.id), *sites,
                                  self._amounts(t.requires)))
        where = ((), ()) if tr is None else graph_sites(tr)
        return GraphSnapshot(self.time, self.cfg.capabilities, tuple(tasks), *where, self.inst.traits)

    # -- results ----------------------------------------------------------------------
    def executed_instance(self) -> Instance:
        """The instance with each finished task's executed duration (travel included)."""
        tasks = tuple(replace(t, duration=(self.end[t.id] - self.start[t.id]) if t.id in self.end else t.duration)
                      for t in self.inst.tasks)
        return replace(self.inst, tasks=tasks)

    def schedule(self, policy: str, decisions: int = 0, compute: float = 0.0) -> Schedule:
        out = [Assignment(t, self.team[t], self.start[t], self.end[t]) for t in self.end]
        return Schedule.from_assignments(self.inst, policy, out, decisions, compute)
