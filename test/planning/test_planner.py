"""The planner: dispatch from a plan reproduces it, repair keeps a plan valid after every kind
of event, the planner never hands out an invalid or a longer plan than its first quick plan,
and with an iteration limit (no time limit) it is deterministic."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance, subteam_heavy_instance
from lvws_ros.core.executor import State, TaskStatus, advance, simulate
from lvws_ros.core.families import family_test_split
from lvws_ros.core.formats import instance_from_dict, instance_to_dict
from lvws_ros.core.importers import import_psplib
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import check_schedule
from lvws_ros.planning.follow import PlanFollower, repair
from lvws_ros.planning.planner import ExactState, Planner, sampling_temperature
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.policies.exact import solve_exact


def _cells() -> list[Instance]:
    """Travel with fixed robots and transports, traits with the way home, the paper's model."""
    return [*family_test_split("depot", 0, 2), *family_test_split("traits-return", 0, 2),
            dataset_instance(DATASETS["I"], 3, seed=13)]


@pytest.mark.parametrize("k", range(5))
def test_dispatch_from_a_plan_reproduces_it(k):
    inst = _cells()[k]
    for plan in (simulate(inst, GreedyPayloadPolicy()).schedule,
                 solve_exact(inst, time_limit=5, workers=2).schedule):
        assert plan is not None
        again = repair(State.initial(inst), plan).schedule
        assert check_schedule(inst, again) == []
        assert again.makespan == pytest.approx(plan.makespan)
        assert {a.task: a.robots for a in again.assignments} == {a.task: a.robots for a in plan.assignments}


def _midway(inst: Instance, plan, steps: int) -> State:
    """The state after ``steps`` decisions of the plan, with something running."""
    follower = PlanFollower(plan)
    state = State.initial(inst)
    for _ in range(steps):
        nxt = advance(state, follower.decide(state))
        assert nxt is not None
        state = nxt
    assert (state.task_status == TaskStatus.ASSIGNED).any()
    return state


def _remap(state: State, inst: Instance, interrupted: set[str] = frozenset()) -> State:
    """``state`` carried over to ``inst`` (another version of the cell) by ids; tasks in
    ``interrupted`` (a member lost mid-task) start again."""
    old = state.instance
    s = State.initial(inst)
    s.time = state.time
    for j, t in enumerate(inst.tasks):
        i = old.task_index.get(t.id)
        if i is None or t.id in interrupted or state.task_status[i] < TaskStatus.ASSIGNED:
            continue
        s.task_status[j], s.task_start[j] = state.task_status[i], state.task_start[i]
        s.task_team[j] = tuple(sorted(inst.robot_index[old.robots[r].id] for r in state.task_team[i]
                                      if old.robots[r].id in inst.robot_index))
    for r, robot in enumerate(inst.robots):
        i = old.robot_index.get(robot.id)
        if i is not None:
            s.robot_free_at[r] = state.robot_free_at[i]
            if s.robot_site is not None and state.robot_site is not None:
                s.robot_site[r] = state.robot_site[i]
    for t in inst.tasks:  # an interrupted task's other members are free now
        if t.id in interrupted:
            for r in state.task_team[old.task_index[t.id]]:
                rid = old.robots[r].id
                if rid in inst.robot_index:
                    s.robot_free_at[inst.robot_index[rid]] = state.time
    s.refresh()
    return s


