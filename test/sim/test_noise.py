"""Duration noise in the simulator: seeded (the same seed, the same executed run), noise 0
is the exact world, each task's factor lies within the noise, and the executed schedule
stays valid by the durations the world took."""

from __future__ import annotations

import subprocess
import sys

import pytest

from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import ConfigError
from lvws_ros.registry import make_policy
from lvws_ros.ros.resources import case_study_config
from lvws_ros.sim.config import load_cell_config
from lvws_ros.sim.runner import run_offline
from lvws_ros.sim.world import CellSim

CFG = load_cell_config(case_study_config())


def _run(noise: float, seed: int, policy: str = "grp"):
    sim = CellSim(CFG, noise=noise, noise_seed=seed)
    sched, _ = run_offline(sim, make_policy(policy))
    return sim, sched


def _key(sched):
    return [(a.task, a.robots, round(a.start, 6), round(a.end, 6)) for a in sched.assignments]


def test_noise_zero_is_the_exact_world_and_the_same_seed_the_same_run():
    exact = run_offline(CellSim(CFG), make_policy("grp"))[0]
    assert _key(_run(0.0, 5)[1]) == _key(exact)
    a, b = _run(0.3, 7)[1], _run(0.3, 7)[1]
    assert _key(a) == _key(b)
    assert _key(_run(0.3, 8)[1]) != _key(a)


def test_each_task_takes_its_duration_within_the_noise_and_the_run_stays_valid():
    sim, sched = _run(0.3, 3)
    factors = [sim.duration_factor(t.id) for t in CFG.tasks]
    assert all(0.7 <= f <= 1.3 for f in factors) and len({round(f, 6) for f in factors}) > 1
    executed = sim.executed_instance()
    assert check_schedule(executed, sched) == []
    nominal = {t.id: t.duration for t in sim.inst.tasks}
    work = [t for t in CFG.tasks if t.type != "transport"]
    for t in work:  # a work task's executed duration is its nominal one times its factor
        a = next(x for x in sched.assignments if x.task == t.id)
        assert (a.end - a.start) == pytest.approx(nominal[t.id] * sim.duration_factor(t.id), abs=0.06)


def test_noise_of_one_or_more_is_refused():
    with pytest.raises(ConfigError, match="duration noise"):
        CellSim(CFG, noise=1.0)
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "sim", "--policy", "grp", "--noise", "1.5"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "duration noise" in out.stderr and "Traceback" not in out.stderr
