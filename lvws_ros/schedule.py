"""Schedules: the ``lvws-schedule/1`` format and its six validity rules (formats.md)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.model import Instance, InstanceError, dumps, read_json

SCHEDULE_FORMAT = "lvws-schedule/1"
TOLERANCE = 1e-6


@dataclass(frozen=True)
class Assignment:
    task: str
    robots: tuple[str, ...]
    start: float
    end: float


@dataclass
class Schedule:
    instance: str
    policy: str
    assignments: list[Assignment]
    makespan: float
    decisions: int = 0
    compute_seconds: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    @classmethod
    def from_assignments(
        cls,
        instance: str,
        policy: str,
        assignments: Sequence[Assignment],
        decisions: int = 0,
        compute_seconds: float = 0.0,
    ) -> Schedule:
        ordered = sorted(assignments, key=lambda a: (a.start, a.task))
        makespan = max((a.end for a in ordered), default=0.0)
        return cls(instance, policy, ordered, makespan, decisions, compute_seconds)

    def by_task(self) -> dict[str, Assignment]:
        return {a.task: a for a in self.assignments}


def schedule_to_dict(s: Schedule) -> dict[str, Any]:
    return {
        "format": SCHEDULE_FORMAT,
        "instance": s.instance,
        "policy": s.policy,
        "makespan": float(s.makespan),
        "assignments": [
            {"task": a.task, "robots": list(a.robots), "start": float(a.start), "end": float(a.end)}
            for a in s.assignments
        ],
        "decisions": int(s.decisions),
        "compute_seconds": float(s.compute_seconds),
        **s.extra,
    }


def schedule_from_dict(data: Any) -> Schedule:
    """Parse ``lvws-schedule/1``; structural problems raise InstanceError.

    Semantic problems (overlaps, coverage, ...) are left to :func:`check_schedule`, so
    that ``lvws check`` can list every violated rule.
    """
    if not isinstance(data, dict):
        raise InstanceError("schedule: the top level must be a JSON object")
    if data.get("format") != SCHEDULE_FORMAT:
        raise InstanceError(f"format: expected {SCHEDULE_FORMAT!r}, got {data.get('format')!r}")
    for key in ("instance", "policy", "makespan", "assignments"):
        if key not in data:
            raise InstanceError(f"schedule: missing key {key!r}")
    if not isinstance(data["assignments"], list):
        raise InstanceError("schedule: assignments must be a list")
    out = []
    for n, a in enumerate(data["assignments"]):
        if not isinstance(a, dict) or not {"task", "robots", "start", "end"} <= a.keys():
            raise InstanceError(f"assignments[{n}]: needs task, robots, start and end")
        if not isinstance(a["robots"], list):
            raise InstanceError(f"assignments[{n}].robots must be a list")
        for key in ("start", "end"):
            if isinstance(a[key], bool) or not isinstance(a[key], (int, float)):
                raise InstanceError(f"assignments[{n}].{key} must be a number")
        out.append(Assignment(str(a["task"]), tuple(str(r) for r in a["robots"]), float(a["start"]), float(a["end"])))
    if isinstance(data["makespan"], bool) or not isinstance(data["makespan"], (int, float)):
        raise InstanceError("schedule: makespan must be a number")
    known = {"format", "instance", "policy", "makespan", "assignments", "decisions", "compute_seconds"}
    return Schedule(
        instance=str(data["instance"]),
        policy=str(data["policy"]),
        assignments=out,
        makespan=float(data["makespan"]),
        decisions=int(data.get("decisions", 0)),
        compute_seconds=float(data.get("compute_seconds", 0.0)),
        extra={k: v for k, v in data.items() if k not in known},
    )


def load_schedule(path: str | Path) -> Schedule:
    data = read_json(path, "schedule")
    try:
        return schedule_from_dict(data)
    except InstanceError as exc:
        raise InstanceError(f"{path}: {exc}") from None


def save_schedule(s: Schedule, path: str | Path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(dumps(schedule_to_dict(s)), encoding="utf-8")


@dataclass(frozen=True)
class Violation:
    rule: int
    message: str

    def __str__(self) -> str:
        return f"rule {self.rule}: {self.message}"


def check_schedule(inst: Instance, s: Schedule, tol: float = TOLERANCE) -> list[Violation]:
    """Every violation of the six validity rules of formats.md (empty list: valid)."""
    v: list[Violation] = []
    # Rule 1: each task exactly once, robots exist.
    counts: dict[str, int] = {}
    for a in s.assignments:
        counts[a.task] = counts.get(a.task, 0) + 1
    for t in inst.tasks:
        if counts.get(t.id, 0) == 0:
            v.append(Violation(1, f"task {t.id!r} is not assigned"))
        elif counts[t.id] > 1:
            v.append(Violation(1, f"task {t.id!r} appears in {counts[t.id]} assignments"))
    for task_id in sorted(set(counts) - set(inst.task_index)):
        v.append(Violation(1, f"unknown task id {task_id!r}"))
    for a in s.assignments:
        unknown = [r for r in a.robots if r not in inst.robot_index]
        if unknown:
            v.append(Violation(1, f"task {a.task!r}: unknown robot id(s) {unknown}"))
        if not a.robots:
            v.append(Violation(2, f"task {a.task!r}: empty subteam"))
        if len(set(a.robots)) != len(a.robots):
            v.append(Violation(1, f"task {a.task!r}: a robot is listed twice"))
    by_task = {a.task: a for a in s.assignments if a.task in inst.task_index}
    for a in by_task.values():
        t = inst.tasks[inst.task_index[a.task]]
        members = [inst.robot_index[r] for r in a.robots if r in inst.robot_index]
        # Rule 2: capability OR covers the task, payloads add up.
        caps = np.zeros(len(inst.capabilities), dtype=bool)
        if members:
            caps = np.asarray(inst.robot_caps[members].any(axis=0))
        missing = [inst.capabilities[c] for c, need in enumerate(t.capabilities) if need and not caps[c]]
        if missing:
            v.append(Violation(2, f"task {t.id!r}: subteam {list(a.robots)} lacks capability {missing}"))
        carried = float(inst.robot_payload[members].sum()) if members else 0.0
        if carried < t.payload - tol:
            v.append(Violation(2, f"task {t.id!r}: subteam payload {carried:g} < needed {t.payload:g}"))
        # Rule 3: duration and start.
        if abs((a.end - a.start) - t.duration) > tol:
            v.append(Violation(3, f"task {t.id!r}: end - start = {a.end - a.start:g}, duration is {t.duration:g}"))
        if a.start < -tol:
            v.append(Violation(3, f"task {t.id!r}: starts at {a.start:g} < 0"))
        # Rule 4: prerequisites finished.
        for p in t.after:
            pa = by_task.get(p)
            if pa is not None and a.start < pa.end - tol:
                v.append(Violation(4, f"task {t.id!r} starts at {a.start:g} before prerequisite {p!r} ends at {pa.end:g}"))
    # Rule 5: no robot in two overlapping assignments.
    per_robot: dict[str, list[Assignment]] = {}
    for a in s.assignments:
        for r in set(a.robots):
            per_robot.setdefault(r, []).append(a)
    for r, items in sorted(per_robot.items()):
        items.sort(key=lambda a: (a.start, a.end))
        for x, y in pairwise(items):
            if y.start < x.end - tol:
                v.append(Violation(5, f"robot {r!r} is in {x.task!r} [{x.start:g}, {x.end:g}) "
                                      f"and {y.task!r} [{y.start:g}, {y.end:g}) at once"))
    # Rule 6: makespan is the largest end.
    latest = max((a.end for a in s.assignments), default=0.0)
    if abs(s.makespan - latest) > tol:
        v.append(Violation(6, f"makespan {s.makespan:g} != largest end {latest:g}"))
    return v
