"""Lower bounds on the makespan of an instance: what no schedule can beat.

Every schedule comes with a bound, so a user sees how far it can be from optimal at any
size (the exact solver proves optima only on small cells):

* **critical path with the least travel**: a task starts no earlier than the end of its
  prerequisites, nor before a subteam covering it (Eqs. 10-11) can first be at its site,
  each robot setting out from where it starts at time 0 by the quickest way between sites
  (driving at its speed or riding a transport, in any order, so the bound holds whatever
  a robot does first); the longest such chain, each task's duration and the longest
  duration path after it added;
* **workload over capacity**: the robot-seconds every task needs (at least as many robots
  as carry its payload and as add up to each trait it needs, :func:`fewest_members`) over
  the team's size; for each capability (trait), the seconds (trait-seconds) of the tasks
  needing it over its holders (what the team has of it); with travel, the same per site for
  a trait only fixed robots have, over the fixed robots at that site; the payload-seconds
  over the team's payload.

Both are O(N M K + M log M + S^3) (S: sites). With travel, times are from time 0 and
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


def _release(inst: Instance) -> FloatArray:
    """(M,) the earliest a covering subteam can be at each task's meeting site (0 without
    travel). A mobile robot gets from site a to b by driving at its speed or by riding a
    transport from a to b (which takes the transport's duration, whatever the distance),
    in any order: the shortest such times, per speed."""
    tr = inst.travel
    m = inst.num_tasks
    if tr is None or m == 0:
        return np.zeros(m)
    site = np.asarray(tr.robot_site, dtype=np.int64)
    speed = np.asarray(tr.robot_speed, dtype=np.float64)
    meet = np.asarray(tr.task_from, dtype=np.int64)
    to = np.asarray(tr.task_to, dtype=np.int64)
    moves = meet != to
    ride = np.full_like(tr.distance, np.inf, dtype=np.float64)  # the quickest transport from a to b
    for j in np.flatnonzero(moves):
        ride[meet[j], to[j]] = min(ride[meet[j], to[j]], float(inst.durations[j]))
    times = np.full((inst.num_robots, m), np.inf)
    for v in np.unique(speed[speed > 0]):
        quickest = _shortest_times(np.minimum(tr.distance / v, ride))
        mine = np.flatnonzero(speed == v)
        times[mine] = quickest[np.ix_(site[mine], meet)]
    fixed = np.flatnonzero(speed <= 0)  # a fixed robot: only at its site, never on a task that moves its team
    times[fixed] = np.where((site[fixed][:, None] == meet[None, :]) & ~moves[None, :], 0.0, np.inf)
    out = earliest_cover(times, inst.robot_amounts, inst.robot_payload, inst.task_needs, inst.task_payload)
    return np.where(np.isfinite(out), out, 0.0)  # never covered from time 0: no bound from it


def _critical_path(inst: Instance) -> float:
    if inst.num_tasks == 0:
        return 0.0
    head = _release(inst)  # earliest start of each task
    for j in inst.topological_order:
        for p in inst.prerequisites[j]:
            head[j] = max(head[j], head[p] + inst.durations[p])
    return float((head + inst.critical_tail).max())


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


def _site_workload(inst: Instance) -> float:
    """With travel: for each site and each trait that no mobile robot has, the tasks
    meeting there that need it can only be served by the fixed robots at that site: their
    trait-seconds over what those robots have of it."""
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
        here = meet == s
        for k in np.flatnonzero(~mobile & (have > 0)):
            best = max(best, float((inst.durations[here] * need[here, k]).sum()) / float(have[k]))
    return best


def _workload(inst: Instance) -> float:
    n, m = inst.num_robots, inst.num_tasks
    if m == 0 or n == 0:
        return 0.0
    durations = inst.durations
    ratios = [float((durations * fewest_members(inst)).sum()) / n, _site_workload(inst)]  # robot-seconds
    holders = inst.robot_amounts.sum(axis=0)  # per capability (trait): how much of it the team has
    for k in range(inst.task_needs.shape[1]):
        need = inst.task_needs[:, k] > 0
        if holders[k] > 0:
            ratios.append(float((durations[need] * inst.task_needs[need, k]).sum()) / float(holders[k]))
    team = float(inst.robot_payload.sum())
    if team > 0:
        ratios.append(float((np.maximum(inst.task_payload - TOLERANCE, 0.0) * durations).sum()) / team)
    return max(ratios)


def lower_bounds(inst: Instance) -> Bounds:
    """The critical-path and workload bounds of ``inst`` (module docstring)."""
    return Bounds(_critical_path(inst), _workload(inst))


def gap(makespan: float, bound: float) -> float:
    """(makespan - bound) / makespan: how far above optimal a schedule can be at most."""
    return max(0.0, (makespan - bound) / makespan) if makespan > 0 else 0.0