def _events(inst: Instance, state: State) -> dict[str, State]:
    """A state of each kind of event, from a state of the plan."""
    out: dict[str, State] = {}
    running = [int(j) for j in np.flatnonzero(state.task_status == TaskStatus.ASSIGNED)]
    late = state.copy()
    j = running[0]
    late.task_start[j] += 5.0
    late.robot_free_at[list(late.task_team[j])] += 5.0
    out["task late"] = late
    data = instance_to_dict(inst)
    quicker = [dict(t, duration=t["duration"] / 2) if t["id"] == inst.tasks[j].id else t for t in data["tasks"]]
    early = _remap(state, instance_from_dict(dict(data, tasks=quicker)))  # the running task ends sooner
    k = early.instance.task_index[inst.tasks[j].id]
    early.robot_free_at[list(early.task_team[k])] = max(early.time, early.task_start[k] + early.instance.durations[k])
    early.refresh()
    out["task early"] = early
    lost = inst.robots[state.task_team[j][0]].id
    fewer = dict(data, robots=[r for r in data["robots"] if r["id"] != lost])
    try:
        without = instance_from_dict(fewer)
    except Exception:  # the robot was the only one able to do some task: no such event for this cell
        without = None
    if without is not None:
        out["robot lost mid-task"] = _remap(state, without, {inst.tasks[j].id})
    todo = [t for t in inst.tasks if state.task_status[inst.task_index[t.id]] < TaskStatus.ASSIGNED]
    extra = [dict(next(t for t in data["tasks"] if t["id"] == todo[0].id), id="added-1", after=[]),
             dict(next(t for t in data["tasks"] if t["id"] == todo[-1].id), id="added-2",
                  after=[todo[0].id])]
    out["tasks added"] = _remap(state, instance_from_dict(dict(data, tasks=[*data["tasks"], *extra])))
    gone = todo[len(todo) // 2].id
    kept = [dict(t, after=[p for p in t.get("after", []) if p != gone])
            for t in data["tasks"] if t["id"] != gone]
    out["task cancelled"] = _remap(state, instance_from_dict(dict(data, tasks=kept)))
    return out


@pytest.mark.parametrize("k", range(4))
def test_repair_after_each_kind_of_event_keeps_the_plan_valid(k):
    inst = _cells()[k]
    plan = simulate(inst, GreedyPayloadPolicy(priority="critical-path")).schedule
    state = _midway(inst, plan, 2)
    events = _events(inst, state)
    assert {"task late", "task early", "tasks added", "task cancelled"} <= set(events)
    for kind, s in events.items():
        res = repair(s, plan)
        sched = res.schedule
        assert check_schedule(s.instance, sched) == [], (inst.name, kind)
        assert {a.task for a in sched.assignments} == {t.id for t in s.instance.tasks}, (inst.name, kind)
        # what was done or running stays as it was
        for j in np.flatnonzero(s.task_status >= TaskStatus.ASSIGNED):
            a = sched.by_task()[s.instance.tasks[j].id]
            assert a.start == pytest.approx(s.task_start[j]), (inst.name, kind)


def test_repair_keeps_the_orders_and_subteams_that_still_hold():
    inst = _cells()[0]
    plan = simulate(inst, GreedyPayloadPolicy()).schedule
    state = _midway(inst, plan, 2)
    late = _events(inst, state)["task late"]
    follower = PlanFollower(plan)
    simulate(late.instance, follower, state=late)
    assert follower.by_grp == 0 and follower.by_plan > 0  # nothing broke: every task as planned, re-timed
    kept = {a.task: a.robots for a in repair(late, plan).schedule.assignments}
    assert kept == {a.task: a.robots for a in plan.assignments}


def _heavy() -> Instance:
    return subteam_heavy_instance(np.random.default_rng(3), 10, 66, "heavy-10r-66t")


@pytest.mark.parametrize("make", [lambda: _cells()[0], lambda: _cells()[2], _heavy])
def test_the_planner_never_hands_out_an_invalid_or_longer_plan(make):
    inst = make()
    state = State.initial(inst)
    quick = min(simulate(inst, GreedyPayloadPolicy(priority="critical-path")).schedule.makespan,
                simulate(inst, GreedyPayloadPolicy()).schedule.makespan)
    planner = Planner(seed=1, workers=1, learned=False, work=0.3)
    seen: list[float] = []
    report = planner.run(state, iterations=5, on_report=lambda r: seen.append(r.makespan))
    assert planner.plan is not None
    assert check_schedule(inst, planner.plan.schedule) == []
    assert seen[0] <= quick + 1e-9 and all(b <= a + 1e-9 for a, b in itertools.pairwise(seen))
    assert report.makespan == pytest.approx(seen[-1])
    assert report.bound <= report.makespan + 1e-9 and 0 <= report.gap < 1
    # the plan as the executor carries it out from the start
    assert simulate(inst, PlanFollower(planner.plan.schedule)).schedule.makespan == pytest.approx(report.makespan)


def test_with_an_iteration_limit_the_planner_is_deterministic():
    for inst in (_heavy(), _cells()[2]):
        plans = []
        for _ in range(2):
            planner = Planner(seed=4, workers=1, samples=4, work=0.2)
            planner.run(State.initial(inst), iterations=4)
            assert planner.plan is not None
            plans.append(sorted((a.task, a.robots, round(a.start, 9)) for a in planner.plan.schedule.assignments))
        assert plans[0] == plans[1], inst.name


def test_the_planner_proves_a_small_cell_optimal_and_stops():
    inst = dataset_instance(DATASETS["I"], 4, seed=13)
    opt = solve_exact(inst, workers=8, time_limit=30)
    assert opt.proven
    planner = Planner(seed=0, workers=8)
    report = planner.run(State.initial(inst), time_limit=30)
    assert report.proven and report.makespan == pytest.approx(opt.makespan) and report.gap == 0
    assert report.seconds < 30


def test_the_sampling_temperature_cools_with_the_tasks_to_do():
    assert sampling_temperature(10) == pytest.approx(0.1)
    assert sampling_temperature(500) == pytest.approx(0.004)
    assert sampling_temperature(5000) < sampling_temperature(500)


def test_cp_sat_keeps_the_next_round_while_its_slices_shorten_the_plan():
    # A PSPLIB project (the pool model): a slice of CP-SAT's whole model that shortens the
    # plan is followed by another (a longer one), not by a round of neighbourhoods; rounds
    # alternate once a slice shortened nothing.
    inst = import_psplib(Path(__file__).parents[2] / "examples" / "psplib" / "j1201_1.sm")
    planner = Planner(seed=0, workers=1, learned=False, work=0.5)
    planner.run(State.initial(inst), iterations=1)
    assert (planner.exact_rounds, planner.lns_rounds) == (1, 0) and planner.exact is ExactState.SHORTENING
    while planner.exact is ExactState.SHORTENING and planner.exact_rounds < 4:
        rounds = planner.exact_rounds
        planner.improve()
        assert (planner.exact_rounds, planner.lns_rounds) == (rounds + 1, 0)
    if planner.exact is not ExactState.SHORTENING:
        planner.improve()
        assert planner.lns_rounds == 1


def _each_cells() -> list[Instance]:
    """Travel cells whose robots set out on their own (``"departure": "each"``): the held-out
    depot family and traits with the way home, as the coalition benchmarks run."""
    from dataclasses import replace

    return [replace(inst, departure="each") for inst in (_cells()[0], _cells()[2])]


@pytest.mark.parametrize("k", range(2))
def test_with_robots_setting_out_on_their_own_plans_are_carried_out_as_made_and_never_later(k):
    """CP-SAT's plan of such a cell is carried out exactly (its subteams, orders and
    makespan); GRP's plan (free robots only) carried out so is never later than GRP's
    own; CP-SAT's optimum there is never above the one of subteams sent off together."""
    from dataclasses import replace

    inst = _each_cells()[k]
    exact = solve_exact(inst, time_limit=10, workers=2)
    assert exact.schedule is not None
    again = repair(State.initial(inst), exact.schedule).schedule
    assert check_schedule(inst, again) == []
    assert again.makespan == pytest.approx(exact.schedule.makespan)
    assert {a.task: a.robots for a in again.assignments} == {a.task: a.robots for a in exact.schedule.assignments}
    grp = simulate(inst, GreedyPayloadPolicy()).schedule
    ahead = repair(State.initial(inst), grp).schedule
    assert check_schedule(inst, ahead) == [] and ahead.makespan <= grp.makespan + 1e-9
    together = solve_exact(replace(inst, departure="together"), time_limit=10, workers=2)
    if exact.proven and together.proven:
        assert exact.makespan <= together.makespan + 1e-6


def test_with_robots_setting_out_on_their_own_the_planner_is_valid_never_longer_and_deterministic():
    inst = _each_cells()[1]
    from lvws_ros.planning.ahead import earliest_start_plan

    quick = earliest_start_plan(State.initial(inst))
    assert quick is not None and check_schedule(inst, quick) == []
    plans = []
    for _ in range(2):
        planner = Planner(seed=2, workers=1, learned=False, work=0.2)
        seen: list[float] = []
        planner.run(State.initial(inst), iterations=4, on_report=lambda r, heard=seen: heard.append(r.makespan))
        assert planner.plan is not None and check_schedule(inst, planner.plan.schedule) == []
        assert seen[0] <= repair(State.initial(inst), quick).schedule.makespan + 1e-9
        assert all(b <= a + 1e-9 for a, b in itertools.pairwise(seen))
        plans.append(sorted((a.task, a.robots, round(a.start, 9)) for a in planner.plan.schedule.assignments))
    assert plans[0] == plans[1]


def test_the_list_schedule_is_timed_as_the_executor_carries_it_out():
    """A task is given once its members' tasks before it are given: B's task P is given at 10,
    so J (A and B) is given then too, and A, free at x from 0, sets out at 10 and arrives at 30
    (not at 20, as leaving when free would have it)."""
    from lvws_ros.planning.ahead import earliest_start_plan

    inst = instance_from_dict({
        "format": "lvws-instance/1", "name": "given-in-order", "traits": ["a", "b", "c"], "departure": "each",
        "sites": {"x": [0, 0], "y": [20, 0]},
        "robots": [{"id": "A", "traits": {"a": 1}, "site": "x", "speed": 1.0},
                   {"id": "B", "traits": {"b": 1}, "site": "y", "speed": 1.0},
                   {"id": "C", "traits": {"c": 1}, "site": "y", "speed": 1.0}],
        "tasks": [{"id": "Q", "requires": {"c": 1}, "duration": 10, "after": [], "site": "y"},
                  {"id": "P", "requires": {"b": 1}, "duration": 10, "after": ["Q"], "site": "y"},
                  {"id": "J", "requires": {"a": 1, "b": 1}, "duration": 1, "after": [], "site": "y"}]})
    for inst_ in (inst, *_each_cells()):
        plan = earliest_start_plan(State.initial(inst_))
        assert plan is not None and check_schedule(inst_, plan) == []
        carried = repair(State.initial(inst_), plan).schedule
        assert carried.makespan == pytest.approx(plan.makespan)
        assert {a.task: a.robots for a in carried.assignments} == {a.task: a.robots for a in plan.assignments}
    plan = earliest_start_plan(State.initial(inst))
    assert plan is not None and plan.by_task()["J"].start == pytest.approx(30.0)
