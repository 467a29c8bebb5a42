"""The DCMRTA / CTAS-D importer: the shipped instance folder gives exactly the shipped
instance file (sites recovered from the distances, durations, requirements, 20 robots
at the depot with the way home), and malformed folders are refused naming the file and
the item, with exit code 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lvws_ros.core.formats import load_instance

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "examples" / "dcmrta" / "env_0"


def _import(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "dcmrta", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, check=False)


def _same(a: Any, b: Any) -> bool:
    """Equal JSON values, numbers within 1e-9 of each other."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and bool(np.isclose(a, b, rtol=0, atol=1e-9))
    return bool(a == b)


def test_the_shipped_folder_gives_the_shipped_instance(tmp_path):
    out = tmp_path / "env_0.json"
    res = _import(FOLDER, "--name", "dcmrta-20a-50t-env_0", "--out", out)
    assert res.returncode == 0, res.stderr
    # the same file, but for the last bits of the recovered sites: the eigen-decomposition's
    # rounding follows the CPU's kernels (OpenBLAS picks them at run time)
    assert _same(json.loads(out.read_text()), json.loads((ROOT / "examples" / "dcmrta" / "env_0.json").read_text()))
    inst = load_instance(out)
    assert inst.num_robots == 20 and inst.num_tasks == 50 and inst.objective == "return"
    assert inst.tasks[0].duration == 4.830310403920351
    # edge0 of vehicle0 is [0, 1, 0, 0.26923954439491876, 0, 1.3461977219745938]: t0 to t1 in 1.346 s
    tr = inst.travel
    assert tr is not None
    assert np.isclose(tr.time(0, tr.task_from[0], tr.task_from[1]), 1.3461977219745938)


def test_malformed_folders_are_refused_naming_the_file_and_item(tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(FOLDER, bad)
    text = (bad / "task_param.yaml").read_text()
    (bad / "task_param.yaml").write_text(text.replace("capId: 0", "capId: 3", 1))
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "task0" in res.stderr and "capId 3" in res.stderr and "Traceback" not in res.stderr
    shutil.copy(FOLDER / "task_param.yaml", bad / "task_param.yaml")
    (bad / "planner_param.yaml").write_text("taskNum: [unclosed\n")
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "planner_param.yaml" in res.stderr and "Traceback" not in res.stderr
    (bad / "planner_param.yaml").unlink()
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "planner_param.yaml" in res.stderr
    assert not (tmp_path / "x.json").exists()


HETERO = ROOT / "examples" / "heteromrta"


def test_a_depot_per_vehicle_type_is_placed_from_its_own_distances(tmp_path):
    out = tmp_path / "env_0.json"
    res = _import(HETERO / "env_0", "--name", "heteromrta-15a-20t-env_0", "--out", out)
    assert res.returncode == 0, res.stderr
    assert _same(json.loads(out.read_text()), json.loads((HETERO / "env_0.json").read_text()))
    inst = load_instance(out)
    assert inst.num_robots == 15 and inst.num_tasks == 20 and inst.departure == "each"
    tr = inst.travel
    assert tr is not None
    assert {tr.sites[tr.robot_site[r]] for r in range(15)} == {f"depot{k}" for k in range(5)}
    v1 = inst.robot_index["v1_0"]
    assert tr.sites[tr.home(v1)] == "depot1"
    # vehicle1's edge from its depot (node 21) to task 0: [21, 0, 0, 0.28917558240390157, 0, 1.4458779120195078]
    assert np.isclose(tr.time(v1, tr.robot_site[v1], tr.task_from[0]), 1.4458779120195078)
    # and vehicle0's from its own: [0, ...] edges of vehicle0 place depot0 elsewhere
    assert not np.isclose(tr.time(0, tr.robot_site[0], tr.task_from[0]), 1.4458779120195078)


def test_the_milp_plan_carried_out_gives_its_published_makespan_and_passes_check(tmp_path):
    """CTAS-D's 600 s plan of env_0 (its routes), each robot setting out once free: the
    makespan its results.yaml reports (timeCost / 100 = 27.845170); the same subteams and
    orders sent off together, as this product's worlds do, take longer."""
    from dataclasses import replace

    from lvws_ros.core.executor import State
    from lvws_ros.core.formats import load_schedule
    from lvws_ros.planning.follow import repair

    inst_file, plan_file = tmp_path / "env_0.json", tmp_path / "plan.json"
    res = _import(HETERO / "env_0", "--out", inst_file, "--plan", plan_file)
    assert res.returncode == 0, res.stderr
    check = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "check", str(inst_file), str(plan_file)],
                           capture_output=True, text=True, cwd=ROOT)
    assert check.returncode == 0, check.stdout + check.stderr
    plan = load_schedule(plan_file)
    assert plan.makespan == pytest.approx(27.845170, abs=1e-5)
    together = replace(load_instance(inst_file), departure="together")
    assert repair(State.initial(together), plan).schedule.makespan > plan.makespan + 3


