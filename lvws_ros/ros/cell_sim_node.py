"""Cell simulator node: ``ros2 run lvws_ros cell_sim``, the case study world on ROS topics.

Publishes TeamState and TaskGraph (latched) on every change (and TeamState once a sim
second for poses), ``/clock`` (sim time), ``visualization_msgs/MarkerArray`` on
``/lvws/markers``; executes the AssignmentArrays it receives. Sim time runs ``rate``
times faster than wall time; with ``sync`` (default) the world pauses at a decision
step until the scheduler answers it (or ``sync_timeout`` wall seconds pass), so runs do
not depend on the machine's speed. When every task is done it prints the makespan,
writes ``summary`` (JSON) and the ``gif``, and exits 0. With ``noise`` (in [0, 1)) each
task takes its duration times a factor in [1 - noise, 1 + noise] drawn from
``noise_seed`` and the task's id (:meth:`~lvws_ros.sim.world.CellSim.duration_factor`):
the world departs from every plan as a real cell does.

The world changes while it runs (the dynamic protocol of docs/ros.md): scripted events
(parameter ``events``, :mod:`lvws_ros.sim.events`) and the services ``submit_tasks``
(lvws_msgs/srv/SubmitTasks), ``cancel_task`` (CancelTask) and ``set_robot_fault``
(SetRobotFault), relative to the node's namespace (``lvws submit / cancel / fault``).
When the robots left can never do a task and no scripted repair or cancel is still to
come, the run ends with that reason (exit 1): at once after a scripted event; after
``stuck_grace`` wall seconds with nothing running after a service call (time to call
``set_robot_fault`` with a repair; the service's answer says so).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from lvws_msgs.msg import AssignmentArray
from lvws_msgs.srv import CancelTask, SetRobotFault, SubmitTasks
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from visualization_msgs.msg import Marker, MarkerArray

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.formats import load_instance
from lvws_ros.errors import AssignmentRejected, ConfigError, LvwsError, WorldEventRejected
from lvws_ros.ros import convert, topics
from lvws_ros.ros.entry import node_main, spin_once
from lvws_ros.ros.resources import case_study_config
from lvws_ros.ros.state_publisher import StatePublisher
from lvws_ros.sim.config import ARM_KINDS, load_cell_config
from lvws_ros.sim.events import WorldEvent, apply_event, load_events, stuck_reason
from lvws_ros.sim.instance_sim import InstanceSim, check_alone
from lvws_ros.sim.world import CellSim, Event

DESCRIPTION = (
    "pymunk assembly-cell simulator of the paper's case study. ROS parameters: config (YAML, default "
    "the shipped config/assembly_cell.yaml), rate (sim/wall speed-up, default 10), sync (pause at "
    "decision steps until answered, default true), sync_timeout (wall s), first_sync_timeout (wall s, the first "
    "decision's; default sync_timeout), expect_subscribers (start once "
    "this many nodes subscribe, default 1), wait_for_subscribers (wall s), "
    "max_sim_time (s), summary (JSON path), gif (animated GIF path), frame_every (sim s between GIF frames), "
    "events (scripted world events, YAML), stuck_grace (wall s a run waits for a repair after a service made a "
    "task impossible, default 10), protocol (snapshots: the whole state at every step; changes: numbered "
    "CellChanges after the first snapshots, which the resync service gives again), retire_after (changes only: "
    "sim s after which done work retires once its dependents have started, default -1: never), instance (an "
    "lvws-instance/1 file run instead of the config: its robots, sites, travel, traits and the way home; each "
    "member sets out on its own with departure each)."
)
PROGRESS_SECONDS = 2.0  # wall seconds between progress lines (lvws launch shows them)
ROBOT_COLORS = {"panda": (1.0, 0.5, 0.0), "jackal": (0.1, 0.4, 0.9), "husky": (0.1, 0.7, 0.2)}


def instance_sim(path: str, config: str, events: str, noise: float, noise_seed: int) -> InstanceSim:
    """The world of an instance file (ConfigError for a config or scripted events beside it)."""
    check_alone(path, config, events)
    return InstanceSim(load_instance(path), noise=noise, noise_seed=noise_seed)


def _sites(sim: InstanceSim) -> tuple[tuple[str, ...], tuple[tuple[float, float], ...]]:
    tr = sim.inst.travel
    return ((), ()) if tr is None else (tuple(tr.sites), tuple(tr.coordinates))


def markers(sim: CellSim | InstanceSim, frame_id: str) -> MarkerArray:
    """Cells, robots (opaque while busy), objects and labels for RViz / Foxglove (an
    instance file: its sites and robots)."""
    stamp = convert.to_time(sim.time)
    out = MarkerArray()

    def add(ns: str, kind: int, x: float, y: float, size: tuple[float, float, float],
            rgba: tuple[float, float, float, float], text: str = "") -> None:
        m = Marker(ns=ns, id=len(out.markers), type=kind, action=Marker.ADD, text=text)
        m.header.frame_id, m.header.stamp = frame_id, stamp
        m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, size[2] / 2
        m.pose.orientation.w = 1.0
        m.scale.x, m.scale.y, m.scale.z = size
        m.color.r, m.color.g, m.color.b, m.color.a = rgba
        out.markers.append(m)

    white = (1.0, 1.0, 1.0, 1.0)
    if isinstance(sim, InstanceSim):
        for name, (x, y) in zip(*_sites(sim), strict=True):
            add("cells", Marker.CUBE, x, y, (0.8, 0.8, 0.02), (0.7, 0.7, 0.7, 0.5))
            add("labels", Marker.TEXT_VIEW_FACING, x, y + 0.6, (0.4, 0.4, 0.4), white, name)
        for rid, task in sim.robot_task.items():
            x, y = sim.position(rid)
            add("robots", Marker.SPHERE, x, y, (0.5, 0.5, 0.5), (0.1, 0.4, 0.9, 1.0 if task else 0.5))
            add("labels", Marker.TEXT_VIEW_FACING, x, y - 0.6, (0.3, 0.3, 0.3), white, f"{rid}: {task or 'wait'}")
        return out
    for cell in sim.cfg.cells.values():
        add("cells", Marker.CUBE, *cell.position, (*cell.size, 0.02), (0.7, 0.7, 0.7, 0.5))
        add("labels", Marker.TEXT_VIEW_FACING, cell.position[0], cell.position[1] + cell.size[1] / 2 + 0.3,
            (0.4, 0.4, 0.4), white, cell.id)
    for r in sim.cfg.robots:
        x, y = sim.position(r.id)
        busy = sim.robot_task[r.id] is not None
        shape = Marker.CYLINDER if r.kind in ARM_KINDS else Marker.SPHERE
        failed = r.id in sim.failed
        add("robots", shape, x, y, (0.7, 0.7, 0.7),
            (0.3, 0.3, 0.3, 1.0) if failed else (*ROBOT_COLORS[r.kind], 1.0 if busy else 0.5))
        add("labels", Marker.TEXT_VIEW_FACING, x, y - 0.8, (0.3, 0.3, 0.3), white,
            f"{r.id}: {'FAILED' if failed else sim.robot_task[r.id] or 'wait'}")
    for o in sim.cfg.objects.values():
        x, y = sim.position(o.id)
        s = 0.4 + 0.08 * o.weight
        add("objects", Marker.CUBE, x, y, (s, s, s), (0.85, 0.1, 0.1, 1.0))
    return out


class CellSimNode(Node):
    def __init__(self) -> None:
        super().__init__("cell_sim")
        cfg_path = str(self.declare_parameter("config", "").value)
        self.rate = float(self.declare_parameter("rate", 10.0).value)
        self.sync = bool(self.declare_parameter("sync", True).value)
        self.sync_timeout = float(self.declare_parameter("sync_timeout", 5.0).value)
        # the first decision may wait for the planner's first plan (the scheduler's first_plan_wait)
        self.first_sync_timeout = float(self.declare_parameter("first_sync_timeout", self.sync_timeout).value)
        self.wait_subs = float(self.declare_parameter("wait_for_subscribers", 20.0).value)
        self.expect_subs = int(self.declare_parameter("expect_subscribers", 1).value)
        self.max_sim_time = float(self.declare_parameter("max_sim_time", 3600.0).value)
        self.summary_path = str(self.declare_parameter("summary", "").value)
        self.gif_path = str(self.declare_parameter("gif", "").value)
        self.frame_every = float(self.declare_parameter("frame_every", 2.0).value)
        events_path = str(self.declare_parameter("events", "").value)
        self.later: list[WorldEvent] = load_events(events_path) if events_path else []
        self.world_events: list[str] = []  # what happened, for the summary
        self.stuck_grace = float(self.declare_parameter("stuck_grace", 10.0).value)
        self.stuck_since: float | None = None  # wall time a service call made the run impossible
        if self.rate <= 0:
            raise LvwsError(f"parameter rate must be > 0, got {self.rate}")
        noise = float(self.declare_parameter("noise", 0.0).value)
        noise_seed = int(self.declare_parameter("noise_seed", 0).value)
        instance = str(self.declare_parameter("instance", "").value)
        self.sim: CellSim | InstanceSim = (
            instance_sim(instance, cfg_path, events_path, noise, noise_seed) if instance else
            CellSim(load_cell_config(cfg_path or case_study_config()), noise=noise, noise_seed=noise_seed))
        if self.gif_path and isinstance(self.sim, InstanceSim):
            self.get_logger().warning(f"gif {self.gif_path}: drawn for an assembly-cell config only; none for an "
                                      "instance file")
            self.gif_path = ""
        self.seen_ready: frozenset[str] = frozenset()
        self.frame = self.sim.cfg.frame_id
        # "snapshots": the whole team and task graph at every state; "changes": those once, then
        # numbered CellChanges, with the snapshots on request (the resync service; docs/ros.md)
        self.out = StatePublisher(self, lambda: (self.sim.team_snapshot(), self.sim.graph_snapshot()),
                                  str(self.declare_parameter("protocol", "snapshots").value),
                                  float(self.declare_parameter("retire_after", -1.0).value), self.frame)
        self.clock_pub = self.create_publisher(Clock, topics.CLOCK_TOPIC, topics.CLOCK_QOS)
        self.marker_pub = self.create_publisher(MarkerArray, topics.MARKERS_TOPIC, topics.MARKERS_QOS)
        self.create_subscription(AssignmentArray, topics.ASSIGNMENTS_TOPIC, self.on_assignments,
                                 topics.ASSIGNMENTS_QOS)
        self.create_service(SubmitTasks, "submit_tasks", self.on_submit)
        self.create_service(CancelTask, "cancel_task", self.on_cancel)
        self.create_service(SetRobotFault, "set_robot_fault", self.on_fault)
        self.waiting_since: float | None = None  # wall time we started waiting for a decision
        self.last_stamp = -1.0
        self.started = False
        self.start_wall = time.monotonic()
        self.finished = False
        self.exit_code = 1
        self.rejected: list[str] = []
        self.decisions = 0
        self.next_pose = 0.0
        self.next_frame = 0.0
        self.tick = 0.02
        self.create_timer(self.tick, self.on_tick)
        self.create_timer(PROGRESS_SECONDS, self.log_progress)

    # -- publishing ----------------------------------------------------------------------
    def publish_state(self) -> None:
        """The clock first, then team and graph stamped with it: a node on sim time never
        gets a state from its future, and answers it no earlier than its stamp."""
        self.last_stamp = self.sim.time
        self.publish_clock()
        self.out.publish(self.sim.team_snapshot(), self.sim.graph_snapshot())

    def publish_team(self) -> None:
        """The team alone (robots moved), as a snapshot or as a change."""
        self.publish_clock()
        self.out.publish_team(self.sim.team_snapshot())

    def publish_clock(self) -> None:
        self.clock_pub.publish(Clock(clock=convert.to_time(self.sim.time)))

    def publish_markers(self) -> None:
        self.marker_pub.publish(markers(self.sim, self.frame))

    # -- input ---------------------------------------------------------------------------
    def on_assignments(self, msg: AssignmentArray) -> None:
        if abs(convert.from_time(msg.team_stamp) - self.last_stamp) < 1e-6:
            self.waiting_since = None  # the decision for our current state: resume
        for a in msg.assignments:
            try:
                self.sim.assign(a.task_id, list(a.robot_ids))
            except AssignmentRejected as exc:
                text = f"t={self.sim.time:.2f}: rejected {a.task_id} <- {list(a.robot_ids)}: {exc}"
                self.rejected.append(text)
                self.get_logger().error(text)
        self.decisions += 1
        if msg.assignments:
            self.publish_state()

    def log_progress(self) -> None:
        if self.started and not self.finished:
            done = sum(s == TaskStatus.DONE for s in self.sim.status.values())
            self.get_logger().info(f"progress: sim time {self.sim.time:.1f} s, {done}/{len(self.sim.status)} tasks "
                                   f"done, {self.decisions} decisions")

    # -- the world changes ------------------------------------------------------------------
    def on_submit(self, req: SubmitTasks.Request, res: SubmitTasks.Response) -> SubmitTasks.Response:
        try:
            tasks = tuple(convert.cell_task_from_msg(t) for t in req.tasks)
        except ConfigError as exc:
            res.success, res.message = False, str(exc)
            return res
        return self.answer(WorldEvent(self.sim.time, "submit", tasks=tasks), res)

    def on_cancel(self, req: CancelTask.Request, res: CancelTask.Response) -> CancelTask.Response:
        return self.answer(WorldEvent(self.sim.time, "cancel", target=req.task_id), res)

    def on_fault(self, req: SetRobotFault.Request, res: SetRobotFault.Response) -> SetRobotFault.Response:
        return self.answer(WorldEvent(self.sim.time, "fail" if req.failed else "repair", target=req.robot_id), res)

    def answer(self, event: WorldEvent, res: Any) -> Any:
        """A service call: apply the event now, or say why not."""
        if self.finished:
            res.success, res.message = False, "the run is over"
            return res
        try:
            events = self.apply(event, scripted=False)
        except WorldEventRejected as exc:
            res.success, res.message = False, str(exc)
            self.get_logger().warning(f"t={self.sim.time:.2f}: {event.kind} refused: {exc}")
            return res
        res.success, res.message = True, "; ".join(self.describe(e) for e in events)
        reason = stuck_reason(self.sim, self.later)
        if reason:
            res.message += f". Warning: the run {reason}; it ends in {self.stuck_grace:g} s unless a robot is repaired"
        return res

    def apply(self, event: WorldEvent, scripted: bool = True) -> list[Event]:
        """Apply a world event and publish the new state (the scheduler replans at once). A
        scripted event that leaves the world unable to finish ends the run; after a service
        call, :meth:`check_stuck` gives it ``stuck_grace``."""
        events = apply_event(self.sim, event)
        for e in events:
            text = f"t={self.sim.time:.2f}: {self.describe(e)}"
            self.world_events.append(text)
            self.get_logger().info(text)
        if self.started:
            self.publish_state()
            self.publish_markers()
            if self.sync and self.decision_due():
                self.waiting_since = time.monotonic()
        if scripted and (reason := stuck_reason(self.sim, self.later)):
            self.finish(reason)
        return events

    def check_stuck(self) -> None:
        """End a run that can never finish once nothing runs and ``stuck_grace`` has passed."""
        reason = stuck_reason(self.sim, self.later)
        if not reason or self.sim.jobs:
            self.stuck_since = None
            return
        if self.stuck_since is None:
            self.stuck_since = time.monotonic()
            self.get_logger().warning(f"t={self.sim.time:.2f}: the run {reason}; it ends in {self.stuck_grace:g} s "
                                      "unless a robot is repaired")
        elif time.monotonic() - self.stuck_since > self.stuck_grace:
            self.finish(reason)

    @staticmethod
    def describe(e: Event) -> str:
        if e.kind in ("failed", "repaired"):
            return f"{e.robots[0]} {e.kind}"
        if e.kind == "interrupted":
            return f"{e.task} interrupted (subteam {'+'.join(e.robots)} released), READY again"
        return f"{e.task} {e.kind}"

    # -- the loop ------------------------------------------------------------------------
    def decision_due(self) -> bool:
        """A robot free and a task ready; with departure each also a task newly ready (the
        node may give it to busy robots)."""
        ready = frozenset(t.id for t in self.sim.graph_snapshot().tasks if t.status == TaskStatus.READY)
        fresh, self.seen_ready = bool(ready - self.seen_ready), ready
        ahead = isinstance(self.sim, InstanceSim) and self.sim.inst.departure == "each"
        return bool(ready) and (any(r.available for r in self.sim.team_snapshot().robots) or (ahead and fresh))

    def start(self) -> None:
        """Once the scheduler and recorder subscribe (or the wait is over): the first state."""
        subs = topics.state_audience(self.out.team_pub, self.out.graph_pub)
        if subs < self.expect_subs and time.monotonic() - self.start_wall < self.wait_subs:
            return  # give the scheduler and recorder time to discover us
        self.started = True
        self.get_logger().info(f"starting: {subs} subscriber(s) on {self.out.team_pub.topic_name}, rate {self.rate:g}x")
        self.publish_state()
        self.publish_markers()
        if self.sync and self.decision_due():
            self.waiting_since = time.monotonic()

    def advance(self) -> None:
        """Run the world for one tick of wall time (``rate`` x tick of sim time), stopping
        at a decision step in sync mode."""
        budget = self.rate * self.tick
        while budget > 1e-9 and not self.sim.done:
            events = self.sim.step()
            budget -= self.sim.cfg.dt
            if self.gif_path and self.sim.time >= self.next_frame - 1e-9:
                self.sim.record_frame()
                self.next_frame += self.frame_every
            if events:
                self.publish_state()
                self.publish_markers()
                self.get_logger().info(f"t={self.sim.time:.2f}: finished {', '.join(e.task for e in events)}")
                if self.sync and self.decision_due():
                    self.waiting_since = time.monotonic()
                    break
            elif self.sim.time >= self.next_pose - 1e-9:
                self.next_pose = self.sim.time + 1.0
                self.publish_team()
                self.publish_markers()
            if self.later and self.sim.time >= self.later[0].at - 1e-9:
                break  # a scripted event is due: on_tick applies it next

    def on_tick(self) -> None:
        if self.finished:
            return
        if not self.started:
            self.start()
            return
        while self.later and self.later[0].at <= self.sim.time + 1e-9 and not self.finished:
            event = self.later.pop(0)
            try:
                self.apply(event)
            except WorldEventRejected as exc:
                self.finish(f"scripted event at t={event.at:g} ({event.kind} {event.target}) refused: {exc}")
        self.check_stuck()
        if self.finished:
            return
        if self.waiting_since is not None:
            limit = self.sync_timeout if self.decisions else self.first_sync_timeout
            if time.monotonic() - self.waiting_since < limit:
                return
            self.get_logger().warn(f"t={self.sim.time:.2f}: no decision within {limit:g} s; running on")
            self.waiting_since = None
        self.advance()
        self.publish_clock()
        if self.sim.done:
            self.finish()
        elif self.sim.time > self.max_sim_time:
            self.finish(f"not finished after {self.max_sim_time:g} s of sim time")

    def finish(self, error: str = "") -> None:
        self.finished = True
        self.exit_code = 1 if error else 0
        summary: dict[str, Any] = {
            "makespan": self.sim.makespan, "tasks_done": sum(s == TaskStatus.DONE for s in self.sim.status.values()),
            "tasks": len(self.sim.status), "decisions_received": self.decisions, "rejected": self.rejected,
            "error": error, "sim_time": self.sim.time, "wall_seconds": time.monotonic() - self.start_wall,
            "world_events": self.world_events, "failed_robots": sorted(self.sim.failed),
        }
        if self.gif_path and isinstance(self.sim, CellSim) and self.sim.trace:
            from lvws_ros.sim.render import render_gif

            self.sim.record_frame()
            shown = [time.monotonic()]

            def drawn(k: int, n: int) -> None:  # a progress line every 2 s (lvws launch prints them)
                if k == n or time.monotonic() - shown[0] >= 2.0:
                    shown[0] = time.monotonic()
                    self.get_logger().info(f"progress: the run ended; writing the GIF, frame {k}/{n}")

            summary["gif"] = str(render_gif(self.sim.cfg, self.sim.trace, len(self.sim.status), self.gif_path,
                                            progress=drawn))
        if self.summary_path:
            Path(self.summary_path).parent.mkdir(parents=True, exist_ok=True)
            Path(self.summary_path).write_text(json.dumps(summary, indent=1))
        if error:
            self.get_logger().error(error)
        else:
            self.get_logger().info(f"all {summary['tasks']} tasks done: makespan {self.sim.makespan:.2f} s")
        print(json.dumps(summary), flush=True)


def run(node: CellSimNode) -> int:
    """Spin until the world is done, then a moment more so the recorder takes the final state."""
    while rclpy.ok() and not node.finished:
        spin_once(node, 0.1)
    if not node.finished:
        return 1
    end = time.monotonic() + 0.5
    while rclpy.ok() and time.monotonic() < end:
        spin_once(node, 0.05)
    return node.exit_code


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="cell_sim", description=DESCRIPTION)
    return node_main("cell_sim", argv, parser, lambda _args: CellSimNode(), run, interrupted=130)


if __name__ == "__main__":
    sys.exit(main())
