"""The change-only protocol over real DDS: the scheduler node follows a world that sends
numbered changes (started late, missing one, sent a bad one), resyncs from the world's
service and finishes the cell valid, nothing assigned twice; the simulator speaks it end to
end and its bag is read back by two readers."""

from __future__ import annotations

import time
from typing import Any

import numpy as np
import pytest
from lvws_msgs.msg import CellChanges, TaskGraph, TeamState
from lvws_msgs.srv import Resync
from test_runtime import read_with_anyreader, read_with_mcap

from lvws_ros.cli.bench_scale import cell_snapshots
from lvws_ros.cli.report import report
from lvws_ros.core import changes
from lvws_ros.core.datasets import random_instance
from lvws_ros.core.executor import State, schedule_from_state
from lvws_ros.core.schedule import check_schedule
from lvws_ros.ros import convert, topics
from scheduler_probe import scheduler_probe

pytestmark = pytest.mark.ros  # crosses processes over real DDS


class ChangeWorld:
    """A world in the test process that speaks changes: its executor state published as a
    first snapshot pair, then numbered CellChanges; its snapshots on the resync service."""

    def __init__(self, node: Any, inst: Any) -> None:
        self.inst, self.state = inst, State.initial(inst)
        self.team_pub = node.create_publisher(TeamState, topics.TEAM_TOPIC, topics.TEAM_QOS)
        self.graph_pub = node.create_publisher(TaskGraph, topics.GRAPH_TOPIC, topics.GRAPH_QOS)
        self.changes_pub = node.create_publisher(CellChanges, topics.CHANGES_TOPIC, topics.CHANGES_QOS)
        node.create_service(Resync, topics.RESYNC_SERVICE, self.on_resync)
        self.seq, self.sent, self.resyncs = 0, None, 0

    def publish(self, skip: bool = False) -> None:
        now = cell_snapshots(self.state)
        if self.sent is None:
            self.team_pub.publish(convert.team_to_msg(now[0]))
            self.graph_pub.publish(convert.graph_to_msg(now[1]))
        else:
            self.seq += 1
            if not skip:  # a batch lost on the way
                self.changes_pub.publish(convert.changes_to_msg(changes.changes_between(self.sent, now, self.seq)))
        self.sent = now

    def send(self, batch: changes.CellChanges) -> None:
        self.seq += 1
        self.changes_pub.publish(convert.changes_to_msg(batch))

    def on_resync(self, _req: Any, res: Any) -> Any:
        self.resyncs += 1
        team, graph = self.sent
        res.team, res.graph, res.seq = convert.team_to_msg(team), convert.graph_to_msg(graph), self.seq
        return res


def answered(got: list[Any], seen: int, stamp: float) -> Any:
    """Whether a decision for the state stamped ``stamp`` came after the first ``seen``."""
    return lambda: any(abs(convert.from_time(m.team_stamp) - stamp) < 1e-9 for m in got[seen:])


def test_a_late_node_that_misses_changes_and_gets_a_bad_one_resyncs_and_finishes_the_cell_valid(ros_context):
    inst = random_instance(np.random.default_rng(3), 6, 30, "changes")
    with scheduler_probe(ros_context, "change_world", ["-p", "policy:=grp", "-p", "ack_timeout:=60.0"]) as probe:
        world = ChangeWorld(probe.node, inst)
        world.publish()  # before the node listens: it misses the team, and gets the latched graph only
        probe.spin(60.0, lambda: world.changes_pub.get_subscription_count() > 0)
        assigned: dict[str, int] = {}
        step, stalls = 0, 0
        while not world.state.done() and stalls < 5:
            stamp = world.state.time
            if step == 3:
                world.publish(skip=True)  # lost: the next batch shows the gap
                world.send(changes.CellChanges(world.seq + 1, stamp))
            elif step == 6:
                world.publish()
                world.send(changes.CellChanges(world.seq + 1, stamp, cancelled=("no_such_task",)))  # refused
                world.send(changes.CellChanges(world.seq + 1, stamp))
            else:
                world.publish()
            seen = len(probe.got)
            probe.spin(3.0, answered(probe.got, seen, stamp))
            for m in probe.got[seen:]:
                if abs(convert.from_time(m.team_stamp) - stamp) > 1e-9:
                    continue
                for a in m.assignments:
                    assigned[a.task_id] = assigned.get(a.task_id, 0) + 1
                    world.state.start(inst.task_index[a.task_id], [inst.robot_index[r] for r in a.robot_ids])
            nxt = world.state.next_event_time()
            if nxt is None:
                stalls += 1
                continue
            world.state.time = nxt
            world.state.refresh()
            step += 1
        probe.spin(1.5)  # the last diagnostics
    assert world.state.done(), (step, probe.diags[-5:], probe.output[-3000:])
    assert set(assigned) == {t.id for t in inst.tasks} and set(assigned.values()) == {1}
    assert check_schedule(inst, schedule_from_state(world.state, "grp")) == []
    warned = [d for d in probe.diags if d.startswith("1:")]  # WARN
    assert any("missed" in d for d in warned), warned
    assert any("unknown task 'no_such_task'" in d for d in warned), warned
    assert world.resyncs >= 3  # late start, the gap, the refused batch
    assert max(int(v.get("changes_seq", 0)) for v in probe.values) == world.seq
    assert all(convert.from_time(m.state_latency) > 0 for m in probe.got)


def test_the_simulator_speaks_changes_end_to_end_and_its_bag_reads_back(tmp_path):
    from lvws_ros.ros.launcher import launch

    res = launch(policy="grp", rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out", name="changes",
                 gif=False, timeout=300.0, protocol="changes", log=lambda _t: None)
    s = res.summary
    assert s["tasks_done"] == 14 and s["error"] == "" and s["rejected"] == []
    a, b = read_with_anyreader(res.bag), read_with_mcap(res.bag)
    assert a == b and a["/lvws/changes"] >= 10 and a["/lvws/task_graph"] == 1  # the first snapshot, then changes
    rep = report(res.bag)
    assert rep.complete and len(rep.schedule.assignments) == 14
    assert check_schedule(rep.instance, rep.schedule) == []
    assert rep.schedule.makespan == pytest.approx(s["makespan"], abs=1e-6)
    time.sleep(0)  # the run is over: nothing else to wait for
