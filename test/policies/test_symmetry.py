"""Symmetry: identical robots are interchangeable, so the order in which a file lists
them must not change the quality of any policy's schedule (GRP and LVWS break ties by
index; the exact expert's pool model does not see the order at all)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from twins import twin_instances

from lvws_ros.core.executor import simulate
from lvws_ros.core.importers import import_psplib
from lvws_ros.core.pools import pools
from lvws_ros.core.schedule import check_schedule
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy

PSPLIB = Path(__file__).resolve().parents[2] / "examples" / "psplib"


def permuted(inst, seed):
    """``inst`` with the robots of each pool in a seeded random order (ids travel with them)."""
    rng = np.random.default_rng(seed)
    order = list(range(inst.num_robots))
    while order == list(range(inst.num_robots)):  # not the order it had
        for pool in pools(inst):
            for a, b in zip(pool.robots, rng.permutation(pool.robots), strict=True):
                order[a] = int(b)
    return replace(inst, robots=tuple(inst.robots[k] for k in order))


CASES = [*twin_instances(4), *twin_instances(4, roles=True), import_psplib(PSPLIB / "j301_1.sm")]


@pytest.mark.parametrize("policy", ["grp", "lvws", "rand_subteam"])
def test_permuting_identical_robots_leaves_the_makespan(policy):
    for inst in CASES:
        base = simulate(inst, make_policy(policy, seed=0)).schedule.makespan
        for seed in range(3):
            other = permuted(inst, seed)
            run = simulate(other, make_policy(policy, seed=0)).schedule
            assert check_schedule(other, run) == []
            assert run.makespan == pytest.approx(base), (inst.name, seed)


def test_permuting_identical_robots_leaves_the_exact_optimum():
    for inst in CASES[:3]:
        for formulation in ("auto", "pool"):
            base = solve_exact(inst, workers=2, time_limit=30, formulation=formulation)
            other = solve_exact(permuted(inst, 0), workers=2, time_limit=30, formulation=formulation)
            assert base.proven and other.proven
            assert other.makespan == pytest.approx(base.makespan)
