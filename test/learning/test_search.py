"""Beam search over LVWS (``lvws_beam``): valid by every rule, never worse than LVWS or
GRP, follows its plan, searches again when the world departs from it, falls back to
LVWS when its budget is spent, and stays close to the exact optimum with travel."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import State, check_decision, simulate
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, LVWSPolicy
from lvws_ros.learning.search import DEFAULT_WIDTH, LVWSBeamPolicy
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy


@pytest.fixture(scope="module")
def small_model() -> GATN:
    torch.manual_seed(5)
    return GATN(GATNConfig(hidden=16, mlp_hidden=16))


def _instances():
    yield from (dataset_instance(DATASETS["IV"], k, seed=11) for k in range(4))  # travel
    yield from (dataset_instance(DATASETS["I"], k, seed=11) for k in range(2))
    rng = np.random.default_rng(7)
    yield random_instance(rng, 3, 7, "u")


def test_beam_is_valid_follows_its_plan_and_is_never_worse_than_lvws_or_grp(small_model):
    lvws, grp = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT), GreedyPayloadPolicy()
    beam = LVWSBeamPolicy(model=small_model, width=3)
    for inst in _instances():
        sched = simulate(inst, beam).schedule
        assert check_schedule(inst, sched) == [], inst.name
        assert beam.searches == 1 and beam.fallbacks == 0, inst.name  # the executor follows the plan exactly
        assert sched.makespan == pytest.approx(beam.planned_makespan), inst.name
        a, g = simulate(inst, lvws).schedule.makespan, simulate(inst, grp).schedule.makespan
        assert sched.makespan <= min(a, g) + 1e-9, inst.name


def test_a_spent_budget_gives_lvws_own_schedule_and_says_so(small_model):
    lvws = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    inst = dataset_instance(DATASETS["IV"], 3, seed=11)
    beam = LVWSBeamPolicy(model=small_model, budget_ms=0.0)
    res = simulate(inst, beam)
    assert sorted(map(str, res.schedule.assignments)) == sorted(map(str, simulate(inst, lvws).schedule.assignments))
    assert beam.fallbacks == beam.searches == len(res.steps) and math.isnan(beam.planned_makespan)


def test_the_beam_searches_again_when_the_world_departs_from_its_plan(small_model):
    inst = dataset_instance(DATASETS["IV"], 1, seed=11)
    beam = LVWSBeamPolicy(model=small_model, width=2)
    steps = simulate(inst, LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT), record_states=True).steps
    beam.reset(inst)
    first = steps[0].state
    assert first is not None
    beam.decide(first)
    assert beam.searches == 1
    late = next(s.state for s in steps[1:] if s.state is not None and s.free_robots and s.ready_tasks)
    assert late is not None
    late = late.copy()
    late.time += 0.5  # a step the plan did not expect (the world ran late)
    late.refresh()
    decision = beam.decide(late)
    check_decision(late, decision, beam.name)
    assert beam.searches == 2


def test_finishes_that_stall_do_not_sink_the_search(small_model):
    """Online, a robot can be away with no task (unavailable until later): every finish
    that needs it stalls. The search leaves such finishes out, and with none left LVWS
    decides the step (a fallback), instead of the step raising."""
    inst = Instance("away", ("a", "b"), (Robot("r0", (1, 0), 1.0), Robot("r1", (0, 1), 1.0)),
                    (Task("t0", (1, 0), 1.0, 1.0), Task("t1", (0, 1), 1.0, 1.0)))
    state = State.initial(inst)
    state.robot_free_at[1] = 5.0  # away until t=5, nothing running
    beam, lvws = LVWSBeamPolicy(model=small_model), LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    beam.reset(inst)
    decision = beam.decide(state)
    check_decision(state, decision, beam.name)
    assert decision == lvws.decide(state) and beam.fallbacks == 1


def test_a_beam_narrower_than_one_is_refused(small_model):
    with pytest.raises(PolicyError, match="width"):
        LVWSBeamPolicy(model=small_model, width=0)


BEAM_BOUND_PERCENT = 5.0  # measured 3.32 % (3/8 at the optimum) at the default width, 64, with lvws-gatn/5
# (and lvws-gatn/4) on the first 8 instances; narrower, lvws-gatn/5 is 8.16 % at widths 8-32 (one instance
# 41.9 % above), so the test runs the width that ships. The width-64 search takes 67-145 s on each of the
# first four instances (11-12 tasks) on 2 cores, 3-67 s on the next four (6-9 tasks): the test runs those
# four (measured there: 1.85 %, 2/4 at the optimum).
BEAM_INSTANCES = range(4, 8)


def test_the_shipped_beam_is_within_bound_of_the_proven_optimum_with_travel():
    """Beam search with the shipped model against CP-SAT's proven optima on Dataset IV
    instances of another seed (13: not the reported data, not the validation split)."""
    beam = make_policy("lvws_beam", width=DEFAULT_WIDTH)
    hit, gaps = 0, []
    for k in BEAM_INSTANCES:
        inst = dataset_instance(DATASETS["IV"], k, seed=13)
        opt = solve_exact(inst, workers=2, time_limit=30)
        if opt.status != "optimal" or not opt.makespan:  # not proven in time on a loaded machine: no reference
            continue
        sched = simulate(inst, beam).schedule
        assert check_schedule(inst, sched) == []
        assert sched.makespan >= opt.makespan - 1e-6  # never below a proven optimum
        gaps.append(100 * (sched.makespan - opt.makespan) / opt.makespan)
        hit += sched.makespan <= opt.makespan + 1e-6
    print(f"beam at the optimum on {hit}/{len(gaps)}, mean gap {np.mean(gaps):.2f} %")
    assert len(gaps) >= 3 and np.mean(gaps) <= BEAM_BOUND_PERCENT and hit >= 1

