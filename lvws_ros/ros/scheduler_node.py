"""Scheduler node: ``ros2 run lvws_ros scheduler`` (also ``lvws scheduler``).

Subscribes to ``/lvws/team_state`` (TeamState) and ``/lvws/task_graph`` (TaskGraph,
latched) and publishes ``/lvws/assignments`` (AssignmentArray) at each decision step:
whenever a robot becomes available or a task becomes ready. A thin shell over
:class:`lvws_ros.core.online.OnlineScheduler`: parameters, message conversion
(:mod:`lvws_ros.ros.convert`), the core, publish. Health goes to ``/diagnostics`` once
a second and on every error.

Parameters: policy (lvws | lvws_rollout | dbgm | grp | rand | rand_subteam | exact;
default lvws), model_path ("" = the shipped checkpoint), seed, ack_timeout, use_sim_time.
"""

from __future__ import annotations

import argparse
import sys
import time

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from lvws_msgs.msg import AssignmentArray, TaskGraph, TeamState
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from lvws_ros.core.online import OnlineScheduler
from lvws_ros.errors import LvwsError
from lvws_ros.registry import LEARNED_POLICIES, POLICY_NAMES, make_policy
from lvws_ros.ros import convert, topics
from lvws_ros.ros.entry import node_main

DESCRIPTION = (
    "LVWS scheduler node: subscribes to /lvws/team_state and /lvws/task_graph, "
    "publishes /lvws/assignments (lvws_msgs/AssignmentArray) at every decision step. "
    "ROS parameters: policy, model_path, seed, ack_timeout, use_sim_time "
    "(--ros-args -p NAME:=VALUE or --params-file config/scheduler.yaml)."
)
DEFAULT_POLICY = "lvws"
SETTLE_SECONDS = 0.2  # wall time to wait for the matching team/graph message


class SchedulerNode(Node):
    def __init__(self) -> None:
        super().__init__("scheduler")
        self.policy_name = str(self.declare_parameter("policy", DEFAULT_POLICY).value)
        model_path = str(self.declare_parameter("model_path", "").value)
        self.seed = int(self.declare_parameter("seed", 0).value)
        ack_timeout = float(self.declare_parameter("ack_timeout", 5.0).value)
        if self.policy_name not in POLICY_NAMES:
            raise LvwsError(f"parameter policy: unknown {self.policy_name!r}; one of {', '.join(POLICY_NAMES)}")
        options = {"model_path": model_path} if self.policy_name in LEARNED_POLICIES else {}
        self.core = OnlineScheduler(make_policy(self.policy_name, seed=self.seed, **options), ack_timeout)
        self.pub = self.create_publisher(AssignmentArray, topics.ASSIGNMENTS_TOPIC, topics.ASSIGNMENTS_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, topics.DIAGNOSTICS_QOS)
        self.create_subscription(TeamState, topics.TEAM_TOPIC, self.on_team, topics.TEAM_QOS)
        self.create_subscription(TaskGraph, topics.GRAPH_TOPIC, self.on_graph, topics.GRAPH_QOS)
        # wall-clock timers: with use_sim_time a paused simulator would stop ROS-time ones
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, self.publish_diagnostics, clock=steady)
        self.create_timer(0.05, self.on_settle, clock=steady)
        self.unsynced_since: float | None = None
        self.error = ""
        self.last_latency = 0.0
        self.received = 0
        self.get_logger().info(f"policy {self.policy_name}, seed {self.seed}, model {model_path or 'shipped'}")

    def on_team(self, msg: TeamState) -> None:
        self.received += 1
        if self.core.offer_team(convert.team_from_msg(msg)):
            self.maybe_step()

    def on_graph(self, msg: TaskGraph) -> None:
        self.received += 1
        if self.core.offer_graph(convert.graph_from_msg(msg)):
            self.maybe_step()

    def maybe_step(self) -> None:
        """Decide when team and graph describe the same instant; a publisher that
        never stamps them alike is served after SETTLE_SECONDS."""
        team, graph = self.core.team, self.core.graph
        if team is not None and graph is not None and abs(team.stamp - graph.stamp) < 1e-9:
            self.unsynced_since = None
            self.step()
        elif self.unsynced_since is None:
            self.unsynced_since = time.monotonic()

    def on_settle(self) -> None:
        if self.unsynced_since is not None and time.monotonic() - self.unsynced_since > SETTLE_SECONDS:
            self.unsynced_since = None
            self.step()

    def step(self) -> None:
        try:
            decision = self.core.decide()
        except LvwsError as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(self.error)
            self.publish_diagnostics()
            return
        self.error = ""
        if decision is None:
            return
        self.last_latency = decision.latency
        self.pub.publish(convert.decision_to_msg(decision, self.get_clock().now().to_msg()))
        made = ", ".join(f"{t}<-{'+'.join(r)}" for t, r in decision.assignments) or "-"
        self.get_logger().info(f"step {decision.step}: {made}; waiting {', '.join(decision.waiting) or '-'} "
                               f"({1000 * decision.latency:.1f} ms)")

    def publish_diagnostics(self) -> None:
        status = DiagnosticStatus(name="lvws_scheduler", hardware_id=self.get_name())
        status.level = DiagnosticStatus.ERROR if self.error else DiagnosticStatus.OK
        status.message = self.error or ("waiting for team and task graph" if self.core.team is None
                                        or self.core.graph is None else "ok")
        status.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ("policy", self.policy_name), ("seed", self.seed), ("decisions", self.core.step),
            ("last_latency_ms", f"{1000 * self.last_latency:.3f}"), ("messages", self.received),
            ("out_of_order_dropped", self.core.dropped), ("pending", len(self.core.pending)))]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scheduler", description=DESCRIPTION)
    return node_main("scheduler", argv, parser, lambda _args: SchedulerNode())


if __name__ == "__main__":
    sys.exit(main())
