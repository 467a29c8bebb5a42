"""A scheduler node in its own process and a test node that talks to it over DDS: the
publishers of team and graph, the assignments and diagnostics it receives (as
"<level>:<message>" strings, their key-values, and the hardware ids), and a spin that stops when a
condition holds. With ``namespace`` the scheduler runs in it and the probe talks there."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import rclpy
from lvws_msgs.msg import AssignmentArray, TaskGraph, TeamState
from rclpy.qos import QoSProfile, ReliabilityPolicy

from lvws_ros.ros.topics import ASSIGNMENTS_TOPIC, DIAGNOSTICS_TOPIC, GRAPH_QOS, GRAPH_TOPIC, TEAM_QOS, TEAM_TOPIC, message_class


@dataclass
class Probe:
    proc: subprocess.Popen[str]
    executor: Any
    team_pub: Any
    graph_pub: Any
    got: list[AssignmentArray] = field(default_factory=list)
    diags: list[str] = field(default_factory=list)
    hardware_ids: set[str] = field(default_factory=set)
    values: list[dict[str, str]] = field(default_factory=list)  # each diagnostics status's key-values
    node: Any = None
    output: str = ""  # the node's stdout and stderr, once it has stopped

    def spin(self, seconds: float, until: Callable[[], bool] = lambda: False) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not until():
            self.executor.spin_once(timeout_sec=0.05)

    def wait_for_scheduler(self, seconds: float = 60.0) -> None:
        """Until the node subscribes to team and graph."""
        self.spin(seconds, lambda: self.team_pub.get_subscription_count() > 0
                  and self.graph_pub.get_subscription_count() > 0)


@contextmanager
def scheduler_probe(ros_context: Any, name: str, ros_args: Sequence[str], namespace: str = "") -> Iterator[Probe]:
    """``python -m lvws_ros.ros.scheduler_node --ros-args *ros_args`` (in ``namespace``)
    and a test node ``name`` there; SIGINT to the scheduler on the way out (its output in
    ``probe.output``)."""
    ns = ["-r", f"__ns:={namespace}"] if namespace else []
    proc = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args", *ns, *ros_args],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    node = rclpy.create_node(name, context=ros_context, namespace=namespace or None)
    executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    reliable = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
    probe = Probe(proc, executor, node.create_publisher(TeamState, TEAM_TOPIC, TEAM_QOS),
                  node.create_publisher(TaskGraph, GRAPH_TOPIC, GRAPH_QOS), node=node)

    def on_diagnostics(m: Any) -> None:
        probe.diags.extend(f"{s.level[0]}:{s.message}" for s in m.status)
        probe.hardware_ids.update(s.hardware_id for s in m.status)
        probe.values.extend({kv.key: kv.value for kv in s.values} for s in m.status)

    node.create_subscription(AssignmentArray, ASSIGNMENTS_TOPIC, probe.got.append, reliable)
    node.create_subscription(message_class("diagnostic_msgs/msg/DiagnosticArray"), DIAGNOSTICS_TOPIC,
                             on_diagnostics, reliable)
    # the node's output is read as it comes: a pipe nobody reads fills up and blocks the node
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(proc.stdout or ()), daemon=True)
    reader.start()
    try:
        yield probe
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=30)
        reader.join(timeout=10)
        probe.output = "".join(lines)
        node.destroy_node()
