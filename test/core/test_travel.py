"""The travel extension of lvws-instance/1 (formats.md): files without it unchanged,
files with it read, written and checked (rule 7), and the executor's robots that travel
before a task starts (a subteam starts when its slowest member is there)."""

from __future__ import annotations

import copy
import json
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO
from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict, instance_key, instance_to_dict, load_instance, schedule_to_dict
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.errors import InstanceError
from lvws_ros.registry import make_policy

CELL = {
    "format": "lvws-instance/1",
    "name": "travel-cell",
    "capabilities": ["arm", "mobile"],
    "sites": {"a": [0.0, 0.0], "b": [6.0, 8.0], "c": [12.0, 0.0]},
    "distances": {"a": {"c": 20.0}},  # a wall in the way: longer than the straight line (12)
    "robots": [
        {"id": "arm_b", "capabilities": [1, 0], "payload": 1.0, "site": "b"},  # fixed at b
        {"id": "fast", "capabilities": [0, 1], "payload": 3.0, "site": "a", "speed": 2.0},
        {"id": "slow", "capabilities": [0, 1], "payload": 4.0, "site": "a", "speed": 1.0},
    ],
    "tasks": [
        {"id": "carry", "capabilities": [0, 1], "payload": 6.0, "duration": 5.0, "after": [], "from": "a", "to": "b"},
        {"id": "fit", "capabilities": [1, 0], "payload": 0.5, "duration": 3.0, "after": ["carry"], "site": "b"},
        {"id": "fetch", "capabilities": [0, 1], "payload": 2.0, "duration": 2.0, "after": [], "site": "c"},
    ],
}


def test_files_without_sites_are_read_and_written_exactly_as_before():
    for path in [REPO / "config" / "example_instance.json", *sorted((REPO / "examples" / "my_cell").glob("*.json"))]:
        data = json.loads(path.read_text())
        inst = load_instance(path)
        assert inst.travel is None
        assert instance_to_dict(inst) == {**data, "robots": [{**r, "payload": float(r["payload"])} for r in data["robots"]],
                                          "tasks": [{**t, "payload": float(t["payload"]), "duration": float(t["duration"]),
                                                     "after": t.get("after", [])} for t in data["tasks"]]}


def test_an_instance_with_sites_round_trips():
    inst = instance_from_dict(CELL)
    tr = inst.travel
    assert tr is not None and tr.sites == ("a", "b", "c")
    assert tr.time(1, 0, 1) == pytest.approx(5.0)  # |ab| = 10 at speed 2
    assert tr.time(2, 0, 2) == pytest.approx(20.0)  # the distances entry, not 12
    assert tr.time(0, 1, 0) == float("inf") and tr.time(0, 1, 1) == 0.0  # the fixed arm
    again = instance_from_dict(instance_to_dict(inst))
    assert again.travel == tr and instance_key(again) == instance_key(inst)
    assert "site" not in inst.robots[0].extra and "from" not in inst.tasks[0].extra


@pytest.mark.parametrize(("mutate", "words"), [
    (lambda d: d["robots"][1].pop("site"), r"robots\[1\].*missing key 'site'"),
    (lambda d: d["robots"][1].update(site="z"), "robot 'fast' site: unknown site 'z'"),
    (lambda d: d["robots"][1].update(speed=0), "robot 'fast' speed: expected a finite number > 0"),
    (lambda d: d["tasks"][2].pop("site"), r"tasks\[2\]: missing key 'site' \(or 'from' and 'to'\)"),
    (lambda d: d["sites"].update(b=[1.0]), r"sites.b: expected \[x, y\]"),
    (lambda d: d["distances"]["a"].update(q=1.0), "distances.a.q: unknown site 'q'"),
    (lambda d: d.update(sites={}), "sites: at least one site"),
])
def test_bad_travel_data_is_refused_naming_the_item(mutate, words):
    data = copy.deepcopy(CELL)
    mutate(data)
    with pytest.raises(InstanceError, match=words):
        instance_from_dict(data)


