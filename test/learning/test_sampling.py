"""Sampling over LVWS (``lvws_sample``): one sample without noise is LVWS, the same seed
gives the same schedule, every sampled schedule is valid, the batched forward pass is the
one-graph pass, the result is never longer than LVWS's, and a spent budget falls back."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import State, simulate
from lvws_ros.core.formats import schedule_from_dict, schedule_to_dict
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError
from lvws_ros.learning.features import InstanceFeatures
from lvws_ros.learning.gatn import GATN, GATNConfig, batch_decision_outputs, decision_outputs
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, LVWSPolicy
from lvws_ros.learning.sampling import SAFETY, LVWSSamplePolicy, RoundCost, sample_schedules
from lvws_ros.registry import make_policy


@pytest.fixture(scope="module")
def small_model() -> GATN:
    torch.manual_seed(5)
    return GATN(GATNConfig(hidden=16, mlp_hidden=16))


def _instances():
    yield from (dataset_instance(DATASETS["IV"], k, seed=11) for k in range(3))  # travel
    yield from (dataset_instance(DATASETS["I"], k, seed=11) for k in range(2))
    yield random_instance(np.random.default_rng(7), 3, 7, "u")


class Replay:
    """Takes the given decisions, one per step."""

    name = "replay"

    def __init__(self, decisions):
        self.decisions = iter(decisions)

    def reset(self, instance):
        pass

    def decide(self, state):
        return next(self.decisions)


def _assignments(sched):
    return sorted((a.task, a.robots, round(a.start, 9)) for a in sched.assignments)


def test_one_sample_without_noise_decides_exactly_as_lvws(small_model):
    lvws = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    one = LVWSSamplePolicy(model=small_model, samples=1, temperature=0.0)
    for inst in _instances():
        a, b = simulate(inst, lvws), simulate(inst, one)
        assert [s.decision for s in a.steps] == [s.decision for s in b.steps], inst.name
        assert _assignments(a.schedule) == _assignments(b.schedule), inst.name


def test_the_shipped_checkpoint_sampled_once_without_noise_is_the_shipped_lvws():
    inst = dataset_instance(DATASETS["II"], 3, seed=11)
    a = simulate(inst, make_policy("lvws")).schedule
    b = simulate(inst, make_policy("lvws_sample", samples=1, temperature=0.0)).schedule
    assert _assignments(a) == _assignments(b)


def test_the_same_seed_gives_the_same_schedule_and_another_seed_may_not(small_model):
    inst = dataset_instance(DATASETS["IV"], 2, seed=11)
    runs = [simulate(inst, LVWSSamplePolicy(model=small_model, samples=6, temperature=0.5, seed=s)).schedule
            for s in (3, 3)]
    assert _assignments(runs[0]) == _assignments(runs[1])
    # the noise is the seed's: the sampled schedules themselves differ between seeds
    lvws = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    state = State.initial(inst)
    draws = [[s.makespan for s in sample_schedules(lvws, state, 8, 0.5, np.random.default_rng(seed))]
             for seed in (1, 1, 2)]
    assert draws[0] == draws[1]
    assert [[_step.decision for _step in s.steps] for s in
            sample_schedules(lvws, state, 8, 0.5, np.random.default_rng(1))] != \
        [[_step.decision for _step in s.steps] for s in
         sample_schedules(lvws, state, 8, 0.5, np.random.default_rng(2))]


def test_every_sampled_schedule_is_valid_by_lvws_check(small_model):
    lvws = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    for inst in _instances():
        found = sample_schedules(lvws, State.initial(inst), 12, 1.0, np.random.default_rng(0), record_states=True)
        assert found, inst.name
        for s in found:
            # the sampled decisions, replayed by the executor, give a schedule the checker accepts
            sched = simulate(inst, Replay([p.decision for p in s.steps])).schedule
            sched = schedule_from_dict(schedule_to_dict(sched))  # as `lvws check` reads it
            assert check_schedule(inst, sched) == [], inst.name
            assert sched.makespan == pytest.approx(s.makespan)
            assert s.states is not None and len(s.states) == len(s.steps)


def test_the_batched_forward_pass_is_the_one_graph_pass(small_model):
    inst = dataset_instance(DATASETS["IV"], 0, seed=11)
    states = [st.state for st in simulate(inst, LVWSPolicy(model=small_model), record_states=True).steps
              if st.state is not None and st.free_robots and st.ready_tasks]
    cache = InstanceFeatures(inst)
    other = dataset_instance(DATASETS["I"], 0, seed=11)
    feats = [cache.encode(s) for s in states] + [InstanceFeatures(other).encode(State.initial(other))]
    batched = batch_decision_outputs(small_model, feats)
    for f, (r, _) in zip(feats, batched, strict=True):
        np.testing.assert_allclose(r, decision_outputs(small_model, f)[0], rtol=1e-5, atol=1e-6)


def test_sampling_is_valid_and_never_longer_than_lvws(small_model):
    lvws = LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)
    sample = LVWSSamplePolicy(model=small_model, samples=8, temperature=0.3)
    better = 0
    for inst in _instances():
        sched = simulate(inst, sample).schedule
        assert check_schedule(inst, sched) == [], inst.name
        base = simulate(inst, lvws).schedule.makespan
        assert sched.makespan <= base + 1e-9, inst.name
        better += sched.makespan < base - 1e-9
    assert better >= 1  # the untrained network's greedy schedule is improved somewhere


def test_a_spent_budget_gives_lvws_own_decisions_and_says_so(small_model):
    inst = dataset_instance(DATASETS["IV"], 1, seed=11)
    sample = LVWSSamplePolicy(model=small_model, budget_ms=0.0)
    res = simulate(inst, sample)
    lvws = simulate(inst, LVWSPolicy(model=small_model, idle_bias=NO_VOLUNTARY_WAIT)).schedule
    assert _assignments(res.schedule) == _assignments(lvws)
    assert sample.fallbacks == sample.searches > 0


def test_a_budget_still_gives_valid_schedules(small_model):
    for inst in _instances():
        sched = simulate(inst, LVWSSamplePolicy(model=small_model, budget_ms=20.0, temperature=0.3)).schedule
        assert check_schedule(inst, sched) == [], inst.name


def test_rounds_are_sized_by_what_a_batch_shares():
    cost = RoundCost()
    assert not cost.known and cost.count(10, 0.05, 16) == 16  # nothing timed: the most, cut by the deadline
    cost.add(10, 1, 0.010)  # one schedule alone, 10 tasks to do: 1 ms a task
    assert cost.count(10, 0.05, 16) > int(0.05 / 0.010)  # a batch shares its forward passes: more than one per 10 ms
    assert cost.count(10, 0.005, 16) == 0  # not even one fits
    cost.add(10, 5, 0.030)  # five in lockstep: 3 ms a task, so a = b = 0.5 ms a task
    a, b = cost.coefficients()
    assert a == pytest.approx(0.0005) and b == pytest.approx(0.0005)
    assert SAFETY == 0.8 and cost.count(10, 0.052, 16) == 7  # 0.8 x 52 ms / 10 tasks = 4.16 ms a task: 7.32 of them
    assert cost.count(10, 0.052, 4) == 4  # never more than asked
    assert cost.count(20, 0.052, 16) == 3  # longer schedules, fewer of them: 2.08 ms a task
    zero = RoundCost()
    zero.add(10, 1, 0.0)  # a round too quick for the clock: as many as asked, not an error
    assert zero.count(10, 0.05, 16) == 16


@pytest.mark.parametrize("kwargs", [{"samples": 0}, {"temperature": -1.0}, {"temperature": float("nan")},
                                    {"rounds": 0}])
def test_bad_settings_are_refused(small_model, kwargs):
    with pytest.raises(PolicyError, match="lvws_sample"):
        LVWSSamplePolicy(model=small_model, **kwargs)
