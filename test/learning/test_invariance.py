"""One model for anyone's problem: any number of capabilities, any order of them, any
units. The features (lvws_ros.learning.features) make these hold for every set of
weights, so an untrained network checks them as well as the shipped one (which
test_shipped_model runs too)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from lvws_ros.core.families import family_instance
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.policies import LVWSPolicy
from samples import permuted_caps, plan, scaled, with_k


@pytest.fixture(scope="module")
def policy():
    torch.manual_seed(0)
    return LVWSPolicy(model=GATN(GATNConfig(hidden=32, mlp_hidden=32)), idle_bias=0.0)


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