def test_a_schedule_that_ignores_travel_is_rejected_by_rule_7():
    inst = instance_from_dict(CELL)
    # fast + slow carry (meet at a, where both start), then the arm at b fits; fetch by fast after
    b_to_c = 10.0 / 2.0  # |bc| = 10 at speed 2
    ok = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("carry", ("fast", "slow"), 0.0, 5.0), Assignment("fit", ("arm_b",), 5.0, 8.0),
        Assignment("fetch", ("fast",), 5.0 + b_to_c, 7.0 + b_to_c)])
    assert check_schedule(inst, ok) == []
    ignoring = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("carry", ("fast", "slow"), 0.0, 5.0), Assignment("fit", ("arm_b",), 5.0, 8.0),
        Assignment("fetch", ("fast",), 5.0, 7.0)])
    problems = check_schedule(inst, ignoring)
    assert [p.rule for p in problems] == [7]
    assert "robot 'fast' needs 5 s from b (end of 'carry') to c for task 'fetch'" in str(problems[0])
    first = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("fetch", ("slow",), 0.0, 2.0), Assignment("carry", ("fast", "slow"), 22.0, 27.0),
        Assignment("fit", ("arm_b",), 27.0, 30.0)])
    problems = check_schedule(inst, first)  # slow needs 20 s from a to c (one way: the entry is a -> c)
    assert [p.rule for p in problems] == [7] and "needs 20 s from a (its start) to c" in str(problems[0])
    arm_away = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("carry", ("fast", "slow", "arm_b"), 0.0, 5.0), Assignment("fit", ("arm_b",), 5.0, 8.0),
        Assignment("fetch", ("fast",), 10.0, 12.0)])
    assert any("robot 'arm_b' cannot leave its site from b (its start) to a" in str(p)
               for p in check_schedule(inst, arm_away))


def test_lvws_check_names_rule_7_and_the_travel(tmp_path: Path):
    inst_path, sched_path = tmp_path / "cell.json", tmp_path / "sched.json"
    inst_path.write_text(json.dumps(CELL))
    sched = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("carry", ("fast", "slow"), 0.0, 5.0), Assignment("fit", ("arm_b",), 5.0, 8.0),
        Assignment("fetch", ("fast",), 5.0, 7.0)])
    sched_path.write_text(json.dumps(schedule_to_dict(sched)))
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "check", str(inst_path), str(sched_path)],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 1 and "rule 7" in out.stdout + out.stderr, out


@pytest.mark.parametrize("policy", ["grp", "rand", "rand_subteam"])
def test_the_executor_makes_robots_travel_before_a_task_starts(policy):
    inst = instance_from_dict(CELL)
    run = simulate(inst, make_policy(policy, seed=1))
    assert check_schedule(inst, run.schedule) == []  # rule 7 included
    fetch = inst.task_index["fetch"]  # at c: no robot is there at any time before
    (when,) = [step.time for step in run.steps if any(j == fetch for j, _ in step.decision.assignments)]
    assert run.schedule.by_task()["fetch"].start - when >= 5.0 - 1e-9  # the fastest way to c takes 5 s (b->c)


def test_grp_takes_the_subteam_that_is_there_first():
    data = copy.deepcopy(CELL)
    data["robots"].append({"id": "far", "capabilities": [0, 1], "payload": 5.0, "site": "c", "speed": 1.0})
    data["tasks"] = [{"id": "fetch", "capabilities": [0, 1], "payload": 2.0, "duration": 2.0, "after": [],
                      "site": "c"}]
    inst = instance_from_dict(data)
    sched = simulate(inst, make_policy("grp")).schedule
    assert sched.by_task()["fetch"].robots == ("far",) and sched.by_task()["fetch"].start == 0.0
    no_travel = instance_from_dict({k: v for k, v in data.items() if k not in ("sites", "distances")}
                                   | {"robots": [{k: v for k, v in r.items() if k not in ("site", "speed")}
                                                 for r in data["robots"]]})
    assert simulate(no_travel, make_policy("grp")).schedule.by_task()["fetch"].robots == ("fast",)  # the lightest


