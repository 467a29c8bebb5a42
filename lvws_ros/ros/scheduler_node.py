"""Scheduler node: ``ros2 run lvws_ros scheduler`` (also ``lvws scheduler``).

Subscribes to ``/lvws/team_state`` (TeamState) and ``/lvws/task_graph`` (TaskGraph,
latched) and publishes ``/lvws/assignments`` (AssignmentArray) at each decision step:
whenever a robot becomes available or a task becomes ready. A thin shell over
:class:`lvws_ros.core.online.OnlineScheduler`: parameters, message conversion
(:mod:`lvws_ros.ros.convert`), the core, publish. Health goes to ``/diagnostics`` once
a second and on every error.

Parameters: policy (lvws | lvws_rollout | dbgm | grp | rand | rand_subteam | exact;
default lvws), fallback_policy (default grp; "" for none: decides a step the main policy
cannot serve, with a WARN on /diagnostics), model_path ("" = the shipped checkpoint), seed,
ack_timeout, expect_subscribers (the first decision waits until this many nodes subscribe
to the assignments, default 0), use_sim_time.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from lvws_msgs.msg import AssignmentArray, TaskGraph, TeamState
from rclpy.clock import Clock, ClockType
from rclpy.node import Node

from lvws_ros.core.online import OnlineScheduler
from lvws_ros.errors import ConfigError, LvwsError
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
# name -> (type, default); the ones a params file may set
PARAMETERS: dict[str, tuple[type, object]] = {"policy": (str, DEFAULT_POLICY), "fallback_policy": (str, "grp"),
                                              "model_path": (str, ""),
                                              "seed": (int, 0), "ack_timeout": (float, 5.0),
                                              "expect_subscribers": (int, 0), "use_sim_time": (bool, False)}
SUBSCRIBER_WAIT = 20.0  # wall seconds the first decision waits for expect_subscribers
SETTLE_SECONDS = 0.2  # wall time to wait for the matching team/graph message


def check_params_file(path: str | Path, node: str = "scheduler") -> dict[str, Any]:
    """The scheduler's parameters in a ROS 2 params file (``<node>:`` or ``/**:`` then
    ``ros__parameters:``), checked without starting anything: ConfigError naming the
    file and the parameter."""
    p = Path(path)
    try:
        data = yaml.safe_load(p.read_text())
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the parameter file: {exc.strerror or exc}") from None
    except yaml.YAMLError as exc:
        raise ConfigError(f"{p}: malformed YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping of node names to ros__parameters")
    params: dict[str, Any] = {}
    for key in ("/**", node, f"/{node}"):
        section = data.get(key)
        if section is None:
            continue
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ConfigError(f"{p}: {key}: expected a 'ros__parameters' mapping")
        params.update(section["ros__parameters"])
    for name, value in params.items():
        if name not in PARAMETERS:
            raise ConfigError(f"{p}: {node}.{name}: unknown parameter (known: {', '.join(PARAMETERS)})")
        kind = PARAMETERS[name][0]
        if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            if not (kind is float and isinstance(value, int) and not isinstance(value, bool)):
                raise ConfigError(f"{p}: {node}.{name}: expected {kind.__name__}, got {value!r}")
    for key in ("policy", "fallback_policy"):
        if key in params and params[key] not in POLICY_NAMES and not (key == "fallback_policy" and params[key] == ""):
            raise ConfigError(f"{p}: {node}.{key}: unknown {params[key]!r}; one of {', '.join(POLICY_NAMES)}")
    if params.get("model_path") and not Path(params["model_path"]).is_file():
        raise ConfigError(f"{p}: {node}.model_path: no such file {params['model_path']!r}")
    return params


class SchedulerNode(Node):
    def __init__(self) -> None:
        super().__init__("scheduler")
        self.policy_name = str(self.declare_parameter("policy", DEFAULT_POLICY).value)
        fallback = str(self.declare_parameter("fallback_policy", "grp").value)
        model_path = str(self.declare_parameter("model_path", "").value)
        self.seed = int(self.declare_parameter("seed", 0).value)
        ack_timeout = float(self.declare_parameter("ack_timeout", 5.0).value)
        # the first decision waits (at most SUBSCRIBER_WAIT) until this many nodes (a recorder,
        # the world) subscribe to lvws/assignments, so none of them misses it
        self.expect_subscribers = int(self.declare_parameter("expect_subscribers", 0).value)
        self.started_at = time.monotonic()
        if self.policy_name not in POLICY_NAMES:
            raise LvwsError(f"parameter policy: unknown {self.policy_name!r}; one of {', '.join(POLICY_NAMES)}")
        if fallback and fallback not in POLICY_NAMES:
            raise LvwsError(f"parameter fallback_policy: unknown {fallback!r}; one of {', '.join(POLICY_NAMES)} or ''")
        options = {"model_path": model_path} if self.policy_name in LEARNED_POLICIES else {}
        self.core = OnlineScheduler(make_policy(self.policy_name, seed=self.seed, **options), ack_timeout,
                                    fallback=make_policy(fallback, seed=self.seed) if fallback else None)
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
        self.rejected: dict[str, str] = {}  # message kind -> why its latest one was ignored
        self.last_latency = 0.0
        self.received = 0
        self.get_logger().info(f"policy {self.policy_name}, seed {self.seed}, model {model_path or 'shipped'}")
        # The start-up objects (torch, rclpy, the model) live as long as the node: freezing
        # them keeps a full garbage collection from pausing a decision (100 x 500: p99 of the
        # decision latency 48 -> 37 ms, docs/scale.md).
        gc.freeze()

    def on_team(self, msg: TeamState) -> None:
        self.guarded(lambda: self.offer("TeamState", lambda: self.core.offer_team(convert.team_from_msg(msg))))

    def on_graph(self, msg: TaskGraph) -> None:
        self.guarded(lambda: self.offer("TaskGraph", lambda: self.core.offer_graph(convert.graph_from_msg(msg))))

    def guarded(self, work: Callable[[], None]) -> None:
        """No message content may stop the node: a bug is logged with its traceback and
        reported (ERROR), and the node serves the next message."""
        try:
            work()
        except Exception as exc:
            self.error = f"internal error {type(exc).__name__}: {exc}"
            self.get_logger().error(traceback.format_exc())
            self.publish_diagnostics(DiagnosticStatus.ERROR, self.error)

    def offer(self, kind: str, take: Callable[[], bool]) -> None:
        """Hand a snapshot to the core; a malformed one is reported (ERROR) and ignored."""
        self.received += 1
        try:
            taken = take()
        except LvwsError as exc:
            self.rejected[kind] = str(exc)
            self.report(DiagnosticStatus.ERROR, f"{kind} ignored: {exc}")
            return
        self.rejected.pop(kind, None)
        self.flush_notices()
        if taken:
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
            self.guarded(self.step)

    def audience_ready(self) -> bool:
        """Whether the expected subscribers of lvws/assignments are there (or the wait is over)."""
        if self.core.step > 0 or self.pub.get_subscription_count() >= self.expect_subscribers:
            return True
        return time.monotonic() - self.started_at > SUBSCRIBER_WAIT

    def step(self) -> None:
        if not self.audience_ready():
            self.unsynced_since = time.monotonic()  # on_settle tries again
            return
        try:
            decision = self.core.decide()
        except LvwsError as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.report(DiagnosticStatus.ERROR, self.error)
            return
        self.error = ""
        self.flush_notices()
        if decision is None:
            return
        self.last_latency = decision.latency
        self.pub.publish(convert.decision_to_msg(decision, self.get_clock().now().to_msg()))
        made = ", ".join(f"{t}<-{'+'.join(r)}" for t, r in decision.assignments) or "-"
        self.get_logger().info(f"step {decision.step}: {made}; waiting {', '.join(decision.waiting) or '-'} "
                               f"({1000 * decision.latency:.1f} ms)")

    def flush_notices(self) -> None:
        """The core's notices (world restarts, released assignments, untrusted readiness) as WARN."""
        while self.core.notices:
            self.report(DiagnosticStatus.WARN, self.core.notices.pop(0))

    def report(self, level: bytes, message: str) -> None:
        """Log and publish one diagnostics status now (besides the periodic one)."""
        if level == DiagnosticStatus.ERROR:  # one call site per severity (rclpy's rule)
            self.get_logger().error(message)
        else:
            self.get_logger().warning(message)
        self.publish_diagnostics(level, message)

    def publish_diagnostics(self, level: bytes | None = None, message: str = "") -> None:
        """The node's health: ERROR while the latest message of a kind was refused or the
        last step failed, else OK; ``level``/``message`` publish one event now."""
        status = DiagnosticStatus(name="lvws_scheduler", hardware_id=self.get_name())
        problem = self.error or "; ".join(f"{k} ignored: {v}" for k, v in sorted(self.rejected.items()))
        status.level = level if level is not None else (DiagnosticStatus.ERROR if problem else DiagnosticStatus.OK)
        status.message = message or problem or ("waiting for team and task graph" if self.core.team is None
                                                or self.core.graph is None else "ok")
        status.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ("policy", self.policy_name), ("seed", self.seed), ("decisions", self.core.step),
            ("last_latency_ms", f"{1000 * self.last_latency:.3f}"), ("messages", self.received),
            ("out_of_order_dropped", self.core.dropped), ("world_restarts", self.core.restarts),
            ("pending", len(self.core.pending)), ("fallback_steps", self.core.fallbacks))]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scheduler", description=DESCRIPTION)
    return node_main("scheduler", argv, parser, lambda _args: SchedulerNode())


if __name__ == "__main__":
    sys.exit(main())
