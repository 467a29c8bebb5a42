"""Problem model of heterogeneous collaborative scheduling (LVWS paper, section III-A).

A team of N robots r_i = [a_i, c_i, w_i] (availability, capability vector, payload
capacity) and M tasks t_j = [s_j, c_j, w_j] (status, required capabilities, payload
need) with durations and a precedence DAG P. Reads and writes the ``lvws-instance/1``
JSON format of ``shared/spec/formats.md`` and rejects bad input with an error that
names the problem and the offending ids.
"""

from __future__ import annotations

import heapq
import json
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

INSTANCE_FORMAT = "lvws-instance/1"
# A capability named "@<site>" is a location: robots there hold it, tasks there need it.
# The matching enforces it like any capability; the network's node features leave it out.
SITE_PREFIX = "@"

BoolArray = npt.NDArray[np.bool_]
FloatArray = npt.NDArray[np.float64]


class InstanceError(ValueError):
    """An instance (file or object) that breaks the lvws-instance/1 rules."""


@dataclass(frozen=True)
class Robot:
    id: str
    capabilities: tuple[int, ...]
    payload: float
    extra: Mapping[str, Any] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Task:
    id: str
    capabilities: tuple[int, ...]
    payload: float
    duration: float
    after: tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict, compare=False)


@dataclass(frozen=True)
class Instance:
    """A validated problem instance; array views are indexed like ``robots``/``tasks``."""

    name: str
    capabilities: tuple[str, ...]
    robots: tuple[Robot, ...]
    tasks: tuple[Task, ...]

    def __post_init__(self) -> None:
        validate_instance(self)

    @property
    def num_robots(self) -> int:
        return len(self.robots)

    @property
    def num_tasks(self) -> int:
        return len(self.tasks)

    @cached_property
    def robot_index(self) -> dict[str, int]:
        return {r.id: i for i, r in enumerate(self.robots)}

    @cached_property
    def task_index(self) -> dict[str, int]:
        return {t.id: j for j, t in enumerate(self.tasks)}

    @cached_property
    def robot_caps(self) -> BoolArray:
        """c^r as an N x K boolean matrix."""
        return _caps_matrix([r.capabilities for r in self.robots], len(self.capabilities))

    @cached_property
    def task_caps(self) -> BoolArray:
        """c^t as an M x K boolean matrix."""
        return _caps_matrix([t.capabilities for t in self.tasks], len(self.capabilities))

    @cached_property
    def skill_columns(self) -> tuple[int, ...]:
        """Capability columns that are skills, not sites (see SITE_PREFIX)."""
        return tuple(k for k, name in enumerate(self.capabilities) if not name.startswith(SITE_PREFIX))

    @cached_property
    def robot_payload(self) -> FloatArray:
        return np.array([r.payload for r in self.robots], dtype=np.float64)

    @cached_property
    def task_payload(self) -> FloatArray:
        return np.array([t.payload for t in self.tasks], dtype=np.float64)

    @cached_property
    def durations(self) -> FloatArray:
        return np.array([t.duration for t in self.tasks], dtype=np.float64)

    @cached_property
    def prerequisites(self) -> tuple[tuple[int, ...], ...]:
        """Indices of each task's prerequisites (the in-edges of P)."""
        return tuple(tuple(self.task_index[p] for p in t.after) for t in self.tasks)

    @cached_property
    def successors(self) -> tuple[tuple[int, ...], ...]:
        succ: list[list[int]] = [[] for _ in self.tasks]
        for j, pre in enumerate(self.prerequisites):
            for i in pre:
                succ[i].append(j)
        return tuple(tuple(s) for s in succ)

    @cached_property
    def precedence_matrix(self) -> BoolArray:
        """P with P[i, j] = True when task i is a prerequisite of task j."""
        p = np.zeros((self.num_tasks, self.num_tasks), dtype=bool)
        for j, pre in enumerate(self.prerequisites):
            p[list(pre), j] = True
        return p

    @cached_property
    def critical_tail(self) -> FloatArray:
        """Longest duration path from each task to the end of the DAG, its own duration included."""
        tail = self.durations.copy()
        for j in reversed(self.topological_order):
            if self.successors[j]:
                tail[j] += max(tail[s] for s in self.successors[j])
        return tail

    @cached_property
    def descendant_count(self) -> npt.NDArray[np.int64]:
        """How many tasks depend on each task, directly or not."""
        reach = self.precedence_matrix.copy()
        for j in reversed(self.topological_order):
            for s in self.successors[j]:
                reach[j] |= reach[s]
        return reach.sum(axis=1).astype(np.int64)

    @cached_property
    def topological_order(self) -> tuple[int, ...]:
        """A canonical topological order (set by validation, which computes it anyway)."""
        order = _topological_order(self)
        assert order is not None  # validated in __post_init__
        return order


def _caps_matrix(rows: Sequence[Sequence[int]], k: int) -> BoolArray:
    if not rows:
        return np.zeros((0, k), dtype=bool)
    return np.array(rows, dtype=np.int8).astype(bool).reshape(len(rows), k)