def _brute_force(inst) -> float:
    """The optimal makespan by enumeration, independently of the solver, in the
    executor's model: every task order consistent with the DAG and every minimal covering
    subteam per task; a subteam sets out once the task is ready and all its members are
    free, and the task starts when the last one is there (the serial schedule: some order
    gives every robot's sequence of an optimal schedule, and setting out as early as
    possible never hurts)."""
    import itertools

    from lvws_ros.core.subteams import minimal_subteams

    tr = inst.travel
    teams = [minimal_subteams(inst.robot_caps, inst.robot_payload, inst.task_caps[j], inst.tasks[j].payload)
             for j in range(inst.num_tasks)]
    best = float("inf")
    for order in itertools.permutations(range(inst.num_tasks)):
        pos = {j: k for k, j in enumerate(order)}
        if any(pos[p] > pos[j] for j in order for p in inst.prerequisites[j]):
            continue
        for choice in itertools.product(*(teams[j] for j in order)):
            free = [0.0] * inst.num_robots
            site = list(tr.robot_site)
            end: dict[int, float] = {}
            for j, team in zip(order, choice, strict=True):
                depart = max([0.0, *(end[p] for p in inst.prerequisites[j]), *(free[r] for r in team)])
                start = depart + max(tr.time(r, site[r], tr.task_from[j]) for r in team)
                end[j] = start + inst.durations[j]
                for r in team:
                    free[r], site[r] = end[j], tr.task_to[j]
            best = min(best, max(end.values()))
    return best


@pytest.mark.parametrize("seed", range(6))
def test_the_exact_expert_with_travel_equals_a_brute_force(seed):
    import numpy as np

    from lvws_ros.policies.exact import ExactPolicy, solve_exact

    rng = np.random.default_rng(seed)
    sites = {s: [float(rng.integers(0, 9)), float(rng.integers(0, 9))] for s in "abc"}
    data = {"format": "lvws-instance/1", "name": f"tiny-{seed}", "capabilities": ["x", "y"], "sites": sites,
            "distances": {a: {b: float(rng.integers(1, 7)) for b in "abc" if b != a} for a in "abc"},
            "robots": [{"id": f"r{k}", "capabilities": [int(k % 2 == 0), int(k > 0)], "payload": float(1 + k),
                        "site": "abc"[k % 3], "speed": float(rng.choice([0.5, 1.0, 2.0]))} for k in range(3)],
            "tasks": []}
    for j in range(4):
        caps = [int(rng.integers(0, 2)), 1] if j % 2 else [1, int(rng.integers(0, 2))]
        where = {"site": "abc"[int(rng.integers(0, 3))]} if j != 1 else {"from": "a", "to": "c"}
        data["tasks"].append({"id": f"t{j}", "capabilities": caps, "payload": float(rng.integers(0, 4)),
                              "duration": float(rng.integers(1, 5)), "after": ["t0"] if j == 3 else [], **where})
    inst = instance_from_dict(data)
    res = solve_exact(inst, workers=2, time_limit=20)
    assert res.proven and check_schedule(inst, res.schedule) == []
    assert res.makespan == pytest.approx(_brute_force(inst), abs=1e-6)
    followed = simulate(inst, ExactPolicy(workers=2, time_limit=20)).schedule  # the executor can follow the plan
    assert followed.makespan == pytest.approx(res.makespan, abs=1e-6) and check_schedule(inst, followed) == []


def test_travel_counts_in_the_content_key_and_fixed_robots_stay_put():
    from lvws_ros.core.executor import Decision, State, check_decision
    from lvws_ros.errors import PolicyError

    inst = instance_from_dict(CELL)
    plain = instance_from_dict({k: v for k, v in CELL.items() if k not in ("sites", "distances")})
    assert instance_key(plain) != instance_key(inst)
    state = State.initial(inst)
    with pytest.raises(PolicyError, match="fixed robot"):  # the arm at b cannot carry from a to b
        check_decision(state, Decision(((0, (0, 1, 2)),)))
    moved = Schedule.from_assignments("travel-cell", "hand", [
        Assignment("carry", ("fast", "slow", "arm_b"), 0.0, 5.0), Assignment("fit", ("arm_b",), 5.0, 8.0),
        Assignment("fetch", ("fast",), 10.0, 12.0)])
    assert any("fixed at b: it cannot take task 'carry'" in str(p) for p in check_schedule(inst, moved))


