"""The robot's side of ExecuteTask over real DDS: ``lvws fake-robots`` (and the plain
example server) in processes of their own, goals sent from here with an rclpy
ActionClient, as the dispatcher sends them.

The file runs on a DDS domain of its own (not the session's of conftest.py), so robots
named like other tests' never answer them.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import rclpy
from action_msgs.msg import GoalStatus
from lvws_msgs.action import ExecuteTask
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor

from conftest import REPO

pytestmark = pytest.mark.ros  # crosses processes over real DDS

DOMAIN = random.SystemRandom().randint(102, 232)  # conftest's session domains are 1-101
NS = "/robots_test"
RATE = 20.0  # the fake robots' time runs 20 x faster: 1 s of the cell is 50 ms
ENV = {**os.environ, "ROS_DOMAIN_ID": str(DOMAIN), "PYTHONPATH": str(REPO), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
CELL = {
    "format": "lvws-instance/1", "name": "robots-test", "capabilities": ["move", "fit"],
    "sites": {"dock": [0.0, 0.0], "b": [3.0, 4.0]},
    "robots": [
        {"id": "mover", "capabilities": [1, 0], "payload": 1.0, "site": "dock", "speed": 1.0},
        {"id": "arm", "capabilities": [0, 1], "payload": 1.0, "site": "b"},
        {"id": "spare", "capabilities": [1, 0], "payload": 1.0, "site": "dock", "speed": 2.0},
    ],
    "tasks": [
        {"id": "carry", "capabilities": [1, 0], "payload": 1.0, "duration": 4.0, "after": [], "site": "b"},
        {"id": "fit", "capabilities": [0, 1], "payload": 1.0, "duration": 4.0, "after": ["carry"], "site": "b"},
    ],
}


def lvws(*args: str) -> list[str]:
    return [sys.executable, "-m", "lvws_ros.cli", *args]


def stop(proc: subprocess.Popen[Any]) -> int:
    if proc.poll() is None:
        proc.terminate()
    try:
        return proc.wait(timeout=15)
    except subprocess.TimeoutExpired:
        proc.kill()
        return proc.wait()


@dataclass
class Outcome:
    accepted: bool
    status: int | None = None  # None: no result came
    result: Any = None
    feedback: list[tuple[float, Any]] = field(default_factory=list)  # (seconds since sent, feedback)

    @property
    def phases(self) -> list[str]:
        out: list[str] = []
        for _, f in self.feedback:
            if not out or out[-1] != f.phase:
                out.append(f.phase)
        return out


class Dispatcher:
    """The dispatcher's side, reduced to what the tests need: one goal at a time."""

    def __init__(self, context: rclpy.Context) -> None:
        self.node = rclpy.create_node("task_server_test", context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.clients: dict[str, ActionClient] = {}

    def client(self, name: str) -> ActionClient:
        if name not in self.clients:
            self.clients[name] = ActionClient(self.node, ExecuteTask, name)
            assert self.clients[name].wait_for_server(timeout_sec=30), f"no action server {name}"
        return self.clients[name]

    def wait(self, future: Any, seconds: float) -> bool:
        deadline = time.monotonic() + seconds
        while not future.done() and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)
        return bool(future.done())

    def send(self, robot: str, task: str, subteam: list[str], duration: float, site: str = "b", site_to: str = "",
             cancel_when_working: bool = False, seconds: float = 20.0, namespace: str = NS) -> Outcome:
        client = self.client(f"{namespace}/{robot}/execute_task")
        sent = time.monotonic()
        feedback: list[tuple[float, Any]] = []
        goal = ExecuteTask.Goal(task_id=task, subteam=subteam, site=site, site_to=site_to, planned_duration=duration)
        accept = client.send_goal_async(goal, feedback_callback=lambda m: feedback.append(
            (time.monotonic() - sent, m.feedback)))
        assert self.wait(accept, 10.0), "no answer to the goal"
        handle = accept.result()
        if not handle.accepted:
            return Outcome(False)
        result = handle.get_result_async()
        if cancel_when_working:
            deadline = time.monotonic() + 10.0
            while not any(f.phase == "working" for _, f in feedback) and time.monotonic() < deadline:
                self.executor.spin_once(timeout_sec=0.05)
            assert self.wait(handle.cancel_goal_async(), 10.0), "no answer to the cancel request"
        if not self.wait(result, seconds):
            return Outcome(True, None, None, feedback)
        return Outcome(True, result.result().status, result.result().result, feedback)

    def close(self) -> None:
        for c in self.clients.values():
            c.destroy()
        self.executor.shutdown()
        self.node.destroy_node()


