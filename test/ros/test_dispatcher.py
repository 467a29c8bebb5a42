"""The dispatcher over real DDS, each node its own process: the scheduler (grp), the
dispatcher of a cell file and ``lvws fake-robots`` (ExecuteTask servers); a test node
watches the goal events, the task graph and the diagnostics. A cell of 6 robots with
subteams, travel and precedence is done and its executed schedule, rebuilt from the bag,
passes ``lvws check``; a robot that aborts, and one whose process is killed with SIGKILL,
fail their task, which is planned again, and the run completes valid; the killed robot
is used again once its server is back; ``cancel_task`` cancels every member's goal; bad
input is named, never fatal."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import rclpy
from lvws_msgs.msg import Assignment, AssignmentArray, GoalEvent, Task, TaskGraph
from rclpy.qos import QoSProfile, ReliabilityPolicy
from test_runtime import read_with_anyreader, read_with_mcap

from lvws_ros.ros.convert import from_time
from lvws_ros.ros.service_call import call, ready
from lvws_ros.ros.topics import (
    ASSIGNMENTS_QOS,
    ASSIGNMENTS_TOPIC,
    DIAGNOSTICS_TOPIC,
    GOAL_EVENTS_TOPIC,
    GRAPH_QOS,
    GRAPH_TOPIC,
    TEAM_QOS,
    TEAM_TOPIC,
    message_class,
)

pytestmark = pytest.mark.ros

REPO = Path(__file__).resolve().parents[2]
RATE = 5.0  # the fake robots' time runs this much faster than the clock
TIMEOUT = 1.5  # the dispatcher's robot_timeout (s) where a test kills a robot
CALM = 6.0  # elsewhere: a loaded CI machine can starve a live robot's feedback for over 1.5 s
CELL = {
    "format": "lvws-instance/1", "name": "six-robots", "capabilities": ["lift", "weld", "scan", "paint"],
    "sites": {"dock": [0, 0], "a": [3, 0], "b": [3, 4], "c": [0, 4]},
    "robots": [
        {"id": "m1", "capabilities": [1, 0, 0, 0], "payload": 2, "site": "dock", "speed": 2.0},
        {"id": "m2", "capabilities": [1, 0, 0, 0], "payload": 2, "site": "dock", "speed": 2.0},
        {"id": "m3", "capabilities": [1, 0, 0, 1], "payload": 3, "site": "dock", "speed": 1.5},
        {"id": "s1", "capabilities": [0, 0, 1, 0], "payload": 1, "site": "dock", "speed": 2.0},
        {"id": "arm_b", "capabilities": [0, 1, 0, 0], "payload": 1, "site": "b"},
        {"id": "arm_c", "capabilities": [0, 1, 0, 0], "payload": 1, "site": "c"}],
    "tasks": [
        {"id": "t1", "capabilities": [1, 0, 0, 0], "payload": 4, "duration": 2, "after": [], "from": "a", "to": "b"},
        {"id": "t2", "capabilities": [1, 0, 0, 0], "payload": 2, "duration": 2, "after": [], "from": "a", "to": "c"},
        {"id": "t3", "capabilities": [0, 1, 0, 0], "payload": 0, "duration": 3, "after": ["t1"], "site": "b"},
        {"id": "t4", "capabilities": [0, 1, 0, 0], "payload": 0, "duration": 2, "after": ["t2"], "site": "c"},
        {"id": "t5", "capabilities": [0, 0, 1, 0], "payload": 0, "duration": 1, "after": ["t3"], "site": "b"},
        {"id": "t6", "capabilities": [1, 0, 1, 0], "payload": 3, "duration": 2, "after": ["t4"], "from": "c",
         "to": "dock"},
        {"id": "t7", "capabilities": [0, 0, 1, 0], "payload": 0, "duration": 1, "after": [], "site": "a"},
        {"id": "t8", "capabilities": [0, 0, 0, 1], "payload": 0, "duration": 1, "after": ["t5"], "site": "b"}],
}


@dataclass
class Cell:
    """The processes of a run and what the test node saw."""

    path: Path
    node: Any
    executor: Any
    procs: dict[str, subprocess.Popen[str]] = field(default_factory=dict)
    events: list[GoalEvent] = field(default_factory=list)
    graphs: list[TaskGraph] = field(default_factory=list)
    diags: list[str] = field(default_factory=list)

    def spin(self, seconds: float, until: Callable[[], bool]) -> bool:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            if until():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return until()

    def done(self) -> bool:
        return bool(self.graphs) and bool(self.graphs[-1].tasks) and \
            all(t.status == Task.STATUS_DONE for t in self.graphs[-1].tasks)

    def of(self, kind: int, robot: str | None = None) -> list[GoalEvent]:
        return [e for e in self.events if e.kind == kind and (robot is None or e.robot_id == robot)]

    def robots(self, robots: str, *extra: str) -> subprocess.Popen[str]:
        return _start([sys.executable, "-m", "lvws_ros.cli", "fake-robots", str(self.path), "--robots", robots,
                       "--rate", str(RATE), *extra])

    def stop(self) -> None:
        """SIGINT to every process still running, then wait for each (killed after 15 s)."""
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in self.procs.values():
            try:
                proc.communicate(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.communicate()

    def output(self, name: str) -> str:
        proc = self.procs[name]
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT)
        try:
            return proc.communicate(timeout=15)[0]
        except subprocess.TimeoutExpired:
            proc.kill()
            return proc.communicate()[0]


def _start(cmd: Sequence[str]) -> subprocess.Popen[str]:
    return subprocess.Popen(list(cmd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env={**os.environ, "PYTHONUNBUFFERED": "1"})


def watcher(ros_context: Any, tmp_path: Path, name: str, data: dict[str, Any]) -> Cell:
    """The cell file of ``data`` and a test node ``name`` that watches the goal events, the
    task graph and the diagnostics."""
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(data))
    node = rclpy.create_node(name, context=ros_context)
    executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    c = Cell(path, node, executor)
    reliable = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
    node.create_subscription(GoalEvent, GOAL_EVENTS_TOPIC, c.events.append, reliable)
    node.create_subscription(TaskGraph, GRAPH_TOPIC, c.graphs.append, GRAPH_QOS)
    node.create_subscription(message_class("diagnostic_msgs/msg/DiagnosticArray"), DIAGNOSTICS_TOPIC,
                             lambda m: c.diags.extend(s.message for s in m.status), reliable)
    return c


@contextmanager
def cell(ros_context: Any, tmp_path: Path, name: str, robots: dict[str, Sequence[str]] | None = None,
         bag: Path | None = None, data: dict[str, Any] | None = None, sim_time: bool = False,
         timeout: float = CALM, policy: str = "grp") -> Iterator[Cell]:
    """Scheduler (grp), dispatcher and the fake robots (process name -> its arguments;
    default: one process for every robot), and a recorder when ``bag`` is given; with
    ``sim_time``, every node on a simulated clock (helpers/sim_clock.py, 4x wall time)."""
    c = watcher(ros_context, tmp_path, name, data or CELL)
    node, path = c.node, c.path
    sim = ["-p", "use_sim_time:=true"] if sim_time else []
    # on wall time the dispatcher publishes the cell's clock (RATE x wall) and the scheduler follows it
    follow = [] if sim_time else ["-p", "use_sim_time:=true", "-p", f"ack_timeout:={5.0 * RATE}"]
    try:
        if sim_time:
            c.procs["clock"] = _start([sys.executable, str(Path(__file__).parent / "helpers" / "sim_clock.py")])
        if bag is not None:
            c.procs["recorder"] = _start([sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag)])
        c.procs["scheduler"] = _start([sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args",
                                       "-p", f"policy:={policy}", *sim, *follow])
        c.procs["dispatcher"] = _start([sys.executable, "-m", "lvws_ros.cli", "dispatcher", str(path), "--ros-args",
                                        "-p", f"robot_timeout:={timeout}", "-p", "rejoin_after:=2.0",
                                        "-p", f"rate:={RATE}", *(sim or ["-p", "publish_clock:=true"])])
        assert c.spin(30, lambda: node.count_publishers(GOAL_EVENTS_TOPIC) > 0)  # no goal event goes unseen
        for pname, args in (robots or {"robots": [",".join(r["id"] for r in CELL["robots"])]}).items():
            c.procs[pname] = c.robots(*args, *(["--use-sim-time"] if sim_time else []))
        yield c
    finally:
        c.stop()
        node.destroy_node()


def executed_is_valid(bag: Path, tmp_path: Path) -> str:
    """``lvws report`` of the bag, and ``lvws check`` of the executed instance and schedule it rebuilds."""
    from lvws_ros.cli.report import report
    from lvws_ros.core.formats import save_instance, save_schedule

    rep = report(bag)
    assert rep.complete, rep.text()
    save_instance(rep.instance, tmp_path / "executed_instance.json")
    save_schedule(rep.schedule, tmp_path / "executed.json")
    check = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "check", str(tmp_path / "executed_instance.json"),
                            str(tmp_path / "executed.json")], capture_output=True, text=True)
    assert check.returncode == 0, check.stdout + check.stderr
    return rep.text()


def test_six_robots_with_subteams_travel_and_precedence_complete_and_the_bag_checks(ros_context, tmp_path):
    bag = tmp_path / "bag"
    with cell(ros_context, tmp_path, "lvws_dispatch_watch", bag=bag) as c:
        assert c.spin(60, c.done), f"not done: {[(t.id, t.status) for t in c.graphs[-1].tasks]}"
        c.spin(1.0, lambda: False)  # the recorder takes the last state
    teams: dict[str, set[str]] = {}
    for e in c.of(GoalEvent.KIND_SUCCEEDED):
        teams.setdefault(e.task_id, set()).add(e.robot_id)
    assert set(teams) == {t["id"] for t in CELL["tasks"]}
    assert teams["t6"] >= {"s1"} and len(teams["t6"]) > 1 and len(teams["t1"]) > 1  # subteams ran
    assert not c.of(GoalEvent.KIND_ABORTED) and not c.of(GoalEvent.KIND_LOST)
    assert len(c.of(GoalEvent.KIND_SENT)) == sum(len(r) for r in teams.values())
    # the task graph is on the cell's clock (rate 5): each task spans its duration in the cell's seconds
    for t in c.graphs[-1].tasks:
        span = from_time(t.end_time) - from_time(t.start_time)
        assert 0.5 * t.duration <= span <= t.duration + 2.0 * RATE, (t.id, span, t.duration)  # wall: 0.2 x
    text = executed_is_valid(bag, tmp_path)
    assert "valid by formats.md: yes" in text and "goals per robot" in text
    report = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "report", str(bag)], capture_output=True, text=True)
    assert report.returncode == 0 and "goals per robot" in report.stdout, report.stdout + report.stderr


def never_double_booked(c: Cell) -> None:
    """No robot ever had two goals at once (a goal runs from sent to its end)."""
    ends = (GoalEvent.KIND_REJECTED, GoalEvent.KIND_SUCCEEDED, GoalEvent.KIND_ABORTED, GoalEvent.KIND_CANCELED,
            GoalEvent.KIND_LOST)
    open_goal: dict[str, str] = {}
    for e in c.events:
        if e.kind == GoalEvent.KIND_SENT:
            assert e.robot_id not in open_goal, f"{e.robot_id} sent {e.task_id} while on {open_goal[e.robot_id]}"
            open_goal[e.robot_id] = e.task_id
        elif e.kind in ends and open_goal.get(e.robot_id) == e.task_id:
            del open_goal[e.robot_id]


# departure each: the node gives tasks to busy robots (auto's plan), the dispatcher holds each
# member's goal until it is free; a member that aborts or is lost releases what it was given
DEPARTURES = [("together", "grp"), ("each", "auto")]


@pytest.mark.parametrize(("departure", "policy"), DEPARTURES)
def test_a_robot_that_aborts_fails_its_task_which_is_planned_again_and_the_run_completes(ros_context, tmp_path,
                                                                                         departure, policy):
    bag = tmp_path / "bag"
    with cell(ros_context, tmp_path, "lvws_dispatch_abort", bag=bag, data={**CELL, "departure": departure},
              policy=policy, robots={"robots": ["m1,m2,m3,s1,arm_b,arm_c",
                                                *(a for m in ("m1", "m2", "m3") for a in ("--abort", f"{m}:t1"))]}) as c:
        # whichever lifters take t1 first abort it (each lifter once): its second subteam succeeds
        assert c.spin(60, c.done), c.output("dispatcher")
        c.spin(1.0, lambda: False)
    aborts = c.of(GoalEvent.KIND_ABORTED)
    assert aborts and {e.task_id for e in aborts} == {"t1"}
    done = {e.task_id: e.robot_id for e in c.of(GoalEvent.KIND_SUCCEEDED)}
    assert "t1" in done and "t2" in done
    assert "valid by formats.md: yes" in executed_is_valid(bag, tmp_path)
    never_double_booked(c)


@pytest.mark.parametrize(("departure", "policy"), DEPARTURES)
def test_a_robot_killed_mid_task_is_lost_in_time_its_task_replanned_and_it_is_used_once_back(ros_context, tmp_path,
                                                                                            departure, policy):
    bag = tmp_path / "bag"
    with cell(ros_context, tmp_path, "lvws_dispatch_kill", bag=bag, data={**CELL, "departure": departure},
              timeout=TIMEOUT, policy=policy, robots={"robots": ["m1,m2,s1,arm_b,arm_c"], "m3": ["m3"]}) as c:
        assert c.spin(60, lambda: any(e.phase == "working" for e in c.of(GoalEvent.KIND_FEEDBACK, "m3")))
        task = c.of(GoalEvent.KIND_FEEDBACK, "m3")[-1].task_id
        c.procs["m3"].send_signal(signal.SIGKILL)
        killed = time.monotonic()
        assert c.spin(TIMEOUT + 10, lambda: bool(c.of(GoalEvent.KIND_LOST, "m3")))
        detected = time.monotonic() - killed
        print(f"SIGKILL detected after {detected:.2f} s (robot_timeout {TIMEOUT} s)")
        assert detected < TIMEOUT + 2.0  # within the timeout (plus the watch's period and the load's delays)
        lost = len(c.events)
        c.procs["m3 again"] = c.robots("m3")
        assert c.spin(60, c.done), c.output("dispatcher")
        c.spin(1.0, lambda: False)
    again = [e for e in c.events[lost:] if e.kind == GoalEvent.KIND_SUCCEEDED and e.robot_id == "m3"]
    assert again  # back in the team, and used (t8 needs its paint)
    assert task in {e.task_id for e in c.events[lost:] if e.kind == GoalEvent.KIND_SUCCEEDED}  # planned again
    assert "valid by formats.md: yes" in executed_is_valid(bag, tmp_path)
    never_double_booked(c)


# a waits at t1's site from the start; b drives 40 s (8 s of wall time at RATE) to join it there: a failure
# halfway (4 s) is known to the dispatcher well before the planned start, even a lost robot's (TIMEOUT)
PAIR = {
    "format": "lvws-instance/1", "name": "pair", "capabilities": ["hold", "fix"], "departure": "each",
    "sites": {"x": [0, 0], "far": [40, 0]},
    "robots": [{"id": "a", "capabilities": [1, 0], "payload": 1, "site": "x", "speed": 1.0},
               {"id": "b", "capabilities": [0, 1], "payload": 1, "site": "far", "speed": 1.0}],
    "tasks": [{"id": "t1", "capabilities": [1, 1], "payload": 0, "duration": 2, "after": [], "site": "x"},
              {"id": "t2", "capabilities": [1, 0], "payload": 0, "duration": 1, "after": ["t1"], "site": "x"}],
}


@pytest.mark.parametrize("fault", ["abort", "crash"])
def test_a_member_that_fails_on_its_way_while_the_other_waits_at_the_site_releases_it_and_the_task_runs_again(
        ros_context, tmp_path, fault):
    """Departing each: ``a`` is at the task's site and waits for the planned start while
    ``b`` is on its way; ``b`` aborts halfway (or its process dies there). The waiting
    member is released (its goal cancelled), the task goes back to the scheduler, and it
    runs again with ``b`` back: done, valid, nobody booked twice."""
    bag = tmp_path / "bag"
    robots = {"robots": ["a,b", "--abort", "b:t1:travelling"]} if fault == "abort" else \
        {"a": ["a"], "b": ["b", "--crash", "b:t1:travelling"]}
    with cell(ros_context, tmp_path, f"lvws_dispatch_wait_{fault}", bag=bag, data=PAIR, robots=robots,
              timeout=TIMEOUT if fault == "crash" else CALM) as c:
        failed = GoalEvent.KIND_ABORTED if fault == "abort" else GoalEvent.KIND_LOST
        assert c.spin(60, lambda: bool(c.of(failed, "b"))), c.output("dispatcher")
        if fault == "crash":
            c.procs["b again"] = c.robots("b")
        assert c.spin(60, c.done), c.output("dispatcher")
        c.spin(1.0, lambda: False)
    first = c.events.index(c.of(failed, "b")[0])
    waited = [e for e in c.events[:first] if e.robot_id == "a" and e.task_id == "t1" and e.phase == "waiting"]
    assert waited, "a was not waiting at the site when b failed"
    assert [e for e in c.events[first:] if e.kind == GoalEvent.KIND_CANCELED and e.robot_id == "a"], "a kept waiting"
    assert {e.robot_id for e in c.of(GoalEvent.KIND_SUCCEEDED) if e.task_id == "t1"} == {"a", "b"}
    never_double_booked(c)
    assert "valid by formats.md: yes" in executed_is_valid(bag, tmp_path)


# b works t0 at "far" (20 m off, 10 s) and comes back to x for t1 with a, who drives 20 m from "home": given
# both tasks at once, a sets out at once, is at x at 20 and waits for the planned start, 50. b's own process
# works 1.9 x slower (noise seed 38 gives t0 that factor): 9 s late, it sets out for t1 at 39 (11 s before the
# start a knows: 2.2 s of wall time for the news to reach a), and the start moves to 59 while a waits
LATE = {
    "format": "lvws-instance/1", "name": "late", "capabilities": ["hold", "fix"], "departure": "each",
    "sites": {"x": [0, 0], "far": [20, 0], "home": [0, 20]},
    "robots": [{"id": "a", "capabilities": [1, 0], "payload": 1, "site": "home", "speed": 1.0},
               {"id": "b", "capabilities": [0, 1], "payload": 1, "site": "x", "speed": 1.0}],
    "tasks": [{"id": "t0", "capabilities": [0, 1], "payload": 0, "duration": 10, "after": [], "site": "far"},
              {"id": "t1", "capabilities": [1, 1], "payload": 0, "duration": 2, "after": [], "site": "x"}],
}


def test_a_member_later_than_planned_moves_the_start_and_the_member_waiting_at_the_site_waits_for_it(
        ros_context, tmp_path):
    """Departing each, the assignments published here (no scheduler): ``a`` is sent to t1
    while ``b`` still works on t0; ``b`` is late, and when it sets out the dispatcher
    publishes t1's new planned start on lvws/planned_starts. ``a``, there first, waits for
    it: it starts with ``b``, not at the start its goal named."""
    from lvws_msgs.msg import PlannedStart

    from lvws_ros.rosbase.goals import PLANNED_STARTS_QOS, PLANNED_STARTS_TOPIC

    c = watcher(ros_context, tmp_path, "lvws_dispatch_late", LATE)
    node, path = c.node, c.path
    moved: list[PlannedStart] = []
    node.create_subscription(PlannedStart, PLANNED_STARTS_TOPIC, moved.append, PLANNED_STARTS_QOS)
    teams: list[Any] = []  # both robots in the team (published every second): the assignments can go out
    node.create_subscription(message_class("lvws_msgs/msg/TeamState"), TEAM_TOPIC, teams.append, TEAM_QOS)
    pub = node.create_publisher(AssignmentArray, ASSIGNMENTS_TOPIC, ASSIGNMENTS_QOS)
    bag = tmp_path / "bag"
    try:
        c.procs["recorder"] = _start([sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag)])
        c.procs["dispatcher"] = _start([sys.executable, "-m", "lvws_ros.cli", "dispatcher", str(path), "--ros-args",
                                        "-p", f"robot_timeout:={CALM}", "-p", f"rate:={RATE}"])
        c.procs["a"] = c.robots("a")
        c.procs["b"] = c.robots("b", "--noise", "0.9", "--noise-seed", "38")
        up = lambda: bool(teams) and {r.id for r in teams[-1].robots} == {"a", "b"}  # noqa: E731
        assert c.spin(30, lambda: pub.get_subscription_count() >= 1 and up()), c.output("dispatcher")
        pub.publish(AssignmentArray(decision_step=0, assignments=[Assignment(task_id="t0", robot_ids=["b"]),
                                                                  Assignment(task_id="t1", robot_ids=["a", "b"])]))
        assert c.spin(60, c.done), c.output("dispatcher")
    finally:
        c.stop()
        node.destroy_node()
    assert [(m.task_id, sorted(m.subteam)) for m in moved] == [("t1", ["a", "b"])]
    sent = {e.robot_id: c.events.index(e) for e in c.of(GoalEvent.KIND_SENT) if e.task_id == "t1"}
    assert sent["a"] < sent["b"]  # a set out while b was busy
    work = {r: next(from_time(e.stamp) for e in c.of(GoalEvent.KIND_FEEDBACK, r)
                    if e.task_id == "t1" and e.phase == "working") for r in ("a", "b")}
    waited = [e for e in c.of(GoalEvent.KIND_FEEDBACK, "a") if e.task_id == "t1" and e.phase == "waiting"]
    assert waited and work["a"] >= work["b"] - 4.5, work  # with b, not 9 s of the cell's time before
    never_double_booked(c)
    a, b = read_with_anyreader(bag), read_with_mcap(bag)  # the bag holds the start that moved, for both readers
    assert a == b and a["/lvws/planned_starts"] == 1 and a["/lvws/goal_events"] > 0


def test_a_cancel_answer_frees_a_lost_robot_only_when_its_goal_is_unknown_or_over():
    from action_msgs.srv import CancelGoal

    from lvws_ros.ros.dispatcher_node import free_by_answer

    R = CancelGoal.Response
    assert free_by_answer(R(return_code=R.ERROR_UNKNOWN_GOAL_ID))  # never came, or forgotten
    assert free_by_answer(R(return_code=R.ERROR_GOAL_TERMINATED))  # over, its result lost
    assert not free_by_answer(R(return_code=R.ERROR_NONE))  # being cancelled: its result will come
    assert not free_by_answer(R(return_code=R.ERROR_REJECTED))  # still at work


def test_a_robot_whose_goal_was_lost_on_the_way_is_back_once_its_server_says_so_a_busy_one_once_done(
        ros_context, tmp_path):
    # the robot's server lives here. Its first goal is forgotten unanswered, as rclpy's action server forgets
    # a goal whose answer DDS would not send: the robot is lost, alive and free, and back once its server
    # answers the dispatcher's cancel request that the goal is unknown. Its second goal it takes and works on
    # in silence, refusing to stop: it is lost and stays out until that goal is over. Its third it does.
    from lvws_msgs.action import ExecuteTask
    from rclpy.action import ActionServer, CancelResponse
    from rclpy.task import Future

    data = {"format": "lvws-instance/1", "name": "one", "capabilities": ["lift"],
            "robots": [{"id": "r1", "capabilities": [1], "payload": 1}],
            "tasks": [{"id": "t1", "capabilities": [1], "payload": 0, "duration": 1, "after": []}]}
    c = watcher(ros_context, tmp_path, "lvws_dispatch_forget", data)
    node, path = c.node, c.path
    forgotten, worked, cancels, release = [], [], [], Future()

    class Forgetful(ActionServer):
        async def _execute_goal_request(self, request_header_and_message: Any) -> None:
            if not forgotten:
                forgotten.append(1)
                return  # no answer, no goal
            await super()._execute_goal_request(request_header_and_message)

    async def execute(handle: Any) -> Any:
        worked.append(1)
        if len(worked) == 1:
            await release  # at work, in silence
        handle.succeed()
        return ExecuteTask.Result(success=True, duration=0.1)

    def refuse(handle: Any) -> CancelResponse:
        cancels.append(1)
        return CancelResponse.REJECT

    def back() -> int:
        return sum("r1 is back in the team (was lost)" in d for d in c.diags)

    def assign(step: int) -> None:
        pub.publish(AssignmentArray(decision_step=step, assignments=[Assignment(task_id="t1", robot_ids=["r1"])]))

    server = Forgetful(node, ExecuteTask, "r1/execute_task", execute_callback=execute, cancel_callback=refuse)
    pub = node.create_publisher(AssignmentArray, ASSIGNMENTS_TOPIC, ASSIGNMENTS_QOS)
    try:
        c.procs["dispatcher"] = _start([sys.executable, "-m", "lvws_ros.cli", "dispatcher", str(path), "--ros-args",
                                        "-p", f"robot_timeout:={TIMEOUT}"])
        assert c.spin(30, lambda: any("r1 is back in the team (was down)" in d for d in c.diags)), c.diags
        assert c.spin(10, lambda: pub.get_subscription_count() >= 1)
        assign(0)
        assert c.spin(30, lambda: len(c.of(GoalEvent.KIND_LOST, "r1")) == 1), c.diags
        assert c.spin(30, lambda: back() == 1), c.output("dispatcher")
        assert forgotten and not cancels  # the goal never reached the server's callbacks

        assign(1)
        assert c.spin(30, lambda: len(c.of(GoalEvent.KIND_LOST, "r1")) == 2), c.diags
        c.spin(4 * TIMEOUT, lambda: back() > 1)
        assert back() == 1 and len(cancels) >= 2  # asked again and again; still at work, it stays out
        release.set_result(None)
        assert c.spin(30, lambda: back() == 2), c.output("dispatcher")  # its goal is over

        assign(2)
        assert c.spin(30, lambda: bool(c.of(GoalEvent.KIND_SUCCEEDED, "r1"))), c.output("dispatcher")
    finally:
        c.stop()
        server.destroy()
        node.destroy_node()


def test_on_sim_time_the_cell_runs_on_the_simulated_clock(ros_context, tmp_path):
    # a robot's first answer on a simulated clock can take over 1.5 wall seconds on a loaded machine:
    # this test is about the clock, not about losing robots
    with cell(ros_context, tmp_path, "lvws_dispatch_sim_time", sim_time=True) as c:
        began = time.monotonic()
        assert c.spin(60, c.done), c.output("dispatcher")
        wall = time.monotonic() - began
    times = [(t.start_time.sec + t.start_time.nanosec * 1e-9, t.end_time.sec + t.end_time.nanosec * 1e-9)
             for t in c.graphs[-1].tasks]
    # the cell's clock: the simulated one (4 x wall) at RATE from the dispatcher's first reading, not 1970's
    assert all(100.0 <= a <= b <= 100.0 + 4.0 * RATE * (wall + 30.0) for a, b in times), times
    assert not c.of(GoalEvent.KIND_LOST)  # silence is counted in wall seconds: a fast clock loses no robot


def test_cancel_task_cancels_every_members_goal_and_bad_assignments_are_named_not_fatal(ros_context, tmp_path):
    from lvws_msgs.srv import CancelTask

    from lvws_ros.ros.dashboard import CellView, LiveFeed

    slow = {**CELL, "tasks": [{**t, "duration": 60} if t["id"] == "t1" else t for t in CELL["tasks"]]}
    with cell(ros_context, tmp_path, "lvws_dispatch_cancel", data=slow) as c:
        pub = c.node.create_publisher(AssignmentArray, ASSIGNMENTS_TOPIC, ASSIGNMENTS_QOS)
        working = lambda: {e.robot_id for e in c.of(GoalEvent.KIND_FEEDBACK) if e.task_id == "t1"}  # noqa: E731
        assert c.spin(60, lambda: len(working()) > 1)
        members = working()
        assert members == {e.robot_id for e in c.of(GoalEvent.KIND_SENT) if e.task_id == "t1"}
        assert c.spin(10, lambda: pub.get_subscription_count() >= 1)  # the dispatcher
        pub.publish(AssignmentArray(decision_step=999, assignments=[Assignment(task_id="t7", robot_ids=["ghost"]),
                                                                    Assignment(task_id="t99", robot_ids=["s1"])]))
        more = tmp_path / "more.json"
        more.write_text(json.dumps([{"id": "t9", "capabilities": [0, 0, 1, 0], "payload": 0, "duration": 1,
                                     "after": ["t7"], "site": "c"}]))
        submit = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "submit", str(more)], capture_output=True,
                                text=True, timeout=60)
        assert submit.returncode == 0 and "t9 added" in submit.stdout, submit.stdout + submit.stderr
        feed = LiveFeed(CellView())  # the dashboard's submit button: the same service, its type found
        try:
            ok, message = feed.call("submit", tasks=[{"id": "t10", "capabilities": [0, 0, 1, 0], "payload": 0,
                                                      "duration": 1, "after": ["t9"], "site": "a"}])
        finally:
            feed.close()
        assert ok and "t10 added" in message, message
        client = c.node.create_client(CancelTask, "cancel_task")
        assert ready(client, 10.0)
        answer = call(client, CancelTask.Request(task_id="t1"), lambda f, s: c.spin(s, f.done), 10.0)
        assert answer is not None and answer.success, answer
        assert c.spin(10, lambda: {e.robot_id for e in c.of(GoalEvent.KIND_CANCELED) if e.task_id == "t1"}
                      == members)
        assert c.spin(60, c.done), c.output("dispatcher")
        assert c.procs["dispatcher"].poll() is None  # alive
    assert len(members) > 1 and "t1" not in {t.id for t in c.graphs[-1].tasks}
    assert {"t9", "t10"} <= {e.task_id for e in c.of(GoalEvent.KIND_SUCCEEDED)}  # lvws submit, dashboard: done
    assert any("unknown robot 'ghost'" in d for d in c.diags), c.diags
    assert any("unknown task 't99'" in d for d in c.diags), c.diags


def test_bad_cell_file_exits_2_naming_the_unknown_trait(tmp_path):
    bad = {**CELL, "traits": ["reach"],
           "tasks": [{**CELL["tasks"][0], "requires": {"strength": 2}}]}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad))
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "dispatcher", str(path)], capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2, out.stdout + out.stderr
    assert str(path) in out.stderr and "strength" in out.stderr and "Traceback" not in out.stderr



def test_a_dispatcher_asked_to_publish_the_clock_it_follows_exits_2_saying_why(tmp_path):
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(CELL))
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "dispatcher", str(path), "--ros-args", "-p",
                          "publish_clock:=true", "-p", "use_sim_time:=true"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "publish_clock with use_sim_time" in out.stderr, out.stdout + out.stderr
    assert "Traceback" not in out.stderr


def _longest_chain(tasks: list[dict[str, Any]]) -> float:
    """The longest chain of durations through the tasks' precedences (no travel)."""
    by_id = {t["id"]: t for t in tasks}
    ends: dict[str, float] = {}

    def end(tid: str) -> float:
        if tid not in ends:
            ends[tid] = by_id[tid]["duration"] + max((end(p) for p in by_id[tid]["after"]), default=0.0)
        return ends[tid]
    return max(end(t["id"]) for t in tasks)