def _topological_order(inst: Instance) -> tuple[int, ...] | None:
    """Kahn's algorithm taking the smallest ready index first (a canonical order);
    None when the prerequisites have a cycle."""
    index = {t.id: j for j, t in enumerate(inst.tasks)}
    indegree = [len(t.after) for t in inst.tasks]
    succ: list[list[int]] = [[] for _ in inst.tasks]
    for j, t in enumerate(inst.tasks):
        for p in t.after:
            succ[index[p]].append(j)
    heap = [j for j, d in enumerate(indegree) if d == 0]
    heapq.heapify(heap)
    order: list[int] = []
    while heap:
        i = heapq.heappop(heap)
        order.append(i)
        for j in succ[i]:
            indegree[j] -= 1
            if indegree[j] == 0:
                heapq.heappush(heap, j)
    return tuple(order) if len(order) == len(inst.tasks) else None


def _find_cycle(inst: Instance) -> list[str]:
    """One cycle of the prerequisite graph, as ids in order (for the error message)."""
    index = {t.id: j for j, t in enumerate(inst.tasks)}
    color = [0] * len(inst.tasks)  # 0 new, 1 on stack, 2 done
    parent: dict[int, int] = {}
    for root in range(len(inst.tasks)):
        if color[root]:
            continue
        stack: list[tuple[int, int]] = [(root, 0)]
        color[root] = 1
        while stack:
            node, k = stack[-1]
            pre = inst.tasks[node].after
            if k < len(pre):
                stack[-1] = (node, k + 1)
                nxt = index[pre[k]]
                if color[nxt] == 1:
                    cycle = [nxt]
                    cur = node
                    while cur != nxt:
                        cycle.append(cur)
                        cur = parent[cur]
                    return [inst.tasks[c].id for c in reversed(cycle)]
                if color[nxt] == 0:
                    color[nxt] = 1
                    parent[nxt] = node
                    stack.append((nxt, 0))
            else:
                color[node] = 2
                stack.pop()
    return []


