"""Constrained bipartite matching with subteams and an idle task (LVWS paper, Eqs. 7-11).

Given a reward matrix R of shape n x (m+1) over the n free robots and m ready tasks,
whose last column is the idle task t_{M+1}, choose the scheduling matrix A maximising
sum_ij A_ij R_ij (Eq. 7) such that each robot takes one task or waits (Eq. 9) and every
task that receives robots is covered: the OR of their capabilities contains the task's
(Eq. 10) and their payloads add up to its need (Eq. 11).

:func:`greedy_match` is the paper's sequential greedy (section III-D), vectorised;
:func:`exact_match` solves the same problem with CP-SAT for small cases.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lvws_ros.model import BoolArray, FloatArray
from lvws_ros.subteams import PAYLOAD_TOL, covers


@dataclass(frozen=True)
class Match:
    """Result of a matching: task column -> robot rows, rows that wait, and the reward."""

    teams: dict[int, tuple[int, ...]]
    waiting: tuple[int, ...]
    reward: float


def _check_shapes(r: FloatArray, robot_caps: BoolArray, robot_payload: FloatArray,
                  task_caps: BoolArray, task_payload: FloatArray) -> tuple[int, int]:
    n, m = robot_caps.shape[0], task_caps.shape[0]
    if r.shape != (n, m + 1):
        raise ValueError(f"reward matrix has shape {r.shape}, expected ({n}, {m + 1}) (last column: idle task)")
    if robot_payload.shape != (n,) or task_payload.shape != (m,):
        raise ValueError("payload vectors do not match the capability matrices")
    if robot_caps.shape[1] != task_caps.shape[1]:
        raise ValueError("robots and tasks have different numbers of capabilities")
    if not np.all(np.isfinite(r)):
        raise ValueError("reward matrix holds NaN or infinite values")
    return n, m


def match_reward(r: FloatArray, teams: dict[int, tuple[int, ...]], waiting: tuple[int, ...]) -> float:
    m = r.shape[1] - 1
    return float(sum(r[i, j] for j, team in teams.items() for i in team) + sum(r[i, m] for i in waiting))


def greedy_match(
    r: FloatArray,
    robot_caps: BoolArray,
    robot_payload: FloatArray,
    task_caps: BoolArray,
    task_payload: FloatArray,
) -> Match:
    """Sequential greedy for Eqs. 7-11.

    Repeatedly takes the largest reward among (free robot, open task) pairs in which the
    robot still helps the task (adds a missing capability or missing payload) and
    (free robot, idle task). A robot picked for a task joins its partial subteam; the
    task closes once covered, and members made redundant by later ones are released,
    so subteams are inclusion-minimal. A partial subteam that the remaining free robots can no
    longer complete releases its robots, which go back into the matching. Each pick
    is one vectorised argmax over n x (m+1): O(n * m) per pick, O(n^2 m) worst case.
    """
    n, m = _check_shapes(r, robot_caps, robot_payload, task_caps, task_payload)
    free = np.ones(n, dtype=bool)
    waiting = np.zeros(n, dtype=bool)
    open_task = np.ones(m, dtype=bool)
    missing_caps = task_caps.copy()
    missing_payload = task_payload.astype(np.float64).copy()
    member = np.zeros((n, m), dtype=bool)
    closed_teams: dict[int, tuple[int, ...]] = {}
    caps_f = robot_caps.astype(np.float64)
    while True:
        # A task is completable when its missing capabilities and payload can still come
        # from free robots. A partial subteam that cannot be completed releases its robots
        # (one task at a time, since released robots may complete another).
        free_caps = robot_caps[free].any(axis=0) if free.any() else np.zeros(task_caps.shape[1], bool)
        free_payload = float(robot_payload[free].sum())
        completable = (~missing_caps | free_caps).all(axis=1) & (missing_payload <= free_payload + PAYLOAD_TOL)
        dead = np.flatnonzero(open_task & ~completable & member.any(axis=0))
        if len(dead):
            j = int(dead[0])
            free |= member[:, j]
            member[:, j] = False
            open_task[j] = False
            continue
        if not free.any():
            break
        helps = (caps_f @ missing_caps.T.astype(np.float64) > 0) | (missing_payload > PAYLOAD_TOL)[None, :]
        ok = free[:, None] & (open_task & completable)[None, :] & helps
        scores = np.where(ok, r[:, :m], -np.inf)
        idle = np.where(free, r[:, m], -np.inf)
        flat = int(np.argmax(np.concatenate([scores, idle[:, None]], axis=1)))
        i, j = divmod(flat, m + 1)
        free[i] = False
        if j == m:
            waiting[i] = True
            continue
        member[i, j] = True
        missing_caps[j] &= ~robot_caps[i]
        missing_payload[j] -= robot_payload[i]
        if not missing_caps[j].any() and missing_payload[j] <= PAYLOAD_TOL:
            # Members made redundant by later ones go back to the pool, cheapest first,
            # so every closed subteam is inclusion-minimal.
            team = [int(x) for x in np.flatnonzero(member[:, j])]
            for q in sorted(team, key=lambda q: r[q, j]):
                rest = [x for x in team if x != q]
                if rest and covers(robot_caps[rest], robot_payload[rest], task_caps[j], task_payload[j]):
                    team = rest
                    member[q, j] = False
                    free[q] = True
            open_task[j] = False
            closed_teams[j] = tuple(team)
    wait = tuple(int(i) for i in np.flatnonzero(waiting))
    return Match(closed_teams, wait, match_reward(r, closed_teams, wait))


def exact_match(
    r: FloatArray,
    robot_caps: BoolArray,
    robot_payload: FloatArray,
    task_caps: BoolArray,
    task_payload: FloatArray,
    *,
    time_limit: float = 10.0,
    workers: int = 2,
    necessary_only: bool = True,
) -> Match:
    """Optimal A* of Eqs. 7-11 with CP-SAT (rewards scaled to integers, 1e-6 resolution).

    With ``necessary_only`` (the default, the same problem :func:`greedy_match` solves)
    every member of a subteam must be needed: without it the task would lack a capability
    or payload. Without it, any robot may join a covered task when that pays more.
    """
    from ortools.sat.python import cp_model

    n, m = _check_shapes(r, robot_caps, robot_payload, task_caps, task_payload)
    model = cp_model.CpModel()
    a = [[model.new_bool_var(f"a_{i}_{j}") for j in range(m + 1)] for i in range(n)]
    z = [model.new_bool_var(f"z_{j}") for j in range(m)]
    pay = np.round(robot_payload * 1000).astype(np.int64)
    need = np.ceil(task_payload * 1000 - 1e-6).astype(np.int64)
    for i in range(n):
        model.add_exactly_one(a[i])  # Eq. 9, with the idle column as "no task"
    for j in range(m):
        for i in range(n):
            model.add_implication(a[i][j], z[j])
        for k in np.flatnonzero(task_caps[j]):  # Eq. 10
            holders = [a[i][j] for i in range(n) if robot_caps[i, k]]
            if holders:
                model.add_bool_or(holders).only_enforce_if(z[j])
            else:
                model.add(z[j] == 0)
        carried = sum(int(pay[i]) * a[i][j] for i in range(n))
        model.add(carried >= int(need[j])).only_enforce_if(z[j])  # Eq. 11
        if necessary_only:
            for i in range(n):
                reasons = []
                short = model.new_bool_var(f"short_{i}_{j}")  # payload would fall short without i
                model.add(carried - int(pay[i]) < int(need[j])).only_enforce_if(short)
                reasons.append(short)
                for k in np.flatnonzero(task_caps[j] & robot_caps[i]):
                    sole = model.new_bool_var(f"sole_{i}_{j}_{k}")  # i is the only holder of k
                    others = [a[q][j] for q in range(n) if q != i and robot_caps[q, k]]
                    if others:
                        model.add(sum(others) == 0).only_enforce_if(sole)
                    reasons.append(sole)
                model.add_bool_or(reasons).only_enforce_if(a[i][j])
    scaled = np.round(r * 1e6).astype(np.int64)
    model.maximize(sum(int(scaled[i, j]) * a[i][j] for i in range(n) for j in range(m + 1)))
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = time_limit
    solver.parameters.num_workers = workers
    status = solver.solve(model)
    if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        raise RuntimeError(f"exact_match: CP-SAT returned {solver.status_name(status)}")
    teams: dict[int, tuple[int, ...]] = {}
    waiting = []
    for i in range(n):
        for j in range(m + 1):
            if solver.boolean_value(a[i][j]):
                if j == m:
                    waiting.append(i)
                else:
                    teams.setdefault(j, ())
                    teams[j] = (*teams[j], i)
    wait = tuple(waiting)
    return Match(teams, wait, match_reward(r, teams, wait))


def feasibility_mask(robot_caps: BoolArray, task_caps: BoolArray, robot_payload: FloatArray,
                     task_payload: FloatArray) -> npt.NDArray[np.bool_]:
    """X of Eq. 12 at one step: robot i can help task j (has a needed capability, or
    the task needs payload); the idle column is always feasible."""
    helps = (robot_caps.astype(np.int32) @ task_caps.T.astype(np.int32) > 0) | (task_payload > PAYLOAD_TOL)[None, :]
    return np.concatenate([helps, np.ones((len(robot_caps), 1), dtype=bool)], axis=1)
