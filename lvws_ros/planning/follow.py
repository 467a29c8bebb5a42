"""Dispatch from a plan, and its repair when the world departs from it.

A plan is a whole schedule (:class:`~lvws_ros.core.schedule.Schedule`: each task's
subteam and planned start). :class:`PlanFollower` is the policy that carries it out in
the executor or online, whatever happened since it was made:

* each robot keeps the plan's order of its tasks (by planned start) and each task its
  planned subteam; at a decision step a ready task starts when every member of its subteam
  is free and the task is next in each member's order: the plan re-timed to what the world
  did (a task late or early moves what follows it, nothing more); with ``"departure":
  "each"`` it is given as soon as it is ready and next in each member's order, busy
  members included, and each member sets out once it is free;
* a task the plan cannot serve any more (new, or its subteam broken: a member lost, or a
  subteam that no longer covers it, found when it is due, or cannot reach it) is planned
  by GRP among the free robots the plan has nothing left for;
* a robot whose next task is not ready waits for it (the plan's voluntary waiting);
  should nothing run and the plan start nothing (the plan's orders cannot go on in this
  state), GRP decides the step over every free robot and ready task, and the tasks it
  starts leave the plan.

A decision costs a pass over the free robots and ready tasks (milliseconds at fleet
scale): this is the node's dispatch. :func:`repair` runs it to the end from a state:
the repaired plan, valid by the executor (Eqs. 8-11 checked at every step).
"""

from __future__ import annotations

import math
from collections import deque

from lvws_ros.core.executor import Decision, SimulationResult, State, TaskStatus, simulate
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.core.subteams import covers
from lvws_ros.policies.baselines import GreedyPayloadPolicy

__all__ = ["PlanFollower", "repair"]

_ASSIGNED = int(TaskStatus.ASSIGNED)  # a plain int: compared for every robot's queue at every decision


class PlanFollower:
    """The policy that carries out a plan (module docstring). ``plan``: assignments by
    task and robot id (a schedule of this instance or of an earlier one: ids, not
    indices, are what survive a change of the cell)."""

    name = "plan"

    def __init__(self, plan: Schedule, grp: GreedyPayloadPolicy | None = None) -> None:
        self.plan = plan
        self.grp = grp if grp is not None else GreedyPayloadPolicy(priority="critical-path")
        self.instance: Instance | None = None
        self.team: dict[int, tuple[int, ...]] = {}  # task index -> planned subteam (robot indices)
        self.start: dict[int, float] = {}  # task index -> planned start
        self.queue: list[deque[int]] = []  # per robot: its planned tasks not started yet, in order
        self.by_plan = self.by_grp = 0  # tasks started as planned; by GRP (new or broken)

    def reset(self, instance: Instance) -> None:
        """Map the plan onto ``instance`` by ids: tasks whose subteam is whole keep it (that
        it still covers the task is checked when it is due); the others are left to GRP."""
        self.instance = instance
        self.grp.reset(instance)
        self.team, self.start, self.by_plan, self.by_grp = {}, {}, 0, 0
        order: list[tuple[float, int]] = []
        tasks, robots = instance.task_index, instance.robot_index
        for a in self.plan.assignments:
            j = tasks.get(a.task)
            team = [robots.get(r) for r in a.robots]
            if j is None or not team or None in team:
                continue
            self.team[j], self.start[j] = tuple(sorted(r for r in team if r is not None)), a.start
            order.append((a.start, j))
        order.sort()
        self.queue = [deque() for _ in instance.robots]
        for _, j in order:
            for r in self.team[j]:
                self.queue[r].append(j)

    def _drop(self, j: int) -> None:
        for r in self.team.pop(j, ()):
            if self.queue[r] and self.queue[r][0] == j:
                self.queue[r].popleft()
            else:
                self.queue[r].remove(j)

    def decide(self, state: State) -> Decision:
        inst = state.instance
        if self.instance is not inst:
            self.reset(inst)
        free = set(state.free_robots())
        ahead = inst.departure == "each"  # a task may be given to busy members: each sets out once free
        for r in range(inst.num_robots) if ahead else free:
            # tasks started (as planned or not) since: out of the orders (a busy robot's when it is free)
            q = self.queue[r]
            while q and state.task_status[q[0]] >= _ASSIGNED:
                self._drop(q[0])
            if q and math.isinf(state.arrival(q[0], [r])):  # a subteam that can no longer get there
                self._drop(q[0])
        ready = state.ready_tasks()
        out: list[tuple[int, tuple[int, ...]]] = []
        planned = sorted((j for j in ready if j in self.team), key=lambda j: (self.start[j], j))
        for j in planned:  # by planned start: a task given here may make a member's next one due too ("each")
            team = self.team[j]
            if all((ahead or r in free) and self.queue[r] and self.queue[r][0] == j for r in team):
                idx = list(team)
                if not covers(inst.robot_amounts[idx], inst.robot_payload[idx], inst.task_needs[j],
                              inst.tasks[j].payload, bool(inst.task_roles[j])):
                    self._drop(j)  # the task changed since the plan: GRP's, below
                    continue
                out.append((j, team))
                free -= set(team)
                self._drop(j)
        given = {j for j, _ in out}
        unplanned = [j for j in ready if j not in self.team and j not in given]
        self.by_plan += len(out)
        idle = sorted(r for r in free if not self.queue[r])  # robots the plan has nothing left for
        if idle and unplanned:
            extra = self.grp.decide_among(state, idle, unplanned)
            out.extend(extra.assignments)
            free -= {r for _, team in extra.assignments for r in team}
            self.by_grp += len(extra.assignments)
        if not out and not (state.task_status == _ASSIGNED).any():
            # The plan's orders cannot go on here: GRP decides the step; what it starts leaves the plan.
            extra = self.grp.decide(state)
            for j, _ in extra.assignments:
                self._drop(j)
            self.by_grp += len(extra.assignments)
            return extra
        return Decision(tuple(out), tuple(sorted(free)))


def repair(state: State, plan: Schedule) -> SimulationResult:
    """``plan`` carried out from ``state`` to the end (:class:`PlanFollower`): the plan
    re-timed to the state, its broken or missing parts planned by GRP; every step checked
    by the executor."""
    return simulate(state.instance, PlanFollower(plan), state=state)
