"""Travel in the learned policies (issue #15): Dataset IV, the travel pair features, the
matching limited to robots that can reach a task, and models and demonstrations written
before the travel features."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import State, TaskStatus, simulate
from lvws_ros.core.formats import instance_from_dict, instance_key, instance_to_dict
from lvws_ros.core.matching import greedy_match
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import covers
from lvws_ros.errors import ModelError
from lvws_ros.learning.checkpoint import DEFAULT_MODELS, load_checkpoint, read_checkpoint
from lvws_ros.learning.demonstrations import expert_demos, load_demos, save_demos
from lvws_ros.learning.features import LEGACY_PAIR_FEATURES, PAIR_FEATURES, TRAVEL_PAIR_FEATURES, InstanceFeatures
from lvws_ros.learning.gatn import GATN, GATNConfig, decision_outputs
from lvws_ros.learning.policies import DBGMPolicy, LVWSPolicy, LVWSRolloutPolicy

IV = DATASETS["IV"]


def test_dataset_iv_is_feasible_reproducible_and_round_trips():
    for k in (0, 1, 2, 3, 1500, 2100):
        inst = dataset_instance(IV, k, seed=0)
        tr = inst.travel
        assert tr is not None and 3 <= len(tr.sites) <= 5
        assert instance_key(dataset_instance(IV, k, seed=0)) == instance_key(inst)
        again = instance_from_dict(instance_to_dict(inst))
        assert instance_key(again) == instance_key(inst) and again.travel == tr
        for j in range(inst.num_tasks):  # every task covered by the robots that can reach it
            able = [r for r in range(inst.num_robots) if np.isfinite(tr.arrival([r], [tr.robot_site[r]], j))]
            assert covers(inst.robot_caps[able], inst.robot_payload[able], inst.task_caps[j], inst.tasks[j].payload)
        times = [tr.time(r, a, b) for r in range(inst.num_robots) for a in range(len(tr.sites))
                 for b in range(len(tr.sites)) if np.isfinite(tr.time(r, a, b))]
        assert all(float(t).is_integer() for t in times)  # integer travel times: exact proofs


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10**6))
def test_greedy_match_never_uses_a_pair_it_is_not_allowed(seed):
    rng = np.random.default_rng(seed)
    n, m, k = int(rng.integers(1, 6)), int(rng.integers(1, 5)), 3
    caps = rng.random((n, k)) < 0.5
    need = rng.random((m, k)) < 0.4
    need[~need.any(axis=1), 0] = True
    payload, need_payload = rng.integers(1, 6, n).astype(float), rng.integers(0, 8, m).astype(float)
    r = rng.normal(size=(n, m + 1))
    allowed = rng.random((n, m)) < 0.6
    match = greedy_match(r, caps, payload, need, need_payload, allowed)
    for j, team in match.teams.items():
        assert all(allowed[i, j] for i in team)
        assert covers(caps[list(team)], payload[list(team)], need[j], need_payload[j])
    # everything allowed is the matching without the argument
    same = greedy_match(r, caps, payload, need, need_payload, np.ones((n, m), bool))
    assert same == greedy_match(r, caps, payload, need, need_payload)


def test_travel_pair_features_are_arrival_times_and_zero_without_travel():
    inst = dataset_instance(IV, 5, seed=0)
    state = State.initial(inst)
    feats = InstanceFeatures(inst).encode(state)
    assert feats.pairs.shape[-1] == PAIR_FEATURES
    ready = np.flatnonzero(state.task_status == TaskStatus.READY)
    arrive = state.arrivals(feats.rows, ready)
    unit = float(inst.durations.mean())
    expect = np.where(np.isfinite(arrive), (arrive / unit) / (1 + arrive / unit), 1.0)
    assert np.allclose(feats.pairs[:, :-1, 5], expect)
    best = arrive.min(axis=0)
    assert np.allclose(feats.pairs[:, :-1, 6][arrive == best[None, :]], 0.0)  # the earliest robot: 0
    assert np.all(feats.pairs[:, -1, :] == 0)  # the idle column
    plain = dataset_instance(DATASETS["I"], 0, seed=0)
    assert np.all(InstanceFeatures(plain).encode(State.initial(plain)).pairs[..., LEGACY_PAIR_FEATURES:] == 0)


def test_busy_robot_pair_features_see_a_task_that_starts_sooner_by_waiting_for_a_busy_robot():
    """A welder-painter is busy until t = 2 on a task that leaves it at c, 4 s from a; the
    free welder is 10 s from a and the welding arm is fixed at b. Waiting for the busy one
    starts the weld at a at 6 instead of 10: the free welder's feature 7 (later than the
    earliest start) and the column's feature 8 (free robots' start later than the
    earliest) both say 4 s; the free carrier at a, who cannot weld, is not later than the
    earliest start, but its column says wait too. Only the busy robot paints: feature 8 is
    1 (free robots never cover it). A model reading 7 pair features gets zeros there."""
    inst = instance_from_dict({
        "format": "lvws-instance/1", "name": "busy-welder", "capabilities": ["weld", "carry", "paint"],
        "sites": {"a": [0.0, 0.0], "b": [10.0, 0.0], "c": [0.0, 4.0]},
        "robots": [{"id": "near", "capabilities": [1, 0, 1], "payload": 1.0, "site": "a", "speed": 1.0},
                   {"id": "far", "capabilities": [1, 0, 0], "payload": 1.0, "site": "b", "speed": 1.0},
                   {"id": "carrier", "capabilities": [0, 1, 0], "payload": 1.0, "site": "a", "speed": 1.0},
                   {"id": "arm", "capabilities": [1, 0, 0], "payload": 1.0, "site": "b"}],
        "tasks": [{"id": "w1", "capabilities": [1, 0, 0], "payload": 0.0, "duration": 2.0, "after": [], "from": "a",
                   "to": "c"},
                  {"id": "w2", "capabilities": [1, 0, 0], "payload": 0.0, "duration": 4.0, "after": [], "site": "a"},
                  {"id": "p3", "capabilities": [0, 0, 1], "payload": 0.0, "duration": 3.0, "after": [], "site": "a"}]})
    state = State.initial(inst)
    state.start(0, [0])  # "near" does w1 until t = 2 and is then at c
    state.refresh()
    feats = InstanceFeatures(inst).encode(state)
    assert list(feats.rows) == [1, 2, 3] and len(feats.cols) == 3  # w2, p3, then the idle column
    unit = 3.0  # mean duration

    def squash(x: float) -> float:
        return x / (1 + x)

    far, carrier, arm = feats.pairs[0], feats.pairs[1], feats.pairs[2]
    assert far[0, 5] == pytest.approx(squash(10 / unit)) and far[0, 6] == pytest.approx(squash(10 / unit))
    assert far[0, 7] == pytest.approx(squash(4 / unit)) and far[0, 8] == pytest.approx(squash(4 / unit))
    assert carrier[0, 8] == far[0, 8] and carrier[0, 7] == 0.0  # there at once, not later than the earliest start
    assert arm[0, 5] == 1.0 and arm[0, 7] == 1.0  # fixed at b: never at a
    assert np.all(feats.pairs[:, 1, 8] == 1.0)  # p3: only the busy robot paints
    assert np.all(feats.pairs[:, -1] == 0)  # the idle column
    at_start = InstanceFeatures(inst).encode(State.initial(inst)).pairs  # nobody busy: nothing sooner by waiting
    assert np.all(at_start[:, :-1, 8] == 0)
    older = InstanceFeatures(inst, read=TRAVEL_PAIR_FEATURES).encode(state).pairs
    assert np.array_equal(older[..., :TRAVEL_PAIR_FEATURES], feats.pairs[..., :TRAVEL_PAIR_FEATURES])
    assert np.all(older[..., TRAVEL_PAIR_FEATURES:] == 0)


@pytest.mark.parametrize("make", [LVWSPolicy, DBGMPolicy, lambda: LVWSRolloutPolicy(budget_ms=200)])
def test_learned_policies_give_schedules_valid_by_the_travel_rules(make):
    for k in (2000, 2001, 2002, 2003):
        inst = dataset_instance(IV, k, seed=0)
        sched = simulate(inst, make()).schedule
        assert check_schedule(inst, sched) == []
        tr = inst.travel
        for a in sched.assignments:  # nobody on a task it cannot reach (a fixed robot elsewhere)
            j = inst.task_index[a.task]
            assert all(tr.can_do(inst.robot_index[r], j) for r in a.robots)


def test_a_model_written_before_the_travel_features_reads_the_first_five():
    data = read_checkpoint(DEFAULT_MODELS["dbgm"])
    assert "pair_features" not in data["config"]  # written as lvws-gatn/2
    model, _ = load_checkpoint(DEFAULT_MODELS["dbgm"])
    assert model.cfg.pair_features == LEGACY_PAIR_FEATURES
    inst = dataset_instance(IV, 7, seed=0)
    feats = InstanceFeatures(inst).encode(State.initial(inst))
    blind = feats.pairs.copy()
    blind[..., LEGACY_PAIR_FEATURES:] = 0
    a = decision_outputs(model, feats)[0]
    b = decision_outputs(model, replace(feats, pairs=blind))[0]
    assert np.array_equal(a, b)  # the travel columns are not read
    new = GATN(GATNConfig())
    assert new.cfg.pair_features == PAIR_FEATURES and new.psi_p.in_features == PAIR_FEATURES
    with pytest.raises(ValueError, match="pair_features"):
        GATN(GATNConfig(pair_features=PAIR_FEATURES + 1))
    torch.manual_seed(0)
    assert not np.array_equal(decision_outputs(new, feats)[0],
                              decision_outputs(new, replace(feats, pairs=blind))[0])


def test_demonstrations_written_before_the_travel_features_read_with_zero_travel_columns(tmp_path):
    inst = dataset_instance(DATASETS["II"], 3, seed=0)
    demos = expert_demos(inst, time_limit=5, workers=1)
    old = [replace(d, features=replace(d.features, pairs=d.features.pairs[..., :LEGACY_PAIR_FEATURES]))
           for d in demos]
    save_demos(old, tmp_path / "old.npz")
    back, _ = load_demos(tmp_path / "old.npz")
    assert len(back) == len(demos)
    for a, b in zip(back, demos, strict=True):
        assert a.features.pairs.shape == b.features.pairs.shape
        assert np.array_equal(a.features.pairs, b.features.pairs)  # no travel: the columns are zeros
    travel = expert_demos(dataset_instance(IV, 0, seed=0), time_limit=5, workers=1)
    assert any(d.features.pairs[..., LEGACY_PAIR_FEATURES:].any() for d in travel)
    for d in travel:  # X: only robots that can reach a task
        assert d.mask.shape == d.expert.shape
        assert not (d.expert > 0)[~d.mask].any()
    # written by lvws-gatn/3 (no busy-robot columns): padded without travel, refused with it
    for name, group in (("plain", demos), ("travel", travel)):
        save_demos([replace(d, features=replace(d.features, pairs=d.features.pairs[..., :TRAVEL_PAIR_FEATURES]))
                    for d in group], tmp_path / f"{name}3.npz")
    assert all(np.array_equal(a.features.pairs, b.features.pairs)
               for a, b in zip(load_demos(tmp_path / "plain3.npz")[0], demos, strict=True))
    with pytest.raises(ModelError, match=r"travel3\.npz: travel states without the busy-robot pair features"):
        load_demos(tmp_path / "travel3.npz")


def test_fine_tuning_a_model_without_travel_features_teaches_it_to_read_them(tmp_path):
    from lvws_ros.learning.checkpoint import save_checkpoint
    from lvws_ros.learning.training import PipelineConfig, TrainConfig, run_pipeline

    old = GATN(GATNConfig(hidden=16, mlp_hidden=16, pair_features=LEGACY_PAIR_FEATURES))
    save_checkpoint(tmp_path / "old.pt", old, {"kind": "lvws", "idle_bias": 0.0})
    cfg = PipelineConfig(datasets=("IV",), count=6, families=(), validation_per_dataset=2, dagger_rounds=0,
                         processes=1, label_time_limit=2, train=TrainConfig(epochs=1, batch_size=16, seed=0))
    logs: list[str] = []
    model, _ = run_pipeline(cfg, tmp_path / "new.pt", init=tmp_path / "old.pt", progress=False, log=logs.append)
    assert model.cfg.pair_features == PAIR_FEATURES and any("more pair features" in line for line in logs)
    assert load_checkpoint(tmp_path / "new.pt")[0].cfg.pair_features == PAIR_FEATURES


def test_a_checkpoint_asking_for_more_pair_features_than_exist_is_refused(tmp_path):
    from lvws_ros.errors import ModelError
    from lvws_ros.learning.checkpoint import save_checkpoint

    model = GATN(GATNConfig(hidden=16, mlp_hidden=16))
    save_checkpoint(tmp_path / "m.pt", model, {})
    data = torch.load(tmp_path / "m.pt", weights_only=True)
    data["config"]["pair_features"] = PAIR_FEATURES + 2
    torch.save(data, tmp_path / "m.pt")
    with pytest.raises(ModelError, match="does not match the network"):
        load_checkpoint(tmp_path / "m.pt")
