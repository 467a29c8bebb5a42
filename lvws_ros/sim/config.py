"""The assembly-cell configuration (``config/assembly_cell.yaml``): cells, robots,
objects and tasks of the paper's case study (section IV-B), read and checked.

Every problem is a :class:`~lvws_ros.errors.ConfigError` naming the file and the item.
"""

from __future__ import annotations

import graphlib
import math
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from lvws_ros.errors import ConfigError

__all__ = ["ARM_KINDS", "FLOOR", "MOBILE_KINDS", "PART_PAYLOAD", "CellConfig", "CellSpec", "ObjectSpec", "RobotSpec", "TaskSpec",
           "check_object_flow", "load_cell_config", "parse_task", "read_yaml", "start_site"]

ARM_KINDS = ("panda",)
PART_PAYLOAD = 0.1  # an assembly's part when its entry names none
MOBILE_KINDS = ("jackal", "husky")
FLOOR = ""  # where an object put down between cells is (a failed transport); only a transport picks it up


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
    traits: tuple[tuple[str, float], ...] = ()  # additive traits it brings (formats.md, "Traits")


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
    requires: tuple[tuple[str, float], ...] = ()  # additive traits its subteam adds up


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
    # Plan with travel (the travel extension of formats.md): the instance has the cells and
    # the mobile robots' start points as sites; robots arrive when the plan says; transports
    # carry at nominal_speed. False (a file without the key): no travel in the plan, as before.
    plan_travel: bool = False
    traits: tuple[str, ...] = ()  # additive trait names (robots' `traits`, tasks' `requires`); none: as before


def start_site(robot_id: str) -> str:
    """The site where a mobile robot starts (the travel plan, ``plan_travel``)."""
    return f"{robot_id}_start"


def _num(value: Any, what: str, *, positive: bool = True) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{what}: expected a finite number, got {value!r}")
    if value < 0 or (positive and value == 0):
        raise ConfigError(f"{what}: must be {'> 0' if positive else '>= 0'}, got {value!r}")
    return float(value)


