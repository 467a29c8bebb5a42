"""The learned policies have no size limit of their own (sparse task graph, reward
entries in bounded chunks: see docs/scale.md for 1,000 robots x 5,000 tasks); a task set far
past the old dense limit schedules; the chunks change no reward; and huge but legal numbers
never make the learned policies stall."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict
from lvws_ros.core.problem import MAX_VALUE, Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.registry import make_policy
from samples import BASE


@pytest.mark.parametrize("name", ["lvws", "dbgm"])
def test_wide_instances_past_the_old_dense_limit_schedule(name):
    m = 16_000  # the first model refused more than about 14,000 tasks
    n = 250  # a layer of tasks per robot at each step: 64 steps (the matching's work grows with robots squared)
    inst = Instance("wide", ("a",), tuple(Robot(f"r{i}", (1,), 1.0) for i in range(n)),
                    tuple(Task(f"t{j}", (1,), 1.0, 1.0, (f"t{j - n}",) if j >= n else ()) for j in range(m)))
    sched = simulate(inst, make_policy(name)).schedule
    assert check_schedule(inst, sched) == [] and sched.makespan == m // n


def test_the_rewards_in_small_chunks_equal_the_rewards_in_one(monkeypatch):
    # The fleet-scale chunks (robot attention rows, reward entries; the network DBGM shares)
    # split a decision's tensors, not its arithmetic: tiny chunks give the rewards and wait
    # logits of one chunk.
    from lvws_ros.core.executor import State
    from lvws_ros.core.families import family_instance
    from lvws_ros.learning import gatn

    inst = family_instance("depot", 0, seed=3, num_robots=40, num_tasks=80)
    policy = make_policy("lvws")
    state = State.initial(inst)
    whole_r, whole_wait = policy.outputs(state)
    assert whole_r.shape[0] > 7 and whole_r.size > 64  # several chunks below
    monkeypatch.setattr(gatn, "ROW_CHUNK", 7)
    monkeypatch.setattr(gatn, "ENTRY_CHUNK", 64)
    r, wait = policy.outputs(state)
    np.testing.assert_allclose(r, whole_r, rtol=1e-5, atol=1e-5)
    assert (wait is None) == (whole_wait is None)
    if wait is not None:
        np.testing.assert_allclose(wait, whole_wait, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize("name", ["lvws", "dbgm", "lvws_rollout", "lvws_beam"])
def test_the_largest_legal_numbers_give_valid_schedules(name):
    doc = copy.deepcopy(BASE)
    for r in doc["robots"]:
        r["payload"] = MAX_VALUE
    for t in doc["tasks"]:
        t["duration"] = t["payload"] = MAX_VALUE
    inst = instance_from_dict(doc)
    sched = simulate(inst, make_policy(name)).schedule
    assert check_schedule(inst, sched) == []
