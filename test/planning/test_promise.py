"""``auto``'s promise, whatever the time limit: the plan it returns is never longer than the
best quick plan that finished; when none would finish in time, the cheapest on the cell is
finished anyway and the overrun is reported; the quick plans run cheapest first, by what each
costs on the cell at hand."""

from __future__ import annotations

import json
import math
import time

import pytest

from lvws_ros.cli.main import main
from lvws_ros.core.executor import Decision, State, simulate
from lvws_ros.core.families import family_instance
from lvws_ros.core.formats import instance_to_dict
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import check_schedule
from lvws_ros.planning.auto import PlannedAutoPolicy
from lvws_ros.planning.planner import Planner
from lvws_ros.policies.baselines import GreedyPayloadPolicy


def _warehouse(n: int = 24, m: int = 60) -> Instance:
    return family_instance("warehouse", 0, 3, num_robots=n, num_tasks=m)


class _Slow(GreedyPayloadPolicy):
    """GRP that takes ``pause`` seconds more per decision: a quick plan dearer on this cell."""

    def __init__(self, pause: float) -> None:
        super().__init__()
        self.pause = pause

    def decide(self, state: State) -> Decision:
        time.sleep(self.pause)
        return super().decide(state)


def test_with_no_time_at_all_the_cheapest_quick_plan_is_finished_and_the_overrun_said():
    inst = _warehouse()
    planner = Planner(seed=0, workers=1)
    report = planner.run(State.initial(inst), time_limit=0.0)
    assert planner.plan is not None and check_schedule(inst, planner.plan.schedule) == []
    assert report.overrun > 0 and report.fallback == planner.plan.source
    assert set(planner.quick) == {report.fallback}  # only the one, not the dearer ones
    # the cheapest on this cell: GRP's (LVWS's network costs more per task)
    assert report.fallback.startswith("grp")
    # (LVWS is probed only when GRP's probe does not promise a whole plan within seconds)
    assert planner.quick_cost[report.fallback] <= planner.quick_cost.get("lvws", math.inf)


def test_the_dearest_quick_plan_runs_last_and_is_skipped_when_it_cannot_fit():
    inst = _warehouse()
    planner = Planner(seed=0, workers=1, learned=False)
    planner._quick = [("slow", lambda: _Slow(0.05)), ("grp", GreedyPayloadPolicy)]  # the slow one listed first
    report = planner.run(State.initial(inst), time_limit=0.5)
    assert planner.quick_order(State.initial(inst))[0][0] == "grp"
    assert "grp" in planner.quick and "slow" not in planner.quick  # 0.05 s x ~60 steps cannot fit 0.5 s
    assert report.overrun == 0 and report.fallback == ""
    assert planner.plan is not None and check_schedule(inst, planner.plan.schedule) == []


@pytest.mark.parametrize("limit", [0.0, 0.2, 3.0])
def test_auto_never_returns_a_plan_longer_than_a_quick_plan_that_finished(limit):
    inst = _warehouse()
    policy = PlannedAutoPolicy(time_limit=limit, workers=1)
    res = simulate(inst, policy)
    assert check_schedule(inst, res.schedule) == []
    finished = policy.planner.quick
    assert finished, "at least one quick plan always finishes"
    assert res.schedule.makespan <= min(makespan for makespan, _ in finished.values()) + 1e-9


def test_lvws_solve_says_by_how_much_the_limit_was_overrun(tmp_path, capsys):
    cell = tmp_path / "warehouse.json"
    cell.write_text(json.dumps(instance_to_dict(_warehouse())))
    out = tmp_path / "plan.json"
    assert main(["solve", str(cell), "--policy", "auto", "--time-limit", "0", "--workers", "1",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "overran the time limit of 0 s by" in err and "no quick plan had finished" in err
    assert main(["check", str(cell), str(out)]) == 0
