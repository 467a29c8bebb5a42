"""Lower bounds on the makespan: never above a proven optimum (Datasets I, II and IV,
with travel), tight where the instance says so, and printed with every schedule."""

from __future__ import annotations

import json

import pytest

from conftest import REPO
from lvws_ros.cli.main import main
from lvws_ros.core.bounds import gap, lower_bounds
from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.policies.exact import solve_exact


@pytest.mark.parametrize(("key", "count"), [("I", 4), ("II", 4), ("IV", 8)])
def test_the_bound_never_exceeds_a_proven_optimum(key, count):
    for k in range(count):
        inst = dataset_instance(DATASETS[key], k, seed=3)
        res = solve_exact(inst, workers=8, time_limit=10)
        b = lower_bounds(inst)
        assert res.makespan is not None
        if res.proven:
            assert b.best <= res.makespan + 1e-9, inst.name
        assert b.critical_path >= float(inst.critical_tail.max()) - 1e-9  # at least the durations' chain
        assert b.best <= simulate(inst, GreedyPayloadPolicy()).schedule.makespan + 1e-9


def test_workload_and_critical_path_are_what_the_instance_forces():
    # two tasks needing capability a, one holder: they run one after the other (workload 7);
    # a chain of 2 + 3 needs 5 at least (critical path)
    inst = Instance("w", ("a", "b"), (Robot("r0", (1, 0), 1.0), Robot("r1", (0, 1), 1.0)),
                    (Task("t0", (1, 0), 0.0, 4.0), Task("t1", (1, 0), 0.0, 3.0), Task("t2", (0, 1), 0.0, 2.0),
                     Task("t3", (0, 1), 0.0, 3.0, ("t2",))))
    b = lower_bounds(inst)
    assert b.workload == pytest.approx(7.0) and b.critical_path == pytest.approx(5.0) and b.best == 7.0
    assert solve_exact(inst, workers=2).makespan == pytest.approx(7.0)
    assert gap(10.0, 7.0) == pytest.approx(0.3) and gap(7.0, 7.0) == 0.0


def test_the_bound_with_travel_counts_the_way_to_the_first_task_by_the_shortest_route():
    # r0 starts at a; the task is at c, 10 m away directly but 2 m via b (a detour the
    # robot may take through another task's site): the bound counts 2 m at 1 m/s, not 10
    data = {"format": "lvws-instance/1", "name": "route", "capabilities": ["x"],
            "sites": {"a": [0, 0], "b": [1, 0], "c": [2, 0]}, "distances": {"a": {"c": 10.0}},
            "robots": [{"id": "r0", "capabilities": [1], "payload": 1, "site": "a", "speed": 1.0}],
            "tasks": [{"id": "t", "capabilities": [1], "payload": 0, "duration": 3, "after": [], "site": "c"}]}
    inst = instance_from_dict(data)
    b = lower_bounds(inst)
    assert b.critical_path == pytest.approx(2.0 + 3.0)
    assert b.best <= simulate(inst, GreedyPayloadPolicy()).schedule.makespan + 1e-9


def test_lvws_solve_prints_and_writes_the_bound_and_the_gap(tmp_path, capsys):
    out = tmp_path / "s.json"
    assert main(["solve", str(REPO / "config" / "example_instance.json"), "--policy", "grp", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "lower bound" in err and "gap" in err
    data = json.loads(out.read_text())
    assert 0 < data["bound"] <= data["makespan"] and data["gap"] == pytest.approx(
        (data["makespan"] - data["bound"]) / data["makespan"])