def test_lvws_launch_with_action_robots_speaking_changes_runs_the_cell_and_its_bag_holds_the_goal_events(tmp_path):
    from lvws_ros.cli.report import report
    from lvws_ros.ros.launcher import launch

    path = tmp_path / "cell.json"
    path.write_text(json.dumps(CELL))
    res = launch(robots="actions", instance=str(path), policy="grp", rate=10.0, bag_dir=tmp_path / "bags",
                 out_dir=tmp_path / "out", name="actions", gif=False, timeout=120.0, protocol="changes",
                 retire_after=0.0, log=lambda _t: None)
    assert res.summary["tasks_done"] == len(CELL["tasks"]) and res.summary["failures"] == 0
    # the summary speaks the cell's seconds (rate 10), never shorter than the cell allows
    assert res.summary["rate"] == 10.0 and res.summary["makespan"] >= _longest_chain(CELL["tasks"])
    rep = report(res.bag)
    assert rep.complete and not rep.problems
    assert rep.topics.get("/lvws/changes", 0) > 3 and len(rep.instance.tasks) == len(CELL["tasks"])
    assert rep.voluntary is not None  # every decision's inputs are in the bag: the first state waited for it
    assert sum(g["succeeded"] for g in rep.goals.values()) == res.summary["goals"] >= len(CELL["tasks"])


