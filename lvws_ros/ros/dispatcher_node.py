"""Dispatcher node (``lvws dispatcher CELL.json``, ``ros2 run lvws_ros dispatcher --ros-args -p cell:=CELL.json``):
the world of a cell of real robots, the ROS shell (messages, action clients, services, clock) over
:class:`lvws_ros.core.dispatch.Dispatch`. Read more in docs/ros.md, "Real robots: the dispatcher".
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import uuid
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

import rclpy
from action_msgs.msg import GoalInfo, GoalStatus
from action_msgs.srv import CancelGoal
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lvws_msgs.action import ExecuteTask
from lvws_msgs.msg import AssignmentArray, GoalEvent, PlannedStart
from lvws_msgs.srv import CancelTask, SetRobotFault, SubmitInstanceTasks
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.action import ActionClient
from rclpy.client import Client
from rclpy.node import Node
from rclpy.task import Future
from rosgraph_msgs.msg import Clock
from unique_identifier_msgs.msg import UUID

from lvws_ros.core.dispatch import Dispatch, GoalKind, GoalSpec, Outcome
from lvws_ros.core.formats import load_instance
from lvws_ros.core.online import GraphSnapshot, TeamSnapshot
from lvws_ros.errors import ConfigError, DispatchRefused, LvwsError
from lvws_ros.ros import convert, topics
from lvws_ros.ros.entry import node_main, spin_once
from lvws_ros.ros.state_publisher import StatePublisher
from lvws_ros.rosbase.goals import ACTION_NAME, PLANNED_STARTS_QOS, PLANNED_STARTS_TOPIC

__all__ = ["DispatcherNode", "cell_clock", "free_by_answer", "main", "node_clock"]

CLOCK_SECONDS = 0.02  # publish_clock: the cell's clock on /clock this often (seconds of the node's clock)
MAX_RATE = 1000.0  # the cell's clock starts at the node's (about 1.8e9 s): at this rate int32 stamps last 4 days
WATCH_SECONDS = 0.25  # how often the robots' servers and silences are looked at
PROGRESS_SECONDS = 2.0
WAIT_FOR_SUBSCRIBERS = 20.0  # wall seconds the first state waits for expect_subscribers
_ENDS = {GoalStatus.STATUS_ABORTED: GoalKind.ABORTED, GoalStatus.STATUS_CANCELED: GoalKind.CANCELED}
PROBES_KEPT = 4  # a silent robot's probes awaiting an answer (older ones are forgotten)


def _new_uuid() -> UUID:
    return UUID(uuid=list(uuid.uuid4().bytes))


def free_by_answer(res: Any) -> bool:
    """Whether a server's answer to the cancel request of a lost goal
    (``action_msgs/srv/CancelGoal`` response) shows the robot alive and free: the goal is
    unknown to it (it never came, or was forgotten) or over (its result was lost). A goal
    it is cancelling or refuses to cancel is still running: its result will say when."""
    return int(res.return_code) in (CancelGoal.Response.ERROR_UNKNOWN_GOAL_ID,
                                    CancelGoal.Response.ERROR_GOAL_TERMINATED)


def cell_clock(seconds: float, epoch: float, rate: float) -> float:
    """The cell's time at ``seconds`` of the node's clock: ``rate`` times faster since ``epoch``."""
    return epoch + (seconds - epoch) * rate


def node_clock(cell_seconds: float, epoch: float, rate: float) -> float:
    """The node's clock when the cell's reads ``cell_seconds`` (:func:`cell_clock` undone)."""
    return epoch + (cell_seconds - epoch) / rate


def _param(node: Node, name: str, default: Any, text: str, low: float | None = None, high: float = 1e6,
           read_only: bool = True) -> Any:
    d = ParameterDescriptor(description=text, read_only=read_only)
    if low is not None:
        d.floating_point_range = [FloatingPointRange(from_value=low, to_value=high, step=0.0)]
    return node.declare_parameter(name, default, d).value


@dataclass
class _Server:
    """What the node knows of one robot's action server."""

    client: ActionClient
    status_topic: str
    probe: Client  # the action's cancel_goal service: does the server answer?
    up_since: float | None = None  # wall (steady) seconds
    last_up: float = -1e18
    seen_down: bool = False  # since the robot left the team
    dead: frozenset[bytes] = frozenset()  # its server's endpoints when it went silent
    handles: dict[int, Any] = field(default_factory=dict)  # goal key -> ClientGoalHandle
    asking: list[Future] = field(default_factory=list)  # the latest probes in flight
    asked: float = -1e18  # wall (steady) seconds the last one was sent
    answered: bool = False  # the server said, since the robot left the team, that it is free
    epoch: int = 0  # how many times the robot left the team: a probe of an earlier time is void


