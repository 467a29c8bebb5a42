"""Constrained bipartite matching with subteams and an idle task (LVWS paper, Eqs. 7-11).

Given a reward matrix R of shape n x (m+1) over the n free robots and m ready tasks,
whose last column is the idle task t_{M+1}, choose the scheduling matrix A maximising
sum_ij A_ij R_ij (Eq. 7) such that each robot takes one task or waits (Eq. 9) and every
task that receives robots is covered: the OR of their capabilities contains the task's
(Eq. 10) and their payloads add up to its need (Eq. 11); with additive traits, their
amounts add up to the task's (:mod:`lvws_ros.core.subteams`: the capability arrays hold
amounts).

:func:`greedy_match` is the paper's sequential greedy (section III-D), vectorised;
:func:`lvws_ros.policies.exact.exact_match` solves the same problem with CP-SAT for
small cases.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lvws_ros.core.subteams import AmountArray, BoolArray, FloatArray, covered, covers, helps
from lvws_ros.errors import PolicyError


@dataclass(frozen=True)
class Match:
    """Result of a matching: task column -> robot rows, rows that wait, and the reward."""

    teams: dict[int, tuple[int, ...]]
    waiting: tuple[int, ...]
    reward: float


def check_shapes(r: FloatArray, robot_caps: AmountArray, robot_payload: FloatArray,
                  task_caps: AmountArray, task_payload: FloatArray) -> tuple[int, int]:
    n, m = robot_caps.shape[0], task_caps.shape[0]
    if r.shape != (n, m + 1):
        raise ValueError(f"reward matrix has shape {r.shape}, expected ({n}, {m + 1}) (last column: idle task)")
    if robot_payload.shape != (n,) or task_payload.shape != (m,):
        raise ValueError("payload vectors do not match the capability matrices")
    if robot_caps.shape[1] != task_caps.shape[1]:
        raise ValueError("robots and tasks have different numbers of capabilities")
    if not np.all(np.isfinite(r)):
        raise PolicyError("reward matrix holds NaN or infinite values")
    return n, m


def match_reward(r: FloatArray, teams: dict[int, tuple[int, ...]], waiting: tuple[int, ...]) -> float:
    m = r.shape[1] - 1
    return float(sum(r[i, j] for j, team in teams.items() for i in team) + sum(r[i, m] for i in waiting))


def _best_pick(r: FloatArray, ok: BoolArray, free: BoolArray) -> tuple[int, int]:
    """(robot, column) of the largest reward among the allowed (robot, task) pairs and
    the free robots' idle column (column m)."""
    m = r.shape[1] - 1
    scores = np.where(ok, r[:, :m], -np.inf)
    idle = np.where(free, r[:, m], -np.inf)
    i, j = divmod(int(np.argmax(np.concatenate([scores, idle[:, None]], axis=1))), m + 1)
    return i, j


def _drop_redundant(team: list[int], rewards: FloatArray, robot_caps: AmountArray, robot_payload: FloatArray,
                    need_caps: AmountArray, need_payload: float, roles: bool = False) -> list[int]:
    """Members made redundant by later ones leave, lowest reward first: the subteam still
    covers the task and is inclusion-minimal."""
    for q in sorted(team, key=lambda q: rewards[q]):
        rest = [x for x in team if x != q]
        if rest and covers(robot_caps[rest], robot_payload[rest], need_caps, need_payload, roles):
            team = rest
    return team


