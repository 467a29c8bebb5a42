"""LVWS with the exact matching of Eqs. 7-11 on R (CP-SAT) instead of the paper's greedy:
valid schedules with and without travel, and each decision's Eq. 7 reward at least the
greedy matching's on the same R."""

from __future__ import annotations

import pytest
import torch

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import TaskStatus, simulate
from lvws_ros.core.matching import match_reward
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.policies import LVWSPolicy, _idle_last, reachable
from lvws_ros.registry import make_policy


@pytest.fixture(scope="module")
def small_model() -> GATN:
    torch.manual_seed(3)
    return GATN(GATNConfig(hidden=16, mlp_hidden=16))


def _first_pass(policy, state, r):
    inst, ready, free = state.instance, state.ready_tasks(), state.free_robots()
    return policy._match(r.copy(), inst.robot_amounts[free], inst.robot_payload[free], inst.task_needs[ready],
                         inst.task_payload[ready], reachable(state, free, ready), inst.task_roles[ready])


def _reward(state, r, decision):
    free, ready = state.free_robots(), state.ready_tasks()
    teams = {ready.index(j): tuple(free.index(i) for i in team) for j, team in decision.assignments}
    return match_reward(r, teams, tuple(free.index(i) for i in decision.waiting))


@pytest.mark.parametrize(("key", "index"), [("I", 2), ("IV", 4), ("IV", 7)])
def test_exact_matching_gives_valid_schedules_and_at_least_the_greedy_reward(small_model, key, index):
    inst = dataset_instance(DATASETS[key], index, seed=5)
    exact = LVWSPolicy(model=small_model, idle_bias=0.0, matching="exact")
    greedy = LVWSPolicy(model=small_model, idle_bias=0.0)
    run = simulate(inst, exact, record_states=True)
    assert check_schedule(inst, run.schedule) == []
    for step in run.steps:
        state = step.state
        assert state is not None
        if not state.free_robots() or not state.ready_tasks():
            continue
        r = exact.rewards(state)
        matched = r  # the R the exact matching's decision maximised
        if not _first_pass(exact, state, r).teams and not (state.task_status == TaskStatus.ASSIGNED).any():
            matched = r.copy()  # all waiting would stall: matched again with the idle task last
            _idle_last(matched)
        by_greedy = greedy.match(state, r)
        assert _reward(state, matched, step.decision) >= _reward(state, matched, by_greedy) - 1e-5


def test_the_registry_makes_lvws_with_either_matching_and_refuses_another():
    assert make_policy("lvws", matching="exact").matching == "exact"
    assert make_policy("lvws").matching == "greedy"
    with pytest.raises(PolicyError, match="unknown matching"):
        LVWSPolicy(model=GATN(GATNConfig(hidden=8, mlp_hidden=8)), matching="hungarian")
