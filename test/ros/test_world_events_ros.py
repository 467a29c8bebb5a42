"""The simulator's changing world on ROS: scripted events (``lvws launch --events``), the
services through ``lvws submit / cancel / fault`` while a namespaced run goes on, and a
run that ends with its reason when a failure makes a task impossible."""

from __future__ import annotations

import json
import random
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lvws_ros.cli.report import report, verify
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import LaunchError
from samples import EVENTS

pytestmark = pytest.mark.ros



def test_scripted_events_complete_and_the_bag_holds_the_final_task_set(tmp_path: Path):
    from lvws_ros.ros.launcher import launch

    events = tmp_path / "events.yaml"
    events.write_text(EVENTS)
    res = launch(policy="lvws", rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out", name="events",
                 gif=False, timeout=300.0, events=str(events), log=lambda _t: None)
    s = res.summary
    assert s["error"] == "" and s["tasks_done"] == s["tasks"] == 15, s
    assert [e.split(": ", 1)[1] for e in s["world_events"]] == [
        "t12 cancelled", "jackal_2 failed", "t15 submitted", "t16 submitted", "jackal_2 repaired"]
    rep = report(res.bag)
    assert rep.complete and check_schedule(rep.instance, rep.schedule) == []
    assert {a.task for a in rep.schedule.assignments} == {f"t{k:02d}" for k in range(1, 17)} - {"t12"}
    checked, bad = verify(res.bag)  # the recorded decisions replay through the same core
    assert checked == rep.decisions and not bad


def test_the_default_policy_auto_replans_through_the_events_and_completes_valid(tmp_path: Path):
    from lvws_ros.ros.bag import read_run
    from lvws_ros.ros.launcher import launch

    events = tmp_path / "events.yaml"
    events.write_text(EVENTS)  # a cancel, a robot failure mid-run, two new tasks, the repair
    res = launch(rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out", name="auto-events",
                 gif=False, timeout=300.0, events=str(events), log=lambda _t: None)
    s = res.summary
    assert s["error"] == "" and s["tasks_done"] == s["tasks"] == 15, s
    assert "jackal_2 failed" in " ".join(s["world_events"])
    rep = report(res.bag)
    assert rep.complete and check_schedule(rep.instance, rep.schedule) == []
    assert {d.policy for d in read_run(res.bag).decisions} == {"auto"}  # the node's default


def test_a_failure_that_makes_a_task_impossible_ends_the_run_with_the_reason(tmp_path: Path):
    from lvws_ros.ros.launcher import launch

    events = tmp_path / "events.yaml"
    events.write_text("- {at: 4.0, fail: husky_1}\n")
    with pytest.raises(LaunchError, match="can never finish"):
        launch(policy="grp", rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out", name="stuck",
               gif=False, timeout=120.0, events=str(events), log=lambda _t: None)
    s = json.loads((tmp_path / "out" / "stuck" / "summary.json").read_text())
    assert "t10: obj1 weighs 7" in s["error"] and s["failed_robots"] == ["husky_1"]


def lvws(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lvws_ros.cli", *args], capture_output=True, text=True, timeout=120)


def test_the_services_change_a_running_namespaced_cell_that_speaks_changes(tmp_path: Path):
    domain = str(random.SystemRandom().randint(1, 101))
    cell = ["--namespace", "cellS", "--domain-id", domain]
    tasks = tmp_path / "more.yaml"
    tasks.write_text("- {id: t15, type: assembly, object: obj1, cell: cell_3, duration: 3.0, after: [t14]}\n")
    run = subprocess.Popen([sys.executable, "-m", "lvws_ros.cli", "launch", *cell, "--policy", "grp", "--rate", "4",
                            "--protocol", "changes", "--retire-after", "0",  # the services speak through the world
                            "--no-gif", "--name", "svc", "--bag-dir", str(tmp_path / "bags"), "--out-dir",
                            str(tmp_path / "out"), "--timeout", "300"], stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        while not (tmp_path / "out" / "svc" / "cell_sim.log").is_file() or \
                "starting" not in (tmp_path / "out" / "svc" / "cell_sim.log").read_text():
            assert time.monotonic() < deadline and run.poll() is None, "the cell did not start"
            time.sleep(0.2)
        answers = {
            "cancel": lvws("cancel", "t12", *cell),
            "unknown": lvws("cancel", "t99", *cell),
            "submit": lvws("submit", str(tasks), *cell),
            "fail": lvws("fault", "husky_1", *cell),  # t10 needs it (obj1 weighs 7): impossible until repaired
            "repair": lvws("fault", "husky_1", "--repair", *cell),
        }
        out = run.communicate(timeout=400)[0]
    finally:
        if run.poll() is None:
            run.kill()
    for name, a in answers.items():
        if name == "unknown":
            assert a.returncode == 1 and "refused: unknown task 't99'" in a.stderr, a
        else:
            assert a.returncode == 0 and "done" in a.stdout, (name, a.stdout, a.stderr)
    assert run.returncode == 0, out
    s = json.loads((tmp_path / "out" / "svc" / "summary.json").read_text())
    kinds = [e.split(": ", 1)[1] for e in s["world_events"]]
    assert kinds[:2] == ["t12 cancelled", "t15 submitted"] and "husky_1 failed" in kinds
    assert "Warning: the run can never finish: t10: obj1 weighs 7" in answers["fail"].stdout
    assert "husky_1 repaired" in kinds and s["tasks_done"] == s["tasks"] == 14 and s["error"] == ""
    rep = report(tmp_path / "bags" / "svc")
    assert rep.complete and check_schedule(rep.instance, rep.schedule) == []
    assert {a.task for a in rep.schedule.assignments} == {f"t{k:02d}" for k in range(1, 16)} - {"t12"}
    assert rep.topics.get("/cellS/lvws/changes", 0) > 10
    assert lvws("cancel", "t01", "--namespace", "cellS", "--domain-id", domain, "--timeout", "2").returncode == 2
