"""Expert demonstrations, parallel/Ray labelling, a tiny model that learns, and the
learned policies (LVWS, DBGM-style) producing valid schedules."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.matching import greedy_match
from lvws_ros.core.schedule import check_schedule
from lvws_ros.learning.demonstrations import GAMMA, expert_demos, label_instances, label_state
from lvws_ros.learning.gatn import GATN, GATNConfig, reward_matrix
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, DBGMPolicy, LVWSPolicy
from lvws_ros.learning.training import PipelineConfig, TrainConfig, evaluate_loss, run_pipeline
from lvws_ros.policies.exact import ExactPolicy


def greedy_on(r, state):
    inst = state.instance
    free, ready = state.free_robots(), state.ready_tasks()
    if not ready:
        return []
    m = greedy_match(r[np.ix_(free, [*ready, inst.num_tasks])], inst.robot_caps[free], inst.robot_payload[free],
                     inst.task_caps[ready], inst.task_payload[ready])
    return sorted((ready[j], tuple(free[i] for i in t)) for j, t in m.teams.items())


@pytest.mark.parametrize(("key", "index"), [("I", 3), ("I", 9), ("II", 4), ("II", 17)])
def test_expert_reward_matrix_reproduces_the_expert_decision(key, index):
    inst = dataset_instance(DATASETS[key], index, seed=0)
    run = simulate(inst, ExactPolicy(workers=2), record_states=True)
    for step in run.steps:
        e, x = label_state(step.state, run.schedule)
        assert e.shape == x.shape == (inst.num_robots, inst.num_tasks + 1)
        assert np.all((e >= 0) & (e <= GAMMA))
        assert not np.any(e[~x]), "expert rewards only where feasible"
        r = np.where(x, e, -1.0)
        assert greedy_on(r, step.state) == sorted((j, tuple(sorted(t))) for j, t in step.decision.assignments)


@pytest.mark.parametrize(("key", "index"), [("I", 3), ("II", 4), ("IV", 2)])
def test_dense_targets_rank_the_experts_decision_first_and_reach_later_tasks(key, index):
    """Dense targets: the greedy matching on them takes the expert's decision, a robot's
    later tasks that are ready now get targets below its current one, and a robot the
    expert keeps waiting has its idle target above its next task's."""
    inst = dataset_instance(DATASETS[key], index, seed=0)
    run = simulate(inst, ExactPolicy(workers=2), record_states=True)
    later = 0
    for step in run.steps:
        e, x = label_state(step.state, run.schedule, targets="dense")
        eq12, x12 = label_state(step.state, run.schedule)
        np.testing.assert_array_equal(x, x12)
        free, ready = step.state.free_robots(), step.state.ready_tasks()
        read = np.ix_(free, [*ready, inst.num_tasks])  # the entries a decision reads
        assert np.all((e >= 0) & (e <= 1)) and not np.any(e[read][~x[read]])
        r = np.where(x, e, -1.0)
        assert greedy_on(r, step.state) == sorted((j, tuple(sorted(t))) for j, t in step.decision.assignments)
        later += int(((e[:, :-1] > 0) & (eq12[:, :-1] == 0) & x[:, :-1]).sum())
    assert later > 0, "some robot has a later task that is ready now"


def test_parallel_and_ray_labelling_match_serial():
    insts = [dataset_instance(DATASETS["I"], k, seed=0) for k in range(4)]
    # One CP-SAT worker is deterministic; several may return different optima.
    serial = label_instances(insts, processes=1, workers=1, progress=False)
    pooled = label_instances(insts, processes=2, workers=1, progress=False)
    ray_local = label_instances(insts, processes=2, workers=1, ray_address="local", progress=False)
    assert len(serial) == len(pooled) == len(ray_local) > 0
    for a, b, c in zip(serial, pooled, ray_local, strict=True):
        np.testing.assert_array_equal(a.expert, b.expert)
        np.testing.assert_array_equal(a.expert, c.expert)
        np.testing.assert_array_equal(a.mask, c.mask)


def choice_accuracy(model, demos_by_state):
    hits = total = 0
    for state, demo in demos_by_state:
        inst = state.instance
        r = reward_matrix(model, demo.features)  # rows: free robots; columns: ready tasks, idle
        free, ready = state.free_robots(), state.ready_tasks()
        assert list(demo.features.rows) == free and len(demo.features.cols) == len(ready) + 1
        m = greedy_match(r, inst.robot_caps[free], inst.robot_payload[free], inst.task_caps[ready],
                         inst.task_payload[ready])
        got = {i: j for j, team in m.teams.items() for i in team}
        for a in range(len(free)):
            total += 1
            hits += got.get(a, len(ready)) == int(np.argmax(demo.expert[a]))
    return hits / total