def test_lvws_launch_refuses_an_instance_beside_a_config_before_anything_runs(tmp_path):
    path = tmp_path / "cell.json"
    path.write_text(json.dumps(CELL))
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "launch", "--instance", str(path), "--config",
                          str(path), "--bag-dir", str(tmp_path / "bags")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and "runs alone; config is for an assembly-cell configuration" in out.stderr
    assert "Traceback" not in out.stderr and not (tmp_path / "bags").exists()  # nothing ran


def test_the_simulator_runs_an_instance_departing_each_members_setting_out_on_their_own(tmp_path):
    """``lvws launch --instance`` without action robots: the simulator runs the file (a
    coalition benchmark's cell: 20 robots, 50 tasks, travel, the way home, departure each).
    Over DDS the run completes valid by the file's own rules, and the bag shows members of
    one subteam setting out for it at different times (each its own current task)."""
    from lvws_ros.cli.report import report
    from lvws_ros.ros.bag import read_run
    from lvws_ros.ros.launcher import launch

    path = Path(__file__).resolve().parents[2] / "examples" / "dcmrta" / "env_0.json"
    res = launch(instance=str(path), policy="auto", rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out",
                 name="each", gif=False, timeout=240.0, log=lambda _t: None)
    assert res.summary["tasks_done"] == res.summary["tasks"] == 50 and not res.summary["rejected"]
    rep = report(res.bag)
    assert rep.complete and not rep.problems
    run = read_run(res.bag)
    assert run.graphs[-1].departure == "each"  # the TaskGraph carried it, and the recorder kept it
    heading: dict[tuple[str, str], float] = {}  # (robot, task) -> when the bag first shows it on its way
    for team in run.teams:
        for r in team.robots:
            if r.current_task:
                heading.setdefault((r.id, r.current_task), team.stamp)
    apart = [a.task for a in rep.schedule.assignments
             if len({heading.get((r, a.task)) for r in a.robots} - {None}) > 1]
    assert apart, "every subteam set out together"


