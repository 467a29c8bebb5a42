"""The assembly-cell case study (paper section IV-B) as a pymunk 2D kinematic world.

No ROS here: :class:`CellSim` loads ``config/assembly_cell.yaml``, executes subteam
assignments and reports what happened; the ``cell_sim`` node and the tests drive it.

* Panda arms are static bodies at their cell; an arm works only on an object at its cell.
* Jackals and the Husky are kinematic bodies driven at bounded speed (travel takes
  time, nothing teleports). A transport task drives every member to the object, loads
  it (handling time), carries it at the slowest member's speed, and unloads it. The
  members' payloads must add up to the object's weight (Eq. 11), so only a Jackal +
  Husky subteam can carry Obj1 (7 units).
* The scheduling instance (:meth:`CellSim.instance`) carries nominal durations; the
  executed schedule (:meth:`CellSim.schedule`) carries what really happened, approach
  drives and real speeds included, and is valid by the rules of formats.md for the
  executed instance (:meth:`CellSim.executed_instance`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pymunk
import yaml

from lvws_ros.executor import Policy, TaskStatus
from lvws_ros.model import Instance, Robot, Task
from lvws_ros.online import GraphSnapshot, OnlineDecision, OnlineScheduler, RobotInfo, TaskInfo, TeamSnapshot
from lvws_ros.schedule import Assignment, Schedule

QUEUED, READY, ASSIGNED, DONE = TaskStatus.QUEUED, TaskStatus.READY, TaskStatus.ASSIGNED, TaskStatus.DONE
ARM_KINDS = ("panda",)
MOBILE_KINDS = ("jackal", "husky")


class CellConfigError(ValueError):
    """A malformed assembly-cell configuration."""


class AssignmentRejected(ValueError):
    """The simulator cannot execute an assignment (the message says why)."""


def default_config_path() -> Path:
    """config/assembly_cell.yaml from the installed share directory, else the source tree."""
    try:
        from ament_index_python.packages import get_package_share_directory

        p = Path(get_package_share_directory("lvws_ros")) / "config" / "assembly_cell.yaml"
        if p.is_file():
            return p
    except Exception:
        pass
    return Path(__file__).resolve().parent.parent / "config" / "assembly_cell.yaml"


@dataclass(frozen=True)
class CellSpec:
    id: str
    position: tuple[float, float]
    size: tuple[float, float]


@dataclass(frozen=True)
class RobotSpec:
    id: str
    kind: str
    payload: float
    cell: str | None = None  # arms: their cell
    start: tuple[float, float] = (0.0, 0.0)
    speed: float = 0.0


@dataclass(frozen=True)
class ObjectSpec:
    id: str
    weight: float
    cell: str


@dataclass(frozen=True)
class TaskSpec:
    id: str
    type: str  # "transport" | "assembly"
    object: str
    cell: str  # assembly: where; transport: destination
    source: str | None = None  # transport: origin
    duration: float = 0.0  # assembly: work time
    payload: float = 0.0  # assembly: the part the arm handles
    after: tuple[str, ...] = ()


@dataclass(frozen=True)
class CellConfig:
    name: str
    frame_id: str
    capabilities: tuple[str, ...]
    dt: float
    handling_time: float
    arrive_tolerance: float
    nominal_speed: float
    cells: Mapping[str, CellSpec]
    robots: tuple[RobotSpec, ...]
    objects: Mapping[str, ObjectSpec]
    tasks: tuple[TaskSpec, ...]


def _num(value: Any, what: str, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise CellConfigError(f"{what}: expected a finite number, got {value!r}")
    if value < 0 or (positive and value == 0):
        raise CellConfigError(f"{what}: must be {'> 0' if positive else '>= 0'}, got {value!r}")
    return float(value)


def _xy(value: Any, what: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise CellConfigError(f"{what}: expected [x, y], got {value!r}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise CellConfigError(f"{what}: expected finite numbers, got {value!r}")
    return (float(value[0]), float(value[1]))


def load_cell_config(path: str | Path | None = None) -> CellConfig:
    """Read and check an assembly-cell YAML file (default: the shipped case study)."""
    p = Path(path) if path is not None else default_config_path()
    try:
        data = yaml.safe_load(p.read_text())
    except FileNotFoundError:
        raise CellConfigError(f"{p}: no such file") from None
    except yaml.YAMLError as exc:
        raise CellConfigError(f"{p}: malformed YAML: {exc}") from None
    if not isinstance(data, dict):
        raise CellConfigError(f"{p}: expected a mapping at the top level")
    try:
        return _parse_config(data)
    except KeyError as exc:
        raise CellConfigError(f"{p}: missing key {exc}") from None
    except CellConfigError as exc:
        raise CellConfigError(f"{p}: {exc}") from None


def _parse_config(d: dict[str, Any]) -> CellConfig:
    sim = d.get("sim", {})
    cells = {cid: CellSpec(cid, _xy(c["position"], f"cell {cid} position"),
                           _xy(c.get("size", [3.0, 3.0]), f"cell {cid} size")) for cid, c in d["cells"].items()}
    robots = []
    for r in d["robots"]:
        kind = str(r["kind"])
        if kind not in ARM_KINDS + MOBILE_KINDS:
            raise CellConfigError(f"robot {r['id']}: unknown kind {kind!r} (known: {ARM_KINDS + MOBILE_KINDS})")
        if kind in ARM_KINDS:
            if r.get("cell") not in cells:
                raise CellConfigError(f"robot {r['id']}: unknown cell {r.get('cell')!r}")
            robots.append(RobotSpec(str(r["id"]), kind, _num(r["payload"], f"robot {r['id']} payload"),
                                    cell=str(r["cell"]), start=cells[r["cell"]].position))
        else:
            robots.append(RobotSpec(str(r["id"]), kind, _num(r["payload"], f"robot {r['id']} payload"),
                                    start=_xy(r["start"], f"robot {r['id']} start"),
                                    speed=_num(r["speed"], f"robot {r['id']} speed")))
    objects = {}
    for o in d["objects"]:
        if o["cell"] not in cells:
            raise CellConfigError(f"object {o['id']}: unknown cell {o['cell']!r}")
        objects[str(o["id"])] = ObjectSpec(str(o["id"]), _num(o["weight"], f"object {o['id']} weight"), str(o["cell"]))
    tasks = []
    for t in d["tasks"]:
        tid = str(t["id"])
        if t.get("object") not in objects:
            raise CellConfigError(f"task {tid}: unknown object {t.get('object')!r}")
        if t["type"] == "transport":
            for key in ("from", "to"):
                if t.get(key) not in cells:
                    raise CellConfigError(f"task {tid}: unknown cell {t.get(key)!r} in {key!r}")
            tasks.append(TaskSpec(tid, "transport", str(t["object"]), str(t["to"]), source=str(t["from"]),
                                  after=tuple(str(a) for a in t.get("after", ()))))
        elif t["type"] == "assembly":
            if t.get("cell") not in cells:
                raise CellConfigError(f"task {tid}: unknown cell {t.get('cell')!r}")
            tasks.append(TaskSpec(tid, "assembly", str(t["object"]), str(t["cell"]),
                                  duration=_num(t["duration"], f"task {tid} duration"),
                                  payload=_num(t.get("payload", 0.1), f"task {tid} payload", positive=False),
                                  after=tuple(str(a) for a in t.get("after", ()))))
        else:
            raise CellConfigError(f"task {tid}: unknown type {t['type']!r} (transport | assembly)")
    caps = tuple(str(c) for c in d["capabilities"])
    for needed in ("manipulation", "mobility", *(f"@{c}" for c in cells)):
        if needed not in caps:
            raise CellConfigError(f"capabilities must include {needed!r}")
    return CellConfig(
        name=str(d.get("name", "assembly-cell")), frame_id=str(d.get("frame_id", "map")), capabilities=caps,
        dt=_num(sim.get("dt", 0.05), "sim.dt"), handling_time=_num(sim.get("handling_time", 3.0), "sim.handling_time",
                                                                  positive=False),
        arrive_tolerance=_num(sim.get("arrive_tolerance", 0.05), "sim.arrive_tolerance"),
        nominal_speed=_num(d.get("nominal_speed", 0.8), "nominal_speed"),
        cells=cells, robots=tuple(robots), objects=objects, tasks=tuple(tasks))


def _dist(a: Sequence[float], b: Sequence[float]) -> float:
    return math.hypot(a[0] - b[0], a[1] - b[1])


def build_instance(cfg: CellConfig) -> Instance:
    """The scheduling problem of the case study, with nominal durations."""
    caps = cfg.capabilities

    def vec(*names: str) -> tuple[int, ...]:
        return tuple(int(c in names) for c in caps)

    robots = tuple(
        Robot(r.id, vec("manipulation", f"@{r.cell}") if r.kind in ARM_KINDS else vec("mobility"), r.payload,
              {"kind": r.kind}) for r in cfg.robots)
    tasks = []
    for t in cfg.tasks:
        weight = cfg.objects[t.object].weight
        if t.type == "transport":
            assert t.source is not None
            travel = _dist(cfg.cells[t.source].position, cfg.cells[t.cell].position) / cfg.nominal_speed
            tasks.append(Task(t.id, vec("mobility"), weight, round(2 * cfg.handling_time + travel, 3), t.after,
                              {"type": t.type, "object": t.object, "from": t.source, "to": t.cell}))
        else:
            tasks.append(Task(t.id, vec("manipulation", f"@{t.cell}"), t.payload, t.duration, t.after,
                              {"type": t.type, "object": t.object, "cell": t.cell}))
    return Instance(cfg.name, caps, robots, tuple(tasks))


@dataclass
class _Job:
    """A task being executed: its subteam and the phase it is in."""

    task: TaskSpec
    team: tuple[str, ...]
    phase: str  # transport: approach, load, carry, unload; assembly: work
    timer: float = 0.0
    targets: dict[str, tuple[float, float]] = field(default_factory=dict)


@dataclass(frozen=True)
class Frame:
    """Positions and work at one instant, for rendering."""

    time: float
    positions: dict[str, tuple[float, float]]
    robot_task: dict[str, str | None]
    done: int


@dataclass
class Event:
    time: float
    kind: str  # started | finished
    task: str
    robots: tuple[str, ...]


class CellSim:
    """The case-study world. ``assign`` starts tasks, ``step`` advances sim time by dt."""

    def __init__(self, cfg: CellConfig | None = None) -> None:
        self.cfg = cfg if cfg is not None else load_cell_config()
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
        self.jobs: dict[str, _Job] = {}
        self.events: list[Event] = []
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

    def _slot(self, cell: str, k: int, n: int) -> tuple[float, float]:
        """Where member k of n stands around an object at ``cell`` (fixed offsets, so a
        team carrying together keeps its formation)."""
        x, y = self.cfg.cells[cell].position
        ang = math.pi / 2 + 2 * math.pi * k / max(n, 1)
        return (x + 0.8 * math.cos(ang), y + 0.8 * math.sin(ang))

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
            if self.robot_task[rid] is not None:
                raise AssignmentRejected(f"task {task_id}: robot {rid} is busy with {self.robot_task[rid]}")
        spec = self._task_spec[task_id]
        obj = self.cfg.objects[spec.object]
        kinds = [self.robot_spec[r].kind for r in robot_ids]
        if spec.type == "transport":
            if any(k not in MOBILE_KINDS for k in kinds):
                raise AssignmentRejected(f"task {task_id}: only mobile robots can transport, got {kinds}")
            if self.object_cell[obj.id] != spec.source:
                raise AssignmentRejected(f"task {task_id}: {obj.id} is not at {spec.source}")
            total = sum(self.robot_spec[r].payload for r in robot_ids)
            if total < obj.weight:
                raise AssignmentRejected(f"task {task_id}: {obj.id} weighs {obj.weight:g}, subteam "
                                         f"{list(robot_ids)} carries only {total:g}")
        else:
            if len(robot_ids) != 1 or kinds[0] not in ARM_KINDS:
                raise AssignmentRejected(f"task {task_id}: assembly needs one arm, got {list(robot_ids)}")
            arm = self.robot_spec[robot_ids[0]]
            if arm.cell != spec.cell:
                raise AssignmentRejected(f"task {task_id}: {arm.id} is at {arm.cell}, the work is at {spec.cell}")
            if self.object_cell[obj.id] != spec.cell:
                raise AssignmentRejected(f"task {task_id}: {obj.id} is not at {spec.cell} "
                                         f"(it is at {self.object_cell[obj.id] or 'a robot'})")
            if arm.payload < spec.payload:
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
            job = _Job(spec, team, "approach",
                       targets={r: self._slot(spec.source, k, len(team)) for k, r in enumerate(team)})
        else:
            job = _Job(spec, team, "work", timer=spec.duration)
        self.jobs[task_id] = job
        self.events.append(Event(self.time, "started", task_id, team))

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
                arrived = [self._drive(r, job.targets[r], self.robot_spec[r].speed, dt) for r in job.team]
                if all(arrived):
                    job.phase, job.timer = "load", self.cfg.handling_time
                    self.object_cell[spec.object] = None
            elif job.phase == "load":
                job.timer -= dt
                if job.timer <= 1e-9:
                    job.phase = "carry"
                    job.targets = {r: self._slot(spec.cell, k, len(job.team)) for k, r in enumerate(job.team)}
            elif job.phase == "carry":
                speed = min(self.robot_spec[r].speed for r in job.team)
                arrived = [self._drive(r, job.targets[r], speed, dt) for r in job.team]
                self.bodies[spec.object].velocity = self.bodies[job.team[0]].velocity
                if all(arrived):
                    job.phase, job.timer = "unload", self.cfg.handling_time
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
            ev = Event(self.time, "finished", tid, job.team)
            self.events.append(ev)
            out.append(ev)
        if out:
            self._refresh_ready()
        return out

    def record_frame(self) -> None:
        """Keep the current positions for rendering (see lvws_ros.cell_render)."""
        self.trace.append(Frame(self.time, {k: self.position(k) for k in self.bodies}, dict(self.robot_task),
                                sum(s == DONE for s in self.status.values())))

    # -- views for the scheduler --------------------------------------------------------
    def team_snapshot(self) -> TeamSnapshot:
        robots = []
        for r, caps in zip(self.cfg.robots, (rb.capabilities for rb in self.inst.robots), strict=True):
            task = self.robot_task[r.id]
            busy = 0.0
            if task is not None:
                busy = max(0.0, self.start[task] + self.inst.tasks[self.inst.task_index[task]].duration - self.time)
            x, y = self.position(r.id)
            robots.append(RobotInfo(r.id, r.kind, task is None, caps, r.payload, task or "", busy, (x, y, 0.0)))
        return TeamSnapshot(self.time, self.cfg.capabilities, tuple(robots))

    def graph_snapshot(self) -> GraphSnapshot:
        tasks = []
        for t in self.inst.tasks:
            tasks.append(TaskInfo(t.id, self.status[t.id], t.capabilities, t.payload, t.duration, t.after,
                                  self.team.get(t.id, ()), self.start.get(t.id), self.end.get(t.id)))
        return GraphSnapshot(self.time, self.cfg.capabilities, tuple(tasks))

    # -- results ----------------------------------------------------------------------
    def executed_instance(self) -> Instance:
        """The instance with each finished task's executed duration (travel included)."""
        tasks = tuple(Task(t.id, t.capabilities, t.payload,
                           (self.end[t.id] - self.start[t.id]) if t.id in self.end else t.duration, t.after, t.extra)
                      for t in self.inst.tasks)
        return Instance(self.inst.name, self.inst.capabilities, self.inst.robots, tasks)

    def schedule(self, policy: str, decisions: int = 0, compute: float = 0.0) -> Schedule:
        out = [Assignment(t, self.team[t], self.start[t], self.end[t]) for t in self.end]
        return Schedule.from_assignments(self.inst.name, policy, out, decisions, compute)


def run_offline(sim: CellSim, policy: Policy, *, max_time: float = 3600.0,
                frame_every: float | None = None) -> tuple[Schedule, list[OnlineDecision]]:
    """Run the case study with ``policy`` in-process (no ROS), through the same
    :class:`~lvws_ros.online.OnlineScheduler` the scheduler node uses."""
    online = OnlineScheduler(policy)
    decisions: list[OnlineDecision] = []
    next_frame = 0.0
    changed = True
    while not sim.done:
        if sim.time > max_time:
            raise RuntimeError(f"case study not finished after {max_time:g} s of sim time "
                               f"(status {sim.status})")
        if changed:
            online.offer_team(sim.team_snapshot())
            online.offer_graph(sim.graph_snapshot())
            d = online.decide()
            if d is not None:
                decisions.append(d)
                for task, robots in d.assignments:
                    sim.assign(task, robots)
        if frame_every is not None and sim.time >= next_frame - 1e-9:
            sim.record_frame()
            next_frame += frame_every
        changed = bool(sim.step())
    if frame_every is not None:
        sim.record_frame()
    latency = sum(d.latency for d in decisions)
    return sim.schedule(policy.name, len(decisions), latency), decisions
