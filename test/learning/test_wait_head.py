"""The wait head (voluntary waiting learned apart from the idle column): its logits in a
batch equal those of one decision, its targets, a loss that teaches it, and an LVWS
policy that uses it and never stalls, even when every robot wants to wait."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.core.datasets import random_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.schedule import check_schedule
from lvws_ros.learning.gatn import GATN, GATNConfig, collate, decision_outputs
from lvws_ros.learning.loss import Demo, batch_tensors, imitation_loss, wait_targets
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, LVWSPolicy, LVWSRolloutPolicy
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from samples import features_at


@pytest.fixture(scope="module")
def model() -> GATN:
    torch.manual_seed(0)
    return GATN(GATNConfig(hidden=32, mlp_hidden=32, wait_head=True)).eval()


def test_batched_wait_logits_equal_one_decision(model):
    graphs = [features_at(s, n, m, step=1) for s, n, m in ((1, 4, 10), (2, 6, 18), (3, 3, 5))]
    with torch.inference_mode():
        _, batched = model.forward_with_wait(collate(graphs))
    assert batched is not None
    one = np.concatenate([decision_outputs(model, g)[1] for g in graphs])  # probabilities
    np.testing.assert_allclose(torch.sigmoid(batched).numpy(), one, rtol=1e-4, atol=1e-5)


def test_without_a_wait_head_there_are_no_wait_outputs():
    net = GATN(GATNConfig(hidden=16, mlp_hidden=16)).eval()
    assert decision_outputs(net, features_at(1, 4, 10))[1] is None


def _demo(expert: np.ndarray, mask: np.ndarray, alone: np.ndarray) -> Demo:
    f = features_at(5, 3, 6, step=0)
    r, c = expert.shape
    pairs = np.zeros((r, c, f.pairs.shape[2]), np.float32)
    pairs[:, :-1, 0] = alone
    return Demo(f.__class__(f.robots, f.tasks, f.edges, f.rows[:r], f.cols[:c], pairs, f.task_ids),
                expert.astype(np.float32), mask.astype(bool))


def test_wait_targets_are_the_voluntary_waits():
    # robot 0 starts task 0; robot 1 waits although it could start task 1 alone (voluntary);
    # robot 2 waits and helps only task 0, started without it (not in the term)
    expert = np.array([[0.9, 0.0, 0.0], [0.0, 0.0, 0.5], [0.0, 0.0, 0.5]])
    mask = np.array([[1, 1, 1], [1, 1, 1], [1, 0, 1]])
    alone = np.array([[1, 1], [0, 1], [0, 0]])
    wait, valid = wait_targets(_demo(expert, mask, alone))
    assert wait.tolist() == [False, True, False]
    assert valid.tolist() == [True, True, False]
    # robot 1 could help task 1 but not alone: its wait is not voluntary by the rule
    wait, valid = wait_targets(_demo(expert, mask, np.array([[1, 1], [0, 0], [0, 0]])))
    assert wait.tolist() == [False, False, False] and valid.tolist() == [True, False, False]


def test_the_wait_term_teaches_the_head():
    torch.manual_seed(1)
    net = GATN(GATNConfig(hidden=16, mlp_hidden=16, wait_head=True))
    expert = np.array([[0.9, 0.0, 0.0], [0.0, 0.0, 0.5], [0.0, 0.0, 0.5]])
    demo = _demo(expert, np.array([[1, 1, 1], [1, 1, 1], [1, 0, 1]]), np.array([[1, 1], [0, 1], [0, 0]]))
    batch, targets = batch_tensors([demo])
    opt = torch.optim.Adam(net.parameters(), lr=1e-2)
    for _ in range(60):
        opt.zero_grad()
        r, w = net.forward_with_wait(batch)
        imitation_loss(r, targets, batch.entry_row, 0.1, 1.0, wait_logits=w, wait_weight=1.0).backward()
        opt.step()
    _, w = net.forward_with_wait(batch)
    assert w is not None and w[1] > 0 > w[0]  # robot 1 waits, robot 0 works


@pytest.mark.parametrize("threshold", [0.0, 0.5, 1.0])
def test_lvws_with_the_wait_head_is_valid_and_never_stalls(model, threshold):
    # threshold 0: every robot wants to wait; the policy must still finish the schedule
    for seed in range(4):
        inst = random_instance(np.random.default_rng(seed), 5, 14, "f")
        policy = LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT, wait_threshold=threshold)
        schedule = simulate(inst, policy).schedule
        assert check_schedule(inst, schedule) == []
    assert LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT).wait_threshold is None  # no checkpoint: off


def test_a_threshold_of_one_is_the_policy_without_the_head(model):
    inst = random_instance(np.random.default_rng(9), 6, 18, "f")
    with_head = simulate(inst, LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT, wait_threshold=1.0)).schedule
    without = simulate(inst, LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT)).schedule
    assert with_head.assignments == without.assignments


def test_the_rollout_proposes_the_heads_waits_and_stays_valid(model):
    inst = random_instance(np.random.default_rng(4), 5, 12, "f")
    rollout = LVWSRolloutPolicy(model=model, budget_ms=None)
    schedule = simulate(inst, rollout).schedule
    assert check_schedule(inst, schedule) == []
    greedy = simulate(inst, GreedyPayloadPolicy()).schedule
    assert schedule.makespan <= greedy.makespan + 1e-9  # GRP's matching is a candidate at every step
