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
from lvws_ros.core.subteams import (
    AmountArray,
    CoverPool,
    FloatArray,
    covered,
    covers_alone,
    lightest_cover,
    random_cover,
    whole_numbers,
)
from lvws_ros.errors import PolicyError


class _ReachableSums:
    """What the free robots that can reach each of some tasks add up to (all the free robots
    without travel), kept as robots leave: a task they do not add up to (Eqs. 10-11 on the
    sums) has no covering subteam among them, so it is skipped at once. A mobile robot
    reaches every task, a fixed one only the tasks at its site that do not move it: the sums
    are the mobile robots' plus those of the fixed robots at each task's site, O((robots +
    tasks) K) each time robots leave."""

    def __init__(self, state: State, free: npt.NDArray[np.int64], tasks: npt.NDArray[np.int64]) -> None:
        inst, tr = state.instance, state.instance.travel
        self.need, self.need_payload = inst.task_needs[tasks], inst.task_payload[tasks]
        self.amounts, self.payloads = inst.robot_amounts[free], inst.robot_payload[free]
        self.mobile = np.ones(len(free), dtype=bool)
        self.site = np.zeros(len(free), dtype=np.int64)
        self.meet: npt.NDArray[np.int64] | None = None  # each task's site; -1: a transport (no fixed robot)
        self.sites = 0
        if tr is not None and state.robot_site is not None:
            speeds, meets, ends = tr.arrays
            self.mobile, self.site = speeds[free] > 0, state.robot_site[free]
            self.meet, self.sites = np.where(meets[tasks] == ends[tasks], meets[tasks], len(tr.sites)), len(tr.sites)
        self.ok = self._covered()

    def _covered(self) -> npt.NDArray[np.bool_]:
        amounts, payloads = self.amounts[self.mobile], self.payloads[self.mobile]
        total, pay = amounts.sum(axis=0)[None, :], np.atleast_1d(payloads.sum())
        if self.meet is not None:
            fixed = ~self.mobile
            by_site = np.zeros((self.sites + 1, self.amounts.shape[1]))  # the last row: no site (transports)
            pay_site = np.zeros(self.sites + 1)
            np.add.at(by_site, self.site[fixed], self.amounts[fixed])
            np.add.at(pay_site, self.site[fixed], self.payloads[fixed])
            total, pay = total + by_site[self.meet], pay + pay_site[self.meet]
        return covered(total, pay, self.need, self.need_payload)

    def possible(self, k: int) -> bool:
        """Whether the ``k``-th task may be covered by the free robots left."""
        return bool(self.ok[k])

    def leave(self, rows: list[int]) -> None:
        """The free robots at ``rows`` (of the current free ones) are given a task."""
        self.amounts, self.payloads = np.delete(self.amounts, rows, axis=0), np.delete(self.payloads, rows)
        self.mobile, self.site = np.delete(self.mobile, rows), np.delete(self.site, rows)
        self.ok = self._covered()


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

    def arrivals(self, state: State, free: npt.NDArray[np.int64], tasks: npt.NDArray[np.int64]) -> FloatArray:
        """(len(free), len(tasks)): seconds each free robot needs to reach each task (zeros
        without travel)."""
        return state.arrivals(free, tasks)

    def pick_reachable(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                       arrival: FloatArray, roles: bool = False) -> tuple[int, ...] | None:
        """``pick`` among the robots that can reach the task at all."""
        ok = np.flatnonzero(np.isfinite(arrival))
        team = self.pick(caps[ok], payloads[ok], need_caps, need_payload, roles) if len(ok) else None
        return None if team is None else tuple(int(ok[i]) for i in team)

    def decide(self, state: State) -> Decision:
        return self.decide_among(state, state.free_robots(), state.ready_tasks())

    def pool(self, inst: Instance, free: npt.NDArray[np.int64]) -> CoverPool | None:
        """The free robots as one :class:`CoverPool` for the whole decision, where ``pick``
        is the lightest cover and the pool gives its answers (None: ``pick`` each time)."""
        return None

    def decide_among(self, state: State, robots: list[int], tasks: list[int]) -> Decision:
        """The decision over some of the free ``robots`` and ready ``tasks`` only (the
        others are left as they are: a plan holds them); ``decide`` takes them all."""
        inst = state.instance
        self.traits_from = len(inst.capabilities) if inst.traits else None
        free = np.array(robots, dtype=np.int64)
        order = np.array(self.order(inst, tasks), dtype=np.int64)
        pool = self.pool(inst, free) if inst.travel is None else None
        if pool is not None:
            return self._decide_pooled(inst, free, order, pool)
        out = []
        sums = _ReachableSums(state, free, order)
        for k in np.flatnonzero(sums.ok):  # a task the free robots cannot add up to stays so as they leave
            if not len(free):
                break
            if not sums.possible(int(k)):
                continue
            task = int(order[k])
            if inst.travel is None:  # the paper's choice, untouched
                team = self.pick(inst.robot_amounts[free], inst.robot_payload[free], inst.task_needs[task],
                                 inst.tasks[task].payload, bool(inst.task_roles[task]))
            else:
                team = self.pick_reachable(inst.robot_amounts[free], inst.robot_payload[free], inst.task_needs[task],
                                           inst.tasks[task].payload, self.arrivals(state, free, order[k:k + 1])[:, 0],
                                           bool(inst.task_roles[task]))
            if team is None:
                continue
            out.append((task, tuple(int(free[i]) for i in team)))
            sums.leave(list(team))
            free = np.delete(free, list(team))
        return Decision(tuple(out), tuple(free.tolist()))

    def _decide_pooled(self, inst: Instance, free: npt.NDArray[np.int64], order: npt.NDArray[np.int64],
                       pool: CoverPool) -> Decision:
        """:meth:`decide_among` without travel, the subteams from ``pool`` (a task it does
        not serve: ``pick`` among the robots left); the same decision."""
        out = []
        left = np.ones(len(free), dtype=bool)
        for task in order.tolist():
            if not pool.n:
                break
            need, payload, roles = inst.task_needs[task], inst.tasks[task].payload, bool(inst.task_roles[task])
            if not roles and pool.serves(need, payload):
                team = pool.lightest(need, payload)
            else:
                rows = np.flatnonzero(left)
                picked = self.pick(inst.robot_amounts[free[rows]], inst.robot_payload[free[rows]], need, payload, roles)
                team = None if picked is None else tuple(int(rows[i]) for i in picked)
            if team is None:
                continue
            out.append((task, tuple(int(free[i]) for i in team)))
            pool.remove(team)
            left[list(team)] = False
        return Decision(tuple(out), tuple(free[left].tolist()))


