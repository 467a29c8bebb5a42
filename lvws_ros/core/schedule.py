"""Schedules and the validity rules of ``lvws-schedule/1`` (formats.md): the six of the
contract, and rule 7 (travel) for instances with the travel extension.

Reading and writing schedule files is :mod:`lvws_ros.core.formats`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import numpy as np

from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import TOLERANCE, role_shortfall, shortfall


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
        instance: Instance | str,
        policy: str,
        assignments: Sequence[Assignment],
        decisions: int = 0,
        compute_seconds: float = 0.0,
    ) -> Schedule:
        """A schedule of ``assignments``; its makespan by the instance's objective (given
        only a name: the largest end)."""
        ordered = sorted(assignments, key=lambda a: (a.start, a.task))
        if isinstance(instance, Instance):
            return cls(instance.name, policy, ordered, makespan(instance, ordered), decisions, compute_seconds)
        return cls(instance, policy, ordered, max((a.end for a in ordered), default=0.0), decisions, compute_seconds)

    def by_task(self) -> dict[str, Assignment]:
        return {a.task: a for a in self.assignments}


def home_times(inst: Instance, assignments: Sequence[Assignment]) -> dict[str, tuple[float, str]]:
    """Robot id -> (when it is back home, how: the task it comes from and the travel),
    for the robots not home at the largest end of ``assignments`` (objective "return";
    without travel every robot is home when its last task ends)."""
    tr = inst.travel
    if tr is None:
        return {}
    last: dict[str, Assignment] = {}
    for a in assignments:
        for r in a.robots:
            if r in inst.robot_index and a.task in inst.task_index and (r not in last or a.end > last[r].end):
                last[r] = a
    out = {}
    for k, robot in enumerate(inst.robots):
        home = tr.home(k)
        prev = last.get(robot.id)
        site, free = (tr.robot_site[k], 0.0) if prev is None else (tr.task_to[inst.task_index[prev.task]], prev.end)
        if site != home:
            move = tr.time(k, site, home)
            before = "its start" if prev is None else f"end of {prev.task!r} at {free:g}"
            out[robot.id] = (free + move, f"{before} + {move:g} s from {tr.sites[site]} to {tr.sites[home]}")
    return out


def makespan(inst: Instance, assignments: Sequence[Assignment]) -> float:
    """The objective of ``inst``: the largest end; with ``"objective": "return"``, when the
    last robot is back home (formats.md, rule 8)."""
    latest = max((a.end for a in assignments), default=0.0)
    if inst.objective != "return":
        return latest
    return max([latest, *(t for t, _ in home_times(inst, assignments).values())])


@dataclass(frozen=True)
class Violation:
    rule: int
    message: str

    def __str__(self) -> str:
        return f"rule {self.rule}: {self.message}"


def _rule1(inst: Instance, s: Schedule) -> list[Violation]:
    """Rule 1: each task exactly once, robots exist (and subteams are not empty)."""
    v: list[Violation] = []
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
    return v


def _rule7(inst: Instance, per_robot: dict[str, list[Assignment]], tol: float) -> list[Violation]:
    tr = inst.travel
    assert tr is not None
    v: list[Violation] = []
    for rid, items in sorted(per_robot.items()):
        if rid not in inst.robot_index:
            continue
        r = inst.robot_index[rid]
        site, free, before = tr.robot_site[r], 0.0, "its start"
        for a in items:  # sorted by start (rule 5)
            if a.task not in inst.task_index:
                continue
            j = inst.task_index[a.task]
            if not tr.can_do(r, j):
                v.append(Violation(7, f"robot {rid!r} is fixed at {tr.sites[tr.robot_site[r]]}: it cannot take "
                                      f"task {a.task!r}, which moves its team from {tr.sites[tr.task_from[j]]} to "
                                      f"{tr.sites[tr.task_to[j]]}"))
            need = tr.time(r, site, tr.task_from[j])
            if not a.start >= free + need - tol:
                how = "cannot leave its site" if math.isinf(need) else f"needs {need:g} s"
                v.append(Violation(7, f"robot {rid!r} {how} from {tr.sites[site]} ({before}) to "
                                      f"{tr.sites[tr.task_from[j]]} for task {a.task!r}, which starts at {a.start:g}"
                                      + ("" if math.isinf(need) else f" < {free + need:g}")))
            site, free, before = tr.task_to[j], a.end, f"end of {a.task!r}"
    return v


def check_schedule(inst: Instance, s: Schedule, tol: float = TOLERANCE) -> list[Violation]:
    """Every violation of the validity rules of formats.md (empty list: valid): rules 1-6,
    and rule 7 (travel) when the instance has the travel extension."""
    v = _rule1(inst, s)
    by_task = {a.task: a for a in s.assignments if a.task in inst.task_index}
    for a in by_task.values():
        t = inst.tasks[inst.task_index[a.task]]
        members = [inst.robot_index[r] for r in a.robots if r in inst.robot_index]
        # Rule 2: the subteam covers the task (Eqs. 10-11: capabilities, payload; traits add up).
        j = inst.task_index[a.task]
        have = inst.robot_amounts[members].sum(axis=0)
        carried = float(inst.robot_payload[members].sum())
        missing, short = shortfall(have, carried, inst.task_needs[j], t.payload)
        k = len(inst.capabilities)
        if missing[:k].any():
            names = [inst.capabilities[c] for c in np.flatnonzero(missing[:k])]
            v.append(Violation(2, f"task {t.id!r}: subteam {list(a.robots)} lacks capability {names}"))
        for c in np.flatnonzero(missing[k:]):
            v.append(Violation(2, f"task {t.id!r}: subteam {list(a.robots)} has {inst.traits[c]} {have[k + c]:g} "
                                  f"< needed {inst.task_needs[j, k + c]:g}"))
        if short > 0:
            v.append(Violation(2, f"task {t.id!r}: subteam payload {carried:g} < needed {t.payload:g}"))
        if inst.task_roles[j] and not missing.any():  # the sums are there; with one trait per member?
            lack = role_shortfall(inst.robot_amounts[members], inst.task_needs[j])
            if lack.any():
                names = [inst.cover_names[c] for c in np.flatnonzero(lack)]
                v.append(Violation(2, f"task {t.id!r}: with roles (each member counts toward one trait) subteam "
                                      f"{list(a.robots)} falls short of {names}"))
        # Rule 3: duration and start. Every comparison is written "violated unless it holds",
        # so that NaN (for which every comparison is False) is a violation, never a pass.
        if not (math.isfinite(a.start) and math.isfinite(a.end)):
            v.append(Violation(3, f"task {t.id!r}: start {a.start!r} and end {a.end!r} must be finite numbers"))
            continue
        if not abs((a.end - a.start) - t.duration) <= tol:
            v.append(Violation(3, f"task {t.id!r}: end - start = {a.end - a.start:g}, duration is {t.duration:g}"))
        if not a.start >= -tol:
            v.append(Violation(3, f"task {t.id!r}: starts at {a.start:g} < 0"))
        # Rule 4: prerequisites finished.
        for p in t.after:
            pa = by_task.get(p)
            if pa is not None and not a.start >= pa.end - tol:
                v.append(Violation(4, f"task {t.id!r} starts at {a.start:g} before prerequisite {p!r} ends at {pa.end:g}"))
    # Rule 5: no robot in two overlapping assignments (non-finite ones are rule 3 violations).
    per_robot: dict[str, list[Assignment]] = {}
    for a in s.assignments:
        if math.isfinite(a.start) and math.isfinite(a.end):
            for r in set(a.robots):
                per_robot.setdefault(r, []).append(a)
    for r, items in sorted(per_robot.items()):
        items.sort(key=lambda a: (a.start, a.end))
        for x, y in pairwise(items):
            if not y.start >= x.end - tol:
                v.append(Violation(5, f"robot {r!r} is in {x.task!r} [{x.start:g}, {x.end:g}) "
                                      f"and {y.task!r} [{y.start:g}, {y.end:g}) at once"))
    # Rule 7 (travel extension): a robot's first task starts no earlier than it can get
    # there from its site, and each next one no earlier than the end of the one before plus
    # the travel between them (a subteam starts when its slowest member can be there).
    if inst.travel is not None:
        v += _rule7(inst, per_robot, tol)
    # Rule 6: makespan is the largest end; with the objective "return", rule 8: every robot
    # is home by the makespan, and the makespan is when the last one is.
    latest = max((a.end for a in s.assignments), default=0.0)
    if inst.objective == "return":
        home = home_times(inst, [a for a in s.assignments if math.isfinite(a.end)])
        for rid, (back, how) in sorted(home.items()):
            if not back <= s.makespan + tol:
                v.append(Violation(8, f"robot {rid!r} is not home in time: back at {back:g} ({how}), "
                                      f"after the makespan {s.makespan:g}"))
        latest = max([latest, *(t for t, _ in home.values())])
        if not abs(s.makespan - latest) <= tol:
            v.append(Violation(6, f"makespan {s.makespan:g} != when the last robot is home {latest:g}"))
        return v
    if not abs(s.makespan - latest) <= tol:
        v.append(Violation(6, f"makespan {s.makespan:g} != largest end {latest:g}"))
    return v
