"""The learned policies' one size limit is documented, tested and reported: an instance
too large for the dense network is refused with a PolicyError (the CLI: exit 2), never
a MemoryError; and huge but legal numbers never make the learned policies stall."""

from __future__ import annotations

import copy

import pytest

from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict
from lvws_ros.core.problem import MAX_VALUE, Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError
from lvws_ros.learning.features import DENSE_MEMORY_LIMIT
from lvws_ros.registry import make_policy
from samples import BASE


@pytest.mark.parametrize("name", ["lvws", "dbgm"])
def test_an_instance_too_large_for_the_dense_network_is_refused_clearly(name):
    m = 20_000
    inst = Instance("big", ("a",), (Robot("r0", (1,), 1.0),),
                    tuple(Task(f"t{j}", (1,), 1.0, 1.0, (f"t{j - 1}",) if j else ()) for j in range(m)))
    with pytest.raises(PolicyError, match=rf"1 robots x {m} tasks need about \d+ GiB.*limit {DENSE_MEMORY_LIMIT // 2**30} GiB"):
        simulate(inst, make_policy(name))


@pytest.mark.parametrize("name", ["lvws", "dbgm", "lvws_rollout"])
def test_the_largest_legal_numbers_give_valid_schedules(name):
    doc = copy.deepcopy(BASE)
    for r in doc["robots"]:
        r["payload"] = MAX_VALUE
    for t in doc["tasks"]:
        t["duration"] = t["payload"] = MAX_VALUE
    inst = instance_from_dict(doc)
    sched = simulate(inst, make_policy(name)).schedule
    assert check_schedule(inst, sched) == []