def greedy_match(
    r: FloatArray,
    robot_caps: AmountArray,
    robot_payload: FloatArray,
    task_caps: AmountArray,
    task_payload: FloatArray,
    allowed: BoolArray | None = None,
    roles: BoolArray | None = None,
) -> Match:
    """Sequential greedy for Eqs. 7-11.

    Repeatedly takes the largest reward among (free robot, open task) pairs in which the
    robot still helps the task (a missing capability or payload) and (free robot, idle
    task). A robot picked for a task joins its partial subteam; the task closes once
    covered, minus members made redundant (subteams are inclusion-minimal). A partial
    subteam the free robots can no longer complete releases its robots. One vectorised
    argmax over n x (m+1) per pick: O(n * m) per pick, O(n^2 m) worst case.

    ``allowed`` (n, m), when given, limits each task to the robots allowed for it (with
    travel: the robots that can reach it at all); None allows every pair. ``roles`` (m,)
    marks the tasks whose members each count toward one trait (:func:`role_cover`): such a
    task closes once the rule holds, what its members lack with roles still missing.
    """
    n, m = check_shapes(r, robot_caps, robot_payload, task_caps, task_payload)
    if allowed is not None and allowed.shape != (n, m):
        raise ValueError(f"allowed has shape {allowed.shape}, expected ({n}, {m})")
    free = np.ones(n, dtype=bool)
    waiting = np.zeros(n, dtype=bool)
    open_task = np.ones(m, dtype=bool)
    amounts = np.asarray(robot_caps, dtype=np.float64)
    missing_caps = np.asarray(task_caps, dtype=np.float64).copy()
    missing_payload = task_payload.astype(np.float64).copy()
    member = np.zeros((n, m), dtype=bool)
    closed_teams: dict[int, tuple[int, ...]] = {}
    with_roles = np.zeros(m, dtype=bool) if roles is None else np.asarray(roles, dtype=bool)
    role_helpers = helps(amounts, task_caps[with_roles], task_payload[with_roles])  # any holder of a needed trait
    while True:
        # A task is completable when its missing capabilities and payload can still come
        # from free robots. A partial subteam that cannot be completed releases its robots
        # (one task at a time, since released robots may complete another).
        if allowed is None:
            free_caps = amounts[free].sum(axis=0)
            free_payload: FloatArray | float = float(robot_payload[free].sum())
        else:  # per task: the free robots allowed for it
            can = (allowed & free[:, None]).astype(np.float64)  # (n, m)
            free_caps = can.T @ amounts  # (m, K)
            free_payload = can.T @ robot_payload.astype(np.float64)  # (m,)
        completable = covered(free_caps, free_payload, missing_caps, missing_payload)
        for q in np.flatnonzero(open_task & with_roles):
            pool = member[:, q] | (free if allowed is None else free & allowed[:, q])  # exactly, with roles
            completable[q] = covers(amounts[pool], robot_payload[pool], task_caps[q], task_payload[q], True)
        dead = np.flatnonzero(open_task & ~completable & member.any(axis=0))
        if len(dead):
            j = int(dead[0])
            free |= member[:, j]
            member[:, j] = False
            open_task[j] = False
            continue
        if not free.any():
            break
        useful = helps(amounts, missing_caps, missing_payload)
        useful[:, with_roles] = role_helpers
        ok = free[:, None] & (open_task & completable)[None, :] & useful
        if allowed is not None:
            ok &= allowed
        i, j = _best_pick(r, ok, free)
        free[i] = False
        if j == m:
            waiting[i] = True
            continue
        member[i, j] = True
        missing_caps[j] -= amounts[i]
        missing_payload[j] -= robot_payload[i]
        if with_roles[j]:
            done = covers(amounts[member[:, j]], robot_payload[member[:, j]], task_caps[j], task_payload[j], True)
        else:
            done = bool(covered(np.zeros_like(missing_caps[j]), 0.0, missing_caps[j], missing_payload[j]))
        if done:
            team = _drop_redundant([int(x) for x in np.flatnonzero(member[:, j])], r[:, j], amounts,
                                   robot_payload, task_caps[j], float(task_payload[j]), bool(with_roles[j]))
            released = member[:, j].copy()
            released[team] = False
            free |= released  # redundant members go back to the pool
            member[:, j] = False
            member[team, j] = True
            open_task[j] = False
            closed_teams[j] = tuple(team)
    wait = tuple(int(i) for i in np.flatnonzero(waiting))
    return Match(closed_teams, wait, match_reward(r, closed_teams, wait))
