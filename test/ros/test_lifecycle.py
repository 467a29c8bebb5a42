"""The scheduler as a managed lifecycle node (``-p managed:=true``), driven from another
process through the lifecycle_msgs services as a lifecycle manager (Nav2's, or
``ros2 lifecycle set``) drives it: unconfigured it decides nothing; configure loads the
policy; active it decides and publishes; inactive it publishes nothing more (and keeps
the messages); activated again it decides on the latest; cleanup frees it. Unmanaged
(the default) it is active from the start."""

from __future__ import annotations

from typing import Any

import pytest
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState

from lvws_ros.ros.service_call import call, ready
from scheduler_probe import scheduler_probe

pytestmark = pytest.mark.ros

CAPS = ["lift", "drive"]


def snapshots(stamp: int, tasks: int) -> tuple[TeamState, TaskGraph]:
    team = TeamState(capability_names=CAPS)
    team.header.stamp.sec = stamp
    for k in range(2):
        team.robots.append(RobotState(id=f"r{k}", kind="x", available=True, capabilities=[1, 1], payload=5.0))
    graph = TaskGraph(capability_names=CAPS)
    graph.header.stamp.sec = stamp
    for k in range(tasks):
        graph.tasks.append(Task(id=f"t{stamp}-{k}", status=Task.STATUS_READY, capabilities=[1, 0], payload=1.0,
                                duration=3.0))
    return team, graph


def _call(probe: Any, client: Any, request: Any, resend: float = 0.0) -> Any:
    """The answer (the client is :func:`ready`); a query is sent again while unanswered."""
    def wait(future: Any, seconds: float) -> bool:
        probe.spin(seconds, future.done)
        return bool(future.done())

    res = call(client, request, wait, 30.0, resend)
    assert res is not None, f"no answer on {client.srv_name}"
    return res


def test_a_managed_scheduler_follows_its_lifecycle(ros_context):
    with scheduler_probe(ros_context, "lvws_lifecycle_test", ["-p", "managed:=true", "-p", "policy:=grp"]) as probe:
        change = probe.node.create_client(ChangeState, "scheduler/change_state")
        get = probe.node.create_client(GetState, "scheduler/get_state")

        def state() -> int:
            return int(_call(probe, get, GetState.Request(), resend=3.0).current_state.id)

        def transition(tid: int) -> bool:
            return bool(_call(probe, change, ChangeState.Request(transition=Transition(id=tid))).success)

        probe.wait_for_scheduler()
        assert ready(change, 30.0) and ready(get, 30.0)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        team, graph = snapshots(10, 2)
        probe.team_pub.publish(team)
        probe.graph_pub.publish(graph)
        probe.spin(2.0)
        assert not probe.got  # unconfigured: nothing decided

        assert transition(Transition.TRANSITION_CONFIGURE)
        assert state() == State.PRIMARY_STATE_INACTIVE
        probe.spin(1.5)
        assert not probe.got  # configured, inactive: still nothing

        assert transition(Transition.TRANSITION_ACTIVATE)
        assert state() == State.PRIMARY_STATE_ACTIVE
        probe.spin(20, lambda: bool(probe.got))
        assert probe.got and probe.got[0].policy == "grp"  # the messages of before: kept and decided on
        assert {a.task_id for a in probe.got[0].assignments} <= {"t10-0", "t10-1"}

        assert transition(Transition.TRANSITION_DEACTIVATE)
        assert state() == State.PRIMARY_STATE_INACTIVE
        seen = len(probe.got)
        team, graph = snapshots(20, 2)  # new robots' view and new tasks: a decision would be due
        probe.team_pub.publish(team)
        probe.graph_pub.publish(graph)
        probe.spin(2.0)
        assert len(probe.got) == seen  # inactive: nothing published

        assert transition(Transition.TRANSITION_ACTIVATE)
        probe.spin(20, lambda: len(probe.got) > seen)
        assert len(probe.got) > seen and probe.got[-1].header.stamp.sec >= 20  # decided on the latest

        assert transition(Transition.TRANSITION_DEACTIVATE)
        assert transition(Transition.TRANSITION_CLEANUP)
        assert state() == State.PRIMARY_STATE_UNCONFIGURED
        probe.spin(1.5, lambda: any("unconfigured" in d for d in probe.diags))
        assert any("unconfigured" in d for d in probe.diags), probe.diags[-3:]
        assert probe.proc.poll() is None
    assert "Traceback" not in probe.output, probe.output


def test_an_unmanaged_scheduler_is_active_from_the_start(ros_context):
    with scheduler_probe(ros_context, "lvws_unmanaged_test", ["-p", "policy:=grp"]) as probe:
        get = probe.node.create_client(GetState, "scheduler/get_state")
        probe.wait_for_scheduler()
        assert ready(get, 30.0)
        assert int(_call(probe, get, GetState.Request(), resend=3.0).current_state.id) == State.PRIMARY_STATE_ACTIVE
        team, graph = snapshots(10, 2)
        probe.team_pub.publish(team)
        probe.graph_pub.publish(graph)
        probe.spin(20, lambda: bool(probe.got))
        assert probe.got and probe.got[0].assignments
