"""Lower bounds on the makespan of an instance: what no schedule can beat.

Every schedule comes with a bound, so a user sees how far it can be from optimal at any
size (the exact solver proves optima only on small cells):

* **critical path with the least travel**: a task starts no earlier than the end of its
  prerequisites, nor before a subteam covering it (Eqs. 10-11) can first be at its site,
  each robot setting out from where it starts at time 0 by the quickest way between sites
  (driving at its speed or riding a transport, in any order, so the bound holds whatever
  a robot does first); the longest such chain, each task's duration and the longest
  duration path after it added; with ``"objective": "return"``, the path ends when a
  subteam covering its last task can all be home (each member by its quickest way from
  where that task ends);
* **workload over capacity, with heads and tails**: the robot-seconds every task needs (at
  least as many robots as carry its payload and as add up to each trait it needs,
  :func:`fewest_members`) over the team's size; for each capability (trait), the seconds
  (trait-seconds) of the tasks needing it over its holders (what the team has of it);
  with travel, the same per site for a trait only fixed robots have, over the fixed robots
  at that site; the payload-seconds over the team's payload. Each is a one-machine
  relaxation: the tasks that cannot start before a time (their head, as in the critical
  path) need their work over the capacity after it, and the last of them to end still
  has its shortest tail to go (its successors' chain, and the way home); the largest over
  every such time.

Both are O(N M K + M log M + S^3) (S: sites), the sweeps O(M log M) per capacity. With travel, times are from time 0 and
robots at their start sites; the executor's model (travel, then the task) is what they
bound.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import TOLERANCE, FloatArray, earliest_cover, fewest_carriers

__all__ = ["Bounds", "fewest_members", "gap", "lower_bounds"]


@dataclass(frozen=True)
class Bounds:
    critical_path: float  # with the least travel
    workload: float  # the largest of the workload ratios

    @property
    def best(self) -> float:
        return max(self.critical_path, self.workload)


def _shortest_times(seconds: FloatArray) -> FloatArray:
    """All-pairs shortest times between sites (Floyd-Warshall): a robot may visit sites
    in any order, so the direct time bounds nothing when a detour is quicker."""
    d = np.array(seconds, dtype=np.float64)
    np.fill_diagonal(d, 0.0)
    for k in range(len(d)):
        d = np.minimum(d, d[:, k:k + 1] + d[k:k + 1, :])
    return d


@dataclass(frozen=True)
class _Quickest:
    """The least seconds a robot needs between two sites, driving at its speed or riding a
    transport from a to b (which takes the transport's duration, whatever the distance), in
    any order: one (S, S) matrix per speed (``by_speed``), each robot's row in it
    (``speed_of``, -1: a fixed robot)."""

    by_speed: FloatArray  # (V, S, S)
    speed_of: npt.NDArray[np.int64]  # (N,)

    def times(self, robots: npt.NDArray[np.int64], a: npt.NDArray[np.int64], b: npt.NDArray[np.int64]) -> FloatArray:
        """Broadcast over ``robots``, ``a`` and ``b``; inf for a fixed robot (the caller
        says where a fixed robot is)."""
        k = self.speed_of[robots]
        out = self.by_speed[np.maximum(k, 0), a, b] if len(self.by_speed) else np.full(np.broadcast(k, a, b).shape,
                                                                                         np.inf)
        return np.where(k >= 0, out, np.inf)


def _quickest(inst: Instance) -> _Quickest:
    tr = inst.travel
    assert tr is not None
    speed = np.asarray(tr.robot_speed, dtype=np.float64)
    meet = np.asarray(tr.task_from, dtype=np.int64)
    to = np.asarray(tr.task_to, dtype=np.int64)
    ride = np.full_like(tr.distance, np.inf, dtype=np.float64)  # the quickest transport from a to b
    for j in np.flatnonzero(meet != to):
        ride[meet[j], to[j]] = min(ride[meet[j], to[j]], float(inst.durations[j]))
    speeds = np.unique(speed[speed > 0])
    by_speed = np.array([_shortest_times(np.minimum(tr.distance / v, ride)) for v in speeds])
    speed_of = np.where(speed > 0, np.searchsorted(speeds, speed), -1).astype(np.int64)
    return _Quickest(by_speed.reshape(len(speeds), *tr.distance.shape), speed_of)


def _release(inst: Instance, quickest: _Quickest | None) -> FloatArray:
    """(M,) the earliest a covering subteam can be at each task's meeting site (0 without
    travel), each robot by its :func:`_quickest` way from where it starts."""
    tr = inst.travel
    m = inst.num_tasks
    if tr is None or quickest is None or m == 0:
        return np.zeros(m)
    site = np.asarray(tr.robot_site, dtype=np.int64)
    speed = np.asarray(tr.robot_speed, dtype=np.float64)
    meet = np.asarray(tr.task_from, dtype=np.int64)
    moves = meet != np.asarray(tr.task_to, dtype=np.int64)
    times = quickest.times(np.arange(inst.num_robots)[:, None], site[:, None], meet[None, :])
    fixed = np.flatnonzero(speed <= 0)  # a fixed robot: only at its site, never on a task that moves its team
    times[fixed] = np.where((site[fixed][:, None] == meet[None, :]) & ~moves[None, :], 0.0, np.inf)
    out = earliest_cover(times, inst.robot_amounts, inst.robot_payload, inst.task_needs, inst.task_payload)
    return np.where(np.isfinite(out), out, 0.0)  # never covered from time 0: no bound from it


def _ways_home(inst: Instance, quickest: _Quickest | None) -> FloatArray:
    """(M,) with ``"objective": "return"``, the least time after a task ends until a
    subteam covering it can all be home, each member by its :func:`_quickest` way from
    where the task ends (0 otherwise: the makespan ends with the last task)."""
    tr = inst.travel
    m = inst.num_tasks
    if tr is None or quickest is None or m == 0 or inst.objective != "return":
        return np.zeros(m)
    homes = np.array([tr.home(i) for i in range(inst.num_robots)], dtype=np.int64)
    to = np.asarray(tr.task_to, dtype=np.int64)
    moves = np.asarray(tr.task_from, dtype=np.int64) != to
    times = quickest.times(np.arange(inst.num_robots)[:, None], to[None, :], homes[:, None])
    fixed = np.flatnonzero(np.asarray(tr.robot_speed, dtype=np.float64) <= 0)  # home is where it stays
    times[fixed] = np.where((homes[fixed][:, None] == to[None, :]) & ~moves[None, :], 0.0, np.inf)
    out = earliest_cover(times, inst.robot_amounts, inst.robot_payload, inst.task_needs, inst.task_payload)
    return np.where(np.isfinite(out), out, 0.0)


@dataclass(frozen=True)
class _Windows:
    """Each task's head (its earliest start) and tail (the least time from its end to the
    makespan: the longest chain of durations after it, and the way home at its end)."""

    head: FloatArray
    tail: FloatArray


def _windows(inst: Instance) -> _Windows:
    quickest = _quickest(inst) if inst.travel is not None and inst.num_tasks else None
    head = _release(inst, quickest)
    for j in inst.topological_order:
        for p in inst.prerequisites[j]:
            head[j] = max(head[j], head[p] + inst.durations[p])
    tail = _ways_home(inst, quickest)
    for j in reversed(inst.topological_order):
        for p in inst.prerequisites[j]:
            tail[p] = max(tail[p], inst.durations[j] + tail[j])
    return _Windows(head, tail)


def _span(win: _Windows, tasks: npt.NDArray[np.bool_], work: FloatArray, capacity: float) -> float:
    """The least makespan for ``tasks`` sharing ``capacity``, their ``work`` (amount x
    seconds) each: for every head h, the tasks that start at h or later end no sooner than
    h plus their work over the capacity, and the last of them has its tail to go."""
    if not tasks.any() or capacity <= 0:
        return 0.0
    order = np.argsort(win.head[tasks], kind="stable")
    head, load, tail = win.head[tasks][order], work[tasks][order], win.tail[tasks][order]
    after = np.cumsum(load[::-1])[::-1] / capacity  # the work of the tasks from each head on
    shortest = np.minimum.accumulate(tail[::-1])[::-1]
    return float((head + after + shortest).max())


def _critical_path(inst: Instance, win: _Windows) -> float:
    if inst.num_tasks == 0:
        return 0.0
    return float((win.head + inst.durations + win.tail).max())


def fewest_members(inst: Instance) -> npt.NDArray[np.int64]:
    """(M,) the fewest robots a covering subteam of each task can have: enough of the
    heaviest to carry its payload, and for each trait enough of its largest holders to add
    up to the need (with roles each member fills one slot: the counts of the traits add
    up; without, the largest count); at least one, at most the team."""
    n = inst.num_robots
    amounts = np.asarray(inst.robot_amounts, dtype=np.float64)
    need = np.asarray(inst.task_needs, dtype=np.float64)
    per_trait = np.zeros(need.shape, dtype=np.int64)
    for k in range(need.shape[1]):
        wanted = need[:, k] > TOLERANCE
        if wanted.any():
            ordered = np.sort(amounts[:, k])[::-1].cumsum()
            per_trait[wanted, k] = np.searchsorted(ordered, need[wanted, k] - TOLERANCE) + 1
    roles = np.asarray(inst.task_roles, dtype=bool)
    traits = np.where(roles, per_trait.sum(axis=1), per_trait.max(axis=1, initial=0))
    carriers = fewest_carriers(inst.robot_payload, inst.task_payload)
    return np.asarray(np.clip(np.maximum(traits, carriers), 1, max(n, 1)), dtype=np.int64)


def _site_workload(inst: Instance, win: _Windows) -> float:
    """With travel: for each site and each trait that no mobile robot has, the tasks
    meeting there that need it can only be served by the fixed robots at that site: their
    trait-seconds over what those robots have of it (:func:`_span`)."""
    tr = inst.travel
    if tr is None or inst.num_tasks == 0:
        return 0.0
    speed = np.asarray(tr.robot_speed, dtype=np.float64)
    site = np.asarray(tr.robot_site, dtype=np.int64)
    amounts = np.asarray(inst.robot_amounts, dtype=np.float64)
    need = np.asarray(inst.task_needs, dtype=np.float64)
    meet = np.asarray(tr.task_from, dtype=np.int64)
    mobile = (amounts[speed > 0] > 0).any(axis=0)  # (K,) some robot that moves has it
    best = 0.0
    for s in np.unique(site[speed <= 0]):
        have = amounts[(speed <= 0) & (site == s)].sum(axis=0)
        for k in np.flatnonzero(~mobile & (have > 0)):
            best = max(best, _span(win, (meet == s) & (need[:, k] > 0), inst.durations * need[:, k], float(have[k])))
    return best


def _workload(inst: Instance, win: _Windows) -> float:
    n, m = inst.num_robots, inst.num_tasks
    if m == 0 or n == 0:
        return 0.0
    durations = inst.durations
    every = np.ones(m, dtype=bool)
    ratios = [_span(win, every, durations * fewest_members(inst), n), _site_workload(inst, win)]  # robot-seconds
    holders = inst.robot_amounts.sum(axis=0)  # per capability (trait): how much of it the team has
    for k in range(inst.task_needs.shape[1]):
        ratios.append(_span(win, inst.task_needs[:, k] > 0, durations * inst.task_needs[:, k], float(holders[k])))
    carried = np.maximum(inst.task_payload - TOLERANCE, 0.0)
    ratios.append(_span(win, carried > 0, carried * durations, float(inst.robot_payload.sum())))
    return max(ratios)


def lower_bounds(inst: Instance) -> Bounds:
    """The critical-path and workload bounds of ``inst`` (module docstring)."""
    win = _windows(inst)
    return Bounds(_critical_path(inst, win), _workload(inst, win))


def gap(makespan: float, bound: float) -> float:
    """(makespan - bound) / makespan: how far above optimal a schedule can be at most."""
    return max(0.0, (makespan - bound) / makespan) if makespan > 0 else 0.0
