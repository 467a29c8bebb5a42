"""GATN (Eqs. 1-6, model lvws-gatn/2) and the imitation loss (Eq. 12): shapes, the idle
column, permutation equivariance, the sparse GAT equal to the dense one, batches that do
not leak, and a loss that goes down."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.learning.features import GraphFeatures
from lvws_ros.learning.gatn import GATN, GATLayer, GATNConfig, SparseGATLayer, collate, reward_matrix
from lvws_ros.learning.loss import Demo, batch_tensors, imitation_loss
from samples import features_at


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return GATN(GATNConfig(hidden=32, mlp_hidden=32)).eval()


@pytest.mark.parametrize(("n", "m"), [(1, 1), (1, 5), (4, 1), (6, 18), (8, 20)])
def test_rewards_for_the_free_robots_by_the_ready_tasks_and_idle(model, n, m):
    feats = features_at(n * 100 + m, n, m, step=0)
    r = reward_matrix(model, feats)
    assert r.shape == (len(feats.rows), len(feats.cols)) == (n, r.shape[1])
    assert feats.cols[-1] == len(feats.tasks) - 1  # the idle task, last
    assert np.all(np.isfinite(r))


def test_permutation_equivariance(model):
    f = features_at(7, 6, 12, step=2)
    n, t = f.robots.shape[0], f.tasks.shape[0] - 1
    rng = np.random.default_rng(0)
    pr, pt = rng.permutation(n), np.append(rng.permutation(t), t)  # the idle task stays last
    inv_r, inv_t = np.argsort(pr), np.argsort(pt)
    pc = rng.permutation(len(f.cols) - 1)
    cols = np.append(f.cols[:-1][pc], f.cols[-1])
    pair_cols = np.append(pc, len(f.cols) - 1)
    permuted = GraphFeatures(f.robots[pr], f.tasks[pt], inv_t[f.edges], inv_r[f.rows], inv_t[cols],
                             f.pairs[:, pair_cols], f.task_ids[pt[:-1]])
    np.testing.assert_allclose(reward_matrix(model, permuted), reward_matrix(model, f)[:, pair_cols],
                               rtol=1e-4, atol=1e-5)


def test_the_sparse_gat_is_the_dense_gat_on_the_same_graph():
    torch.manual_seed(3)
    dense, sparse = GATLayer(16, 16, 4), SparseGATLayer(16, 16, 4)
    sparse.load_state_dict(dense.state_dict())
    t = 12
    gen = np.random.default_rng(4)
    adj = np.triu(gen.random((t, t)) < 0.3, k=1)
    h = torch.randn(t, 16)
    edges = torch.from_numpy(np.array(np.nonzero(adj), dtype=np.int64))
    with torch.no_grad():
        want = dense(h[None], torch.from_numpy(adj)[None], torch.ones(1, t, dtype=torch.bool))[0]
        got = sparse(h, edges)
    torch.testing.assert_close(got, want, rtol=1e-5, atol=1e-5)


def test_rewards_depend_on_the_state(model):
    a, b = features_at(3, 5, 10, step=0), features_at(3, 5, 10, step=3)
    assert reward_matrix(model, a).shape != reward_matrix(model, b).shape or \
        not np.allclose(reward_matrix(model, a), reward_matrix(model, b))


def test_a_batch_of_graphs_gives_each_graph_its_own_rewards(model):
    graphs = [features_at(1, 3, 4), features_at(2, 7, 15), features_at(3, 5, 9)]
    with torch.inference_mode():
        batched = model(collate(graphs)).numpy()
    start = 0
    for g in graphs:
        size = len(g.rows) * len(g.cols)
        np.testing.assert_allclose(batched[start:start + size].reshape(len(g.rows), len(g.cols)),
                                   reward_matrix(model, g), rtol=1e-4, atol=1e-5)
        start += size


def test_dbgm_variant_has_no_global_context():
    torch.manual_seed(0)
    net = GATN(GATNConfig(hidden=32, mlp_hidden=32, use_transformer=False)).eval()
    assert len(net.robot_encoder.globals) == 0 and len(net.task_encoder.globals) == 0
    f = features_at(5, 4, 6, step=0)
    assert reward_matrix(net, f).shape == (4, len(f.cols))


def test_a_few_training_steps_reduce_the_eq12_loss():
    torch.manual_seed(0)
    net = GATN(GATNConfig(hidden=32, mlp_hidden=32))
    graphs = [features_at(s, 3 + s % 4, 6 + s, step=s % 3) for s in range(6)]
    gen = np.random.default_rng(1)
    demos = []
    for g in graphs:
        x = gen.random((len(g.rows), len(g.cols))) < 0.5
        x[:, -1] = True
        demos.append(Demo(g, np.where(x, gen.random(x.shape), 0.0).astype(np.float32), x))
    batch, targets = batch_tensors(demos)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    losses = []
    for _ in range(60):
        opt.zero_grad()
        loss = imitation_loss(net(batch), targets, batch.entry_row, lam=0.1, choice_weight=1.0)
        loss.backward()
        opt.step()
        losses.append(loss.item())
    assert losses[-1] < 0.8 * losses[0], (losses[0], losses[-1])


@pytest.mark.parametrize("scale", [1.0, 10.0, 60.0])
def test_the_complete_graph_in_n_log_n_is_the_dense_gat(scale):
    """At inference a complete robot graph (no adjacency, every node real) takes the
    sorted prefix-sum form of Eqs. 1-2; it gives the dense rows' values up to float
    rounding, also with large logits (no overflow) and tied scores, with 1 and 2 nodes."""
    torch.manual_seed(3)
    layer = GATLayer(16, 16, 4)
    with torch.no_grad():
        layer.a_src.mul_(scale)
        layer.a_dst.mul_(scale)
    for n in (1, 2, 7, 300):
        h = torch.randn(2, n, 16) * 2
        h[:, n // 2:] = h[:, :1]  # many equal scores
        mask = torch.ones(2, n, dtype=torch.bool)
        with torch.no_grad():
            layer.train()
            dense = layer(h, None, mask)
            layer.eval()
            fast = layer(h, None, mask)
        assert torch.isfinite(fast).all()
        assert torch.allclose(fast, dense, rtol=1e-4, atol=1e-5 * float(dense.abs().max())), (scale, n)
