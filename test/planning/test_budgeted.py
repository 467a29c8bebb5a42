"""The ``auto`` policy: never worse than its quick plan (the shortest of GRP's, LVWS's and
GRP's in critical-path order), the quick plan alone with a budget of 0, the proven optimum on a small cell
within a second or two, valid with travel, and replanning when the world departs."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import State, advance, check_decision, simulate
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError
from lvws_ros.planning.budgeted import AutoPolicy
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy


def _instances():
    yield from (dataset_instance(DATASETS["IV"], k, seed=13) for k in range(2))  # travel
    yield from (dataset_instance(DATASETS["I"], k, seed=13) for k in range(2))
    yield random_instance(np.random.default_rng(2), 4, 9, "r")


def _quick(inst):
    return min(simulate(inst, GreedyPayloadPolicy()).schedule.makespan,
               simulate(inst, make_policy("lvws")).schedule.makespan,
               simulate(inst, GreedyPayloadPolicy(priority="critical-path")).schedule.makespan)


def test_auto_is_valid_and_never_worse_than_its_quick_plan():
    for inst in _instances():
        auto = AutoPolicy()
        sched = simulate(inst, auto).schedule
        assert check_schedule(inst, sched) == [], inst.name
        assert sched.makespan <= _quick(inst) + 1e-9, inst.name
        assert auto.plans == 1 and auto.fallbacks == 0, inst.name  # the executor follows the plan
        assert auto.quick_makespan == pytest.approx(_quick(inst))


def test_with_a_budget_of_zero_auto_decides_as_its_quick_plan_does():
    for inst in _instances():
        sched = simulate(inst, AutoPolicy(budget_ms=0.0)).schedule
        assert sched.makespan == pytest.approx(_quick(inst)), inst.name


def test_auto_reaches_the_proven_optimum_of_a_small_cell():
    inst = dataset_instance(DATASETS["I"], 4, seed=13)
    opt = solve_exact(inst, workers=8, time_limit=30)
    assert opt.proven
    auto = AutoPolicy(budget_ms=3000.0)
    sched = simulate(inst, auto).schedule
    assert sched.makespan == pytest.approx(opt.makespan)
    assert auto.proven


def test_auto_plans_again_when_the_world_departs_from_its_plan():
    inst = dataset_instance(DATASETS["IV"], 1, seed=13)
    auto = AutoPolicy()
    steps = simulate(inst, make_policy("lvws"), record_states=True).steps
    auto.reset(inst)
    first = steps[0].state
    assert first is not None
    auto.decide(first)
    late = next(s.state for s in steps[1:] if s.state is not None and s.free_robots and s.ready_tasks).copy()
    late.time += 5.0  # a step the plan did not expect (the world ran late, beyond PLAN_DRIFT)
    late.refresh()
    check_decision(late, auto.decide(late), auto.name)
    assert auto.plans == 2


def test_a_negative_budget_is_refused_and_the_registry_makes_auto():
    with pytest.raises(PolicyError, match="auto"):
        AutoPolicy(budget_ms=-1.0)
    assert isinstance(make_policy("auto", budget_ms=5.0), AutoPolicy)


def test_where_no_quick_plan_fits_the_budget_auto_takes_grp_steps_without_trying_each_time():
    inst = random_instance(np.random.default_rng(5), 30, 120, "big")
    auto = AutoPolicy(budget_ms=0.5, samples=2)  # not even GRP's whole schedule fits half a millisecond
    sched = simulate(inst, auto).schedule
    grp = simulate(inst, GreedyPayloadPolicy()).schedule
    assert check_schedule(inst, sched) == []
    assert sched.makespan <= grp.makespan + 1e-9
    assert auto.fallbacks > 0
    assert auto.plans <= 9  # tried again only when half as many tasks were left (120 -> 60 -> ... -> 1)


def test_after_searches_that_do_not_pay_auto_follows_its_plan_between_fewer_searches():
    """A depot cell of 12 robots x 60 tasks with travel: hundreds of decision steps. After
    SEARCH_PATIENCE searches in a row without a shorter plan, steps are followed without a
    search (1, 2, 4, ... between searches); the run stays valid and never worse than its
    quick plan, and every step with a search still decides within its budget's reach."""
    from lvws_ros.core.families import family_instance
    from lvws_ros.planning.budgeted import SEARCH_PATIENCE

    inst = family_instance("depot", 0, 0, num_robots=12, num_tasks=60)
    auto = AutoPolicy(budget_ms=200.0, workers=1)
    res = simulate(inst, auto)
    assert check_schedule(inst, res.schedule) == []
    assert res.schedule.makespan <= simulate(inst, GreedyPayloadPolicy()).schedule.makespan + 1e-9
    steps = len(res.steps)
    assert steps > 4 * SEARCH_PATIENCE and auto.skipped > 0
    assert auto.skipped < steps  # it searched on some steps


def test_a_budget_spent_before_the_step_costs_that_step_only():
    # The node counts a budget from the message's arrival; if it was spent before the step
    # came to auto (a stale clock), that step is GRP's, and the next one plans again.
    inst = dataset_instance(DATASETS["I"], 0, seed=13)
    auto = AutoPolicy(budget_ms=150.0)
    auto.reset(inst)
    state = State.initial(inst)
    auto.clock = time.perf_counter() - 5.0
    first = auto.decide(state)
    check_decision(state, first, auto.name)
    assert auto.fallbacks == 1 and auto.unplannable == math.inf and auto.clock is None
    auto.reset(inst)
    auto.decide(state)  # counted from now: a quick plan fits
    assert auto.fallbacks == 0 and auto.plans == 1


def test_a_quick_plan_the_budget_cut_is_made_at_the_next_step():
    """The critical-path GRP's finish, slowed past the first step's budget, waits in
    ``retry`` and is made (once) from the next step's state, its plan offered there."""
    from lvws_ros.core.problem import Instance, Robot, Task

    class SlowFirstRun(GreedyPayloadPolicy):
        runs = 0

        def reset(self, instance):
            super().reset(instance)
            self.runs += 1

        def decide(self, state):
            if self.runs == 1:
                time.sleep(0.2)  # past the 300 ms budget over the run's decisions
            return super().decide(state)

    inst = Instance("chain", ("a",), (Robot("r0", (1,), 1.0), Robot("r1", (1,), 1.0)),
                    (Task("x0", (1,), 0.0, 5.0), Task("x1", (1,), 0.0, 5.0), Task("head", (1,), 0.0, 1.0),
                     Task("tail", (1,), 0.0, 10.0, ("head",))))
    auto = AutoPolicy(budget_ms=300.0, exact_tasks=0)  # no proof of optimality, which would end the search
    slow = SlowFirstRun(priority="critical-path")
    auto.quick_plans = (auto.quick_plans[0], auto.quick_plans[1], slow)
    auto.reset(inst)
    state = State.initial(inst)
    nxt = advance(state, auto.decide(state))
    assert auto.retry == [slow] and slow.runs == 1
    assert nxt is not None and auto.plan.follows(nxt, auto.name)
    auto.decide(nxt)
    assert auto.retry == [] and slow.runs == 2  # made once more, from this step's state
    path = simulate(inst, GreedyPayloadPolicy(priority="critical-path"), state=nxt).schedule.makespan
    assert auto.plan.makespan <= path + 1e-9
