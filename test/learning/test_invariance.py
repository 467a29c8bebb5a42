"""One model for anyone's problem: any number of capabilities, any order of them, any
units. The features (lvws_ros.learning.features) make these hold for every set of
weights, so an untrained network checks them as well as the shipped one (which
test_shipped_model runs too)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.core.executor import simulate
from lvws_ros.core.families import family_instance
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.policies import LVWSPolicy


@pytest.fixture(scope="module")
def policy():
    torch.manual_seed(0)
    return LVWSPolicy(model=GATN(GATNConfig(hidden=32, mlp_hidden=32)), idle_bias=0.0)


def with_k(inst: Instance, k: int, seed: int) -> Instance:
    """``inst`` with K = k capabilities drawn anew (every task coverable)."""
    rng = np.random.default_rng(seed)
    rc = rng.random((inst.num_robots, k)) < 0.5
    rc[np.arange(inst.num_robots), rng.integers(k, size=inst.num_robots)] = True
    robots = tuple(Robot(r.id, tuple(int(c) for c in rc[i]), r.payload) for i, r in enumerate(inst.robots))
    held = np.flatnonzero(rc.any(axis=0))
    tasks = []
    for t in inst.tasks:
        caps = np.zeros(k, dtype=int)
        caps[rng.choice(held, size=min(len(held), int(rng.integers(1, 3))), replace=False)] = 1
        tasks.append(Task(t.id, tuple(int(c) for c in caps), t.payload, t.duration, t.after))
    return Instance(f"{inst.name}-k{k}", tuple(f"c{c}" for c in range(k)), robots, tuple(tasks))


def permuted_caps(inst: Instance, order: np.ndarray) -> Instance:
    return Instance(inst.name, tuple(inst.capabilities[c] for c in order),
                    tuple(Robot(r.id, tuple(r.capabilities[c] for c in order), r.payload) for r in inst.robots),
                    tuple(Task(t.id, tuple(t.capabilities[c] for c in order), t.payload, t.duration, t.after)
                          for t in inst.tasks))


def scaled(inst: Instance, payload: float = 1.0, duration: float = 1.0) -> Instance:
    return Instance(inst.name, inst.capabilities,
                    tuple(Robot(r.id, r.capabilities, r.payload * payload) for r in inst.robots),
                    tuple(Task(t.id, t.capabilities, t.payload * payload, t.duration * duration, t.after)
                          for t in inst.tasks))


def plan(policy, inst):
    sched = simulate(inst, policy).schedule
    assert check_schedule(inst, sched) == []
    return sorted((a.task, a.start, tuple(sorted(a.robots))) for a in sched.assignments)


@pytest.mark.parametrize("k", [1, 2, 4, 8, 16])
def test_any_number_of_capabilities_gives_valid_schedules(policy, k):
    for index in range(3):
        plan(policy, with_k(family_instance("mixed", index, seed=5), k, seed=index))


@pytest.mark.parametrize("k", [3, 8])
def test_permuting_capability_columns_gives_the_same_schedule(policy, k):
    inst = with_k(family_instance("mixed", 7, seed=5), k, seed=1)
    order = np.random.default_rng(2).permutation(k)
    assert plan(policy, permuted_caps(inst, order)) == plan(policy, inst)


@pytest.mark.parametrize("family", ["assembly", "mspsp"])
def test_scaling_payloads_or_durations_gives_the_same_decisions(policy, family):
    inst = family_instance(family, 3, seed=5)
    base = plan(policy, inst)
    assert plan(policy, scaled(inst, payload=8.0)) == base
    slow = plan(policy, scaled(inst, duration=4.0))
    assert [(t, r) for t, _, r in slow] == [(t, r) for t, _, r in base]
    np.testing.assert_allclose([s for _, s, _ in slow], [4.0 * s for _, s, _ in base], rtol=1e-9)
