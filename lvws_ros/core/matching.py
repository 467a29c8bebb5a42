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

from lvws_ros.core.subteams import AmountArray, BoolArray, FloatArray, IntArray, covered, covers, helps
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


def _best_pick(r: FloatArray, ok: BoolArray) -> tuple[int, int]:
    """(row, column) of the largest reward among the allowed (robot, task) pairs and the
    idle column (column m), ``r`` holding the free robots' rows only."""
    m = r.shape[1] - 1
    scores = np.where(ok, r[:, :m], -np.inf)
    i, j = divmod(int(np.argmax(np.concatenate([scores, r[:, m:]], axis=1))), m + 1)
    return i, j


def _idle_first(r: FloatArray, rows: IntArray, ok: BoolArray, free_caps: FloatArray, free_payload: FloatArray,
                missing_caps: FloatArray, missing_payload: FloatArray, amounts: FloatArray, payload: FloatArray,
                reach: BoolArray, partial: BoolArray, with_roles: BoolArray) -> IntArray:
    """The free robots (``rows``) the next picks send to the idle task, all at once: those
    whose idle reward beats every open (robot, task) entry ``ok``, in the order single picks
    take them (largest first, then lower index), up to and including the first whose
    leaving makes a task with a partial subteam (``partial``) impossible to complete (its
    release may bring back better entries). Their leaving only closes entries, so each
    would be picked before any task. None at once while a partial subteam has roles (its
    completion is not a sum)."""
    m = r.shape[1] - 1
    if (partial & with_roles).any():
        return rows[:0]
    best_task = float(np.max(np.where(ok, r[rows, :m], -np.inf), initial=-np.inf))
    cand: IntArray = rows[r[rows, m] > best_task]
    if len(cand) < 2:
        return cand
    order: IntArray = cand[np.lexsort((cand, -r[cand, m]))]
    tasks = np.flatnonzero(partial)
    if not len(tasks):
        return order
    share = reach[np.ix_(order, tasks)].astype(np.float64)  # (c, p): who counts for which partial task
    gone_caps = np.cumsum(share[:, :, None] * amounts[order][:, None, :], axis=0)  # (c, p, K)
    gone_payload = np.cumsum(share * payload[order][:, None], axis=0)  # (c, p)
    still = covered(free_caps[tasks][None] - gone_caps, free_payload[tasks][None] - gone_payload,
                    missing_caps[tasks][None], missing_payload[tasks][None])  # (c, p)
    short = np.flatnonzero(~still.all(axis=1))
    return order if not len(short) else np.asarray(order[: int(short[0]) + 1], dtype=np.int64)


def _drop_redundant(team: list[int], rewards: FloatArray, robot_caps: AmountArray, robot_payload: FloatArray,
                    need_caps: AmountArray, need_payload: float, roles: bool = False) -> list[int]:
    """Members made redundant by later ones leave, lowest reward first: the subteam still
    covers the task and is inclusion-minimal."""
    for q in sorted(team, key=lambda q: rewards[q]):
        rest = [x for x in team if x != q]
        if rest and covers(robot_caps[rest], robot_payload[rest], need_caps, need_payload, roles):
            team = rest
    return team


