"""Large-neighbourhood search: it improves a deliberately bad start on a mid-size cell,
stays valid by ``lvws check`` (the file round trip included), never returns a longer
schedule, repeats itself with the same seed, works from a mid-run state, and with travel
(the way home included) improves a bad start and stays valid. ``auto`` uses it on a cell
too big for CP-SAT's whole model, with travel too."""

from __future__ import annotations

import itertools
import time
from pathlib import Path

import numpy as np
import pytest
from ortools.sat.python import cp_model

from lvws_ros.core.datasets import subteam_heavy_instance
from lvws_ros.core.executor import State, simulate
from lvws_ros.core.families import family_instance
from lvws_ros.core.formats import instance_from_dict, load_schedule, save_schedule
from lvws_ros.core.importers import import_psplib
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.errors import ExpertError
from lvws_ros.planning.budgeted import AutoPolicy
from lvws_ros.policies import lns
from lvws_ros.policies.baselines import GreedyPayloadPolicy, RandomPolicy
from lvws_ros.policies.exact import _time_scale, _travel_times, left_shift, solve_exact
from lvws_ros.policies.lns import KINDS, _neighbourhood, _window_model, critical_chain, improve


def _cell():
    return subteam_heavy_instance(np.random.default_rng([0, 12, 40]), 12, 40, "heavy-12r-40t")


@pytest.mark.parametrize("family", ["subteam-heavy", "depot", "traits-return"])  # no travel; travel; and return
def test_lns_improves_a_bad_start_and_stays_valid(tmp_path, family):
    inst = _cell() if family == "subteam-heavy" else family_instance(family, 0, seed=5, num_robots=10, num_tasks=40)
    bad = simulate(inst, RandomPolicy(seed=0)).schedule
    found = improve(inst, bad, time_limit=3.0 if inst.travel is None else 4.0, window=10,
                    round_limit=0.3 if inst.travel is None else 0.4)
    assert found.rounds >= 2 and found.improved >= 1
    assert found.schedule.makespan < bad.makespan
    save_schedule(found.schedule, tmp_path / "lns.json")
    assert check_schedule(inst, load_schedule(tmp_path / "lns.json")) == []


def test_lns_never_returns_a_longer_schedule_and_repeats_with_its_seed():
    inst = _cell()
    start = simulate(inst, GreedyPayloadPolicy()).schedule
    one = improve(inst, start, time_limit=1.5, window=8, round_limit=0.2, seed=3)
    assert one.schedule.makespan <= start.makespan
    assert one.start_makespan == start.makespan


