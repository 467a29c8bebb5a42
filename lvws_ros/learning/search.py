"""Beam search over LVWS (ours, beyond the paper): the ``lvws_beam`` policy.

The one-step rollout (:class:`~lvws_ros.learning.policies.LVWSRolloutPolicy`) commits to
the best candidate of each decision step as LVWS and GRP would finish the schedule from
it. Beam search keeps the ``width`` best partial schedules of each depth instead of one:

* a node is an executor state at a decision step, reached by a path of decisions from
  the state the search started in;
* its children are the rollout's candidates in that state (LVWS's matching, its learned
  waits, GRP's matching, a subteam held back, a robot left out) and each ready task
  started alone by the subteam LVWS's rewards match to it; each child is advanced to its
  next decision step and scored by the makespan LVWS and GRP reach when they finish the
  schedule from it (the better of the two);
* the ``width`` best-scored distinct children of all nodes form the next depth, until
  every path has finished.

Every finish simulated along the way is a complete, valid schedule; the search returns
the shortest (the first found on ties: LVWS's own schedule, then GRP's, are among the
first), as the decisions of every step to its end, and the policy follows them. Without
a budget it is therefore never worse than LVWS or GRP alone on the executor's model
(with one, never worse than LVWS once its own finish fits in the budget). A finish that
cannot complete the schedule (it stalls) is left out of the search. When the world
departs from the plan (a step further from the plan's times than
:data:`~lvws_ros.core.executor.PLAN_DRIFT` allows, other free robots or ready tasks:
online use with failures or late tasks), the policy searches again from the state it is
in; a world only a little early or late (a simulator integrating travel) is followed.

``budget_ms`` (anytime): a search stops when its budget is spent, a finish still running
then is abandoned, and the best schedule found so far is followed; when none was found
the step is LVWS's own decision and the next step searches again. None: no budget.
Cost without a budget: about ``width`` x candidates x 2 simulated finishes per decision
step of the plan (measured figures: ``docs/results.md``).
"""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lvws_ros.core.executor import (
    Decision,
    Policy,
    SimulationResult,
    State,
    advance,
    check_decision,
    decision_deadline,
    final_makespan,
    plan_step_near,
    simulate,
)
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import TOLERANCE
from lvws_ros.errors import PolicyError
from lvws_ros.learning.gatn import GATN
from lvws_ros.learning.policies import LVWSRolloutPolicy, OutOfTime, Until

DEFAULT_WIDTH = 64  # chosen on Dataset IV validation (lvws-gatn/4): 8 3.00 %, 16 2.44 %, 32 2.12 %, 64 1.85 %


@dataclass(frozen=True)
class PlannedStep:
    """One decision step of a plan: when, whom it expects free and ready, and what it decides."""

    time: float
    free: tuple[int, ...]
    ready: tuple[int, ...]
    decision: Decision


def planned_steps(result: SimulationResult) -> list[PlannedStep]:
    """The decision steps of a simulated schedule, as a plan to follow."""
    return [PlannedStep(r.time, r.free_robots, r.ready_tasks, r.decision) for r in result.steps]


def _step(state: State, decision: Decision) -> PlannedStep:
    return PlannedStep(state.time, tuple(state.free_robots()), tuple(state.ready_tasks()), decision)


StateKey = tuple[bytes, bytes, tuple[tuple[int, ...], ...], float]


def _key(s: State) -> StateKey:
    """States reached by different paths that are the same state."""
    return s.task_status.tobytes(), np.nan_to_num(s.task_start, nan=-1.0).tobytes(), tuple(map(tuple, s.task_team)), s.time


class FollowedPlan:
    """The remaining decision steps of a plan a policy follows (``lvws_beam``,
    ``lvws_sample``), and the one rule for whether the world still follows it."""

    def __init__(self) -> None:
        self.steps: deque[PlannedStep] = deque()
        self.instance: Instance | None = None
        self.makespan = math.nan  # of the plan (nan: none)

    def clear(self) -> None:
        self.steps.clear()
        self.instance, self.makespan = None, math.nan

    def replace(self, instance: Instance, steps: list[PlannedStep], makespan: float) -> None:
        self.steps = deque(steps)
        self.instance, self.makespan = instance, makespan

    def follows(self, state: State, policy: str) -> bool:
        """Whether the plan's next step is this state's: steps that start nothing and lie
        behind the world's step are skipped (online, decisions come only when a robot is
        freed or a task gets ready); the step must be the world's step by time
        (:func:`~lvws_ros.core.executor.plan_step_near`: online, the world runs a little
        early or late), expect the same free robots and ready tasks, and still obey Eqs.
        8-11 here."""
        if self.instance is not state.instance:
            return False
        times = [p.time for p in self.steps]
        now = plan_step_near(times, state.time, self.makespan)
        while self.steps and not self.steps[0].decision.assignments and (now is None or self.steps[0].time < now):
            self.steps.popleft()
        if not self.steps:
            return False
        p = self.steps[0]
        if now is None or p.time != now or p.free != tuple(state.free_robots()) or p.ready != tuple(state.ready_tasks()):
            return False
        try:
            check_decision(state, p.decision, policy)
        except PolicyError:  # e.g. a robot the plan sends is at another site than planned
            return False
        return True

    def pop(self) -> Decision:
        return self.steps.popleft().decision


