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