def _check_number(value: Any, what: str, *, positive: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InstanceError(f"{what} must be a number, got {value!r}")
    if not math.isfinite(value):
        raise InstanceError(f"{what} must be finite, got {value!r}")
    if positive and value <= 0:
        raise InstanceError(f"{what} must be > 0, got {value!r}")
    if not positive and value < 0:
        raise InstanceError(f"{what} must be >= 0, got {value!r}")


def _check_vector(vec: Sequence[Any], k: int, what: str) -> None:
    if len(vec) != k:
        raise InstanceError(f"{what} has {len(vec)} entries, expected {k} (one per capability)")
    if any(isinstance(v, bool) or v not in (0, 1) for v in vec):
        raise InstanceError(f"{what} must hold only 0 or 1, got {list(vec)}")


def validate_instance(inst: Instance) -> None:
    """Raise InstanceError naming every kind of problem of section 'Problem instance'."""
    k = len(inst.capabilities)
    if k < 1:
        raise InstanceError("capabilities: at least one capability name is needed")
    if len(set(inst.capabilities)) != k:
        raise InstanceError(f"capabilities: duplicate names in {list(inst.capabilities)}")
    if not inst.robots:
        raise InstanceError("robots: the team is empty")
    _no_duplicates([r.id for r in inst.robots], "robot")
    _no_duplicates([t.id for t in inst.tasks], "task")
    for r in inst.robots:
        _check_vector(r.capabilities, k, f"robot {r.id!r} capabilities")
        _check_number(r.payload, f"robot {r.id!r} payload", positive=True)
    task_ids = {t.id for t in inst.tasks}
    for t in inst.tasks:
        _check_vector(t.capabilities, k, f"task {t.id!r} capabilities")
        if not any(t.capabilities):
            raise InstanceError(f"task {t.id!r} capabilities: needs at least one capability")
        _check_number(t.payload, f"task {t.id!r} payload", positive=False)
        _check_number(t.duration, f"task {t.id!r} duration", positive=True)
        unknown = [p for p in t.after if p not in task_ids]
        if unknown:
            raise InstanceError(f"task {t.id!r} after: unknown task id(s) {unknown}")
        if t.id in t.after:
            raise InstanceError(f"task {t.id!r} after: a task cannot be its own prerequisite")
        if len(set(t.after)) != len(t.after):
            raise InstanceError(f"task {t.id!r} after: duplicate prerequisite ids")
    order = _topological_order(inst)
    if order is None:
        raise InstanceError(f"cyclic prerequisites: {' -> '.join(_find_cycle(inst))} -> ...")
    inst.__dict__["topological_order"] = order  # prime the cached_property
    team_caps = np.zeros(k, dtype=bool)
    for r in inst.robots:
        team_caps |= np.array(r.capabilities, dtype=bool)
    team_payload = sum(r.payload for r in inst.robots)
    for t in inst.tasks:
        missing = [inst.capabilities[c] for c in range(k) if t.capabilities[c] and not team_caps[c]]
        if missing:
            raise InstanceError(
                f"task {t.id!r} can never be covered: no robot has capability {missing}"
            )
        if t.payload > team_payload + 1e-9:
            raise InstanceError(
                f"task {t.id!r} can never be covered: needs payload {t.payload}, "
                f"the whole team carries {team_payload}"
            )


def _no_duplicates(ids: Sequence[str], kind: str) -> None:
    for i in ids:
        if not isinstance(i, str) or not i:
            raise InstanceError(f"{kind} ids must be non-empty strings, got {i!r}")
    dups = sorted(i for i, count in Counter(ids).items() if count > 1)
    if dups:
        raise InstanceError(f"duplicate {kind} id(s): {dups}")


# ---------------------------------------------------------------- JSON (lvws-instance/1)


def _require(obj: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise InstanceError(f"{where}: missing key {key!r}")
    return obj[key]


def _as_list(value: Any, where: str) -> list[Any]:
    if not isinstance(value, list):
        raise InstanceError(f"{where} must be a list, got {type(value).__name__}")
    return value


def instance_from_dict(data: Any) -> Instance:
    """Build a validated Instance from parsed ``lvws-instance/1`` JSON."""
    if not isinstance(data, dict):
        raise InstanceError("instance: the top level must be a JSON object")
    fmt = data.get("format")
    if fmt != INSTANCE_FORMAT:
        raise InstanceError(f"format: expected {INSTANCE_FORMAT!r}, got {fmt!r}")
    name = data.get("name", "")
    if not isinstance(name, str):
        raise InstanceError(f"name must be a string, got {name!r}")
    caps = _as_list(_require(data, "capabilities", "instance"), "capabilities")
    if not all(isinstance(c, str) for c in caps):
        raise InstanceError("capabilities must be a list of names")
    robots = []
    for n, r in enumerate(_as_list(_require(data, "robots", "instance"), "robots")):
        where = f"robots[{n}]"
        if not isinstance(r, dict):
            raise InstanceError(f"{where} must be an object")
        robots.append(
            Robot(
                id=_require(r, "id", where),
                capabilities=tuple(_as_list(_require(r, "capabilities", where), f"{where}.capabilities")),
                payload=_require(r, "payload", where),
                extra={k: v for k, v in r.items() if k not in {"id", "capabilities", "payload"}},
            )
        )
    tasks = []
    task_keys = {"id", "capabilities", "payload", "duration", "after"}
    for n, t in enumerate(_as_list(_require(data, "tasks", "instance"), "tasks")):
        where = f"tasks[{n}]"
        if not isinstance(t, dict):
            raise InstanceError(f"{where} must be an object")
        after = _as_list(t.get("after", []), f"{where}.after")
        tasks.append(
            Task(
                id=_require(t, "id", where),
                capabilities=tuple(_as_list(_require(t, "capabilities", where), f"{where}.capabilities")),
                payload=_require(t, "payload", where),
                duration=_require(t, "duration", where),
                after=tuple(after),
                extra={k: v for k, v in t.items() if k not in task_keys},
            )
        )
    return Instance(name=name, capabilities=tuple(caps), robots=tuple(robots), tasks=tuple(tasks))


def instance_to_dict(inst: Instance) -> dict[str, Any]:
    return {
        "format": INSTANCE_FORMAT,
        "name": inst.name,
        "capabilities": list(inst.capabilities),
        "robots": [
            {"id": r.id, "capabilities": list(r.capabilities), "payload": float(r.payload), **r.extra}
            for r in inst.robots
        ],
        "tasks": [
            {
                "id": t.id,
                "capabilities": list(t.capabilities),
                "payload": float(t.payload),
                "duration": float(t.duration),
                "after": list(t.after),
                **t.extra,
            }
            for t in inst.tasks
        ],
    }


def read_json(path: str | Path, what: str) -> Any:
    """Parse a JSON file; a missing or malformed file is an InstanceError naming it."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise InstanceError(f"{p}: cannot read {what}: {exc.strerror or exc}") from exc
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise InstanceError(f"{p}: malformed JSON {what}: {exc}") from exc


def _reject_constant(name: str) -> float:
    # json accepts NaN/Infinity by default; the format does not.
    raise InstanceError(f"non-finite number {name} is not allowed")


def load_instance(path: str | Path) -> Instance:
    data = read_json(path, "instance")
    try:
        return instance_from_dict(data)
    except InstanceError as exc:
        raise InstanceError(f"{path}: {exc}") from None


def dumps(data: Mapping[str, Any]) -> str:
    """Canonical JSON text (same object, same bytes): one line per top-level key, and
    one line per element of a list of objects (robots, tasks, assignments)."""
    lines = []
    for key, value in data.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            items = ",\n".join("    " + json.dumps(v, allow_nan=False) for v in value)
            lines.append(f"  {json.dumps(key)}: [\n{items}\n  ]")
        else:
            lines.append(f"  {json.dumps(key)}: {json.dumps(value, allow_nan=False)}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


def save_instance(inst: Instance, path: str | Path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(dumps(instance_to_dict(inst)), encoding="utf-8")
