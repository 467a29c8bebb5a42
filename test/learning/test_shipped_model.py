"""The shipped LVWS and DBGM checkpoints: they load, carry their training metadata, give
valid schedules for any number and order of capabilities, and LVWS stays within stated
suboptimality bounds on small fixed sets: one of Dataset I, and one of each held-out
family (never trained or tuned on).

The fixed sets are generated with data seed 12345 (not the seed-0 data the model was
trained, selected or reported on). The bounds were set from the shipped model's
measured figures on these sets with a margin; a regression past them fails.
"""

from __future__ import annotations

import statistics

import numpy as np
import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.families import HELD_OUT_FAMILIES, family_instance
from lvws_ros.core.schedule import check_schedule
from lvws_ros.learning.checkpoint import DEFAULT_MODELS, load_checkpoint
from lvws_ros.learning.policies import DBGMPolicy, LVWSPolicy
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy
from samples import permuted_caps, plan, with_k

FIXED_SEED = 12345
SHIPPED_BOUND_PERCENT = 10.0  # measured 7.33 % (lvws-gatn/5, 2026-12-02; lvws-gatn/4 7.22 %)
HELD_OUT_BOUND_PERCENT = {"assembly": 12.0, "mspsp": 18.0}  # measured 8.37 and 14.69 % (lvws-gatn/5; GRP 19.85, 28.87 %)


@pytest.mark.parametrize("kind", ["lvws", "dbgm"])
def test_checkpoint_loads_with_its_training_record(kind):
    path = DEFAULT_MODELS[kind]
    assert path.is_file() and path.stat().st_size < 5_000_000
    model, meta = load_checkpoint(path)
    assert meta["kind"] == kind
    assert model.cfg.use_transformer == (kind == "lvws")
    for key in ("datasets", "families", "data_seed", "training_seed", "train_config", "stages", "idle_bias"):
        assert key in meta, key


def test_shipped_policies_give_valid_schedules():
    lvws, dbgm = make_policy("lvws"), make_policy("dbgm")
    assert isinstance(lvws, LVWSPolicy) and isinstance(dbgm, DBGMPolicy)
    for seed in range(15):
        rng = np.random.default_rng([FIXED_SEED, seed])
        inst = random_instance(rng, int(rng.integers(1, 9)), int(rng.integers(1, 25)), f"v{seed}")
        for policy in (lvws, dbgm):
            assert check_schedule(inst, simulate(inst, policy).schedule) == [], (policy.name, inst.name)


def test_shipped_lvws_within_bound_of_the_expert():
    lvws, grp = make_policy("lvws"), make_policy("grp")
    subs, grp_subs = [], []
    for k in range(20):
        inst = dataset_instance(DATASETS["I"], k, seed=FIXED_SEED)
        opt = solve_exact(inst, workers=2, time_limit=60)
        assert opt.status == "optimal" and opt.makespan
        subs.append(100 * (simulate(inst, lvws).schedule.makespan - opt.makespan) / opt.makespan)
        grp_subs.append(100 * (simulate(inst, grp).schedule.makespan - opt.makespan) / opt.makespan)
    mean = statistics.fmean(subs)
    print(f"shipped LVWS on the fixed set: {mean:.2f} % (GRP {statistics.fmean(grp_subs):.2f} %)")
    assert mean <= SHIPPED_BOUND_PERCENT
    assert mean < statistics.fmean(grp_subs)


def test_rollout_is_valid_and_never_worse_than_lvws_or_grp():
    """The rollout keeps LVWS's and GRP's own decisions as candidates and scores each
    candidate by the better of their continuations; both are Markov policies, so the
    rollout can only shorten the schedule of either."""
    lvws, grp, roll = make_policy("lvws"), make_policy("grp"), make_policy("lvws_rollout")
    better = 0
    for k in range(8):
        inst = dataset_instance(DATASETS["II"], k, seed=FIXED_SEED)
        a, g, b = simulate(inst, lvws).schedule, simulate(inst, grp).schedule, simulate(inst, roll).schedule
        assert check_schedule(inst, b) == []
        assert b.makespan <= min(a.makespan, g.makespan) + 1e-9, inst.name
        better += b.makespan < min(a.makespan, g.makespan) - 1e-9
    print(f"rollout shorter than both on {better}/8")


@pytest.mark.parametrize("family", HELD_OUT_FAMILIES)
def test_shipped_lvws_within_bound_of_the_expert_on_held_out_families(family):
    lvws, grp = make_policy("lvws"), make_policy("grp")
    subs, grp_subs = [], []
    for k in range(10):
        inst = family_instance(family, k, seed=FIXED_SEED)
        opt = solve_exact(inst, workers=2, time_limit=60)
        if opt.status != "optimal":
            continue
        subs.append(100 * (simulate(inst, lvws).schedule.makespan - opt.makespan) / opt.makespan)
        grp_subs.append(100 * (simulate(inst, grp).schedule.makespan - opt.makespan) / opt.makespan)
    assert len(subs) >= 8
    mean = statistics.fmean(subs)
    print(f"shipped LVWS on {family} (held out): {mean:.2f} % (GRP {statistics.fmean(grp_subs):.2f} %)")
    assert mean <= HELD_OUT_BOUND_PERCENT[family]
    assert mean < statistics.fmean(grp_subs)


@pytest.mark.parametrize("k", [1, 2, 4, 8, 16])
def test_shipped_lvws_serves_any_number_and_order_of_capabilities(k):
    lvws = make_policy("lvws")
    for index in range(2):
        inst = with_k(family_instance("mixed", index, seed=FIXED_SEED), k, seed=index)
        base = plan(lvws, inst)
        order = np.random.default_rng(index).permutation(k)
        assert plan(lvws, permuted_caps(inst, order)) == base


def test_the_shipped_model_reads_traits_and_the_way_home():
    """The shipped model was trained with the trait families: it reads the way home
    (every pair feature), gives valid schedules on trait instances with and without roles
    and the way home, and on the fixed set of its training family with the way home it
    plans shorter than GRP on average (measured: 9.9 % against GRP's 14.0 % above the best
    known on validation)."""
    from lvws_ros.learning.features import PAIR_FEATURES

    model, meta = load_checkpoint(DEFAULT_MODELS["lvws"])
    assert meta["kind"] == "lvws" and model.cfg.pair_features == PAIR_FEATURES
    assert {"traits", "traits-return"} <= {family for family, _ in meta["families"]}
    lvws, grp = make_policy("lvws"), make_policy("grp")
    ratios = []
    for family in ("traits", "traits-return", "traits-roles"):
        for k in range(6):
            inst = family_instance(family, k, seed=FIXED_SEED)
            sched = simulate(inst, lvws).schedule
            assert check_schedule(inst, sched) == [], inst.name
            if family == "traits-return":
                ratios.append(sched.makespan / simulate(inst, grp).schedule.makespan)
    assert statistics.fmean(ratios) < 1.0, ratios
