"""The scheduler node never stalls on its main policy: with a model that cannot serve a
4-capability team (its weights give non-finite rewards), every decision comes from the
fallback policy (grp), and /diagnostics says so (WARN)."""

from __future__ import annotations

import pytest
import torch
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState

from lvws_ros.learning.checkpoint import save_checkpoint
from lvws_ros.learning.gatn import GATN, GATNConfig
from scheduler_probe import scheduler_probe

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
    with scheduler_probe(ros_context, "lvws_fallback_test", ["-p", "policy:=lvws", "-p",
                                                             f"model_path:={broken}"]) as probe:
        probe.wait_for_scheduler()
        probe.spin(20, lambda: bool(probe.diags))
        team, graph = snapshots(10)
        probe.team_pub.publish(team)
        probe.graph_pub.publish(graph)
        probe.spin(30, lambda: bool(probe.got) and any("fallback grp" in d for d in probe.diags))
        got, diags = probe.got, probe.diags
        assert got and got[0].policy == "grp" and got[0].assignments, (got, diags[-5:])
        assert any(d.startswith("1:") and "fallback grp" in d and "non-finite" in d for d in diags), diags[-5:]
        assert probe.proc.poll() is None
    assert "Traceback" not in probe.output, probe.output
