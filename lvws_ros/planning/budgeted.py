"""The ``auto`` policy within a budget per decision (``--budget-ms``): the best schedule it
can find within each decision step's budget (the whole-run planner is :mod:`lvws_ros.planning.auto`).

A user should not need to know which policy suits which cell. At a decision step with no
plan to follow, ``auto``

1. makes the quick plans: GRP's, LVWS's and GRP's with the ready tasks taken longest
   path to the end first (``priority="critical-path"``) whole schedules from the state
   (each a finish, under the budget, in that order), and takes the shortest; a GRP plan
   the budget cut is made at the next step's search, from the state then (once);
2. improves it while the budget lasts: CP-SAT from the state, warm-started from the
   incumbent (for a cell of at most ``exact_tasks`` tasks still to do; a proof of
   optimality ends the search for the run) or, for a bigger cell (with travel too),
   large-neighbourhood search on the plan (:mod:`~lvws_ros.policies.lns`), then LVWS sampling
   (only where LVWS's own quick plan finished within the budget: a sample costs as much)
   (:func:`~lvws_ros.learning.sampling.sample_schedules`) in rounds sized to the time left
   (:class:`~lvws_ros.learning.sampling.RoundCost`);
3. follows the best plan (:class:`~lvws_ros.learning.search.FollowedPlan`, with the drift
   rule of :data:`~lvws_ros.core.executor.PLAN_DRIFT`); when the world departs from it (a
   task late or early, a robot lost or back, tasks added or cancelled), it plans again
   from the state it is in, the rest of the old plan no longer valid.

While it follows a plan not proven optimal, each later step spends its budget on the
same improvement from its own state, replacing the plan only by a shorter one: a plan
never gets worse. After SEARCH_PATIENCE searches in a row that did not shorten the plan,
it follows the plan without searching for 1, then 2, 4, ... steps between searches
(until a search shortens it, or the plan is made afresh): a run of thousands of decision
steps (fleet scale with travel) costs a few dozen budgets, not one per step. With a
budget of 0 it decides as its quick plan does; when not even a quick plan finishes
within the budget (fleet scale), it takes GRP's decision for the step and counts it in
``fallbacks``, and takes GRP's decisions at once (no quick plan tried) until half as
many tasks are left, when it tries again: at fleet scale a run costs GRP's time and a
few budgets, and is never longer than GRP's schedule (a quick plan found later holds
GRP's own finish). With a budget of 0 the quick plans are made however long they take,
and nothing more. Each step's compute stays within the budget plus at most one decision
of LVWS or GRP and CP-SAT's overshoot of its time limit.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np

from lvws_ros.core.executor import (
    Decision,
    Policy,
    SimulationResult,
    State,
    decision_deadline,
    schedule_from_state,
    simulate,
)
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.core.subteams import TOLERANCE
from lvws_ros.errors import ExpertError, PolicyError
from lvws_ros.learning.policies import OutOfTime, Until
from lvws_ros.learning.sampling import (
    DEFAULT_SAMPLES,
    DEFAULT_TEMPERATURE,
    LVWSSamplePolicy,
    RoundCost,
    sample_schedules,
)
from lvws_ros.learning.search import FollowedPlan, PlannedStep, planned_steps
from lvws_ros.policies.baselines import GreedyPayloadPolicy

DEFAULT_BUDGET_MS = 1000.0
EXACT_TASKS = 60  # CP-SAT improves plans of cells with at most this many tasks still to do
EXACT_SHARE = 0.6  # of the time left that CP-SAT may take (the rest: sampling)
FOLLOW_SECONDS_PER_TASK = 0.003  # first guess of the time to turn an LNS schedule into steps, per task to do
SEARCH_PATIENCE = 8  # searches in a row without a shorter plan before steps between searches are skipped

__all__ = ["DEFAULT_BUDGET_MS", "EXACT_TASKS", "SEARCH_PATIENCE", "AutoPolicy"]


class AutoPolicy:
    """The best plan found within ``budget_ms`` per decision step (module docstring)."""

    name = "auto"

    def __init__(self, model_path: str | Path | None = None, budget_ms: float = DEFAULT_BUDGET_MS, seed: int = 0,
                 exact_tasks: int = EXACT_TASKS, samples: int = DEFAULT_SAMPLES,
                 temperature: float = DEFAULT_TEMPERATURE, workers: int = 8) -> None:
        if not math.isfinite(budget_ms) or budget_ms < 0:
            raise PolicyError(f"auto: the budget must be a finite number of ms >= 0, got {budget_ms}")
        self.sampler = LVWSSamplePolicy(model_path=model_path, samples=samples, temperature=temperature, seed=seed)
        self.grp = GreedyPayloadPolicy()
        self.quick_plans = (self.grp, self.sampler.base, GreedyPayloadPolicy(priority="critical-path"))
        self.retry: list[Policy] = []  # GRP plans the budget cut, made at the next search
        self.budget_ms, self.exact_tasks, self.workers, self.seed = budget_ms, exact_tasks, workers, seed
        self.clock: float | None = None  # when the next decision's budget starts (core.executor.Budgeted)
        self.plan = FollowedPlan()
        self.proven = False  # the plan followed is a proven optimum (nothing left to improve)
        self.quick_makespan = math.nan  # of the latest quick plan
        self.rng = np.random.default_rng(seed)
        self.plans = self.fallbacks = 0  # plans made afresh; steps decided by GRP alone (no plan in the budget)
        self.improved = {"quick": 0, "exact": 0, "lns": 0, "sample": 0}  # times each improver shortened the plan
        self.unplannable = math.inf  # more tasks to do than this: no quick plan is tried (none fitted the budget)
        self.follow_per_task = FOLLOW_SECONDS_PER_TASK  # turning an LNS schedule into steps (measured)
        self.lns_windows = 0  # neighbourhoods the large-neighbourhood search solved
        self.sampling_fits = True  # LVWS's quick plan finished within the budget (else neither would a sample)
        self.round_cost = RoundCost()  # what sampling rounds cost (measured; sizes them to the time left)
        self._schedule: Schedule | None = None  # the plan's whole schedule (CP-SAT's warm start)
        self.unimproved = 0  # searches in a row that did not shorten the plan
        self.skip = 0  # steps left to follow the plan without searching
        self.skipped = 0  # steps followed without a search (after SEARCH_PATIENCE unimproved ones)

    def reset(self, instance: Instance) -> None:
        self.sampler.reset(instance)
        self.sampler.base.decide(State.initial(instance))  # the network's first pass (slow) before any budget
        self.grp.reset(instance)
        self.plan.clear()
        self.proven = False
        self.quick_makespan = math.nan
        self.rng = np.random.default_rng(self.seed)
        self.plans = self.fallbacks = 0
        self.improved = {"quick": 0, "exact": 0, "lns": 0, "sample": 0}
        self.unplannable = math.inf
        self.retry = []
        self.sampling_fits = True
        self.round_cost = RoundCost()
        self.lns_windows = 0
        self.unimproved = self.skip = self.skipped = 0

    @property
    def planned_makespan(self) -> float:
        return self.plan.makespan

    def _finish(self, policy: Policy, state: State, deadline: float | None,
                cut: list[Policy] | None = None) -> SimulationResult | None:
        """``policy``'s whole schedule from ``state`` (None when it stalls or the deadline
        passes; then, when ``cut`` is given, ``policy`` is appended to it if the deadline cut it)."""
        try:
            return simulate(state.instance, policy if deadline is None else Until(policy, deadline), state=state)
        except OutOfTime:
            if cut is not None:
                cut.append(policy)
            return None
        except PolicyError:
            return None

    def _offer_run(self, state: State, res: SimulationResult) -> bool:
        return self._offer(state, float(res.schedule.makespan), planned_steps(res), lambda: res.schedule)

    def _offer(self, state: State, makespan: float, steps: list[PlannedStep],
               schedule: Callable[[], Schedule]) -> bool:
        """Follow ``steps`` from ``state`` when shorter than the plan (True then);
        ``schedule`` makes the plan's whole schedule (CP-SAT's warm start), only then."""
        if steps and makespan < (self.plan.makespan if self.plan.steps else math.inf) - TOLERANCE:
            self.plan.replace(state.instance, steps, makespan)
            self._schedule = schedule()
            return True
        return False

    def _exact(self, state: State, deadline: float) -> None:
        """CP-SAT from ``state``, warm-started from the plan, within the time left."""
        from lvws_ros.policies.exact import ExactPolicy, proves_executor_bound

        todo = len(state.tasks_to_do())
        left = deadline - time.perf_counter()
        if left <= 0.01:
            return
        if todo > self.exact_tasks:
            self._lns(state, todo, deadline)
            return
        hint = self._schedule if self.plan.steps else None  # warm start: the plan followed
        expert = ExactPolicy(time_limit=left * EXACT_SHARE, workers=self.workers, seed=self.seed, hint=hint)
        try:
            res = simulate(state.instance, expert, state=state)
        except (ExpertError, PolicyError):
            return
        if expert.result is None:
            return
        if self._offer_run(state, res):
            self.improved["exact"] += 1
        if expert.result.proven and proves_executor_bound(state.instance, expert.result) \
                and abs(float(res.schedule.makespan) - self.plan.makespan) <= TOLERANCE:
            self.proven = True  # optimal for the executor's model too: nothing left to improve

    def _lns(self, state: State, todo: int, deadline: float) -> None:
        """Large-neighbourhood search on the plan from ``state`` (cells too big for CP-SAT's
        whole model), followed when shorter. Time is kept back for turning
        an improved schedule into steps (measured per task to do), all within ``deadline``."""
        from lvws_ros.policies.exact import ExactPolicy, ExpertResult
        from lvws_ros.policies.lns import improve

        left = deadline - time.perf_counter()
        seconds = left * EXACT_SHARE - self.follow_per_task * todo
        if self._schedule is None or not self.plan.steps or seconds <= 0.05:
            return
        try:
            found = improve(state.instance, self._schedule, state=state, time_limit=seconds, workers=1,
                            seed=self.seed + state.step)
        except ExpertError:
            return
        self.lns_windows += found.rounds
        if not found.improved:
            return
        follower = ExactPolicy(time_limit=0.1, workers=1, seed=self.seed)
        follower.follow(ExpertResult(found.schedule, "feasible", found.schedule.makespan, math.nan, found.seconds,
                                     False), state)
        t0 = time.perf_counter()
        res = self._finish(follower, state, deadline)
        if res is not None:
            self.follow_per_task = (time.perf_counter() - t0) / max(1, todo)
            if self._offer_run(state, res):
                self.improved["lns"] += 1
        else:  # the steps did not fit: keep more time back next time
            self.follow_per_task *= 2

    def decide(self, state: State) -> Decision:
        deadline = decision_deadline(self)
        assert deadline is not None  # auto always has a budget (0: its quick plan alone)
        late = time.perf_counter() >= deadline  # the budget was spent before the step came here
        following = self.plan.follows(state, self.name)
        if following and self.proven:
            return self.plan.pop()
        if following and self.skip > 0:  # the search has not paid lately: follow without one
            self.skip -= 1
            self.skipped += 1
            return self.plan.pop()
        todo = len(state.tasks_to_do())
        if not following:
            self.plan.clear()
            self.proven = False
            self.unimproved = self.skip = 0
            if todo > self.unplannable:  # no quick plan fitted the budget at this size: GRP's step at once
                self.fallbacks += 1
                return self.grp.decide(state)
            self.plans += 1
            limit = None if self.budget_ms == 0 else deadline  # budget 0: the quick plan alone, however long
            self.retry = []
            for policy in self.quick_plans:
                t0 = time.perf_counter()
                lvws = policy is self.sampler.base
                res = self._finish(policy, state, limit, None if lvws else self.retry)  # a GRP plan cut: made later
                if lvws:
                    if res is not None:  # a schedule alone: a sampling round of one costs as much
                        self.round_cost.add(todo, 1, time.perf_counter() - t0)
                    self.sampling_fits = res is not None
                if res is not None:
                    self._offer_run(state, res)
            self.quick_makespan = self.plan.makespan if self.plan.steps else math.nan
            if not self.plan.steps and not late:
                self.unplannable = todo // 2  # try again when half as many tasks are left
        before = self.plan.makespan if self.plan.steps else math.inf
        while following and self.retry and time.perf_counter() < deadline:  # a GRP plan the budget cut, once
            res = self._finish(self.retry.pop(0), state, deadline)
            if res is not None and self._offer_run(state, res):
                self.improved["quick"] += 1
        if time.perf_counter() < deadline:
            self._exact(state, deadline)
        while not self.proven and self.sampling_fits and self.sampler.temperature > 0 \
                and (t0 := time.perf_counter()) < deadline:
            count = self.round_cost.count(todo, deadline - t0, self.sampler.samples)  # rounds sized to the time left
            if not count:  # not even one schedule would finish in time
                break
            found = sample_schedules(self.sampler.base, state, count, self.sampler.temperature, self.rng,
                                     deadline=deadline)
            if time.perf_counter() <= deadline:  # a round that ended in time: what it cost
                self.round_cost.add(todo, count, time.perf_counter() - t0)
            for s in found:
                final = s.final
                if self._offer(state, s.makespan, s.steps, partial(schedule_from_state, final, self.name)):
                    self.improved["sample"] += 1
        if not self.plan.steps:
            self.fallbacks += 1
            return self.grp.decide(state)
        if following:  # a search on a plan it already had: did it pay?
            self.unimproved = 0 if self.plan.makespan < before - TOLERANCE else self.unimproved + 1
            if self.unimproved >= SEARCH_PATIENCE:
                self.skip = 2 ** (self.unimproved - SEARCH_PATIENCE)
        return self.plan.pop()