class _Greedy:
    """The greedy's state between picks: free and waiting robots, open tasks and their
    partial subteams, what each task still misses, who still helps which task, and what
    the free robots allowed for each task bring to it (updated as robots leave and rejoin
    the pool, not recomputed)."""

    def __init__(self, robot_caps: AmountArray, robot_payload: FloatArray, task_caps: AmountArray,
                 task_payload: FloatArray, allowed: BoolArray | None, roles: BoolArray | None) -> None:
        n, m = robot_caps.shape[0], task_caps.shape[0]
        self.robot_payload, self.task_caps, self.task_payload = robot_payload, task_caps, task_payload
        self.free = np.ones(n, dtype=bool)
        self.waiting = np.zeros(n, dtype=bool)
        self.open_task = np.ones(m, dtype=bool)
        self.amounts = np.asarray(robot_caps, dtype=np.float64)
        self.missing_caps = np.asarray(task_caps, dtype=np.float64).copy()
        self.missing_payload = task_payload.astype(np.float64).copy()
        self.member = np.zeros((n, m), dtype=bool)
        self.closed_teams: dict[int, tuple[int, ...]] = {}
        self.with_roles = np.zeros(m, dtype=bool) if roles is None else np.asarray(roles, dtype=bool)
        # with roles, any holder of a needed trait helps
        role_helpers = helps(self.amounts, task_caps[self.with_roles], task_payload[self.with_roles])
        self.payload64 = robot_payload.astype(np.float64)
        self.reach = np.ones((n, m), dtype=bool) if allowed is None else np.asarray(allowed, dtype=bool)
        # What the free robots allowed for each task bring to it (m, K) and (m,): updated as
        # robots leave and rejoin the pool (whole amounts add up exactly; a tolerance covers the rest).
        self.free_caps = self.reach.T.astype(np.float64) @ self.amounts
        self.free_payload = self.reach.T.astype(np.float64) @ self.payload64
        self.useful = helps(self.amounts, self.missing_caps, self.missing_payload)
        self.useful[:, self.with_roles] = role_helpers

    def shift(self, rows: IntArray, sign: float) -> None:
        """Robots ``rows`` leave (-1) or rejoin (+1) the free pool."""
        if len(rows):
            counts = sign * self.reach[rows].T.astype(np.float64)  # (m, len(rows))
            self.free_caps[...] += counts @ self.amounts[rows]
            self.free_payload[...] += counts @ self.payload64[rows]

    def completable(self) -> BoolArray:
        """The tasks whose missing capabilities and payload can still come from free robots
        (with roles: exactly, from the members and the free robots allowed)."""
        completable = covered(self.free_caps, self.free_payload, self.missing_caps, self.missing_payload)
        for q in np.flatnonzero(self.open_task & self.with_roles):
            pool = self.member[:, q] | (self.free & self.reach[:, q])  # exactly, with roles
            completable[q] = covers(self.amounts[pool], self.robot_payload[pool], self.task_caps[q],
                                    self.task_payload[q], True)
        return completable

    def release_dead(self, completable: BoolArray) -> bool:
        """The first partial subteam that cannot be completed releases its robots (one task
        at a time, since released robots may complete another); whether there was one."""
        dead = np.flatnonzero(self.open_task & ~completable & self.member.any(axis=0))
        if not len(dead):
            return False
        j = int(dead[0])
        self.shift(np.flatnonzero(self.member[:, j]), 1.0)
        self.free |= self.member[:, j]
        self.member[:, j] = False
        self.open_task[j] = False
        return True

    def pick(self, r: FloatArray, completable: BoolArray) -> bool:
        """The next pick (or the run of idle picks :func:`_idle_first` finds); False when no
        robot is free."""
        rows = np.flatnonzero(self.free)
        if not len(rows):
            return False
        ok = (self.open_task & completable)[None, :] & self.useful[rows] & self.reach[rows]
        idle = _idle_first(r, rows, ok, self.free_caps, self.free_payload, self.missing_caps, self.missing_payload,
                           self.amounts, self.payload64, self.reach, self.open_task & self.member.any(axis=0),
                           self.with_roles)
        if len(idle) > 1:  # the picks one by one would send these to the idle task, in this order
            self.free[idle] = False
            self.waiting[idle] = True
            self.shift(idle, -1.0)
            return True
        k, j = _best_pick(r[rows], ok)
        i = int(rows[k])
        self.free[i] = False
        self.shift(np.array([i]), -1.0)
        if j == r.shape[1] - 1:
            self.waiting[i] = True
        else:
            self.join(r, i, j)
        return True

    def join(self, r: FloatArray, i: int, j: int) -> None:
        """Robot ``i`` joins task ``j``'s partial subteam; the task closes once covered."""
        self.member[i, j] = True
        self.missing_caps[j] -= self.amounts[i]
        self.missing_payload[j] -= self.robot_payload[i]
        if self.with_roles[j]:
            team = self.member[:, j]
            done = covers(self.amounts[team], self.robot_payload[team], self.task_caps[j], self.task_payload[j], True)
        else:
            self.useful[:, j] = helps(self.amounts, self.missing_caps[j][None, :], self.missing_payload[j:j + 1])[:, 0]
            done = bool(covered(np.zeros_like(self.missing_caps[j]), 0.0, self.missing_caps[j], self.missing_payload[j]))
        if done:
            self.close(r, j)

    def close(self, r: FloatArray, j: int) -> None:
        """Task ``j`` closes with its subteam minus the members made redundant, who go back
        to the pool."""
        team = _drop_redundant([int(x) for x in np.flatnonzero(self.member[:, j])], r[:, j], self.amounts,
                               self.robot_payload, self.task_caps[j], float(self.task_payload[j]),
                               bool(self.with_roles[j]))
        released = self.member[:, j].copy()
        released[team] = False
        self.shift(np.flatnonzero(released), 1.0)
        self.free |= released  # redundant members go back to the pool
        self.member[:, j] = False
        self.member[team, j] = True
        self.open_task[j] = False
        self.closed_teams[j] = tuple(team)


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
    argmax over the free robots x (m+1) per pick; what the free robots can still bring to
    each task, and who helps which task, are updated for the robot and the task a pick
    changes, not recomputed: O(n * m) per pick, O(n^2 m) worst case.

    ``allowed`` (n, m), when given, limits each task to the robots allowed for it (with
    travel: the robots that can reach it at all); None allows every pair. ``roles`` (m,)
    marks the tasks whose members each count toward one trait (:func:`role_cover`): such a
    task closes once the rule holds, what its members lack with roles still missing.
    """
    n, m = check_shapes(r, robot_caps, robot_payload, task_caps, task_payload)
    if allowed is not None and allowed.shape != (n, m):
        raise ValueError(f"allowed has shape {allowed.shape}, expected ({n}, {m})")
    state = _Greedy(robot_caps, robot_payload, task_caps, task_payload, allowed, roles)
    while True:
        completable = state.completable()
        if state.release_dead(completable):
            continue
        if not state.pick(r, completable):
            break
    wait = tuple(int(i) for i in np.flatnonzero(state.waiting))
    return Match(state.closed_teams, wait, match_reward(r, state.closed_teams, wait))
