"""The held-out warehouse family: orders of four stages chained at their stations, fixed
arms, AMRs that lift together, scanners, a dock, the way home; every task coverable by the
robots that can reach it; seeded."""

from __future__ import annotations

import numpy as np
import pytest

from lvws_ros.core.families import FAMILIES, HELD_OUT_FAMILIES, TRAVEL_FAMILIES, family_instance
from lvws_ros.core.formats import instance_from_dict, instance_to_dict
from lvws_ros.core.subteams import covers


def test_the_warehouse_is_held_out_and_stays_out_of_the_papers_tables():
    fam = FAMILIES["warehouse"]
    assert fam.held_out and fam.travel and fam.traits
    assert "warehouse" not in HELD_OUT_FAMILIES and "warehouse" not in TRAVEL_FAMILIES


@pytest.mark.parametrize("k", range(6))
def test_orders_are_chains_of_four_stages_every_task_coverable_by_who_can_reach_it(k):
    inst = family_instance("warehouse", k, 0, num_robots=40, num_tasks=100)
    assert inst.objective == "return" and set(inst.traits) == {"arm", "lift", "scanner"}
    assert inst.num_tasks == 100 and inst.num_robots == 40
    tr = inst.travel
    assert tr is not None
    reach = np.isfinite(tr.arrivals(np.arange(inst.num_robots), np.array(tr.robot_site), np.arange(inst.num_tasks)))
    for j, task in enumerate(inst.tasks):
        order, stage = task.id.split("-")
        assert stage in ("pick", "carry", "kit", "inspect")
        if stage != "pick":
            previous = {"carry": "pick", "kit": "carry", "inspect": "kit"}[stage]
            assert f"{order}-{previous}" in task.after
        able = reach[:, j]
        assert covers(inst.robot_amounts[able], inst.robot_payload[able], inst.task_needs[j], task.payload), task.id
        arms = [r for r in np.flatnonzero(able) if inst.robots[r].id.startswith("arm")]
        assert bool(arms) == (stage in ("pick", "kit"))  # arms are fixed: only at their station
    heavy = [t for t in inst.tasks if t.id.endswith("carry") and dict(t.requires)["lift"] > 2]
    assert heavy, "some totes need two or three AMRs"


def test_the_warehouse_is_seeded_and_round_trips_through_the_format():
    a, b = (family_instance("warehouse", 3, 7, num_robots=30, num_tasks=80) for _ in range(2))
    assert instance_to_dict(a) == instance_to_dict(b)
    assert instance_to_dict(instance_from_dict(instance_to_dict(a))) == instance_to_dict(a)
    with pytest.raises(ValueError, match="at least 4 robots"):
        family_instance("warehouse", 0, 0, num_robots=3, num_tasks=8)