def test_action_robots_departing_each_set_out_on_their_own_and_the_cell_completes_valid(tmp_path):
    """A coalition benchmark's cell (20 robots, 50 tasks, travel, the way home, departure
    each) through the dispatcher and fake robots: the node gives tasks to busy robots, the
    dispatcher sends each member its goal once it is free, and the bag shows members of one
    subteam sent off at different times; every task done, none failed, the report valid.
    The first decision waits 1.5 wall seconds for the plan, 15 s of the cell's time at rate
    10, three times the node's ack_timeout: the node follows the cell's clock (the
    dispatcher's /clock), so it offers no task twice (none refused)."""
    from rosbags.highlevel import AnyReader

    from lvws_ros.cli.report import report
    from lvws_ros.ros.launcher import launch

    path = Path(__file__).resolve().parents[2] / "examples" / "dcmrta" / "env_0.json"
    params = tmp_path / "params.yaml"
    params.write_text("scheduler:\n  ros__parameters:\n    first_plan_wait: 1.5\n")
    res = launch(robots="actions", instance=str(path), policy="auto", rate=10.0, bag_dir=tmp_path / "bags",
                 out_dir=tmp_path / "out", name="each", gif=False, timeout=240.0, params_file=str(params),
                 log=lambda _t: None)
    assert res.summary["tasks_done"] == 50 and res.summary["failures"] == 0 and res.summary["refused"] == 0
    rep = report(res.bag)
    assert rep.complete and not rep.problems
    sent: dict[str, list[int]] = {}  # task -> when each member's goal went out (ns)
    with AnyReader([res.bag]) as reader:
        conns = [c for c in reader.connections if c.topic.endswith("goal_events")]
        for c, stamp, raw in reader.messages(connections=conns):
            m = reader.deserialize(raw, c.msgtype)
            if m.kind == GoalEvent.KIND_SENT:
                sent.setdefault(m.task_id, []).append(stamp)
    apart = [t for t, s in sent.items() if len(s) > 1 and max(s) - min(s) > 0.2e9]
    assert apart, "every subteam was sent off together"