def test_the_shipped_benchmarks_let_robots_set_out_on_their_own():
    for folder, count in ((ROOT / "examples" / "dcmrta", 50), (HETERO, 50)):
        files = sorted(folder.glob("env_*.json"))
        assert len(files) == count
        assert all(load_instance(f).departure == "each" for f in files)


def test_a_missing_or_broken_plan_is_refused_naming_the_file(tmp_path):
    res = _import(FOLDER, "--out", tmp_path / "x.json", "--plan", tmp_path / "plan.json")  # DCMRTA ships no results
    assert res.returncode == 2 and "results.yaml" in res.stderr and "Traceback" not in res.stderr
    bad = tmp_path / "bad"
    shutil.copytree(HETERO / "env_0", bad)
    text = (bad / "results.yaml").read_text()
    (bad / "results.yaml").write_text(text.replace("node: [0, 13, 8, 2, 4, 0]", "node: [0, 13, 8, 2, 99, 0]", 1))
    res = _import(bad, "--out", tmp_path / "x.json", "--plan", tmp_path / "plan.json")
    assert res.returncode == 2 and "node 99" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "plan.json").exists()


def test_a_plan_whose_visitors_do_not_cover_a_task_is_refused_naming_it(tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(HETERO / "env_0", bad)
    text = (bad / "results.yaml").read_text()
    (bad / "results.yaml").write_text(text.replace("node: [0, 13, 8, 2, 4, 0]", "node: [0, 13, 8, 2, 0]", 1))
    res = _import(bad, "--out", tmp_path / "x.json", "--plan", tmp_path / "plan.json")
    assert res.returncode == 2 and "'t3'" in res.stderr and "do not cover" in res.stderr, res.stderr
    assert not (tmp_path / "plan.json").exists()


def _line_graph(points: list[tuple[float, float]], depot: tuple[float, float]) -> dict[str, Any]:
    """One vehicle type's CTAS-D graph: the tasks at ``points``, its depot (nodes n and n + 1)."""
    where = [*points, depot, depot]
    edges = {}
    for a in range(len(where)):
        for b in range(len(where)):
            if a != b:
                d = float(np.hypot(where[a][0] - where[b][0], where[a][1] - where[b][1]))
                edges[f"edge{len(edges)}"] = [a, b, 0, d, 0, d / 0.2]
    return {**edges, **{f"node{j}": 1.0 for j in range(len(points))}}


@pytest.mark.parametrize("points", [[(0.0, 1.0), (1.0, 1.0), (3.0, 1.0)], [(0.0, 1.0), (1.0, 1.0)], [(0.5, 0.5)]])
def test_a_depot_is_placed_when_the_tasks_lie_on_a_line_or_are_one(points):
    """Trilateration from collinear tasks (or one) leaves a mirror image: either keeps every distance."""
    from lvws_ros.core.importers import dcmrta_instance

    n = len(points)
    graph = {"vehicle0": _line_graph(points, (0.0, 0.0)), "vehicle1": _line_graph(points, (2.0, 3.0))}
    tasks = {f"task{j}": {"and0": {"or0": {"capId": j % 2, "capReq": 1.0, "capVar": 0.0, "geq": True}}}
             for j in range(n)}
    vehicles = {"vehicle0": {"capVector": [1.0, 0.0]}, "vehicle1": {"capVector": [0.0, 1.0]}}
    planner = {"taskNum": n, "vehNumPerType": [1, 1], "capNum": 2}
    inst = dcmrta_instance(graph, tasks, vehicles, planner, "line", "line")
    tr = inst.travel
    assert tr is not None
    for j, (x, y) in enumerate(points):
        for r, depot in ((0, (0.0, 0.0)), (1, (2.0, 3.0))):
            assert tr.time(r, tr.robot_site[r], tr.task_from[j]) == pytest.approx(
                np.hypot(x - depot[0], y - depot[1]) / 0.2)
