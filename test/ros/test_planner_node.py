"""The scheduler node with its planner beside it (``auto``, the default), over DDS between
processes: decisions come from the plan while the planner works, the plan's figures are on
diagnostics, and when the planner's process is killed mid-run the run completes valid, the
node says so with a WARN and the planner comes back."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from lvws_ros.cli.report import report
from lvws_ros.core.schedule import check_schedule
from scheduler_probe import scheduler_probe

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
    run = subprocess.Popen([sys.executable, "-m", "lvws_ros.cli", "launch", "--rate", "4", "--no-gif", "--name",
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
        time.sleep(2.5)  # a few decisions from the plan (sim time runs at 4x)
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
    assert after and float(after[-1]["plan_makespan"]) > 0 and math.isfinite(float(after[-1]["plan_left"]))


def _answers(got: list[Any], now: float) -> list[Any]:
    """The decisions among ``got`` that answer the state stamped ``now``."""
    return [m for m in got if abs(m.team_stamp.sec + m.team_stamp.nanosec * 1e-9 - now) < 1e-6]


FLEET_PACE = 0.3  # wall seconds per unit of the cell's time: its tasks take time, as a real cell's do


def test_decisions_come_from_the_plan_while_the_planner_works_on_a_fleet_cell(ros_context: Any) -> None:
    """A 100-robot x 500-task cell (a world driven by the executor, over DDS) scheduled by
    the node's ``auto``: its planner's plan arrives while the cell runs and the decisions go
    on from it, every due step is answered, and the executed schedule is valid. (How fast
    each decision is belongs to the benchmark: ``bench_scale --latency``.)"""
    from lvws_ros.cli.bench_scale import cell_snapshots, make_instance
    from lvws_ros.core.executor import State, TaskStatus, schedule_from_state
    from lvws_ros.ros import convert

    inst = make_instance("ours", 100, 500, 0)
    state = State.initial(inst)
    seen_free: set[int] = set()
    seen_ready: set[int] = set()
    plan_seen_at = None  # how many decisions had come when the diagnostics first carried a plan
    due_steps = answered = 0
    with scheduler_probe(ros_context, "lvws_fleet_world", ["-p", "seed:=0"]) as probe:
        probe.wait_for_scheduler()
        while not state.done():
            team, graph = cell_snapshots(state)
            before = len(probe.got)
            probe.graph_pub.publish(convert.graph_to_msg(graph))
            probe.team_pub.publish(convert.team_to_msg(team))
            free, ready = set(state.free_robots()), set(state.ready_tasks())
            running = bool((state.task_status == TaskStatus.ASSIGNED).any())
            if free and ready and (free - seen_free or ready - seen_ready or not running):  # the node's rule
                due_steps += 1

                probe.spin(60.0, lambda: bool(_answers(probe.got[before:], state.time)))  # noqa: B023
                for m in _answers(probe.got[before:], state.time)[:1]:
                    answered += 1
                    for a in m.assignments:
                        state.start(inst.task_index[a.task_id], [inst.robot_index[r] for r in a.robot_ids])
                    free -= {inst.robot_index[r] for a in m.assignments for r in a.robot_ids}
                    ready -= {inst.task_index[a.task_id] for a in m.assignments}
            seen_free, seen_ready = free, ready
            if plan_seen_at is None and any("plan_makespan" in v for v in probe.values):
                plan_seen_at = answered
            nxt = state.next_event_time()
            assert nxt is not None, f"no progress at t={state.time}"
            probe.spin(FLEET_PACE * (nxt - state.time))
            state.time = nxt
            state.refresh()
        probe.spin(1.5)
    print(f"fleet cell: {answered} decisions, the plan seen after {plan_seen_at}")
    assert answered == due_steps, f"{due_steps - answered} due steps got no decision"
    assert check_schedule(inst, schedule_from_state(state, "auto")) == []
    assert plan_seen_at is not None, "no plan reached diagnostics"
    assert answered - plan_seen_at >= answered // 3, (plan_seen_at, answered)  # the later decisions: the plan's
    assert all(v.get("planner_restarts", "0") == "0" for v in probe.values)
