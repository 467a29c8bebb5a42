"""A quick plan for robots that set out on their own (``"departure": "each"``).

GRP and LVWS give ready tasks to the robots free at a decision step. Where each robot sets
out for its next task as soon as it is free and waits there for the rest of the subteam
(the coalition benchmarks' robots: ``lvws import dcmrta``), a task is best given to the
robots that can be there soonest, busy ones included. :func:`earliest_start_plan` builds a
whole schedule so (list scheduling):

* each robot is available from a time at a site (the end of the last task given to it, where
  that task leaves it; at first, the state's); a task is given (as the executor gives it) once
  it is ready and its members' tasks before it are given, and each member sets out then or
  once free, whichever is later: the schedule's times are the executor's;
* at each step, for every task whose prerequisites are all placed, the earliest time its
  subteam can be there (:func:`~lvws_ros.core.subteams.earliest_cover` over the robots'
  arrival times: available, then the travel); the task that can start first is placed (ties:
  the longer first; ``finish``: the task that can end first), its subteam the robots there by
  then in order of arrival, pruned to an inclusion-minimal one (the latest to arrive dropped
  first);
* the members are available again at the task's end, at its (``to``) site.

With noise on the keys it samples other list schedules (the planner's rounds of them).
It costs one arrival table of the robots and the placeable tasks per task placed
(O(N T^2) for N robots and T tasks in all), so it is made within the planner's deadline
and given up past it. The schedule is carried out by the executor from the state
(:func:`~lvws_ros.planning.follow.repair`) before it is offered.
"""

from __future__ import annotations

import time

import numpy as np

from lvws_ros.core.executor import State, TaskStatus
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.subteams import covers, earliest_cover, prune

__all__ = ["earliest_start_plan"]


def earliest_start_plan(state: State, finish: bool = False, deadline: float | None = None,
                        rng: np.random.Generator | None = None, noise: float = 0.0) -> Schedule | None:
    """The list schedule of the module docstring from ``state`` (the tasks it has started
    kept); None past ``deadline`` (a perf_counter time), or when a task cannot be covered
    from here (a robot lost, a fixed robot elsewhere). With ``rng``, each step's keys get
    uniform noise of up to ``noise`` x the mean duration of the tasks to place (one of many
    randomized list schedules: the planner's samples)."""
    inst = state.instance
    tr = inst.travel
    free = np.maximum(state.robot_free_at.astype(float), state.time)
    given = np.full(inst.num_robots, float(state.time))  # when each robot's last task was given to it
    site = None if state.robot_site is None else state.robot_site.copy()
    end = {j: float(state.task_start[j] + inst.durations[j])
           for j in np.flatnonzero(state.task_status >= TaskStatus.ASSIGNED).tolist()}
    out = [Assignment(inst.tasks[j].id, tuple(inst.robots[r].id for r in state.task_team[j]),
                      float(state.task_start[j]), e) for j, e in end.items()]
    todo = set(state.tasks_to_do())
    robots = np.arange(inst.num_robots)
    while todo:
        if deadline is not None and time.perf_counter() > deadline:
            return None
        open_ = sorted(j for j in todo if all(p in end for p in inst.prerequisites[j]))
        if not open_:
            return None
        ready = np.array([max([state.time, *(end[p] for p in inst.prerequisites[j])]) for j in open_])
        # a task is given once ready and its members' tasks before it are given; each sets out then
        # or once free (the executor's rule): per robot, a time no member can beat
        leave = np.maximum(np.maximum(free, given)[:, None], ready[None, :])
        way = np.zeros(leave.shape) if tr is None or site is None else tr.arrivals(robots, site, open_)
        times = leave + way
        first = earliest_cover(times, inst.robot_amounts, inst.robot_payload, inst.task_needs[open_],
                               inst.task_payload[open_])
        dur = inst.durations[open_]
        when = first + dur if finish else first
        if rng is not None and noise > 0:
            when = when + rng.uniform(0.0, noise * float(dur.mean()), len(open_))
        key = np.lexsort((-dur, when))
        c = int(key[0])
        if not np.isfinite(first[c]):
            return None
        j = open_[c]
        order = np.argsort(times[:, c], kind="stable").tolist()
        team: list[int] = []
        for r in order:  # the soonest there until they cover (with roles the bound may take more)
            if not np.isfinite(times[r, c]):
                return None
            team.append(r)
            if times[r, c] >= first[c] - 1e-12 and covers(inst.robot_amounts[team], inst.robot_payload[team],
                                                           inst.task_needs[j], inst.tasks[j].payload,
                                                           bool(inst.task_roles[j])):
                break
        else:  # with roles, the whole team may not cover it
            return None
        team = prune(team[::-1], inst.robot_amounts, inst.robot_payload, inst.task_needs[j], inst.tasks[j].payload,
                     roles=bool(inst.task_roles[j]))
        depart = max(float(ready[c]), *(float(given[r]) for r in team))  # when the executor gives it
        start = max(depart, *(max(depart, float(free[r])) + float(way[r, c]) for r in team))
        stop = start + float(inst.durations[j])
        free[team] = stop
        given[team] = depart
        if site is not None and tr is not None:
            site[team] = tr.task_to[j]
        end[j] = stop
        todo.discard(j)
        out.append(Assignment(inst.tasks[j].id, tuple(inst.robots[r].id for r in sorted(team)), start, stop))
    return Schedule.from_assignments(inst, "earliest-start", out)
