"""Hostile messages from another process on the same DDS domain change nothing: for each
message that once killed, deafened or fooled the scheduler node, the node stays alive,
reports the problem on /diagnostics, and then decides the next valid state."""

from __future__ import annotations

from collections.abc import Callable

import pytest
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState

from scheduler_probe import scheduler_probe

pytestmark = pytest.mark.ros

ROBOTS = ("a", "b", "c")


def team(stamp: int, *, ids: tuple[str, ...] = ROBOTS, edit: Callable[[RobotState], None] | None = None) -> TeamState:
    msg = TeamState(capability_names=["lift", "drive"])
    msg.header.stamp.sec = stamp
    for rid in ids:
        r = RobotState(id=rid, kind="x", available=True, capabilities=[1, 1], payload=5.0)
        if edit is not None and rid == "a":
            edit(r)
        msg.robots.append(r)
    return msg


def graph(stamp: int, tag: str, *, edit: Callable[[Task], None] | None = None, after: bool = False) -> TaskGraph:
    """Two ready tasks (or one ready and one QUEUED after it) with ids new to each scenario."""
    msg = TaskGraph(capability_names=["lift", "drive"])
    msg.header.stamp.sec = stamp
    for k in range(2):
        t = Task(id=f"{tag}{k}", status=Task.STATUS_READY, capabilities=[1, 0], payload=1.0, duration=5.0)
        if after and k == 1:
            t.prerequisites = [f"{tag}0"]  # READY although its prerequisite is not done
        if edit is not None and k == 0:
            edit(t)
        msg.tasks.append(t)
    return msg


def _set(**fields: object) -> Callable[[object], None]:
    def edit(m: object) -> None:
        for k, v in fields.items():
            setattr(m, k, v)
    return edit


# (name, hostile messages (topic, msg) given the scenario's stamp, words expected on /diagnostics)
SCENARIOS = [
    ("status 200", lambda s: [("graph", graph(s, "s", edit=_set(status=200)))], "status: 200 is not one of"),
    ("stamp far ahead", lambda s: [("team", team(2147483647)), ("graph", graph(2147483647, "f"))],
     "world restart assumed"),
    ("NaN busy_for", lambda s: [("team", team(s, edit=_set(available=False, busy_for=float("nan"))))], None),
    ("NaN payload", lambda s: [("team", team(s, edit=_set(payload=float("nan"))))], "payload: nan"),
    ("unready task", lambda s: [("team", team(s)), ("graph", graph(s, "u", after=True))],
     "is READY but its prerequisite u0 is not DONE"),
    ("robot vanishes while pending", lambda s: [("team", team(s)), ("graph", graph(s, "v")),
                                                ("team", team(s + 1, ids=("b", "c")))], "left the latest snapshots"),
]


@pytest.mark.parametrize("policy", ["grp", "lvws"])
def test_hostile_messages_change_nothing(ros_context, policy):
    with scheduler_probe(ros_context, "lvws_hostile", ["-p", f"policy:={policy}", "-p",
                                                       "ack_timeout:=60.0"]) as probe:
        pubs = {"team": probe.team_pub, "graph": probe.graph_pub}
        got, diags, spin = probe.got, probe.diags, probe.spin
        probe.wait_for_scheduler()
        spin(3 if policy == "grp" else 10, lambda: bool(diags))  # the node is up and reporting
        stamp = 10
        for name, hostile, words in SCENARIOS:
            for topic, msg in hostile(stamp):
                pubs[topic].publish(msg)
                spin(0.3)
            assert probe.proc.poll() is None, f"{name}: the node died\n{probe.proc.communicate()[0]}"
            stamp += 10
            valid_tag = f"ok{stamp}"
            before = len(got)
            pubs["team"].publish(team(stamp))
            pubs["graph"].publish(graph(stamp, valid_tag))
            spin(30, lambda s=stamp, b=before: any(m.graph_stamp.sec == s for m in got[b:]))
            decided = [m for m in got[before:] if m.graph_stamp.sec == stamp]
            assert decided and {a.task_id for a in decided[0].assignments} == {f"{valid_tag}0", f"{valid_tag}1"}, \
                (name, [(m.graph_stamp.sec, [(a.task_id, list(a.robot_ids)) for a in m.assignments]) for m in got])
            if words is not None:  # reported on /diagnostics (ERROR or WARN)
                spin(5, lambda w=words: any(w in d for d in diags))
                assert any(words in d for d in diags), (name, diags[-5:])
            for m in got:  # never an unready task, nor anything of a refused graph
                assert not {a.task_id for a in m.assignments} & {"u1", "s0", "s1"}, name
            stamp += 10
        assert probe.proc.poll() is None
    assert "Traceback" not in probe.output, probe.output
