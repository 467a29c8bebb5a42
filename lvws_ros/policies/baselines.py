"""Baseline scheduling policies of the LVWS paper, section IV.

* ``rand``: for each ready task (random order) a random capable single free robot; a
  random minimal subteam only when no single robot can do the task.
* ``rand_subteam``: a random choice among all minimal covering robots and subteams.
* ``grp``: the robot or subteam with the smallest total payload that meets the task's
  requirements (ties: fewer robots, then lower robot indices), the ready tasks taken in
  index order (the paper's). With ``priority="critical-path"`` (ours, beyond the paper;
  one of ``auto``'s quick plans) the ready tasks are taken longest path to the end first
  (the task's duration plus its longest chain of successors,
  :attr:`~lvws_ros.core.problem.Instance.critical_tail`; ties: lower index), the
  classic priority rule of list scheduling: the tasks that hold up the most work start
  first.

All are work-conserving: they start every ready task for which free robots suffice.
With travel (the travel extension of formats.md), a robot that can never reach a task (a
fixed robot elsewhere) is never picked for it, and GRP takes the subteam that can be
there first (the smallest arrival of its slowest member), the lightest among those;
without travel every arrival is 0 and the choices are the paper's. With ``"objective":
"return"`` (formats.md), in the last wave of tasks GRP counts each robot's way home from
where the task ends into its arrival (robots that could be back sooner first).
Subteams are inclusion-minimal (a superset only ties up more robots, the duration
being the same) and built constructively (:mod:`lvws_ros.core.subteams`), never by
enumerating subsets: any team size, polynomial time.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from lvws_ros.core.executor import Decision, State, TaskStatus
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import AmountArray, FloatArray, covered, covers_alone, lightest_cover, random_cover
from lvws_ros.errors import PolicyError


class _SequentialPolicy:
    """Takes ready tasks one by one and gives each a subteam of the free robots chosen
    by ``pick`` (None: no subteam of them covers the task)."""

    name = "sequential"

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.traits_from: int | None = None  # the first column of additive traits (None: the paper's model)

    def reset(self, instance: Instance) -> None:
        self.rng = np.random.default_rng(self.seed)

    def order(self, inst: Instance, ready: list[int]) -> list[int]:
        return ready

    def pick(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
             need_payload: float, roles: bool = False) -> tuple[int, ...] | None:
        raise NotImplementedError

    def arrivals(self, state: State, free: npt.NDArray[np.int64], task: int) -> FloatArray:
        """Seconds each free robot needs to reach ``task`` (zeros without travel)."""
        return state.arrivals(free, [task])[:, 0]

    def pick_reachable(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                       arrival: FloatArray, roles: bool = False) -> tuple[int, ...] | None:
        """``pick`` among the robots that can reach the task at all."""
        ok = np.flatnonzero(np.isfinite(arrival))
        team = self.pick(caps[ok], payloads[ok], need_caps, need_payload, roles) if len(ok) else None
        return None if team is None else tuple(int(ok[i]) for i in team)

    def decide(self, state: State) -> Decision:
        return self.decide_among(state, state.free_robots(), state.ready_tasks())

    def decide_among(self, state: State, robots: list[int], tasks: list[int]) -> Decision:
        """The decision over some of the free ``robots`` and ready ``tasks`` only (the
        others are left as they are: a plan holds them); ``decide`` takes them all."""
        inst = state.instance
        self.traits_from = len(inst.capabilities) if inst.traits else None
        free = np.array(robots, dtype=np.int64)
        order = np.array(self.order(inst, tasks), dtype=np.int64)
        out = []
        # tasks the free robots together can cover, all at once (a subset covers no more)
        possible = covered(inst.robot_amounts[free].sum(axis=0), inst.robot_payload[free].sum(),
                           inst.task_needs[order], inst.task_payload[order])
        for k, task in enumerate(order):
            if not len(free):
                break
            if not possible[k]:
                continue
            if inst.travel is None:  # the paper's choice, untouched
                team = self.pick(inst.robot_amounts[free], inst.robot_payload[free], inst.task_needs[task],
                                 inst.tasks[task].payload, bool(inst.task_roles[task]))
            else:
                team = self.pick_reachable(inst.robot_amounts[free], inst.robot_payload[free], inst.task_needs[task],
                                           inst.tasks[task].payload, self.arrivals(state, free, int(task)),
                                           bool(inst.task_roles[task]))
            if team is None:
                continue
            out.append((int(task), tuple(int(free[i]) for i in team)))
            free = np.delete(free, list(team))
            rest = order[k + 1:]
            possible[k + 1:] = covered(inst.robot_amounts[free].sum(axis=0), inst.robot_payload[free].sum(),
                                       inst.task_needs[rest], inst.task_payload[rest])
        return Decision(tuple(out), tuple(free.tolist()))


PRIORITIES = ("index", "critical-path")  # the order in which GRP takes the ready tasks


class GreedyPayloadPolicy(_SequentialPolicy):
    name = "grp"

    def __init__(self, seed: int = 0, priority: str = "index") -> None:
        if priority not in PRIORITIES:
            raise PolicyError(f"grp: unknown priority {priority!r}; one of {', '.join(PRIORITIES)}")
        super().__init__(seed)
        self.priority = priority
        self._ways_home: tuple[Instance | None, FloatArray | None] = (None, None)

    def order(self, inst: Instance, ready: list[int]) -> list[int]:
        if self.priority == "index":
            return ready
        tail = inst.critical_tail
        return sorted(ready, key=lambda j: (-float(tail[j]), j))

    def arrivals(self, state: State, free: npt.NDArray[np.int64], task: int) -> FloatArray:
        """Seconds each free robot needs to reach ``task``; with ``"objective": "return"``,
        in the last wave (every task not started is ready, so a robot's task now may be
        its last), plus its own way home from where the task ends: robots are ranked by
        when they could be back (a heuristic: it ignores the members' latest arrival and
        the tasks still to come)."""
        out = super().arrivals(state, free, task)
        inst = state.instance
        if inst.objective != "return" or inst.travel is None or (state.task_status == TaskStatus.QUEUED).any():
            return out
        if self._ways_home[0] is not inst:
            self._ways_home = (inst, inst.travel.ways_home())
        ways = self._ways_home[1]
        assert ways is not None
        return out + ways[free, task]

    def pick_reachable(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                       arrival: FloatArray, roles: bool = False) -> tuple[int, ...] | None:
        """The lightest subteam among the robots that are there soonest: robots arriving
        within each distinct arrival time in turn, the first that can cover wins."""
        for limit in np.unique(arrival[np.isfinite(arrival)]):
            near = np.flatnonzero(arrival <= limit)
            team = self.pick(caps[near], payloads[near], need_caps, need_payload, roles)
            if team is not None:
                return tuple(int(near[i]) for i in team)
        return None

    def pick(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
             need_payload: float, roles: bool = False) -> tuple[int, ...] | None:
        return lightest_cover(caps, payloads, need_caps, need_payload, roles, self.traits_from)


class RandomPolicy(_SequentialPolicy):
    name = "rand"

    def order(self, inst: Instance, ready: list[int]) -> list[int]:
        return [ready[i] for i in self.rng.permutation(len(ready))]

    def pick(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
             need_payload: float, roles: bool = False) -> tuple[int, ...] | None:
        alone = np.flatnonzero(covers_alone(caps, payloads, need_caps[None, :], need_payload, roles))
        if len(alone):
            return (int(alone[int(self.rng.integers(len(alone)))]),)
        return random_cover(caps, payloads, need_caps, need_payload, self.rng, roles)


class RandomSubteamPolicy(RandomPolicy):
    name = "rand_subteam"

    def pick(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
             need_payload: float, roles: bool = False) -> tuple[int, ...] | None:
        return random_cover(caps, payloads, need_caps, need_payload, self.rng, roles)
