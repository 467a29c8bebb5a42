"""The cell simulator's config takes traits (robots' ``traits``, tasks' ``requires``, the
top-level ``traits``): the instance it builds and the snapshots it publishes carry them,
and a run schedules subteams that cover by the trait rule."""

from __future__ import annotations

import pytest

from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import ConfigError, WorldEventRejected
from lvws_ros.registry import make_policy
from lvws_ros.sim.runner import run_offline
from lvws_ros.sim.world import CellSim
from samples import trait_cell_config


@pytest.mark.parametrize("policy", ["grp", "lvws"])
def test_a_cell_with_traits_runs_and_every_transport_has_battery_two(tmp_path, policy):
    cfg = trait_cell_config(tmp_path)
    sim = CellSim(cfg)
    assert sim.inst.traits == ("battery",)
    team, graph = sim.team_snapshot(), sim.graph_snapshot()
    assert team.trait_names == ("battery",) and graph.trait_names == ("battery",)
    assert {r.id: r.traits for r in team.robots}["husky_1"] == (2.0,)
    sched, _ = run_offline(sim, make_policy(policy))
    assert check_schedule(sim.executed_instance(), sched) == []  # by the durations the world took
    for a in sched.assignments:
        if a.task in ("t04", "t05", "t06", "t10", "t11", "t12"):
            assert "husky_1" in a.robots or {"jackal_1", "jackal_2"} <= set(a.robots), (a.task, a.robots)


def test_a_trait_the_cell_does_not_name_is_refused(tmp_path):
    with pytest.raises(Exception, match="unknown trait 'laser'"):
        CellSim(trait_cell_config(tmp_path, lambda d: d["tasks"][0].update(requires={"laser": 1})))
    with pytest.raises(ConfigError, match="requires battery"):
        trait_cell_config(tmp_path, lambda d: d["tasks"][0].update(requires={"battery": "lots"}))


def test_a_task_submitted_at_run_time_carries_its_traits(tmp_path):
    sim = CellSim(trait_cell_config(tmp_path))
    sim.submit([{"id": "t20", "type": "transport", "object": "obj3", "from": "cell_3", "to": "cell_1",
                 "after": ["t14"], "requires": {"battery": 3}}])
    inst = sim.inst
    j = inst.task_index["t20"]
    assert dict(inst.tasks[j].requires) == {"battery": 3.0}
    with pytest.raises(WorldEventRejected, match="task t21: unknown trait 'laser'"):
        sim.submit([{"id": "t21", "type": "assembly", "object": "obj1", "cell": "cell_3", "duration": 1.0,
                     "after": ["t14"], "requires": {"laser": 1}}])


def test_a_submitted_task_the_team_can_never_cover_is_refused_and_the_world_is_unchanged(tmp_path):
    sim = CellSim(trait_cell_config(tmp_path))
    tasks, status = sim.cfg.tasks, dict(sim.status)
    with pytest.raises(WorldEventRejected, match="task 't20' can never be covered: needs battery 100"):
        sim.submit([{"id": "t20", "type": "transport", "object": "obj3", "from": "cell_3", "to": "cell_1",
                     "after": ["t14"], "requires": {"battery": 100}}])
    assert sim.cfg.tasks == tasks and sim.status == status and "t20" not in sim.inst.task_index
