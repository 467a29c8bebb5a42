"""Lower bounds on the makespan: never above a proven optimum (Datasets I, II and IV,
with travel), tight where the instance says so, and printed with every schedule."""

from __future__ import annotations

import json

import numpy as np
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


def _travel_instance(name, caps, robots, tasks, sites, moves):
    from lvws_ros.core.travel import build_travel

    tr = build_travel(sites, {}, [(r.id, site, 1.0) for r, site in robots], moves)
    return Instance(name, caps, tuple(r for r, _ in robots), tasks, travel=tr)


def test_a_transport_is_a_quick_way_between_sites_for_the_bound():
    """A 1 s transport carries its robot 100 m: the bound must not count the 100 s drive."""
    inst = _travel_instance("ride", ("x",), [(Robot("r0", (1,), 1.0), "A")],
                            (Task("t0", (1,), 0.0, 1.0), Task("t1", (1,), 0.0, 1.0)),
                            {"A": [0, 0], "B": [100, 0]}, [("t0", "A", "B"), ("t1", "B", "B")])
    b = lower_bounds(inst)
    assert b.best <= 2.0 + 1e-9
    assert simulate(inst, GreedyPayloadPolicy()).schedule.makespan == pytest.approx(2.0)


def test_cp_sats_bound_with_travel_is_not_taken_as_the_instances(tmp_path, capsys):
    """With travel a rider can beat the expert's model (minimal subteams): r1 rides along
    on t0 and is at B for t1 at 12, which the expert's 'optimal' 22 does not see."""
    from lvws_ros.core.executor import Decision
    from lvws_ros.core.formats import save_instance
    from lvws_ros.policies.exact import proves_executor_bound

    inst = _travel_instance("rider", ("x", "y"), [(Robot("r0", (1, 0), 1.0), "A"), (Robot("r1", (0, 1), 1.0), "A")],
                            (Task("t0", (1, 0), 0.0, 1.0), Task("t1", (0, 1), 0.0, 1.0, ("t0",))),
                            {"A": [0, 0], "B": [10, 0]}, [("t0", "B", "B"), ("t1", "B", "B")])

    class Rider:
        name = "rider"

        def reset(self, instance):
            pass

        def decide(self, state):
            ready = state.ready_tasks()
            return Decision(((0, (0, 1)),) if 0 in ready else ((1, (1,)),) if 1 in ready else ())

    assert simulate(inst, Rider()).schedule.makespan == pytest.approx(12.0)
    expert = solve_exact(inst, workers=1, time_limit=5)
    assert not proves_executor_bound(inst, expert)
    assert lower_bounds(inst).best <= 12.0 + 1e-9
    path = tmp_path / "rider.json"
    save_instance(inst, path)
    out = tmp_path / "s.json"
    assert main(["solve", str(path), "--policy", "exact", "--workers", "1", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["bound"] <= 12.0 + 1e-9
    assert "warning" not in capsys.readouterr().err


def test_the_fewest_members_bound_every_covering_subteam_and_the_bound_stays_below_the_optimum():
    from lvws_ros.core.bounds import fewest_members
    from lvws_ros.core.families import family_test_split
    from lvws_ros.core.subteams import lightest_cover, random_cover

    rng = np.random.default_rng(0)
    for inst in family_test_split("traits-roles", 0, 12) + family_test_split("traits", 0, 6):
        fewest = fewest_members(inst)
        traits_from = len(inst.capabilities) if inst.traits else None
        for j, t in enumerate(inst.tasks):
            roles = bool(inst.task_roles[j])
            args = (inst.robot_amounts, inst.robot_payload, inst.task_needs[j], t.payload)
            for team in (lightest_cover(*args, roles=roles, traits_from=traits_from),
                         random_cover(*args, rng, roles=roles)):
                assert team is not None and len(team) >= fewest[j], (inst.name, t.id)
        res = solve_exact(inst, workers=8, time_limit=10)
        if res.proven:
            assert lower_bounds(inst).best <= res.makespan + 1e-9, inst.name


def test_a_trait_only_fixed_robots_have_bounds_the_work_at_their_site():
    # two welding tasks at site a, one fixed welder there: they run one after the other
    data = {"format": "lvws-instance/1", "name": "site", "traits": ["weld", "lift"],
            "sites": {"a": [0, 0], "b": [5, 0]},
            "robots": [{"id": "w", "traits": {"weld": 1}, "site": "a"},
                       {"id": "m0", "traits": {"lift": 1}, "site": "b", "speed": 1.0},
                       {"id": "m1", "traits": {"lift": 1}, "site": "b", "speed": 1.0}],
            "tasks": [{"id": "t0", "requires": {"weld": 1}, "duration": 4, "after": [], "site": "a"},
                      {"id": "t1", "requires": {"weld": 1}, "duration": 3, "after": [], "site": "a"},
                      {"id": "t2", "requires": {"lift": 1}, "duration": 1, "after": [], "site": "b"}]}
    inst = instance_from_dict(data)
    assert lower_bounds(inst).workload == pytest.approx(7.0)
    assert simulate(inst, GreedyPayloadPolicy()).schedule.makespan == pytest.approx(7.0)


def test_the_way_home_and_each_sites_heads_and_tails_count_in_the_bound():
    # one fixed welder at a, two mobile lifters at the dock b (5 m, 1 m/s); objective
    # "return". Welds w0 (4 s) and w1 (3 s) at a, each followed by a lift of 2 s at a:
    # the welder works 7 s from time 0, then the last weld's lift takes 2 s and its lifter
    # 5 s home. No schedule ends before 0 + 7 + 2 + 5 = 14; without heads, tails and the
    # way home the workload bound said 7 and the critical path 5 + 2 = 7. (The optimum is
    # 17: a lifter sets out for a lift only once the lift is ready.)
    data = {"format": "lvws-instance/1", "name": "home", "traits": ["weld", "lift"], "objective": "return",
            "sites": {"a": [0, 0], "b": [5, 0]},
            "robots": [{"id": "w", "traits": {"weld": 1}, "site": "a"},
                       {"id": "m0", "traits": {"lift": 1}, "site": "b", "speed": 1.0},
                       {"id": "m1", "traits": {"lift": 1}, "site": "b", "speed": 1.0}],
            "tasks": [{"id": "w0", "requires": {"weld": 1}, "duration": 4, "after": [], "site": "a"},
                      {"id": "w1", "requires": {"weld": 1}, "duration": 3, "after": [], "site": "a"},
                      {"id": "l0", "requires": {"lift": 1}, "duration": 2, "after": ["w0"], "site": "a"},
                      {"id": "l1", "requires": {"lift": 1}, "duration": 2, "after": ["w1"], "site": "a"}]}
    inst = instance_from_dict(data)
    b = lower_bounds(inst)
    assert b.critical_path == pytest.approx(5 + 2 + 5)  # a lifter's way to a, the lift, its way home
    assert b.workload == pytest.approx(7 + 2 + 5)  # the welder's 7 s, then the shortest tail: a lift and home
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.proven and res.makespan == pytest.approx(17.0) and b.best <= res.makespan
    assert simulate(inst, GreedyPayloadPolicy()).schedule.makespan >= b.best - 1e-9


@pytest.mark.parametrize("key", ["depot", "traits-return", "warehouse"])
def test_the_bound_with_the_way_home_never_exceeds_a_proven_optimum_nor_any_schedule(key):
    from lvws_ros.core.families import family_instance
    from lvws_ros.policies.baselines import RandomPolicy, RandomSubteamPolicy

    proven = 0
    for k in range(4):
        inst = family_instance(key, k, 7, 8 if key == "warehouse" else 5, 8)  # a warehouse lifts 4 with a few AMRs
        b = lower_bounds(inst).best
        for policy in (GreedyPayloadPolicy(), GreedyPayloadPolicy(priority="critical-path"), RandomPolicy(seed=k),
                       RandomSubteamPolicy(seed=k)):
            assert b <= simulate(inst, policy).schedule.makespan + 1e-9, (inst.name, policy.name)
        res = solve_exact(inst, workers=2, time_limit=5)
        if res.proven:
            proven += 1
            assert b <= res.makespan + 1e-9, inst.name
    assert proven  # the exact solver closes some of them: the bound is held to an optimum
