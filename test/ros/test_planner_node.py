"""The scheduler node with its planner beside it (``auto``, the default), over DDS between
processes: decisions come from the plan while the planner works, the plan's figures are on
diagnostics, and when the planner's process is killed mid-run the run completes valid, the
node says so with a WARN and the planner comes back."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from lvws_ros.cli.report import report
from lvws_ros.core.schedule import check_schedule

pytestmark = pytest.mark.ros


def _children(pid: int) -> list[int]:
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        text = (task / "children").read_text().split()
        out += [int(c) for c in text]
    return out


def _planner_of(scheduler: int) -> int | None:
    """The scheduler's child process that runs the planner (a multiprocessing spawn)."""
    for child in _children(scheduler):
        try:
            cmd = Path(f"/proc/{child}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if "multiprocessing" in cmd and "resource_tracker" not in cmd:
            return child
    return None


def test_killing_the_planner_mid_run_the_run_completes_valid_and_the_planner_comes_back(tmp_path: Path):
    out = tmp_path / "out"
    run = subprocess.Popen([sys.executable, "-m", "lvws_ros.cli", "launch", "--rate", "2", "--no-gif", "--name",
                            "kill", "--bag-dir", str(tmp_path / "bags"), "--out-dir", str(out), "--timeout", "300"],
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        pids = out / "kill" / "pids.json"
        while not pids.is_file() or '"scheduler"' not in pids.read_text():
            assert time.monotonic() < deadline and run.poll() is None, "the cell did not start"
            time.sleep(0.2)
        time.sleep(0.2)  # written whole
        scheduler = json.loads(pids.read_text())["scheduler"]
        planner = None
        while planner is None:
            assert time.monotonic() < deadline and run.poll() is None, "no planner process beside the scheduler"
            planner = _planner_of(scheduler)
            time.sleep(0.2)
        log = out / "kill" / "scheduler.log"
        while not log.is_file() or "step 1:" not in log.read_text():
            assert time.monotonic() < deadline and run.poll() is None, "no decision"
            time.sleep(0.2)
        time.sleep(5.0)  # a few decisions from the plan (sim time runs at 2x)
        os.kill(planner, signal.SIGKILL)
        text = run.communicate(timeout=400)[0]
    finally:
        if run.poll() is None:
            run.kill()
    assert run.returncode == 0, text
    summary = json.loads((out / "kill" / "summary.json").read_text())
    assert summary["error"] == "" and summary["tasks_done"] == summary["tasks"] == 14, summary
    rep = report(next((tmp_path / "bags").iterdir()))
    assert rep.complete and check_schedule(rep.instance, rep.schedule) == []
    from lvws_ros.ros.bag import read_run

    diags = read_run(next((tmp_path / "bags").iterdir())).diagnostics
    warns = [d for d in diags if d["level"] == str(1) and "planner's process is gone" in d["message"]]
    assert warns, [d["message"] for d in diags][-10:]
    restarts = [int(d["planner_restarts"]) for d in diags if "planner_restarts" in d]
    assert restarts and max(restarts) >= 1
    sources = {d.get("plan_source") for d in diags if d.get("plan_source")}
    assert sources, "the plan's figures never reached diagnostics"
    after = [d for d in diags if "plan_makespan" in d]
    assert after and float(after[-1]["plan_makespan"]) > 0
