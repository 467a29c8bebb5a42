"""The cell simulator's config takes traits (robots' ``traits``, tasks' ``requires``, the
top-level ``traits``): the instance it builds and the snapshots it publishes carry them,
and a run schedules subteams that cover by the trait rule."""

from __future__ import annotations

import pytest
import yaml

from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import ConfigError
from lvws_ros.registry import make_policy
from lvws_ros.ros.resources import case_study_config
from lvws_ros.sim.config import load_cell_config
from lvws_ros.sim.runner import run_offline
from lvws_ros.sim.world import CellSim


def _config(tmp_path, edit=None):
    data = yaml.safe_load(open(case_study_config()).read())
    data["traits"] = ["battery"]
    for r in data["robots"]:
        if r["kind"] != "panda":
            r["traits"] = {"battery": 2 if r["kind"] == "husky" else 1}
    for t in data["tasks"]:
        if t["type"] == "transport":
            t["requires"] = {"battery": 2}  # the husky, or both jackals
    if edit:
        edit(data)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_cell_config(path)


@pytest.mark.parametrize("policy", ["grp", "lvws"])
def test_a_cell_with_traits_runs_and_every_transport_has_battery_two(tmp_path, policy):
    cfg = _config(tmp_path)
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
        CellSim(_config(tmp_path, lambda d: d["tasks"][0].update(requires={"laser": 1})))
    with pytest.raises(ConfigError, match="requires battery"):
        _config(tmp_path, lambda d: d["tasks"][0].update(requires={"battery": "lots"}))
