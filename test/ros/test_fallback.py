"""The scheduler node never stalls on its main policy: with a model that cannot serve a
4-capability team (its weights give non-finite rewards), every decision comes from the
fallback policy (grp), and /diagnostics says so (WARN)."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from collections.abc import Callable

import pytest
import rclpy
import torch
from lvws_msgs.msg import AssignmentArray, RobotState, Task, TaskGraph, TeamState
from rclpy.qos import QoSProfile, ReliabilityPolicy

from lvws_ros.learning.checkpoint import save_checkpoint
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.ros.topics import GRAPH_QOS, TEAM_QOS, message_class

pytestmark = pytest.mark.ros

CAPS = ["lift", "drive", "weld", "scan"]


def snapshots(stamp: int) -> tuple[TeamState, TaskGraph]:
    team = TeamState(capability_names=CAPS)
    team.header.stamp.sec = stamp
    for k, caps in enumerate(([1, 1, 0, 0], [0, 0, 1, 1], [1, 0, 1, 0])):
        team.robots.append(RobotState(id=f"r{k}", kind="x", available=True, capabilities=caps, payload=5.0))
    graph = TaskGraph(capability_names=CAPS)
    graph.header.stamp.sec = stamp
    for k, caps in enumerate(([1, 0, 0, 0], [0, 0, 0, 1], [0, 1, 1, 0])):
        graph.tasks.append(Task(id=f"t{k}", status=Task.STATUS_READY, capabilities=caps, payload=2.0, duration=5.0))
    return team, graph


def test_a_model_that_cannot_serve_gives_way_to_the_fallback(ros_context, tmp_path):
    model = GATN(GATNConfig(hidden=16, mlp_hidden=16))
    with torch.no_grad():
        model.psi_out[-1].bias.fill_(float("nan"))  # every reward NaN
    broken = tmp_path / "nan.pt"
    save_checkpoint(broken, model, {"kind": "lvws", "idle_bias": 0.0})
    proc = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args", "-p", "policy:=lvws",
                             "-p", f"model_path:={broken}"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    node = rclpy.create_node("lvws_fallback_test", context=ros_context)
    executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    got: list[AssignmentArray] = []
    diags: list[str] = []
    try:
        team_pub = node.create_publisher(TeamState, "/lvws/team_state", TEAM_QOS)
        graph_pub = node.create_publisher(TaskGraph, "/lvws/task_graph", GRAPH_QOS)
        node.create_subscription(AssignmentArray, "/lvws/assignments", got.append,
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))
        node.create_subscription(message_class("diagnostic_msgs/msg/DiagnosticArray"), "/diagnostics",
                                 lambda m: diags.extend(f"{s.level[0]}:{s.message}" for s in m.status),
                                 QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))

        def spin(seconds: float, until: Callable[[], bool]) -> None:
            end = time.monotonic() + seconds
            while time.monotonic() < end and not until():
                executor.spin_once(timeout_sec=0.05)

        spin(60, lambda: team_pub.get_subscription_count() > 0 and graph_pub.get_subscription_count() > 0)
        spin(20, lambda: bool(diags))
        team, graph = snapshots(10)
        team_pub.publish(team)
        graph_pub.publish(graph)
        spin(30, lambda: bool(got) and any("fallback grp" in d for d in diags))
        assert got and got[0].policy == "grp" and got[0].assignments, (got, diags[-5:])
        assert any(d.startswith("1:") and "fallback grp" in d and "non-finite" in d for d in diags), diags[-5:]
        assert proc.poll() is None
    finally:
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=30)
        node.destroy_node()
    assert "Traceback" not in out, out