class LVWSBeamPolicy:
    """Beam search over LVWS's candidate decisions (module docstring)."""

    name = "lvws_beam"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 width: int = DEFAULT_WIDTH, budget_ms: float | None = None) -> None:
        if width < 1:
            raise PolicyError(f"lvws_beam: the beam width must be at least 1, got {width}")
        self.rollout = LVWSRolloutPolicy(model=model, model_path=model_path, single_tasks=True)
        self.width, self.budget_ms = width, budget_ms
        self.clock: float | None = None  # when the next decision's budget starts (core.executor.Budgeted)
        self.plan = FollowedPlan()
        self.planned_makespan = math.nan  # of the schedule the latest search found (nan: none)
        self.searches = 0  # searches run since reset (1 when the world followed the plan)
        self.fallbacks = 0  # steps decided by LVWS alone: the budget was spent before any schedule was found

    def reset(self, instance: Instance) -> None:
        self.rollout.reset(instance)
        self.plan.clear()
        self.planned_makespan = math.nan
        self.searches = self.fallbacks = 0

    def decide(self, state: State) -> Decision:
        if not self.plan.follows(state, self.name):
            self.plan.clear()  # a search that raises leaves no stale plan behind
            steps = self.search(state)
            self.plan.replace(state.instance, steps, self.planned_makespan)
            self.searches += 1
            if not steps:
                self.fallbacks += 1
                return self.rollout.base.decide(state)
        return self.plan.pop()

    def _finishes(self, state: State, deadline: float | None) -> Iterator[tuple[float, list[PlannedStep]]]:
        """LVWS's and GRP's finishes from ``state``, each as soon as it is done: (makespan,
        their steps). A finish that cannot complete the schedule (PolicyError: it stalls,
        e.g. online with a robot that is away with no task) is left out; OutOfTime past
        ``deadline``."""
        for pol in (self.rollout.base, self.rollout.grp):
            runner: Policy = pol if deadline is None else Until(pol, deadline)
            try:
                res = simulate(state.instance, runner, state=state, record_states=False)
            except PolicyError:
                continue
            yield float(res.schedule.makespan), planned_steps(res)

    def search(self, state: State) -> list[PlannedStep]:
        """The decisions, from ``state`` to the end, of the shortest schedule the search
        finds (empty if the budget was spent before any)."""
        deadline = decision_deadline(self)
        best, best_plan = math.inf, []
        beam: list[tuple[State, list[PlannedStep]]] = [(state.copy(), [])]
        try:
            while beam:
                children: dict[StateKey, tuple[float, State, list[PlannedStep]]] = {}
                for s, path in beam:
                    for d in self.rollout.candidates(s, deadline):
                        if deadline is not None and time.perf_counter() > deadline:
                            raise OutOfTime
                        child = advance(s, d)
                        if child is None or (key := _key(child)) in children:  # the same state: the same finishes
                            continue
                        here = [*path, _step(s, d)]
                        finishes: Iterator[tuple[float, list[PlannedStep]]]
                        if child.done():
                            finishes = iter([(final_makespan(child), [])])
                        else:
                            finishes = self._finishes(child, deadline)
                        score = math.inf
                        for makespan, rest in finishes:  # the incumbent is kept finish by finish
                            score = min(score, makespan)
                            if makespan < best - TOLERANCE:
                                best, best_plan = makespan, [*here, *rest]
                        if not child.done() and math.isfinite(score):
                            children[key] = (score, child, here)
                ranked = sorted(children.values(), key=lambda c: c[0])  # stable: earlier candidates first on ties
                beam = [(s, path) for _, s, path in ranked[: self.width]]
        except OutOfTime:
            pass
        self.planned_makespan = best if best_plan else math.nan
        return best_plan
