"""Cell simulator node: ``ros2 run lvws_ros cell_sim``, the case study world on ROS topics.

Publishes TeamState and TaskGraph (latched) on every change (and TeamState once a sim
second for poses), ``/clock`` (sim time), ``visualization_msgs/MarkerArray`` on
``/lvws/markers``; executes the AssignmentArrays it receives. Sim time runs ``rate``
times faster than wall time; with ``sync`` (default) the world pauses at a decision
step until the scheduler answers it (or ``sync_timeout`` wall seconds pass), so runs do
not depend on the machine's speed. When every task is done it prints the makespan,
writes ``summary`` (JSON) and the ``gif``, and exits 0.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from lvws_ros.ros.common import user_args

DESCRIPTION = (
    "pymunk assembly-cell simulator of the paper's case study. ROS parameters: config (YAML, default "
    "the shipped config/assembly_cell.yaml), rate (sim/wall speed-up, default 10), sync (pause at "
    "decision steps until answered, default true), sync_timeout (wall s), expect_subscribers (start once "
    "this many nodes subscribe, default 1), wait_for_subscribers (wall s), "
    "max_sim_time (s), summary (JSON path), gif (animated GIF path), frame_every (sim s between GIF frames)."
)


def build_parser() -> argparse.ArgumentParser:
    return argparse.ArgumentParser(prog="cell_sim", description=DESCRIPTION)


def make_node() -> Any:
    from lvws_msgs.msg import AssignmentArray, TaskGraph, TeamState
    from rclpy.node import Node
    from rosgraph_msgs.msg import Clock
    from visualization_msgs.msg import Marker, MarkerArray

    from lvws_ros.cell_sim import ARM_KINDS, READY, AssignmentRejected, CellSim, load_cell_config
    from lvws_ros.ros import common

    class CellSimNode(Node):
        def __init__(self) -> None:
            super().__init__("cell_sim")
            cfg_path = str(self.declare_parameter("config", "").value)
            self.rate = float(self.declare_parameter("rate", 10.0).value)
            self.sync = bool(self.declare_parameter("sync", True).value)
            self.sync_timeout = float(self.declare_parameter("sync_timeout", 5.0).value)
            self.wait_subs = float(self.declare_parameter("wait_for_subscribers", 20.0).value)
            self.expect_subs = int(self.declare_parameter("expect_subscribers", 1).value)
            self.max_sim_time = float(self.declare_parameter("max_sim_time", 3600.0).value)
            self.summary_path = str(self.declare_parameter("summary", "").value)
            self.gif_path = str(self.declare_parameter("gif", "").value)
            self.frame_every = float(self.declare_parameter("frame_every", 2.0).value)
            if self.rate <= 0:
                raise ValueError(f"parameter rate must be > 0, got {self.rate}")
            self.sim = CellSim(load_cell_config(cfg_path or None))
            self.frame = self.sim.cfg.frame_id
            self.team_pub = self.create_publisher(TeamState, common.TEAM_TOPIC, common.TEAM_QOS)
            self.graph_pub = self.create_publisher(TaskGraph, common.GRAPH_TOPIC, common.GRAPH_QOS)
            self.clock_pub = self.create_publisher(Clock, common.CLOCK_TOPIC, common.CLOCK_QOS)
            self.marker_pub = self.create_publisher(MarkerArray, common.MARKERS_TOPIC, common.MARKERS_QOS)
            self.create_subscription(AssignmentArray, common.ASSIGNMENTS_TOPIC, self.on_assignments,
                                     common.ASSIGNMENTS_QOS)
            self.Marker, self.MarkerArray, self.Clock = Marker, MarkerArray, Clock
            self.arm_kinds = ARM_KINDS
            self.Rejected = AssignmentRejected
            self.waiting_since: float | None = None  # wall time we started waiting for a decision
            self.last_stamp = -1.0
            self.started = False
            self.start_wall = time.monotonic()
            self.finished = False
            self.rejected: list[str] = []
            self.decisions = 0
            self.next_pose = 0.0
            self.next_frame = 0.0
            self.tick = 0.02
            self.create_timer(self.tick, self.on_tick)

        # -- publishing ------------------------------------------------------------------
        def publish_state(self) -> None:
            self.last_stamp = self.sim.time
            self.team_pub.publish(common.team_to_msg(self.sim.team_snapshot(), self.frame))
            self.graph_pub.publish(common.graph_to_msg(self.sim.graph_snapshot(), self.frame))

        def publish_clock(self) -> None:
            self.clock_pub.publish(self.Clock(clock=common.to_time(self.sim.time)))

        def publish_markers(self) -> None:
            Marker = self.Marker
            stamp = common.to_time(self.sim.time)
            out = self.MarkerArray()
            k = 0

            def add(ns: str, kind: int, x: float, y: float, sx: float, sy: float, sz: float,
                    rgba: tuple[float, float, float, float], text: str = "") -> None:
                nonlocal k
                m = Marker(ns=ns, id=k, type=kind, action=Marker.ADD, text=text)
                m.header.frame_id, m.header.stamp = self.frame, stamp
                m.pose.position.x, m.pose.position.y, m.pose.position.z = x, y, sz / 2
                m.pose.orientation.w = 1.0
                m.scale.x, m.scale.y, m.scale.z = sx, sy, sz
                m.color.r, m.color.g, m.color.b, m.color.a = rgba
                out.markers.append(m)
                k += 1

            for cell in self.sim.cfg.cells.values():
                add("cells", Marker.CUBE, *cell.position, *cell.size, 0.02, (0.7, 0.7, 0.7, 0.5))
                add("labels", Marker.TEXT_VIEW_FACING, cell.position[0], cell.position[1] + cell.size[1] / 2 + 0.3,
                    0.4, 0.4, 0.4, (1.0, 1.0, 1.0, 1.0), cell.id)
            for r in self.sim.cfg.robots:
                x, y = self.sim.position(r.id)
                busy = self.sim.robot_task[r.id] is not None
                color = {"panda": (1.0, 0.5, 0.0), "jackal": (0.1, 0.4, 0.9), "husky": (0.1, 0.7, 0.2)}[r.kind]
                shape = Marker.CYLINDER if r.kind in self.arm_kinds else Marker.SPHERE
                add("robots", shape, x, y, 0.7, 0.7, 0.7, (*color, 1.0 if busy else 0.5))
                add("labels", Marker.TEXT_VIEW_FACING, x, y - 0.8, 0.3, 0.3, 0.3, (1.0, 1.0, 1.0, 1.0),
                    f"{r.id}: {self.sim.robot_task[r.id] or 'wait'}")
            for o in self.sim.cfg.objects.values():
                x, y = self.sim.position(o.id)
                s = 0.4 + 0.08 * o.weight
                add("objects", Marker.CUBE, x, y, s, s, s, (0.85, 0.1, 0.1, 1.0))
            self.marker_pub.publish(out)

        # -- input -----------------------------------------------------------------------
        def on_assignments(self, msg: Any) -> None:
            if abs(common.from_time(msg.team_stamp) - self.last_stamp) < 1e-6:
                self.waiting_since = None  # the decision for our current state: resume
            for a in msg.assignments:
                try:
                    self.sim.assign(a.task_id, list(a.robot_ids))
                except self.Rejected as exc:
                    text = f"t={self.sim.time:.2f}: rejected {a.task_id} <- {list(a.robot_ids)}: {exc}"
                    self.rejected.append(text)
                    self.get_logger().error(text)
            self.decisions += 1
            if msg.assignments:
                self.publish_state()

        # -- the loop --------------------------------------------------------------------
        def decision_due(self) -> bool:
            team = self.sim.team_snapshot()
            graph = self.sim.graph_snapshot()
            return any(r.available for r in team.robots) and any(t.status == READY for t in graph.tasks)

        def on_tick(self) -> None:
            if self.finished:
                return
            if not self.started:
                subs = min(self.team_pub.get_subscription_count(), self.graph_pub.get_subscription_count())
                if subs < self.expect_subs and time.monotonic() - self.start_wall < self.wait_subs:
                    return  # give the scheduler and recorder time to discover us
                self.started = True
                self.get_logger().info(f"starting: {subs} subscriber(s) on {common.TEAM_TOPIC}, rate {self.rate:g}x")
                self.publish_clock()
                self.publish_state()
                self.publish_markers()
                if self.sync and self.decision_due():
                    self.waiting_since = time.monotonic()
                return
            if self.waiting_since is not None:
                if time.monotonic() - self.waiting_since < self.sync_timeout:
                    return
                self.get_logger().warn(f"t={self.sim.time:.2f}: no decision within {self.sync_timeout:g} s; running on")
                self.waiting_since = None
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
                    self.team_pub.publish(common.team_to_msg(self.sim.team_snapshot(), self.frame))
                    self.publish_markers()
            self.publish_clock()
            if self.sim.done:
                self.finish()
            elif self.sim.time > self.max_sim_time:
                self.finish(f"not finished after {self.max_sim_time:g} s of sim time")

        def finish(self, error: str = "") -> None:
            self.finished = True
            self.exit_code = 1 if error else 0
            summary = {
                "makespan": self.sim.makespan, "tasks_done": sum(s == 3 for s in self.sim.status.values()),
                "tasks": len(self.sim.status), "decisions_received": self.decisions, "rejected": self.rejected,
                "error": error, "sim_time": self.sim.time, "wall_seconds": time.monotonic() - self.start_wall,
            }
            if self.gif_path and self.sim.trace:
                from lvws_ros.cell_render import render_gif

                self.sim.record_frame()
                summary["gif"] = str(render_gif(self.sim.cfg, self.sim.trace, len(self.sim.status), self.gif_path))
            if self.summary_path:
                Path(self.summary_path).parent.mkdir(parents=True, exist_ok=True)
                Path(self.summary_path).write_text(json.dumps(summary, indent=1))
            if error:
                self.get_logger().error(error)
            else:
                self.get_logger().info(f"all {summary['tasks']} tasks done: makespan {self.sim.makespan:.2f} s")
            print(json.dumps(summary), flush=True)

    return CellSimNode()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    build_parser().parse_args(user_args(argv))
    import rclpy
    from rclpy.executors import ExternalShutdownException

    rclpy.init(args=["cell_sim", *argv])
    try:
        node = make_node()
    except Exception as exc:
        sys.stderr.write(f"cell_sim: {exc}\n")
        rclpy.try_shutdown()
        return 1
    code = 1
    try:
        while rclpy.ok() and not node.finished:
            rclpy.spin_once(node, timeout_sec=0.1)
        if node.finished:
            # let the recorder take the final state before we go
            end = time.monotonic() + 0.5
            while rclpy.ok() and time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
            code = node.exit_code
    except (KeyboardInterrupt, ExternalShutdownException):
        code = 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
