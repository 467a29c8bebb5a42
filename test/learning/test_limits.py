"""The learned policies have no size limit of their own (sparse task graph, reward
entries in bounded chunks: see docs/scale.md for 1,000 robots x 5,000 tasks); a team far
past the old dense limit schedules; and huge but legal numbers never make the learned
policies stall."""

from __future__ import annotations

import copy

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
