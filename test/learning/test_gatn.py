"""GATN (Eqs. 1-6) and the imitation loss (Eq. 12): shapes, the idle column,
permutation equivariance, padding that does not leak, and a loss that goes down."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.core.datasets import random_instance
from lvws_ros.core.executor import simulate
from lvws_ros.learning.features import GraphFeatures, encode_state
from lvws_ros.learning.gatn import GATN, GATNConfig, collate, reward_matrix
from lvws_ros.learning.loss import imitation_loss
from lvws_ros.policies.baselines import GreedyPayloadPolicy


def features_at(seed: int, n: int, m: int, step: int = 1) -> GraphFeatures:
    inst = random_instance(np.random.default_rng(seed), n, m, "f")
    run = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = run.steps[min(step, len(run.steps) - 1)].state
    assert state is not None
    return encode_state(state)


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return GATN(GATNConfig(hidden=32, mlp_hidden=32)).eval()


@pytest.mark.parametrize(("n", "m"), [(1, 1), (1, 5), (4, 1), (6, 18), (8, 20)])
def test_any_size_gives_n_by_m_plus_idle(model, n, m):
    feats = features_at(n * 100 + m, n, m)
    r = reward_matrix(model, feats)
    assert r.shape == (n, m + 1)
    assert np.all(np.isfinite(r))


def test_permutation_equivariance(model):
    feats = features_at(7, 6, 12, step=2)
    n, m = feats.robots.shape[0], feats.tasks.shape[0] - 1
    rng = np.random.default_rng(0)
    pr = rng.permutation(n)
    pt = np.append(rng.permutation(m), m)  # the idle task stays last
    permuted = GraphFeatures(feats.robots[pr], feats.tasks[pt], feats.task_adjacency[np.ix_(pt, pt)],
                             feats.pairs[np.ix_(pr, pt)])
    r = reward_matrix(model, feats)
    rp = reward_matrix(model, permuted)
    np.testing.assert_allclose(rp, r[np.ix_(pr, pt)], rtol=1e-4, atol=1e-5)


def test_rewards_depend_on_the_state(model):
    a, b = features_at(3, 5, 10, step=0), features_at(3, 5, 10, step=3)
    assert not np.allclose(reward_matrix(model, a), reward_matrix(model, b))


def test_padding_does_not_leak(model):
    graphs = [features_at(1, 3, 4), features_at(2, 7, 15), features_at(3, 5, 9)]
    with torch.inference_mode():
        batched = model(collate(graphs))
    for k, g in enumerate(graphs):
        n, m1 = g.robots.shape[0], g.tasks.shape[0]
        np.testing.assert_allclose(batched[k, :n, :m1].numpy(), reward_matrix(model, g), rtol=1e-4, atol=1e-5)


def test_dbgm_variant_has_no_global_context():
    torch.manual_seed(0)
    net = GATN(GATNConfig(hidden=32, mlp_hidden=32, use_transformer=False)).eval()
    assert len(net.robot_encoder.transformers) == 0
    assert reward_matrix(net, features_at(5, 4, 6)).shape == (4, 7)


def test_a_few_training_steps_reduce_the_eq12_loss():
    torch.manual_seed(0)
    net = GATN(GATNConfig(hidden=32, mlp_hidden=32))
    graphs = [features_at(s, 3 + s % 4, 6 + s, step=s % 3) for s in range(6)]
    batch = collate(graphs)
    valid = batch.reward_mask()
    gen = torch.Generator().manual_seed(1)
    x = (torch.rand(valid.shape, generator=gen) < 0.5) & valid
    e = torch.where(x, torch.rand(valid.shape, generator=gen), torch.zeros(valid.shape))
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss = imitation_loss(net(batch), e, x.float(), valid.float(), lam=0.1)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.8 * losses[0], (losses[0], losses[-1])
