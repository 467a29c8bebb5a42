"""The CP-SAT expert: brute-force optimal on tiny instances, never worse than the
baselines, and correct when resuming from a mid-run state."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from twins import twin_instances, with_twins

from lvws_ros.core.datasets import DATASETS, dataset_instance, random_instance
from lvws_ros.core.executor import TaskStatus, simulate
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import TOLERANCE, covers
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from lvws_ros.policies.exact import solve_exact
from lvws_ros.registry import make_policy


def brute_force_makespan(inst) -> float:
    """Min over every covering subteam (not only minimal ones) per task and every
    precedence-respecting task order of the list schedule: each task as early as its
    prerequisites and robots allow. Every semi-active schedule arises this way."""
    n, m = inst.num_robots, inst.num_tasks
    subsets = [s for k in range(1, n + 1) for s in itertools.combinations(range(n), k)]
    teams = [[s for s in subsets if covers(inst.robot_caps[list(s)], inst.robot_payload[list(s)],
                                           inst.task_caps[j], inst.tasks[j].payload)] for j in range(m)]
    orders = [p for p in itertools.permutations(range(m))
              if all(p.index(q) < p.index(j) for j in range(m) for q in inst.prerequisites[j])]
    best = float("inf")
    for choice in itertools.product(*teams):
        for order in orders:
            free = [0.0] * n
            end = [0.0] * m
            for j in order:
                s = max([*(end[q] for q in inst.prerequisites[j]), *(free[r] for r in choice[j])])
                end[j] = s + inst.tasks[j].duration
                for r in choice[j]:
                    free[r] = end[j]
            best = min(best, max(end))
    return best


@pytest.mark.parametrize("seed", range(12))
def test_expert_matches_brute_force(seed):
    rng = np.random.default_rng(1000 + seed)
    inst = random_instance(rng, int(rng.integers(1, 4)), int(rng.integers(1, 5)), f"tiny{seed}")
    res = solve_exact(inst, workers=2)
    assert res.status == "optimal" and res.bound == pytest.approx(res.makespan)
    assert check_schedule(inst, res.schedule) == []
    assert res.makespan == pytest.approx(brute_force_makespan(inst))


def test_expert_never_worse_than_baselines_on_dataset_i():
    spec = DATASETS["I"]
    for k in range(800, 808):
        inst = dataset_instance(spec, k, seed=0)
        res = solve_exact(inst, workers=2, time_limit=60)
        assert res.status == "optimal", inst.name
        assert check_schedule(inst, res.schedule) == []
        for name in ["grp", "rand", "rand_subteam"]:
            assert simulate(inst, make_policy(name, seed=k)).schedule.makespan >= res.makespan - 1e-9


def test_fractional_durations_are_scaled_exactly():
    rng = np.random.default_rng(3)
    base = random_instance(rng, 3, 4, "frac")
    from dataclasses import replace

    inst = replace(base, tasks=tuple(replace(t, duration=t.duration / 4) for t in base.tasks))
    res = solve_exact(inst, workers=2)
    assert res.status == "optimal" and res.exact_scale
    assert res.makespan == pytest.approx(brute_force_makespan(inst))


@pytest.mark.parametrize("index", [800, 801, 802])
@pytest.mark.parametrize("step", [1, 3, 6])
def test_expert_resumes_from_mid_run_state(index, step):
    inst = dataset_instance(DATASETS["I"], index, seed=0)
    grp = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = grp.steps[min(step, len(grp.steps) - 1)].state
    assert state is not None
    res = solve_exact(inst, state=state, workers=2)
    assert res.status == "optimal"
    sched = res.schedule
    assert check_schedule(inst, sched) == []
    by_task = sched.by_task()
    for j, t in enumerate(inst.tasks):
        a = by_task[t.id]
        if state.task_status[j] >= TaskStatus.ASSIGNED:  # fixed: started before the state
            assert a.start == pytest.approx(state.task_start[j])
            assert tuple(inst.robot_index[r] for r in a.robots) == state.task_team[j]
        else:
            assert a.start >= state.time - 1e-9
            for r in a.robots:
                assert a.start >= state.robot_free_at[inst.robot_index[r]] - 1e-9
    # Optimal from here: no worse than GRP's own continuation, no better than from scratch.
    assert res.makespan <= grp.schedule.makespan + 1e-9
    assert res.makespan >= solve_exact(inst, workers=2).makespan - 1e-9
    # The exact policy, started at that state, reaches the same makespan.
    cont = simulate(inst, make_policy("exact", workers=2), state=state)
    assert cont.schedule.makespan == pytest.approx(res.makespan)


def test_resuming_on_the_optimal_path_keeps_the_optimum():
    inst = dataset_instance(DATASETS["I"], 805, seed=0)
    opt = simulate(inst, make_policy("exact", workers=2), record_states=True)
    for rec in opt.steps[1::3]:
        assert solve_exact(inst, state=rec.state, workers=2).makespan == pytest.approx(opt.schedule.makespan)


def test_the_exact_policy_replans_when_the_world_misses_a_planned_departure():
    """Online, the world may run late (a robot arrives after the plan's time): a ready task
    whose planned departure has passed is planned again from now, never left waiting."""
    from dataclasses import replace

    from lvws_ros.core.executor import State
    from lvws_ros.policies.exact import ExactPolicy

    inst = dataset_instance(DATASETS["IV"], 2000, seed=0)
    policy = ExactPolicy(workers=2, time_limit=10)
    policy.reset(inst)
    first = policy.decide(State.initial(inst))
    assert first.assignments
    assert policy.result is not None and policy.result.schedule is not None
    at = min(a.end for a in policy.result.schedule.assignments)  # a time the plan expects
    late = replace(State.initial(inst), time=at)  # but nothing was started at 0: those departures missed
    d = policy.decide(late)
    assert d.assignments  # planned again from then, not left waiting for 0
    assert all(abs(policy._leave.get(inst.tasks[j].id, at) - at) <= 1e-6 for j, _ in d.assignments)


# ---------------------------------------------------------------- the pool model

@pytest.mark.parametrize("roles,objective", [(False, "makespan"), (True, "makespan"), (False, "return")])
def test_the_pool_model_proves_the_per_robot_optimum(roles, objective):
    from lvws_ros.core.pools import pools, trivial

    cases = twin_instances(8, roles=roles, objective=objective)
    assert len(cases) >= 5
    for inst in cases:
        assert not trivial(pools(inst))
        per_robot = solve_exact(inst, workers=2, time_limit=60, formulation="coalition")
        pooled = solve_exact(inst, workers=2, time_limit=60, formulation="pool")
        assert pooled.model == "pool" and per_robot.model == "coalition"
        assert per_robot.proven and pooled.proven, inst.name
        assert pooled.makespan == pytest.approx(per_robot.makespan), inst.name
        assert check_schedule(inst, pooled.schedule) == [], inst.name


@pytest.mark.parametrize("index", [800, 801])
def test_the_pool_model_on_the_paper_recipe_with_twins_and_from_a_mid_run_state(index):
    inst = with_twins(dataset_instance(DATASETS["I"], index, seed=0), [1, 0, 2])
    per_robot = solve_exact(inst, workers=2, time_limit=60, formulation="coalition")
    pooled = solve_exact(inst, workers=2, time_limit=60, formulation="pool")
    assert pooled.model == "pool" and pooled.proven and per_robot.proven
    assert pooled.makespan == pytest.approx(per_robot.makespan)
    grp = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = grp.steps[2].state  # some robots busy: they join their pool when free
    assert state is not None and (state.robot_free_at > state.time).any()
    a = solve_exact(inst, state=state, workers=2, time_limit=60, formulation="coalition")
    b = solve_exact(inst, state=state, workers=2, time_limit=60, formulation="pool")
    assert b.model == "pool" and a.proven and b.proven
    assert b.makespan == pytest.approx(a.makespan)
    assert check_schedule(inst, b.schedule) == []
    for j in state.tasks_to_do():
        x = b.schedule.by_task()[inst.tasks[j].id]
        assert all(x.start >= state.robot_free_at[inst.robot_index[r]] - 1e-9 for r in x.robots)


def test_the_pool_model_brute_force_on_tiny_twins():
    for seed in range(6):
        rng = np.random.default_rng(3000 + seed)
        base = random_instance(rng, 2, int(rng.integers(2, 5)), f"tiny{seed}")
        inst = with_twins(base, [1, int(rng.integers(0, 2))])
        res = solve_exact(inst, workers=2, formulation="pool")
        assert res.model == "pool" and res.proven
        assert res.makespan == pytest.approx(brute_force_makespan(inst))


def test_pool_schedules_pass_lvws_check(tmp_path):
    import subprocess
    import sys

    from lvws_ros.core.formats import save_instance, save_schedule

    inst = twin_instances(3, roles=True)[0]
    res = solve_exact(inst, workers=2, formulation="pool")
    save_instance(inst, tmp_path / "i.json")
    save_schedule(res.schedule, tmp_path / "s.json")
    done = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "check", str(tmp_path / "i.json"),
                           str(tmp_path / "s.json")], capture_output=True, text=True, check=False)
    assert done.returncode == 0 and done.stdout.startswith("valid"), done.stdout + done.stderr


def test_without_identical_robots_the_per_robot_model_is_solved_as_before():
    for k in (800, 801, 802):
        inst = dataset_instance(DATASETS["I"], k, seed=0)
        auto = solve_exact(inst, workers=1, time_limit=60)
        per_robot = solve_exact(inst, workers=1, time_limit=60, formulation="coalition")
        assert auto.model == "coalition"
        assert auto.schedule.assignments == per_robot.schedule.assignments


def test_auto_solves_pools_where_the_team_is_too_large_for_coalitions():
    """Small teams keep the coalition model (it proves faster there); a PSPLIB project
    (41 robots in four pools) gets the pool model."""
    from pathlib import Path

    from lvws_ros.core.importers import import_psplib

    small = twin_instances(1)[0]
    assert solve_exact(small, workers=2).model == "coalition"
    big = import_psplib(Path(__file__).resolve().parents[2] / "examples" / "psplib" / "j301_1.sm")
    res = solve_exact(big, workers=2, time_limit=30)
    assert res.model == "pool" and res.proven and res.makespan == 43  # the published optimum
    assert check_schedule(big, res.schedule) == []


def test_the_pool_model_has_no_travel():
    from lvws_ros.errors import ExpertError

    inst = dataset_instance(DATASETS["IV"], 0, seed=0)
    assert solve_exact(inst, workers=2, time_limit=10).model != "pool"
    with pytest.raises(ExpertError, match="no travel"):
        solve_exact(inst, formulation="pool")


def test_the_slot_cumulatives_take_every_subset_within_their_terms(monkeypatch):
    """Within SLOT_TERMS every subset of the needed traits gets a cumulative (one per set of
    holders); beyond, all of them together and each alone: fewer, the whole set among them."""
    from ortools.sat.python import cp_model

    import lvws_ros.policies.exact as exact
    from lvws_ros.core.executor import State
    from lvws_ros.core.families import family_instance

    inst = family_instance("traits-roles", 0, 0)
    state = State.initial(inst)
    state.refresh()
    todo = state.tasks_to_do()
    h = exact._horizon(inst, state, todo, exact.heuristic_schedule(inst, state), coalitions=False)
    cols = np.flatnonzero((inst.task_needs[todo] > TOLERANCE).any(axis=0))
    assert len(cols) >= 3

    class Recording(cp_model.CpModel):  # the capacity of each cumulative added
        capacities: list[int]

        def add_cumulative(self, intervals, demands, capacity):  # type: ignore[no-untyped-def]
            self.capacities.append(int(capacity))
            return super().add_cumulative(intervals, demands, capacity)

    def capacities(terms: int) -> list[int]:
        monkeypatch.setattr(exact, "SLOT_TERMS", terms)
        model = Recording()
        model.capacities = []
        start = {j: model.new_int_var(0, h.upper, f"S_{j}") for j in todo}
        assert exact._slot_cumulatives(model, inst, state, h, start)
        return model.capacities

    every, few = capacities(exact.SLOT_TERMS), capacities(0)
    holders = int((inst.robot_amounts[:, cols] > 0).any(axis=1).sum())
    assert len(every) > len(few) >= 1
    assert max(every) == max(few) <= holders  # the whole set's cumulative in both, when binding


@pytest.mark.parametrize("formulation", ["coalition", "boolean", "pool"])
def test_the_slot_cumulatives_of_roles_keep_every_optimum(formulation, monkeypatch):
    """The redundant cumulatives of the multi-skill rule (a member fills one slot) cut no
    schedule: with them (on every subset of the needed traits, or on each alone and all
    together) and without them every formulation proves the same optimum, from the start
    and from a mid-run state (busy robots holding their units)."""
    import lvws_ros.policies.exact as exact
    from lvws_ros.core.executor import State
    from lvws_ros.core.families import family_instance

    cases = twin_instances(4, roles=True) if formulation == "pool" else \
        [family_instance("traits-roles", k, 0) for k in range(4)]
    for inst in cases:
        mid = State.initial(inst)
        grp = GreedyPayloadPolicy()
        grp.reset(inst)
        for task, team in grp.decide(mid).assignments:  # the first decision taken: busy robots from here
            mid.start(task, team)
        for state in (None, mid):
            runs = []
            for on, terms in ((True, exact.SLOT_TERMS), (True, 0), (False, exact.SLOT_TERMS)):  # 0: no subsets
                monkeypatch.setattr(exact, "SLOT_CUMULATIVES", on)
                monkeypatch.setattr(exact, "SLOT_TERMS", terms)
                runs.append(solve_exact(inst, state=state, workers=2, time_limit=60, formulation=formulation))
            assert all(r.proven for r in runs), inst.name
            assert all(r.makespan == pytest.approx(runs[-1].makespan) for r in runs), inst.name
            assert check_schedule(inst, runs[0].schedule) == [], inst.name


def test_the_assignment_model_proves_the_same_optima():
    """The assignment model (the boolean one with a literal per pair of tasks that may
    overlap) cuts no schedule: from the start and mid-run it proves the optimum the
    coalition model proves, and its schedules are valid."""
    from lvws_ros.core.executor import State
    from lvws_ros.core.families import family_instance

    for k in range(3):
        inst = family_instance("traits-roles", k, 0)
        mid = State.initial(inst)
        grp = GreedyPayloadPolicy()
        grp.reset(inst)
        for task, team in grp.decide(mid).assignments:
            mid.start(task, team)
        for state in (None, mid):
            pairs = solve_exact(inst, state=state, workers=2, time_limit=60, formulation="assignment")
            coalitions = solve_exact(inst, state=state, workers=2, time_limit=60, formulation="coalition")
            assert pairs.model == "assignment" and pairs.proven and coalitions.proven, inst.name
            assert pairs.makespan == pytest.approx(coalitions.makespan), inst.name
            assert check_schedule(inst, pairs.schedule) == [], inst.name


def test_the_pairs_leave_out_tasks_ordered_by_precedence():
    """A chain a -> b -> c beside a free task d: only the pairs with d may overlap (c after
    a is ordered through b, with no edge of its own)."""
    import lvws_ros.policies.exact as exact
    from lvws_ros.core.executor import State
    from lvws_ros.core.problem import Instance, Robot, Task

    robots = (Robot("r0", (1,), 1.0), Robot("r1", (1,), 1.0))
    tasks = (Task("a", (1,), 0.0, 1.0), Task("b", (1,), 0.0, 1.0, after=("a",)),
             Task("c", (1,), 0.0, 1.0, after=("b",)), Task("d", (1,), 0.0, 1.0))
    inst = Instance("chain", ("c0",), robots, tasks)
    state = State.initial(inst)
    state.refresh()
    todo = state.tasks_to_do()
    h = exact._horizon(inst, state, todo, exact.heuristic_schedule(inst, state))
    h.upper += 10  # windows wide enough for any two free tasks to overlap
    names = {(inst.tasks[i].id, inst.tasks[j].id) for i, j in exact._unordered_pairs(inst, h)}
    assert {tuple(sorted(p)) for p in names} == {("a", "d"), ("b", "d"), ("c", "d")}
    d = inst.task_index["d"]
    h.head[d] = h.upper - h.tail[inst.task_index["b"]] + 1  # d starts after b's latest end: b, a never beside it
    names = {(inst.tasks[i].id, inst.tasks[j].id) for i, j in exact._unordered_pairs(inst, h)}
    assert {tuple(sorted(p)) for p in names} == {("c", "d")}


def test_the_assignment_model_beyond_its_pair_limit_is_the_boolean_one(monkeypatch):
    """Beyond PAIR_TERMS pair literals the assignment formulation solves the boolean model,
    and the result says so."""
    import lvws_ros.policies.exact as exact
    from lvws_ros.core.families import family_instance

    inst = family_instance("traits-roles", 0, 0)
    monkeypatch.setattr(exact, "PAIR_TERMS", 0)
    res = solve_exact(inst, workers=2, time_limit=60, formulation="assignment")
    assert res.model == "boolean" and res.proven
    assert check_schedule(inst, res.schedule) == []


def test_auto_with_roles_solves_the_assignment_model_beside_its_own(monkeypatch):
    """With roles, "auto" solves its own model and the assignment model side by side (each
    with half the workers); the answer is the proven one or the shorter, with the better
    bound of the two; deterministic under a deterministic-time limit with two workers; with
    one worker its own model alone."""
    import lvws_ros.policies.exact as exact
    from lvws_ros.core.families import family_instance

    inst = family_instance("traits-roles", 1, 0)
    alone = solve_exact(inst, workers=2, time_limit=60, formulation="coalition")
    seen: dict[str, exact.ExpertResult] = {}
    solve = exact._solve_model

    def spy(inst, state, todo, hint, formulation, run):  # type: ignore[no-untyped-def]
        assert run.workers == 1
        seen[formulation] = solve(inst, state, todo, hint, formulation, run)
        return seen[formulation]

    monkeypatch.setattr(exact, "_solve_model", spy)
    runs = [solve_exact(inst, workers=2, work=0.2, time_limit=60) for _ in range(2)]
    assert set(seen) == {"auto", "assignment"}
    res = runs[0]
    assert res.schedule.assignments == runs[1].schedule.assignments
    assert res.makespan == pytest.approx(min(r.makespan for r in seen.values()))
    assert res.bound == pytest.approx(min(max(r.bound for r in seen.values()), res.makespan))
    assert res.model in ("coalition", "assignment") and check_schedule(inst, res.schedule) == []
    seen.clear()
    one = solve_exact(inst, workers=1, time_limit=60)  # one worker: one thread, its own model alone
    assert set(seen) == {"auto"} and one.model == "coalition"
    seen.clear()
    roomy = solve_exact(inst, workers=2, time_limit=60)
    assert roomy.proven and "auto" in seen and alone.proven
    assert roomy.makespan == pytest.approx(alone.makespan)


def test_a_proof_stops_the_model_beside_it():
    """Solved side by side, a proof stops the other model's search (it returns its best at
    once, not at its limit), and a model that starts after the proof does not solve."""
    import threading
    import time

    import lvws_ros.policies.exact as exact
    from lvws_ros.core.executor import State

    inst = random_instance(np.random.default_rng(7), 8, 60, "long")
    state = State.initial(inst)
    state.refresh()
    todo = state.tasks_to_do()
    hint = exact.left_shift(inst, exact.heuristic_schedule(inst, state), state)
    run = exact._Run(60.0, 1, 0, None, time.perf_counter())
    out: list[exact.ExpertResult] = []
    thread = threading.Thread(target=lambda: out.append(exact._solve_model(inst, state, todo, hint, "boolean", run)))
    thread.start()
    while not run.solvers:  # registered: its search is about to begin
        time.sleep(0.01)
    time.sleep(1.0)
    run.stop()  # as a model beside it does when it proves
    while thread.is_alive() and time.perf_counter() - run.t_start < 30:
        thread.join(0.1)
        run.stop()  # as the side-by-side loop does: a stop before the search began is given again
    assert not thread.is_alive() and time.perf_counter() - run.t_start < 30
    assert out[0].status == "feasible" and check_schedule(inst, out[0].schedule) == []
    late = exact._solve_model(inst, state, todo, hint, "assignment", run)
    assert late.status == "unknown" and late.schedule is hint