def _xy(value: Any, what: str) -> tuple[float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 2:
        raise ConfigError(f"{what}: expected [x, y], got {value!r}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise ConfigError(f"{what}: expected finite numbers, got {value!r}")
    return (float(value[0]), float(value[1]))


def read_yaml(path: str | Path, what: str) -> Any:
    """The data of a YAML file (``safe_load``: a file never runs code); ConfigError naming
    the file when it is missing, unreadable or malformed. ``what`` names the kind of file."""
    p = Path(path)
    try:
        return yaml.safe_load(p.read_text())
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the {what}: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: malformed YAML: {exc}") from None


def load_cell_config(path: str | Path) -> CellConfig:
    """Read and check an assembly-cell YAML file (the shipped case study:
    :func:`lvws_ros.ros.resources.case_study_config`)."""
    p = Path(path)
    if not p.exists():
        raise ConfigError(f"{p}: no such file")
    data = read_yaml(p, "cell configuration")
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping at the top level")
    try:
        return _parse_config(data)
    except KeyError as exc:
        raise ConfigError(f"{p}: missing key {exc}") from None
    except ConfigError as exc:
        raise ConfigError(f"{p}: {exc}") from None


def _robot(r: dict[str, Any], cells: Mapping[str, CellSpec]) -> RobotSpec:
    kind = str(r["kind"])
    if kind not in ARM_KINDS + MOBILE_KINDS:
        raise ConfigError(f"robot {r['id']}: unknown kind {kind!r} (known: {ARM_KINDS + MOBILE_KINDS})")
    payload = _num(r["payload"], f"robot {r['id']} payload")
    traits = _amounts(r.get("traits", {}), f"robot {r['id']} traits")
    if kind in ARM_KINDS:
        if r.get("cell") not in cells:
            raise ConfigError(f"robot {r['id']}: unknown cell {r.get('cell')!r}")
        return RobotSpec(str(r["id"]), kind, payload, cell=str(r["cell"]), start=cells[r["cell"]].position,
                         traits=traits)
    return RobotSpec(str(r["id"]), kind, payload, start=_xy(r["start"], f"robot {r['id']} start"),
                     speed=_num(r["speed"], f"robot {r['id']} speed"), traits=traits)


def _amounts(value: Any, what: str) -> tuple[tuple[str, float], ...]:
    """A ``traits``/``requires`` mapping: trait name -> amount >= 0 (the instance checks the names)."""
    if not isinstance(value, dict):
        raise ConfigError(f"{what}: expected a mapping of trait names to amounts, got {value!r}")
    return tuple((str(k), _num(v, f"{what} {k}", positive=False)) for k, v in value.items())


def parse_task(t: dict[str, Any], cells: Mapping[str, CellSpec], objects: Mapping[str, ObjectSpec]) -> TaskSpec:
    """One entry of the task list (KeyError for a missing key, ConfigError naming the task)."""
    tid = str(t["id"])
    if t.get("object") not in objects:
        raise ConfigError(f"task {tid}: unknown object {t.get('object')!r}")
    after = tuple(str(a) for a in t.get("after", ()))
    requires = _amounts(t.get("requires", {}), f"task {tid} requires")
    if t["type"] == "transport":
        for key in ("from", "to"):
            if t.get(key) not in cells:
                raise ConfigError(f"task {tid}: unknown cell {t.get(key)!r} in {key!r}")
        return TaskSpec(tid, "transport", str(t["object"]), str(t["to"]), source=str(t["from"]), after=after,
                        requires=requires)
    if t["type"] == "assembly":
        if t.get("cell") not in cells:
            raise ConfigError(f"task {tid}: unknown cell {t.get('cell')!r}")
        return TaskSpec(tid, "assembly", str(t["object"]), str(t["cell"]),
                        duration=_num(t["duration"], f"task {tid} duration"),
                        payload=_num(t.get("payload", PART_PAYLOAD), f"task {tid} payload", positive=False),
                        after=after, requires=requires)
    raise ConfigError(f"task {tid}: unknown type {t['type']!r} (transport | assembly)")


def check_object_flow(tasks: Sequence[TaskSpec], at: Mapping[str, str | None], started: Collection[str] = ()) -> None:
    """Every task finds its object where it needs it, whatever order the scheduler picks:
    two tasks on one object must be ordered by ``after`` (directly or not) unless both are
    assemblies at one cell, and a task's object is then at the ``to`` of the latest
    transport of it before the task, else where it is now (``at``; FLOOR: put down
    between cells, where a transport picks it up). A transport needs it at ``from``, an
    assembly at its cell; the ``started`` tasks have it already. ConfigError naming the
    task(s) otherwise: such a task would wait forever."""
    spec = {t.id: t for t in tasks}
    graph = {t.id: [a for a in t.after if a in spec] for t in tasks}
    try:
        order = list(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError:
        return  # the instance names the cycle (lvws_ros.core.problem)
    before: dict[str, set[str]] = {}  # every task a task waits on, directly or not
    for tid in order:
        before[tid] = set().union(*(before[a] | {a} for a in graph[tid]))
    on: dict[str, list[TaskSpec]] = {}  # each object's tasks, in order
    for tid in order:
        on.setdefault(spec[tid].object, []).append(spec[tid])
    for tid in order:
        t = spec[tid]
        need = t.source if t.type == "transport" else t.cell
        same = [o for o in on[t.object] if o.id != tid]
        for o in same:
            unordered = o.id not in before[tid] and tid not in before[o.id]
            if unordered and not (t.type == o.type == "assembly" and t.cell == o.cell):
                raise ConfigError(f"tasks {tid} and {o.id} both work on {t.object} and neither comes after the "
                                  f"other: one may take it away before the other (add one to the other's 'after')")
        if tid in started:
            continue
        moves = [o for o in same if o.type == "transport" and o.id in before[tid]]  # ordered, by the check above
        last = max(moves, key=lambda o: len(before[o.id])) if moves else None
        here = at[t.object] if last is None else last.cell
        if here != need and not (t.type == "transport" and here == FLOOR):
            where = "between cells" if here == FLOOR else "on a robot" if here is None else f"at {here}"
            why = "no transport of it comes before" if last is None else f"the latest transport of it before: {last.id}"
            raise ConfigError(f"task {tid}: {t.object} is {where} when it comes, not at {need} ({why})")


def _parse_config(d: dict[str, Any]) -> CellConfig:
    sim = d.get("sim", {})
    cells = {cid: CellSpec(cid, _xy(c["position"], f"cell {cid} position"),
                           _xy(c.get("size", [3.0, 3.0]), f"cell {cid} size")) for cid, c in d["cells"].items()}
    robots = tuple(_robot(r, cells) for r in d["robots"])
    objects = {}
    for o in d["objects"]:
        if o["cell"] not in cells:
            raise ConfigError(f"object {o['id']}: unknown cell {o['cell']!r}")
        objects[str(o["id"])] = ObjectSpec(str(o["id"]), _num(o["weight"], f"object {o['id']} weight"), str(o["cell"]))
    tasks = tuple(parse_task(t, cells, objects) for t in d["tasks"])
    check_object_flow(tasks, {o.id: o.cell for o in objects.values()})
    plan_travel = _flag(d.get("plan_travel", False), "plan_travel")
    if plan_travel:  # the plan's sites: cells and start points; transports carry at nominal_speed
        nominal = _num(d.get("nominal_speed", 0.8), "nominal_speed")
        for r in robots:
            if r.kind in MOBILE_KINDS and r.speed < nominal:
                raise ConfigError(f"robot {r.id} speed: {r.speed:g} is below nominal_speed {nominal:g}, at which "
                                  "transports carry in the plan (plan_travel)")
            if start_site(r.id) in cells:
                raise ConfigError(f"cell {start_site(r.id)}: the name of robot {r.id}'s start site (plan_travel)")
    caps = tuple(str(c) for c in d["capabilities"])
    for needed in ("manipulation", "mobility", *(f"@{c}" for c in cells)):
        if needed not in caps:
            raise ConfigError(f"capabilities must include {needed!r}")
    return CellConfig(
        name=str(d.get("name", "assembly-cell")), frame_id=str(d.get("frame_id", "map")), capabilities=caps,
        dt=_num(sim.get("dt", 0.05), "sim.dt"), handling_time=_num(sim.get("handling_time", 3.0), "sim.handling_time",
                                                                  positive=False),
        arrive_tolerance=_num(sim.get("arrive_tolerance", 0.05), "sim.arrive_tolerance"),
        nominal_speed=_num(d.get("nominal_speed", 0.8), "nominal_speed"),
        cells=cells, robots=robots, objects=objects, tasks=tasks, plan_travel=plan_travel,
        traits=tuple(str(c) for c in d.get("traits", ())))


def _flag(value: Any, what: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{what}: expected true or false, got {value!r}")
    return value
