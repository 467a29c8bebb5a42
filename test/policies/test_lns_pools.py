"""Large-neighbourhood search over pools of interchangeable robots: windows of counts per
pool on a PSPLIB project and on small instances with twins, from the start and from a
mid-run state; valid by `lvws check`, never longer, the same plan for the same seed."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from twins import twin_instances, with_twins

from lvws_ros.core.executor import simulate
from lvws_ros.core.importers import import_psplib
from lvws_ros.core.pools import pools, trivial
from lvws_ros.core.schedule import check_schedule
from lvws_ros.core.subteams import MAX_ENUMERATED
from lvws_ros.policies.baselines import GreedyPayloadPolicy, RandomSubteamPolicy
from lvws_ros.policies.lns import improve

PSPLIB = Path(__file__).resolve().parents[2] / "examples" / "psplib"


def test_pool_windows_improve_a_project_and_stay_valid():
    inst = import_psplib(PSPLIB / "j601_2.sm")
    assert not trivial(pools(inst))
    grp = simulate(inst, GreedyPayloadPolicy()).schedule
    found = improve(inst, grp, time_limit=60, max_rounds=6, round_limit=1.0, seed=0)
    assert check_schedule(inst, found.schedule) == []
    assert found.improved >= 1 and found.schedule.makespan < grp.makespan
    assert found.schedule.makespan >= 68  # the published optimum
    again = improve(inst, grp, time_limit=60, max_rounds=6, round_limit=1.0, seed=0)
    assert again.schedule.assignments == found.schedule.assignments  # deterministic time: the same plan


@pytest.mark.parametrize("roles", [False, True])
def test_pool_windows_from_a_mid_run_state_keep_what_has_started(roles):
    for small in twin_instances(4, roles=roles):
        inst = with_twins(small, [4] * small.num_robots)  # past the coalition model's size: windows over pools
        assert inst.num_robots > MAX_ENUMERATED
        run = simulate(inst, RandomSubteamPolicy(seed=1), record_states=True)
        state = run.steps[len(run.steps) // 3].state
        found = improve(inst, run.schedule, state=state, time_limit=60, max_rounds=4, round_limit=0.5, window=3)
        assert check_schedule(inst, found.schedule) == [], inst.name
        assert found.schedule.makespan <= run.schedule.makespan + 1e-9
        by_task = found.schedule.by_task()
        for j in np.flatnonzero(state.task_status >= 2):  # assigned or done: as they were
            a = by_task[inst.tasks[j].id]
            assert a.start == pytest.approx(state.task_start[j])
            assert a.robots == tuple(inst.robots[r].id for r in state.task_team[j])
        for j in state.tasks_to_do():  # busy robots join their pool only when free
            a = by_task[inst.tasks[j].id]
            assert all(a.start >= state.robot_free_at[inst.robot_index[r]] - 1e-9 for r in a.robots)
