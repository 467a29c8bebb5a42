"""A search policy deliberates beside the scheduler node's callbacks: while ``lvws_sample``
spends a 3 s budget on one decision, the node keeps publishing its health on diagnostics
(a timer callback), and a team message that arrives meanwhile is taken after the decision
is published (nothing lost), over DDS between processes."""

from __future__ import annotations

import time

import pytest
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState

from scheduler_probe import scheduler_probe

pytestmark = pytest.mark.ros

CAPS = ["lift", "drive"]
BUDGET_S = 3.0


def snapshots(stamp: int, robots: int, ready: int) -> tuple[TeamState, TaskGraph]:
    team = TeamState(capability_names=CAPS)
    team.header.stamp.sec = stamp
    for k in range(robots):
        team.robots.append(RobotState(id=f"r{k}", kind="x", available=True, capabilities=[1, k % 2], payload=5.0))
    graph = TaskGraph(capability_names=CAPS)
    graph.header.stamp.sec = stamp
    for k in range(ready):
        graph.tasks.append(Task(id=f"t{k}", status=Task.STATUS_READY, capabilities=[1, 0], payload=2.0, duration=5.0))
    return team, graph


def test_the_node_serves_its_callbacks_while_a_decision_deliberates(ros_context):
    args = ["-p", "policy:=lvws_sample", "-p", f"decision_budget_ms:={1000 * BUDGET_S}"]
    with scheduler_probe(ros_context, "lvws_thread_test", args) as probe:
        probe.wait_for_scheduler()
        probe.spin(20, lambda: bool(probe.diags))
        team, graph = snapshots(10, 3, 5)
        probe.team_pub.publish(team)
        probe.graph_pub.publish(graph)
        sent, before = time.monotonic(), len(probe.diags)
        probe.spin(1.0)
        later_team, later_graph = snapshots(11, 5, 7)  # new robots and tasks, while the first decision is made
        probe.team_pub.publish(later_team)
        probe.graph_pub.publish(later_graph)
        probe.spin(30, lambda: bool(probe.got))
        took, during = time.monotonic() - sent, len(probe.diags) - before
        assert probe.got and probe.got[0].assignments, probe.diags[-5:]
        assert took >= BUDGET_S * 0.8  # the sampler spent its budget on the decision
        assert during >= 2, probe.diags[-5:]  # the 1 Hz health timer ran meanwhile
        # the later messages were kept and answered: a decision stamped no earlier than them
        probe.spin(30, lambda: any(m.header.stamp.sec >= 11 for m in probe.got))
        assert any(m.header.stamp.sec >= 11 for m in probe.got), [m.header.stamp.sec for m in probe.got]
        assert probe.proc.poll() is None
    assert "Traceback" not in probe.output, probe.output
