"""Justification: a plan's list schedule run backwards and forwards again, the classic
improvement of list schedules (forward-backward improvement, "double justification").

A plan's tasks still to do are scheduled backwards in time by GRP, the latest-ending first
(:func:`reversed_rest`: every precedence reversed, each task meeting where it ends, the
robots setting out from home); the backward schedule, mirrored, gives each task a start
that leaves no gap a later task could have filled, and GRP takes the tasks forwards in the
order of those starts, from the plan's state. The backward schedule only orders tasks: it
need not be valid in forward time, and the forward one is made by the executor, so it is
valid whatever the backward one was. Each pass costs two GRP runs.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from lvws_ros.core.executor import SimulationResult, State, simulate
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.core.subteams import FloatArray
from lvws_ros.learning.policies import Until
from lvws_ros.policies.baselines import GreedyPayloadPolicy

__all__ = ["justify", "reversed_rest"]


def reversed_rest(inst: Instance, todo: list[int]) -> Instance:
    """The tasks ``todo`` of ``inst`` run backwards in time: each one after the tasks it
    was before (among ``todo``), meeting where it ended and ending where it met; the robots
    setting out from home and going back to where they started."""
    keep = {inst.tasks[j].id for j in todo}
    before: dict[str, list[str]] = {t: [] for t in keep}
    for j in todo:
        for p in inst.tasks[j].after:
            if p in keep:
                before[p].append(inst.tasks[j].id)
    tasks = tuple(dataclasses.replace(inst.tasks[j], after=tuple(before[inst.tasks[j].id])) for j in todo)
    tr = inst.travel
    if tr is None:
        return dataclasses.replace(inst, name=f"{inst.name} reversed", tasks=tasks)
    homes = tuple(tr.home(i) for i in range(inst.num_robots))
    travel = dataclasses.replace(tr, distance=np.ascontiguousarray(tr.distance.T), robot_site=homes,
                                 robot_home=tuple(tr.robot_site) if inst.objective == "return" else (),
                                 task_from=tuple(tr.task_to[j] for j in todo),
                                 task_to=tuple(tr.task_from[j] for j in todo))
    return dataclasses.replace(inst, name=f"{inst.name} reversed", tasks=tasks, travel=travel)


def _ends(inst: Instance, schedule: Schedule) -> FloatArray:
    """(M,) the ends of ``schedule``'s tasks, indexed like ``inst.tasks`` (nan: not in it)."""
    end = np.full(inst.num_tasks, np.nan)
    for a in schedule.assignments:
        end[inst.task_index[a.task]] = a.end
    return end


def justify(state: State, schedule: Schedule, backward: Instance, todo: list[int], deadline: float,
            noise: float = 0.0, seed: int = 0) -> SimulationResult:
    """One pass from ``state``: ``backward`` (:func:`reversed_rest` of the tasks ``todo``)
    scheduled by GRP with ``schedule``'s latest ends first, then the rest forwards by GRP
    with the mirrored backward starts first (``noise``: in mean task durations, on both
    passes' keys). OutOfTime when a pass would run past ``deadline`` (perf_counter)."""
    inst = state.instance
    keys = -_ends(inst, schedule)[todo]  # the latest end first (nan, a task not in the plan, sorts last)
    back = simulate(backward, Until(GreedyPayloadPolicy(seed=seed, keys=keys, noise=noise), deadline)).schedule
    forward = np.full(inst.num_tasks, np.inf)
    forward[todo] = back.makespan - _ends(backward, back)  # the mirrored start: when the task starts, run forwards
    policy = GreedyPayloadPolicy(seed=seed + 1, keys=forward, noise=noise)
    return simulate(inst, Until(policy, deadline), state=state)
