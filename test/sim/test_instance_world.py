"""Duration noise for any instance file (``lvws solve --noise``): noise 0 is the
executor's run, the same seed the same run, every factor within the noise, and the
executed schedule valid by the durations the world took, with travel, traits and roles."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.formats import load_instance
from lvws_ros.core.schedule import check_schedule
from lvws_ros.registry import make_policy
from lvws_ros.sim.instance_world import duration_factor, run_noisy

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "weld_cell_traits.json"


@pytest.mark.parametrize("policy", ["grp", "lvws"])
def test_noise_zero_is_the_executor_and_a_seed_is_one_run(policy):
    """For the deterministic policies (a budgeted search such as auto's depends on the
    time it is given: see the next test)."""
    inst = dataset_instance(DATASETS["IV"], 2001, 0)  # travel
    exact = run_noisy(inst, lambda: make_policy(policy), 0.0, 3)
    assert exact.executed.makespan == pytest.approx(exact.planned.makespan, abs=1e-6)
    assert [(a.task, a.robots) for a in exact.executed.assignments] == \
        [(a.task, a.robots) for a in exact.planned.assignments]
    one = run_noisy(inst, lambda: make_policy(policy), 0.3, 3)
    two = run_noisy(inst, lambda: make_policy(policy), 0.3, 3)
    assert [(a.task, a.robots, a.start) for a in one.executed.assignments] == \
        [(a.task, a.robots, a.start) for a in two.executed.assignments]
    assert check_schedule(one.executed_instance, one.executed) == []
    for t, took in zip(inst.tasks, one.executed_instance.tasks, strict=True):
        assert 0.7 * t.duration - 1e-9 <= took.duration <= 1.3 * t.duration + 1e-9
        assert took.duration == pytest.approx(t.duration * duration_factor(0.3, 3, t.id))


def test_auto_runs_in_the_noisy_world_and_its_run_is_valid():
    inst = dataset_instance(DATASETS["IV"], 2001, 0)
    for noise in (0.0, 0.3):
        run = run_noisy(inst, lambda: make_policy("auto", budget_ms=200), noise, 3)
        assert check_schedule(run.executed_instance, run.executed) == []
        assert run.decisions > 0


def test_a_trait_cell_that_returns_home_runs_noisy_and_valid():
    inst = load_instance(EXAMPLE)
    run = run_noisy(inst, lambda: make_policy("grp"), 0.3, 1)
    assert check_schedule(run.executed_instance, run.executed) == []


def test_lvws_solve_prints_planned_and_executed_and_refuses_bad_noise():
    ok = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "solve", str(EXAMPLE), "--noise", "0.3",
                         "--noise-seed", "4"], capture_output=True, text=True, check=False)
    assert ok.returncode == 0 and "with duration noise 0.3 (noise seed 4): planned 19, executed" in ok.stderr
    bad = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "solve", str(EXAMPLE), "--noise", "1"],
                         capture_output=True, text=True, check=False)
    assert bad.returncode == 2 and "duration noise must be in [0, 1)" in bad.stderr and "Traceback" not in bad.stderr


def test_a_cell_departing_each_runs_online_as_its_plan_members_setting_out_on_their_own():
    """The TaskGraph carries "departure": "each": the node gives tasks to robots still busy
    (the plan's order), each sets out once free, and the run is the plan, to the second.
    Sent off together (as before the field), the same plan takes longer."""
    from dataclasses import replace

    from lvws_ros.core.executor import simulate
    from lvws_ros.planning.follow import PlanFollower

    inst = load_instance(Path(__file__).resolve().parents[2] / "examples" / "dcmrta" / "env_0.json")
    assert inst.departure == "each"
    plan = simulate(inst, make_policy("auto", seed=0, iterations=1)).schedule
    run = run_noisy(inst, lambda: PlanFollower(plan), 0.0, 0)
    assert run.executed.makespan == pytest.approx(plan.makespan, abs=1e-6)
    assert check_schedule(run.executed_instance, run.executed) == []
    # some task was given while a member was still at work: fewer decisions than tasks
    assert run.decisions < inst.num_tasks
    together = replace(inst, departure="together")
    apart = run_noisy(together, lambda: PlanFollower(plan), 0.0, 0)
    assert apart.executed.makespan > plan.makespan + 1.0
    noisy = run_noisy(inst, lambda: PlanFollower(plan), 0.2, 5)
    assert check_schedule(noisy.executed_instance, noisy.executed) == []