def test_tiny_model_learns(tmp_path):
    cfg = PipelineConfig(datasets=("I",), count=40, families=(), validation_per_dataset=8, dagger_rounds=1,
                         dagger_instances=8, dagger_epochs=1, processes=1,
                         train=TrainConfig(epochs=8, batch_size=32, lr=3e-3, seed=0,
                                           model=GATNConfig(hidden=32, mlp_hidden=32)))
    model, meta = run_pipeline(cfg, tmp_path / "tiny.pt", progress=False, log=lambda s: None)
    losses = [h["loss"] for h in meta["stages"][0]["history"]]
    assert losses[-1] < 0.9 * losses[0], losses
    # On held-out states: a lower Eq. 12 loss than an untrained network's, and choices
    # that match the expert's at least as often.
    held_out = [dataset_instance(DATASETS["I"], k, seed=0) for k in range(700, 706)]
    pairs = []
    for inst in held_out:
        run = simulate(inst, ExactPolicy(workers=1), record_states=True)
        pairs += list(zip([s.state for s in run.steps], expert_demos(inst, workers=1), strict=True))
    untrained = []
    for seed in range(3):  # an untrained network's accuracy depends on its draw: their mean
        torch.manual_seed(seed)
        untrained.append(GATN(GATNConfig(hidden=32, mlp_hidden=32)).eval())
    held = [demo for _, demo in pairs]
    assert evaluate_loss(model, held, cfg.train) < 0.9 * evaluate_loss(untrained[0], held, cfg.train)
    assert choice_accuracy(model, pairs) >= np.mean([choice_accuracy(u, pairs) for u in untrained])
    policy = LVWSPolicy(model_path=tmp_path / "tiny.pt")
    assert policy.idle_bias == meta["idle_bias"]
    for inst in held_out:
        assert check_schedule(inst, simulate(inst, policy).schedule) == []


@pytest.mark.parametrize("bias", [0.0, NO_VOLUNTARY_WAIT])
def test_untrained_learned_policies_still_give_valid_schedules(bias):
    torch.manual_seed(1)
    lvws = LVWSPolicy(model=GATN(GATNConfig(hidden=16)), idle_bias=bias)
    dbgm = DBGMPolicy(model=GATN(GATNConfig(hidden=16, use_transformer=False)))
    for seed in range(12):
        rng = np.random.default_rng(seed)
        inst = random_instance(rng, int(rng.integers(1, 9)), int(rng.integers(1, 21)), "u")
        for policy in (lvws, dbgm):
            assert check_schedule(inst, simulate(inst, policy).schedule) == []


def test_rollout_budget_zero_is_lvws_and_no_budget_is_never_worse():
    from lvws_ros.learning.policies import LVWSRolloutPolicy

    torch.manual_seed(2)
    model = GATN(GATNConfig(hidden=16, mlp_hidden=16))
    lvws = LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT)
    for k in range(4):
        inst = dataset_instance(DATASETS["I"], k, seed=3)
        base = simulate(inst, lvws).schedule
        rushed = simulate(inst, LVWSRolloutPolicy(model=model, budget_ms=0.0)).schedule
        assert sorted(map(str, rushed.assignments)) == sorted(map(str, base.assignments))
        full = simulate(inst, LVWSRolloutPolicy(model=model)).schedule
        assert check_schedule(inst, full) == [] and full.makespan <= base.makespan + 1e-9


def test_validation_makespans_are_kept_and_read_back(tmp_path):
    from lvws_ros.learning import training

    val = [random_instance(np.random.default_rng(k), 3, 6, f"v{k}") for k in range(3)]  # proven at once
    first = training.validation_makespans(val, 10.0, 1, tmp_path, lambda s: None)
    assert len(first) == 3 and all(proven for _, proven in first.values())
    [cache] = tmp_path.glob("optima-*.json")
    assert cache.name.startswith("optima-t10-w1-")  # the limit and the workers in the name
    kept = json.loads(cache.read_text())
    for record in kept.values():
        record["makespan"] = 999.0  # marks what is read back rather than solved again
    cache.write_text(json.dumps(kept))
    again = training.validation_makespans(val, 10.0, 1, tmp_path, lambda s: None)
    assert again == {k: (999.0, True) for k in first}