def test_the_exact_plan_with_travel_is_followed_step_by_step_by_the_executor():
    from lvws_ros.policies.exact import ExactPolicy, departures, left_shift, solve_exact

    inst = instance_from_dict(CELL)
    res = solve_exact(inst, workers=2, time_limit=10)
    assert res.proven and res.schedule is not None and check_schedule(inst, res.schedule) == []
    assert left_shift(inst, res.schedule).assignments == res.schedule.assignments
    leave = departures(inst, res.schedule)
    assert leave["fetch"] < res.schedule.by_task()["fetch"].start  # it sets out, then travels
    run = simulate(inst, ExactPolicy(workers=2, time_limit=10))
    assert run.schedule.makespan == pytest.approx(res.makespan) and check_schedule(inst, run.schedule) == []
    grp = simulate(inst, make_policy("grp")).schedule
    assert res.makespan <= grp.makespan + 1e-9


def test_expert_demonstrations_on_a_travel_instance_label_the_departures():
    from lvws_ros.learning.demonstrations import expert_demos

    inst = instance_from_dict(CELL)
    demos = expert_demos(inst, time_limit=10, workers=2)
    fetch = inst.task_index["fetch"]  # at c: its robot sets out before the task starts
    chosen = []
    for d in demos:
        tasks = list(d.features.task_ids[d.features.cols[:-1]])
        if fetch in tasks:
            chosen.append(bool((d.expert[:, tasks.index(fetch)] > 0).any()))
    assert any(chosen), "the expert's departure to fetch is labelled at no decision step"


def test_a_robot_that_cannot_reach_a_task_does_not_wait_voluntarily_for_it():
    from lvws_ros.core.executor import Decision, State, voluntary_waits

    data = copy.deepcopy(CELL)
    data["tasks"][1]["after"] = []  # "fit" at b, ready at once: only arm_b (fixed at b) can do it
    data["robots"].append({"id": "arm_a", "capabilities": [1, 0], "payload": 1.0, "site": "a"})  # fixed at a
    inst = instance_from_dict(data)
    state = State.initial(inst)
    fit, arm_a, arm_b = inst.task_index["fit"], inst.robot_index["arm_a"], inst.robot_index["arm_b"]
    waits = voluntary_waits(state, Decision((), tuple(state.free_robots())))
    assert fit in waits[arm_b]  # arm_b could start it now: a voluntary wait
    assert fit not in waits.get(arm_a, ())  # arm_a can never get there: not voluntary


def test_the_held_out_depot_family_is_feasible_round_trips_and_is_proven_by_the_expert():
    import numpy as np

    from lvws_ros.core.families import DEPOT_SPEEDS, FAMILIES, TRAVEL_FAMILIES, family_instance
    from lvws_ros.core.subteams import covers
    from lvws_ros.policies.exact import solve_exact

    assert TRAVEL_FAMILIES == ("depot",) and FAMILIES["depot"].held_out
    with pytest.raises(ValueError, match="at least 3 robots"):  # two could never hold K = 5 skills
        family_instance("depot", 0, seed=3, num_robots=2)
    for k in range(6):
        inst = family_instance("depot", k, seed=3)
        assert instance_key(inst) == instance_key(family_instance("depot", k, seed=3))  # seeded
        tr = inst.travel
        assert tr is not None and 4 <= len(tr.sites) <= 7 and 3 <= len(inst.capabilities) <= 5
        assert np.allclose(tr.distance * 2, np.round(tr.distance * 2))  # 0.5 m steps, as a matrix in the file
        assert {v for v in tr.robot_speed if v > 0} <= set(DEPOT_SPEEDS)  # 0: fixed
        for j in range(inst.num_tasks):  # the robots that can reach a task cover it (Eqs. 10-11)
            able = [i for i in range(inst.num_robots) if tr.can_do(i, j)]
            assert covers(inst.robot_caps[able], inst.robot_payload[able], inst.task_caps[j], inst.tasks[j].payload)
        again = instance_from_dict(json.loads(json.dumps(instance_to_dict(inst))))
        assert instance_key(again) == instance_key(inst)
        if k < 2:  # travel times fall on whole milliseconds: the expert proves, and its plan obeys rule 7
            opt = solve_exact(inst, workers=2, time_limit=60)
            assert opt.status == "optimal" and check_schedule(inst, opt.schedule) == []