class DispatcherNode(Node):
    def __init__(self, cell: str = "") -> None:
        super().__init__("dispatcher")
        path = str(_param(self, "cell", cell, "the cell: an lvws-instance/1 file (robots, sites, speeds, tasks)"))
        self.robot_timeout = float(_param(self, "robot_timeout", 5.0, "wall seconds of silence (no feedback, "
                                          "or no server) after which a robot counts as lost", 0.1))
        self.rejoin_after = float(_param(self, "rejoin_after", 5.0, "seconds (of the node's clock) a robot that "
                                         "rejected or aborted a goal stays out of the team", 0.0))
        self.state_period = float(_param(self, "state_period", 1.0, "seconds (of the node's clock) between two "
                                         "unchanged TeamState/TaskGraph publications", 0.05))
        self.frame_id = str(_param(self, "frame_id", "map", "frame of the robots' poses and the sites"))
        self.exit_when_done = bool(_param(self, "exit_when_done", False, "exit 0 once every task is done"))
        self.summary_path = str(_param(self, "summary", "", "where to write the JSON summary at exit"))
        self.expect_subs = int(_param(self, "expect_subscribers", 0, "publish the state once this many nodes "
                                      "subscribe to its team and task graph (the scheduler, a recorder), or after 20 s"))
        self.rate = float(_param(self, "rate", 1.0, "the cell's seconds per second of the node's clock: robots whose "
                                 "time runs faster (lvws fake-robots --rate R) need rate R", 1e-3, MAX_RATE))
        self.clock_epoch: float | None = None  # where the cell's clock meets the node's: its first reading
        self.clock_pub = self._clock_publisher()
        if not path:
            raise ConfigError("no cell given (-p cell:=CELL.json, or lvws dispatcher CELL.json)")
        self.cell_path = path
        self.cell = Dispatch(load_instance(path), present=[])
        self.out = StatePublisher(
            self, self.snapshots,
            str(_param(self, "protocol", "snapshots", "how the state goes out: snapshots (the whole team and task "
                       "graph each time) or changes (those once, then numbered CellChanges; docs/ros.md)")),
            float(_param(self, "retire_after", -1.0, "protocol changes: seconds after which done work retires "
                         "once its dependents have started (-1: never)")),
            self.frame_id)
        self.events_pub = self.create_publisher(GoalEvent, topics.GOAL_EVENTS_TOPIC, topics.GOAL_EVENTS_QOS)
        self.starts_pub = self.create_publisher(PlannedStart, PLANNED_STARTS_TOPIC, PLANNED_STARTS_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, topics.DIAGNOSTICS_QOS)
        self.create_subscription(AssignmentArray, topics.ASSIGNMENTS_TOPIC, self.on_assignments,
                                 topics.ASSIGNMENTS_QOS)
        self.create_service(SubmitInstanceTasks, "submit_tasks", self.on_submit)
        self.create_service(CancelTask, "cancel_task", self.on_cancel)
        self.create_service(SetRobotFault, "set_robot_fault", self.on_fault)
        self.servers = {r.id: _Server(ActionClient(self, ExecuteTask, f"{r.id}/{ACTION_NAME}"),
                                      self.resolve_topic_name(f"{r.id}/{ACTION_NAME}") + "/_action/status",
                                      self.create_client(CancelGoal, f"{r.id}/{ACTION_NAME}/_action/cancel_goal"))
                        for r in self.cell.inst.robots}
        self.goal_of: dict[int, str] = {}  # goal key -> robot
        self.last_uuid: dict[str, UUID] = {}  # robot -> the goal id of its latest goal
        self.heard: dict[int, float] = {}  # goal key -> when its robot last answered (wall, steady)
        self.counts = {"goals": 0, "failures": 0, "refused": 0}
        self.finished = False
        self.exit_code = 0
        self.started_wall = time.monotonic()
        self.last_published = -1e18
        self.waiting = self.expect_subs > 0
        self.create_timer(WATCH_SECONDS, self.watch)
        self.create_timer(PROGRESS_SECONDS, self.log_progress)
        self.get_logger().info(f"cell {path}: {len(self.servers)} robot(s), {len(self.cell.tasks)} task(s); "
                               f"goals to <robot>/{ACTION_NAME}, robot_timeout {self.robot_timeout:g} s")

    def _clock_publisher(self) -> Any:
        """The publisher of the cell's clock (``publish_clock``; None: not asked for), every
        CLOCK_SECONDS of the node's clock. A node on that clock itself would feed on it."""
        if not bool(_param(self, "publish_clock", False, "publish the cell's clock on clock (rosgraph_msgs/Clock, "
                           "50 times a second of the node's clock) for the scheduler and a recorder to follow "
                           "(use_sim_time) when rate is not 1")):
            return None
        if bool(self.get_parameter("use_sim_time").value):
            raise ConfigError("publish_clock with use_sim_time: the dispatcher would follow the clock it publishes "
                              "(publish the cell's clock from a dispatcher on wall time)")
        pub = self.create_publisher(Clock, topics.CLOCK_TOPIC, topics.CLOCK_QOS)
        self.create_timer(CLOCK_SECONDS, self.publish_clock)
        return pub

    def publish_clock(self) -> None:
        if self.clock_pub is not None:
            self.clock_pub.publish(Clock(clock=convert.to_time(self.now())))

    def to_node_clock(self, cell_seconds: float) -> float:
        """The node's clock when the cell's reads ``cell_seconds`` (as is before the first reading)."""
        return cell_seconds if self.clock_epoch is None else node_clock(cell_seconds, self.clock_epoch, self.rate)

    def clock_seconds(self) -> float:
        """Seconds on the node's clock (ROS time: wall, or simulated with ``use_sim_time``)."""
        return float(self.get_clock().now().nanoseconds) / 1e9

    def now(self) -> float:
        """Seconds on the cell's clock: the node's, ``rate`` times faster since the node
        started. Every stamp the dispatcher publishes and every time it keeps is on it."""
        seconds = self.clock_seconds()
        if self.clock_epoch is None and seconds > 0:  # a simulated clock reads 0 until its first message
            self.clock_epoch = seconds
        return seconds if self.clock_epoch is None else cell_clock(seconds, self.clock_epoch, self.rate)

    def snapshots(self) -> tuple[TeamSnapshot, GraphSnapshot]:
        """The team and task graph now, with one stamp."""
        now = self.now()
        return self.cell.team_snapshot(now), self.cell.graph_snapshot(now)

    # -- publishing ----------------------------------------------------------------------
    def publish_state(self) -> None:
        """TeamState and TaskGraph with one stamp (the team only once a robot is up)."""
        now = self.now()
        self.last_published = self.clock_seconds()
        self.publish_clock()  # a node on the cell's clock never gets a state from its future
        team = self.cell.team_snapshot(now)
        if not self.audience():
            return
        graph = self.cell.graph_snapshot(now)
        if not team.robots and (self.out.sent is None or self.out.protocol == "snapshots"):
            self.out.graph_pub.publish(convert.graph_to_msg(graph, self.frame_id))  # no robot up: no team yet
            return
        self.out.publish(team, graph)

    def audience(self) -> bool:
        """Whether the expected subscribers are there (or 20 s went by): a bag then holds
        the first state."""
        if not self.waiting:
            return True
        subs = topics.state_audience(self.out.team_pub, self.out.graph_pub)
        if subs >= self.expect_subs or time.monotonic() - self.started_wall > WAIT_FOR_SUBSCRIBERS:
            self.waiting = False
            self.get_logger().info(f"publishing to {subs} subscriber(s)")
        return not self.waiting

    def apply(self, out: Outcome) -> None:
        """Send the goals now due (departure each: a member free for its next task) and the
        planned starts that moved, publish what an input did: goal events, cancels,
        warnings, the new state."""
        now = self.now()
        for moved in out.moved:  # before the goals: a member sent now has the new start in its goal anyway
            self.starts_pub.publish(convert.planned_start_to_msg(moved, self.to_node_clock(moved.planned_start), now))
        for spec in out.send:
            self.send(spec)
        for news in out.news:
            self.events_pub.publish(convert.goal_event_to_msg(news, now))
            if news.kind in (GoalKind.REJECTED, GoalKind.ABORTED, GoalKind.LOST):
                self.counts["failures"] += 1
        for key in out.cancel:
            self.cancel_goal(key)
        for note in out.notes:
            self.warn(note)
        if out.changed:
            self.publish_state()
        if self.cell.done and self.exit_when_done and not self.finished and self.cell.tasks:
            self.finish()

    def warn(self, text: str) -> None:
        self.get_logger().warning(text)
        status = DiagnosticStatus(level=DiagnosticStatus.WARN, name="lvws_dispatcher", message=text,
                                  hardware_id=self.get_fully_qualified_name())
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = convert.to_time(self.now())
        self.diag_pub.publish(msg)

    # -- assignments and goals -----------------------------------------------------------
    def on_assignments(self, msg: AssignmentArray) -> None:
        """A decision, taken whole: its goals go out and the cell's state is published once,
        with every assignment it took (a state in between would show the scheduler a
        decision half taken)."""
        out, now = Outcome(), self.now()
        for a in msg.assignments:
            try:
                out.add(self.cell.assign(a.task_id, list(a.robot_ids), now))
            except DispatchRefused as exc:
                self.counts["refused"] += 1
                self.warn(f"decision {msg.decision_step}: {exc}")
        self.apply(out)

    def send(self, spec: GoalSpec) -> None:
        server = self.servers[spec.robot]
        goal = ExecuteTask.Goal(task_id=spec.task, subteam=list(spec.subteam), site=spec.site, site_to=spec.site_to,
                                require_names=list(spec.require_names), requires=list(spec.requires),
                                planned_start=self.to_node_clock(spec.planned_start),
                                planned_duration=spec.planned_duration)
        self.goal_of[spec.key] = spec.robot
        self.last_uuid[spec.robot] = _new_uuid()
        self.heard[spec.key] = time.monotonic()
        self.counts["goals"] += 1
        future = server.client.send_goal_async(goal, feedback_callback=partial(self.on_feedback, spec.key),
                                               goal_uuid=self.last_uuid[spec.robot])
        future.add_done_callback(partial(self.on_goal_response, spec.key))

    def on_goal_response(self, key: int, future: Any) -> None:
        self.heard[key] = time.monotonic()
        handle = future.result()
        if handle is None or not handle.accepted:
            self.apply(self.cell.ended(key, self.now(), GoalKind.REJECTED, "the robot's server rejected the goal"))
            return
        self.servers[self.goal_of[key]].handles[key] = handle
        self.apply(self.cell.accepted(key, self.now()))
        goal = self.cell.goals[key]
        if goal.cancelling:  # cancelled before the server answered
            handle.cancel_goal_async()
        handle.get_result_async().add_done_callback(partial(self.on_result, key))

    def on_feedback(self, key: int, msg: Any) -> None:
        self.heard[key] = time.monotonic()
        fb = msg.feedback
        self.apply(self.cell.feedback(key, self.now(), fb.phase, fb.progress, fb.site,
                                      (fb.pose.x, fb.pose.y, fb.pose.theta)))

    def on_result(self, key: int, future: Any) -> None:
        wrapped = future.result()
        self.heard.pop(key, None)
        self.servers[self.goal_of[key]].handles.pop(key, None)
        if wrapped is None:
            return
        result, now = wrapped.result, self.now()
        if wrapped.status == GoalStatus.STATUS_SUCCEEDED and result.success:
            self.apply(self.cell.succeeded(key, now, result.duration, result.message))
        else:
            kind = _ENDS.get(wrapped.status, GoalKind.ABORTED)
            self.apply(self.cell.ended(key, now, kind, result.message or f"goal status {wrapped.status}"))

    def cancel_goal(self, key: int) -> None:
        handle = self.servers[self.goal_of[key]].handles.get(key)
        if handle is not None:  # else: cancelled once the server accepts it (on_goal_response)
            handle.cancel_goal_async()

    # -- the robots' servers -------------------------------------------------------------
    def watch(self) -> None:
        """Servers up or gone, silent goals, robots back."""
        if self.finished:
            return
        now, wall = self.now(), time.monotonic()  # silence is counted in wall seconds, even on sim time
        for server in self.servers.values():
            if server.client.server_is_ready():
                server.last_up = wall
                server.up_since = wall if server.up_since is None else server.up_since
            else:
                server.up_since, server.seen_down = None, True
        available = {rid: wall - s.last_up <= self.robot_timeout for rid, s in self.servers.items()}
        before = set(self.cell.failed_robots())
        out = self.cell.silent(now, self.robot_timeout, available, {k: wall - t for k, t in self.heard.items()})
        for rid in set(self.cell.failed_robots()) - before:
            self.left(rid)
        for rid, (why, _) in self.cell.failed_robots().items():
            if why == "lost":
                self.ask(rid, wall)
        for rid in self.back(now):
            out.add(self.cell.rejoin(rid))
        self.apply(out)
        if self.clock_seconds() - self.last_published >= self.state_period:
            self.publish_state()

    def endpoints(self, server: _Server) -> frozenset[bytes]:
        return frozenset(bytes(i.endpoint_gid) for i in self.get_publishers_info_by_topic(server.status_topic))

    def left(self, robot: str) -> None:
        """Remember the server a robot left the team with (a restart brings a new one)."""
        server = self.servers[robot]
        server.seen_down, server.answered, server.asked = False, False, -1e18
        server.dead = self.endpoints(server)
        server.epoch += 1
        for future in server.asking:
            server.probe.remove_pending_request(future)
        server.asking.clear()

    def ask(self, robot: str, wall: float) -> None:
        """Ask the server of a robot that went silent to cancel its lost goal; again every
        ``robot_timeout`` seconds until it says the goal is unknown or over (a request can
        be lost like the goal was, and a slow answer still counts)."""
        server = self.servers[robot]
        if server.answered or server.up_since is None or wall - server.asked < self.robot_timeout:
            return
        while len(server.asking) >= PROBES_KEPT:
            server.probe.remove_pending_request(server.asking.pop(0))
        goal_id = self.last_uuid.get(robot) or _new_uuid()
        server.asked = wall
        future = server.probe.call_async(CancelGoal.Request(goal_info=GoalInfo(goal_id=goal_id)))
        future.add_done_callback(partial(self.on_answer, server, server.epoch))
        server.asking.append(future)

    def on_answer(self, server: _Server, epoch: int, future: Future) -> None:
        if epoch == server.epoch and future.result() is not None and free_by_answer(future.result()):
            server.answered = True

    def back(self, now: float) -> list[str]:
        """Robots out of the team whose server answers again (the module doc's rules)."""
        out = []
        for rid, (why, since) in self.cell.failed_robots().items():
            server = self.servers[rid]
            if why == "fault" or server.up_since is None:
                continue
            if why == "down" or (why in ("rejected", "aborted") and now - since >= self.rejoin_after * self.rate) or \
                    (why in ("lost", "canceled") and (server.seen_down or server.answered
                                                      or self.endpoints(server) - server.dead)):
                out.append(rid)
        return out

    # -- services ------------------------------------------------------------------------
    def on_submit(self, req: Any, res: Any) -> Any:
        try:
            entries = [convert.instance_task_from_msg(t) for t in req.tasks]
            out = self.cell.add_tasks(entries)
        except LvwsError as exc:
            res.success, res.message = False, str(exc)
            self.warn(f"submit_tasks refused: {exc}")
            return res
        res.success, res.message = True, "; ".join(out.notes)
        self.apply(out)
        return res

    def on_cancel(self, req: Any, res: Any) -> Any:
        return self._answer(res, lambda: self.cell.cancel(req.task_id, self.now()))

    def on_fault(self, req: Any, res: Any) -> Any:
        return self._answer(res, lambda: self.cell.fault(req.robot_id, bool(req.failed), self.now()))

    def _answer(self, res: Any, call: Any) -> Any:
        try:
            out = call()
        except DispatchRefused as exc:
            res.success, res.message = False, str(exc)
            self.warn(str(exc))
            return res
        res.success, res.message = True, "; ".join(out.notes)
        self.apply(out)
        return res

    # -- the end -------------------------------------------------------------------------
    def log_progress(self) -> None:
        if not self.finished:
            counts = ", ".join(f"{n} {k}" for k, n in sorted(self.cell.counts().items()))
            present = len(self.cell.inst.robots) - len(self.cell.failed_robots())
            self.get_logger().info(f"progress: {counts or 'no tasks'}; {present}/{len(self.servers)} robots in the "
                                   f"team, {self.counts['goals']} goals, {self.counts['failures']} failed")

    def summary(self) -> dict[str, Any]:
        graph = self.cell.graph_snapshot(self.now())
        ends = [t.end for t in graph.tasks if t.end is not None]
        starts = [t.start for t in graph.tasks if t.start is not None]
        return {"cell": self.cell_path, "rate": self.rate, "tasks": len(graph.tasks), "tasks_done": len(ends),
                "makespan": (max(ends) - min(starts)) if ends and starts else 0.0, **self.counts,
                "failed_robots": sorted(self.cell.failed_robots()), "error": "",
                "wall_seconds": time.monotonic() - self.started_wall}

    def finish(self) -> None:
        self.finished = True
        summary = self.summary()
        self.get_logger().info(f"all {summary['tasks']} tasks done: makespan {summary['makespan']:.2f} s of the cell")
        if self.summary_path:
            Path(self.summary_path).parent.mkdir(parents=True, exist_ok=True)
            Path(self.summary_path).write_text(json.dumps(summary, indent=1))
        print(json.dumps(summary), flush=True)


def run(node: DispatcherNode) -> int:
    """Spin until the cell is done (with ``exit_when_done``), then a moment more so the
    recorder takes the final state."""
    while rclpy.ok() and not node.finished:
        spin_once(node, 0.1)
    end = time.monotonic() + 0.5
    while rclpy.ok() and time.monotonic() < end:
        spin_once(node, 0.05)
    return node.exit_code


def build_parser(prog: str = "dispatcher") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description=(
        "The world of a cell of real robots: publishes TeamState and TaskGraph for the scheduler and carries out "
        "its assignments as ExecuteTask goals to <robot id>/execute_task. ROS parameters: cell, robot_timeout, "
        "rejoin_after, state_period, frame_id, expect_subscribers, exit_when_done, summary, rate, publish_clock, "
        "use_sim_time."))
    p.add_argument("cell", nargs="?", default="", help="the cell (lvws-instance/1); or -p cell:=CELL.json")
    return p


def main(argv: list[str] | None = None, prog: str = "dispatcher") -> int:
    return node_main(prog, argv, build_parser(prog), lambda args: DispatcherNode(args.cell), run, interrupted=0)


if __name__ == "__main__":
    sys.exit(main())