@pytest.fixture(scope="module")
def cell(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cell") / "cell.json"
    path.write_text(json.dumps(CELL), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def dispatcher() -> Iterator[Dispatcher]:
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=DOMAIN)
    d = Dispatcher(context)
    try:
        yield d
    finally:
        d.close()
        context.try_shutdown()


@pytest.fixture(scope="module")
def robots(cell: Path) -> Iterator[subprocess.Popen[str]]:
    """mover and arm (not spare: the crash test serves it alone); arm aborts 'fit'."""
    log = cell.parent / "fake_robots.log"
    with log.open("w", encoding="utf-8") as err:
        proc = subprocess.Popen(lvws("fake-robots", str(cell), "--robots", "mover,arm", "--namespace", NS[1:],
                                     "--rate", str(RATE), "--abort", "arm:fit"), env=ENV, stderr=err, text=True)
        try:
            yield proc
            assert proc.poll() is None, f"fake-robots died: {log.read_text(encoding='utf-8')}"
        finally:
            code = stop(proc)
    assert code == 0, f"fake-robots did not exit cleanly on SIGTERM ({code}): {log.read_text(encoding='utf-8')[-3000:]}"
    assert "Traceback" not in log.read_text(encoding="utf-8")


def test_a_goal_travels_then_works_and_succeeds(robots, dispatcher):
    out = dispatcher.send("mover", "carry", ["mover", "arm"], 4.0)
    assert out.status == GoalStatus.STATUS_SUCCEEDED, out
    assert out.result.success and out.result.duration == pytest.approx(4.0)  # work only: no noise, travel excluded
    assert out.phases == ["travelling", "working"]
    travelling = [f for _, f in out.feedback if f.phase == "travelling"]
    working = [f for _, f in out.feedback if f.phase == "working"]
    assert {f.site for f in travelling} == {""} and {f.site for f in working} == {"b"}
    assert working[-1].progress == pytest.approx(1.0) and (working[-1].pose.x, working[-1].pose.y) == (3.0, 4.0)
    progress = [f.progress for _, f in out.feedback]
    assert progress == sorted(progress)
    # 5 m at 1 m/s, then 4 s of work, 20 x faster: 0.45 s; feedback at least every 0.2 s of it
    assert out.feedback[-1][0] >= 0.4 and len(out.feedback) >= 0.45 / 0.2
    again = dispatcher.send("mover", "carry_on", ["mover"], 2.0)  # it is at b now: no travel
    assert again.status == GoalStatus.STATUS_SUCCEEDED and again.phases == ["working"], again


def test_a_transport_ends_at_its_site_to(robots, dispatcher):
    out = dispatcher.send("mover", "haul", ["mover"], 2.0, site="dock", site_to="b")
    assert out.status == GoalStatus.STATUS_SUCCEEDED and out.result.duration == pytest.approx(2.0), out
    working = [f for _, f in out.feedback if f.phase == "working"]
    assert working[0].site == "" and working[-1].site == "b"  # it carries from dock to b while it works
    after = dispatcher.send("mover", "at_b", ["mover"], 1.0, site="b")
    assert after.status == GoalStatus.STATUS_SUCCEEDED and after.phases == ["working"], after


def test_a_goal_whose_subteam_omits_the_robot_is_rejected(robots, dispatcher):
    assert not dispatcher.send("mover", "carry", ["arm", "spare"], 4.0).accepted


def test_cancel_mid_task_ends_canceled_and_frees_the_robot(robots, dispatcher):
    out = dispatcher.send("arm", "long", ["arm"], 400.0, cancel_when_working=True)
    assert out.status == GoalStatus.STATUS_CANCELED, out
    assert not out.result.success and 0.0 < out.result.duration < 400.0
    assert dispatcher.send("arm", "short", ["arm"], 1.0).status == GoalStatus.STATUS_SUCCEEDED


def test_a_busy_robot_rejects_a_second_goal(robots, dispatcher):
    client = dispatcher.client(f"{NS}/arm/execute_task")
    first = client.send_goal_async(ExecuteTask.Goal(task_id="long", subteam=["arm"], site="b", planned_duration=400.0))
    assert dispatcher.wait(first, 10.0) and first.result().accepted
    try:
        assert not dispatcher.send("arm", "other", ["arm"], 1.0).accepted
    finally:
        assert dispatcher.wait(first.result().cancel_goal_async(), 10.0)
        assert dispatcher.wait(first.result().get_result_async(), 10.0)


def test_a_scripted_abort_aborts_with_its_message(robots, dispatcher):
    out = dispatcher.send("arm", "fit", ["arm", "mover"], 4.0)
    assert out.status == GoalStatus.STATUS_ABORTED, out
    assert not out.result.success and "fit" in out.result.message and "--abort" in out.result.message
    assert out.result.duration == pytest.approx(2.0, abs=1.0)  # halfway through 4 s of work
    assert dispatcher.send("arm", "fit_again", ["arm"], 1.0).status == GoalStatus.STATUS_SUCCEEDED


def test_a_crash_ends_the_process_and_the_goal_never_succeeds(cell, dispatcher):
    proc = subprocess.Popen(lvws("fake-robots", str(cell), "--robots", "spare", "--namespace", "/crash_test",
                                 "--rate", str(RATE), "--crash", "spare:boom"), env=ENV, stderr=subprocess.PIPE, text=True)
    try:
        out = dispatcher.send("spare", "boom", ["spare"], 40.0, seconds=3.0, namespace="/crash_test")  # 2 s of work
        assert proc.wait(timeout=10) == 137  # os._exit, as a SIGKILL would have it
        assert out.accepted and out.status is None  # no result came, nor will
        assert out.feedback and out.feedback[-1][1].phase == "working"
        assert "crashing" in (proc.stderr.read() if proc.stderr else "")
    finally:
        stop(proc)


def test_sigint_mid_task_ends_the_process_cleanly(cell, dispatcher):
    proc = subprocess.Popen(lvws("fake-robots", str(cell), "--robots", "spare", "--namespace", "/sigint_test",
                                 "--rate", str(RATE)), env=ENV, stderr=subprocess.PIPE, text=True)
    try:
        client = dispatcher.client("/sigint_test/spare/execute_task")
        feedback: list[Any] = []
        sent = client.send_goal_async(ExecuteTask.Goal(task_id="long", subteam=["spare"], site="b",
                                                       planned_duration=400.0),
                                      feedback_callback=lambda m: feedback.append(m.feedback.phase))
        assert dispatcher.wait(sent, 10.0) and sent.result().accepted
        deadline = time.monotonic() + 10.0
        while "working" not in feedback and time.monotonic() < deadline:
            dispatcher.executor.spin_once(timeout_sec=0.05)
        assert "working" in feedback
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
        assert "Traceback" not in (proc.stderr.read() if proc.stderr else "")
    finally:
        stop(proc)


def test_the_plain_example_server_answers_a_goal(dispatcher):
    proc = subprocess.Popen([sys.executable, str(REPO / "examples" / "robots" / "plain_server.py"), "p1", "--rate",
                             str(RATE), "--ros-args", "-r", "__ns:=/plain_test"], env=ENV)
    try:
        out = dispatcher.send("p1", "job", ["p1", "p2"], 2.0, namespace="/plain_test")
        assert out.status == GoalStatus.STATUS_SUCCEEDED and out.result.success, out
        assert out.result.duration == pytest.approx(2.0) and "working" in out.phases
        assert not dispatcher.send("p1", "job", ["p2"], 2.0, namespace="/plain_test").accepted
    finally:
        assert stop(proc) == 0


@pytest.mark.parametrize(("args", "named"), [
    (["--robots", "mover,ghost"], "'ghost'"),
    (["--abort", "ghost:carry"], "'ghost'"),
    (["--crash", "mover"], "'mover'"),
    (["--abort", "mover:carry:flying"], "unknown phase 'flying'"),
    (["--rate", "0"], "--rate"),
    (["--noise", "1.5"], "--noise"),
])
def test_bad_input_exits_2_naming_the_item(cell, args, named):
    res = subprocess.run(lvws("fake-robots", str(cell), *args), env=ENV, capture_output=True, text=True, timeout=60)
    assert res.returncode == 2 and named in res.stderr and "Traceback" not in res.stderr, res.stderr


def test_a_malformed_cell_file_exits_2_naming_the_file(tmp_path):
    bad = tmp_path / "bad_cell.json"
    bad.write_text(json.dumps({**CELL, "robots": [{**CELL["robots"][0], "site": "nowhere"}]}), encoding="utf-8")
    res = subprocess.run([sys.executable, "-m", "lvws_ros.robot.fake", str(bad)], env=ENV, capture_output=True,
                         text=True, timeout=60)  # the fake_robots executable's main
    assert res.returncode == 2, res.stderr
    assert "bad_cell.json" in res.stderr and "nowhere" in res.stderr and "Traceback" not in res.stderr