def test_lns_from_a_mid_run_state_keeps_what_has_started():
    inst = _cell()
    run = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = run.steps[len(run.steps) // 2].state
    found = improve(inst, run.schedule, state=state, time_limit=1.5, window=8, round_limit=0.2)
    assert check_schedule(inst, found.schedule) == []
    by_task = found.schedule.by_task()
    for j in np.flatnonzero(state.task_status >= 2):  # assigned or done: as they were
        a = by_task[inst.tasks[j].id]
        assert a.start == pytest.approx(state.task_start[j])
        assert a.robots == tuple(inst.robots[r].id for r in state.task_team[j])


def test_lns_with_travel_from_a_mid_run_state():
    inst = family_instance("depot", 1, seed=5, num_robots=10, num_tasks=40)
    run = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = run.steps[len(run.steps) // 2].state
    found = improve(inst, run.schedule, state=state, time_limit=2.0, window=8, round_limit=0.3)
    assert check_schedule(inst, found.schedule) == []
    assert found.schedule.makespan <= run.schedule.makespan + 1e-9
    by_task = found.schedule.by_task()
    for j in np.flatnonzero(state.task_status >= 2):  # assigned or done: as they were
        assert by_task[inst.tasks[j].id].robots == tuple(inst.robots[r].id for r in state.task_team[j])


def test_lns_refuses_an_empty_window():
    cell = _cell()
    with pytest.raises(ExpertError, match="window"):
        improve(cell, simulate(cell, GreedyPayloadPolicy()).schedule, window=0)


@pytest.mark.parametrize("travel", [False, True])
def test_auto_searches_neighbourhoods_on_a_cell_too_big_for_the_whole_model(travel):
    inst = family_instance("depot", 2, seed=5, num_robots=8, num_tasks=30) if travel else _cell()
    auto = AutoPolicy(budget_ms=800.0, exact_tasks=10, samples=2)
    sched = simulate(inst, auto).schedule
    assert check_schedule(inst, sched) == []
    grp = simulate(inst, GreedyPayloadPolicy()).schedule
    assert sched.makespan <= grp.makespan + 1e-9
    assert auto.lns_windows >= 1  # it searched (whether a window paid depends on the machine's speed)


def test_lns_stops_at_a_lower_bound():
    inst = _cell()
    start = simulate(inst, GreedyPayloadPolicy()).schedule
    found = improve(inst, start, time_limit=30.0, bound=start.makespan)
    assert found.rounds == 0 and found.seconds < 5.0


def test_lns_from_a_state_that_ran_ahead_of_the_plan():
    inst = _cell()
    run = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = run.steps[len(run.steps) // 2].state
    # the plan followed is 0.3 s behind the world: every task planned 0.3 s later than it ran
    plan = Schedule.from_assignments(inst.name, "plan", [Assignment(a.task, a.robots, a.start + 0.3, a.end + 0.3)
                                                         for a in run.schedule.assignments])
    assert check_schedule(inst, plan) == []
    found = improve(inst, plan, state=state, time_limit=1.0, window=8, round_limit=0.2)
    assert check_schedule(inst, found.schedule) == []
    by_task = found.schedule.by_task()
    for j in np.flatnonzero(state.task_status >= 2):  # what has started is as the world has it
        assert by_task[inst.tasks[j].id].start == pytest.approx(state.task_start[j])


@pytest.mark.parametrize("index", [9, 21, 22])
def test_a_late_window_with_the_way_home_holds_its_incumbent(index):
    # From a late state of a cell with "objective": "return", a robot given nothing more
    # goes home from where its last task ended, when it ended (not from now): the window
    # over the rest of the schedule holds the incumbent, so CP-SAT finds a schedule.
    inst = family_instance("traits-return", index, seed=3, num_robots=6, num_tasks=10)
    run = simulate(inst, RandomPolicy(seed=index), record_states=True)
    state = run.steps[9].state
    inc = left_shift(inst, run.schedule, state)
    started = [j for j in range(inst.num_tasks) if state.task_status[j] >= 2]
    rest = sorted(set(range(inst.num_tasks)) - set(started), key=lambda j: (inc.by_task()[inst.tasks[j].id].start, j))
    scale, _ = _time_scale(np.concatenate([inst.durations, [state.time], _travel_times(inst, state)]))
    cand, solved = _window_model(inst, state, inc, started, rest, [], scale, time.perf_counter() + 5.0, 1, 0)
    assert solved and cand is not None
    assert check_schedule(inst, cand) == [] and cand.makespan <= inc.makespan + 1e-9


class _HeldToTheHint(cp_model.CpSolver):
    """CP-SAT with every hinted variable fixed to its hint: it finds a solution exactly
    when the hint is one."""

    def __init__(self) -> None:
        super().__init__()
        self.parameters.fix_variables_to_their_hinted_value = True


def _coalition_cell(robots: int = 20, tasks: int = 30, seed: int = 4):
    """Interchangeable robots at one depot, tasks at random points each needing 1-5 of
    them, the way home counted (the shape of public coalition benchmarks)."""
    rng = np.random.default_rng(seed)
    xy = rng.random((tasks + 1, 2))
    doc = {"format": "lvws-instance/1", "name": f"coalitions-{robots}r-{tasks}t", "traits": ["unit"],
           "objective": "return", "sites": {f"s{k}": xy[k].tolist() for k in range(tasks + 1)},
           "robots": [{"id": f"a{r}", "traits": {"unit": 1}, "site": f"s{tasks}", "speed": 0.2}
                      for r in range(robots)],
           "tasks": [{"id": f"t{k}", "requires": {"unit": int(rng.integers(1, 6))}, "duration": 5.0, "after": [],
                      "site": f"s{k}"} for k in range(tasks)]}
    return instance_from_dict(doc)


@pytest.mark.parametrize("family", ["coalitions", "depot", "traits-return"])
def test_the_travel_hint_is_a_solution_of_the_window_and_whole_models(monkeypatch, family):
    # The incumbent timed on the model's ticks (travel rounded up): a hint rounded from real
    # times can start a task a tick before its last member is there, and CP-SAT then spends
    # a neighbourhood's time repairing it (with 20 robots, every neighbourhood of 0.5 s).
    inst = _coalition_cell() if family == "coalitions" else family_instance(family, 5, seed=2, num_robots=12,
                                                                             num_tasks=30)
    state = State.initial(inst)
    inc = left_shift(inst, simulate(inst, GreedyPayloadPolicy()).schedule, state)
    rest = sorted(range(inst.num_tasks), key=lambda j: (inc.by_task()[inst.tasks[j].id].start, j))
    scale, _ = _time_scale(np.concatenate([inst.durations, [state.time], _travel_times(inst, state)]))
    monkeypatch.setattr(cp_model, "CpSolver", _HeldToTheHint)
    for first in (0, 8, 20):
        cand, _ = _window_model(inst, state, inc, rest[:first], rest[first:first + 6], rest[first + 6:first + 12],
                                scale, time.perf_counter() + 10.0, 1, 0)
        assert cand is not None and check_schedule(inst, cand) == [], first
    res = solve_exact(inst, hint=inc, time_limit=10.0, workers=1)
    assert res.schedule is not None and check_schedule(inst, res.schedule) == []


def test_the_window_adapts_to_what_cp_sat_proves_in_a_round():
    # Twenty interchangeable robots with travel and the way home: a window of six tasks is
    # more than CP-SAT closes in a round; the window shrinks until it does, and the results
    # (three seeds: the neighbourhoods are drawn at random) are no longer than the fixed window's.
    inst = _coalition_cell()
    inc = simulate(inst, GreedyPayloadPolicy()).schedule
    fixed = [improve(inst, inc, max_rounds=12, round_limit=0.05, adaptive=False, seed=s) for s in range(3)]
    adapted = [improve(inst, inc, max_rounds=12, round_limit=0.05, seed=s) for s in range(3)]
    assert all(a.window < f.window for a, f in zip(adapted, fixed, strict=True))
    assert all(check_schedule(inst, a.schedule) == [] for a in adapted)
    assert sum(a.schedule.makespan for a in adapted) <= sum(f.schedule.makespan for f in fixed)


@pytest.mark.parametrize("family", ["subteam-heavy", "depot", "traits-return"])
def test_the_critical_chain_is_what_holds_the_makespan_up(family):
    # Each task of the chain starts when the one after it in the list ends (a prerequisite,
    # or a member's previous task and the way from it); the first one ends the schedule.
    inst = _cell() if family == "subteam-heavy" else family_instance(family, 0, seed=5, num_robots=10, num_tasks=40)
    inc = left_shift(inst, simulate(inst, GreedyPayloadPolicy()).schedule, State.initial(inst))
    chain = critical_chain(inst, inc)
    at = {inst.task_index[a.task]: a for a in inc.assignments}
    assert len(chain) >= 2 and len(set(chain)) == len(chain)
    if inst.objective == "makespan":
        assert at[chain[0]].end == pytest.approx(inc.makespan)
    for later, earlier in itertools.pairwise(chain):
        assert at[earlier].end <= at[later].start + 1e-6
        shares = set(at[earlier].robots) & set(at[later].robots)
        assert earlier in inst.prerequisites[later] or shares
        if inst.travel is None:
            assert at[earlier].end == pytest.approx(at[later].start)


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_of_neighbourhood_keeps_the_prerequisites_of_its_tasks_inside(kind):
    # Prefix, window and later tasks are the tasks up to a point in start order, so every
    # prerequisite of a task in the model is fixed or in the model too; the window is the
    # kind's choice: the chain's tasks first, the busiest robot's, or the last ones.
    inst = family_instance("depot", 0, seed=5, num_robots=10, num_tasks=40)
    inc = left_shift(inst, simulate(inst, GreedyPayloadPolicy()).schedule, State.initial(inst))
    by_task = inc.by_task()
    todo = sorted(range(inst.num_tasks), key=lambda j: (by_task[inst.tasks[j].id].start, j))
    chain = set(critical_chain(inst, inc))
    for seed in range(5):
        prefix, picked, later = _neighbourhood(inst, inc, by_task, todo, set(), kind, 6, 1, np.random.default_rng(seed), ())
        assert len(picked) == len(set(picked)) <= 6 and not set(picked) & set(later)
        inside = set(prefix) | set(picked) | set(later)
        assert inside == set(todo[:len(inside)])
        assert all(set(inst.prerequisites[j]) <= inside for j in inside)
        if kind == "tail":
            assert inside == set(todo) and picked == todo[len(prefix):len(prefix) + 6]
        if kind == "chain":
            assert chain & set(picked)


def test_the_kinds_of_neighbourhood_over_pools_improve_a_bad_start_from_a_fixed_seed(monkeypatch):
    # Over pools (a PSPLIB project: units of four resources) every kind is drawn over the
    # rounds, a kind that shortens the schedule more often; with an iteration limit the
    # result repeats. Per robot the windows are the time and tail kinds alone.
    drawn: list[str] = []

    def recorded(inst, inc, by_task, todo, started, kind, *rest):
        drawn.append(kind)
        return _neighbourhood(inst, inc, by_task, todo, started, kind, *rest)

    monkeypatch.setattr(lns, "_neighbourhood", recorded)
    inst = import_psplib(Path(__file__).parents[2] / "examples" / "psplib" / "j301_1.sm")
    bad = simulate(inst, RandomPolicy(seed=0)).schedule
    one, two = (improve(inst, bad, max_rounds=12, round_limit=0.1, seed=1, window=10) for _ in range(2))
    assert one.schedule.makespan < bad.makespan and one.schedule.assignments == two.schedule.assignments
    assert check_schedule(inst, one.schedule) == [] and set(drawn) == set(KINDS)
    drawn.clear()
    improve(_cell(), simulate(_cell(), RandomPolicy(seed=0)).schedule, max_rounds=3, round_limit=0.1)
    assert drawn and set(drawn) <= {"time", "tail"}