PRIORITIES = ("index", "critical-path")  # the order in which GRP takes the ready tasks


class GreedyPayloadPolicy(_SequentialPolicy):
    name = "grp"

    def __init__(self, seed: int = 0, priority: str = "index", noise: float = 0.0,
                 keys: npt.ArrayLike | None = None) -> None:
        if priority not in PRIORITIES:
            raise PolicyError(f"grp: unknown priority {priority!r}; one of {', '.join(PRIORITIES)}")
        if not noise >= 0:
            raise PolicyError(f"grp: the noise must be >= 0, got {noise}")
        super().__init__(seed)
        self.priority, self.noise = priority, noise
        self.keys = None if keys is None else np.asarray(keys, dtype=np.float64)  # (M,) given priorities
        self._ways_home: tuple[Instance | None, FloatArray | None] = (None, None)

    def order(self, inst: Instance, ready: list[int]) -> list[int]:
        """The ready tasks in the priority's order; with ``noise``, the critical-path keys
        each perturbed by Gaussian noise of ``noise`` mean task durations (randomized list
        schedules, drawn from the policy's seeded generator). With ``keys`` (one per task,
        a list schedule's priorities, e.g. the starts of a schedule justified backwards):
        the smallest key first, the noise on them alike, whatever the priority."""
        if self.keys is not None and ready:
            given = self.keys[ready]
            if self.noise > 0:
                given = given + self.noise * float(inst.durations.mean()) * self.rng.standard_normal(len(ready))
            tasks = np.array(ready)
            return tasks[np.lexsort((tasks, given))].tolist()  # ties: lower index
        if self.priority == "index" or not ready:
            return ready
        keys = inst.critical_tail[ready]
        if self.noise > 0:
            keys = keys + self.noise * float(inst.durations.mean()) * self.rng.standard_normal(len(ready))
        tasks = np.array(ready)
        return tasks[np.lexsort((tasks, -keys))].tolist()  # the longest first (ties: lower index)

    def arrivals(self, state: State, free: npt.NDArray[np.int64], tasks: npt.NDArray[np.int64]) -> FloatArray:
        """Seconds each free robot needs to reach each task; with ``"objective": "return"``,
        in the last wave (every task not started is ready, so a robot's task now may be
        its last), plus its own way home from where the task ends: robots are ranked by
        when they could be back (a heuristic: it ignores the members' latest arrival and
        the tasks still to come)."""
        out = super().arrivals(state, free, tasks)
        inst = state.instance
        if inst.objective != "return" or inst.travel is None or (state.task_status == TaskStatus.QUEUED).any():
            return out
        if self._ways_home[0] is not inst:
            self._ways_home = (inst, inst.travel.ways_home())
        ways = self._ways_home[1]
        assert ways is not None
        return out + ways[np.ix_(free, tasks)]

    def pick_reachable(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray, need_payload: float,
                       arrival: FloatArray, roles: bool = False) -> tuple[int, ...] | None:
        """The lightest subteam among the robots that are there soonest: robots arriving
        within each distinct arrival time in turn, the first that can cover wins. The
        arrival times at which the robots there do not even add up to the needs (Eqs.
        10-11 on their sums, a necessary condition) are skipped at once."""
        limits = np.unique(arrival[np.isfinite(arrival)])
        if not len(limits):
            return None
        by_arrival = np.argsort(arrival, kind="stable")
        there = np.searchsorted(arrival[by_arrival], limits, side="right") - 1  # the last robot within each limit
        enough = covered(np.cumsum(caps[by_arrival], axis=0)[there], np.cumsum(payloads[by_arrival])[there],
                         need_caps, need_payload)
        if not enough.any():
            return None
        for limit in limits[int(np.argmax(enough)):]:
            near = np.flatnonzero(arrival <= limit)
            team = self.pick(caps[near], payloads[near], need_caps, need_payload, roles)
            if team is not None:
                return tuple(int(near[i]) for i in team)
        return None

    def pick(self, caps: AmountArray, payloads: FloatArray, need_caps: AmountArray,
             need_payload: float, roles: bool = False) -> tuple[int, ...] | None:
        return lightest_cover(caps, payloads, need_caps, need_payload, roles, self.traits_from)

    def pool(self, inst: Instance, free: npt.NDArray[np.int64]) -> CoverPool | None:
        if self.traits_from is not None or not len(free) \
                or not whole_numbers(inst.robot_amounts[free], inst.robot_payload[free]):
            return None
        return CoverPool(inst.robot_amounts[free], inst.robot_payload[free])


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
