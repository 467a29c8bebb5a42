"""The change-only protocol over real DDS: the scheduler node follows a world that sends
numbered changes (started late, missing one, sent a bad one), resyncs from the world's
service and finishes the cell valid, nothing assigned twice; the simulator speaks it end to
end and its bag is read back by two readers."""

from __future__ import annotations

import signal
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lvws_msgs.msg import CellChanges, TaskGraph, TeamState
from lvws_msgs.srv import Resync
from test_runtime import read_with_anyreader, read_with_mcap

from lvws_ros.cli.bench_scale import cell_snapshots
from lvws_ros.cli.report import report, verify
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
            elif step == 9:  # a malformed robot (one capability for a cell of three): refused whole
                world.publish()
                robot = replace(world.sent[0].robots[0], capabilities=(1,))
                world.send(changes.CellChanges(world.seq + 1, stamp, robots=(robot,)))
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
    assert any("robots[0]" in d and "capabilities" in d for d in warned), warned
    assert world.resyncs >= 4  # late start, the gap, the two refused batches
    assert max(int(v.get("changes_seq", 0)) for v in probe.values) == world.seq
    assert all(convert.from_time(m.state_latency) > 0 for m in probe.got)


def test_a_node_that_heard_the_first_snapshots_follows_batch_one_without_a_resync(ros_context):
    inst = random_instance(np.random.default_rng(4), 4, 10, "from-zero")
    with scheduler_probe(ros_context, "zero_world", ["-p", "policy:=grp", "-p", "ack_timeout:=60.0"]) as probe:
        world = ChangeWorld(probe.node, inst)
        probe.spin(60.0, lambda: world.changes_pub.get_subscription_count() > 0
                   and world.graph_pub.get_subscription_count() > 0 and world.team_pub.get_subscription_count() > 0)
        assigned: dict[str, int] = {}
        while not world.state.done():
            stamp = world.state.time
            world.publish()
            seen = len(probe.got)
            probe.spin(10.0, answered(probe.got, seen, stamp))
            for m in probe.got[seen:]:
                for a in m.assignments if abs(convert.from_time(m.team_stamp) - stamp) < 1e-9 else ():
                    assigned[a.task_id] = assigned.get(a.task_id, 0) + 1
                    world.state.start(inst.task_index[a.task_id], [inst.robot_index[r] for r in a.robot_ids])
            nxt = world.state.next_event_time()
            assert nxt is not None, probe.output[-3000:]
            world.state.time = nxt
            world.state.refresh()
        probe.spin(1.5)  # the last diagnostics
    assert world.seq > 3 and world.resyncs == 0  # the first snapshots were change 0
    assert set(assigned) == {t.id for t in inst.tasks} and set(assigned.values()) == {1}
    assert check_schedule(inst, schedule_from_state(world.state, "grp")) == []
    assert max(int(v.get("changes_seq", 0)) for v in probe.values) == world.seq


def test_the_simulator_speaks_changes_with_done_work_retiring_and_its_bag_reads_back(tmp_path):
    from lvws_ros.ros.bag import read_run
    from lvws_ros.ros.launcher import launch

    res = launch(policy="grp", rate=20.0, bag_dir=tmp_path / "bags", out_dir=tmp_path / "out", name="changes",
                 gif=False, timeout=300.0, protocol="changes", retire_after=0.0, log=lambda _t: None)
    s = res.summary
    assert s["tasks_done"] == 14 and s["error"] == "" and s["rejected"] == []
    a, b = read_with_anyreader(res.bag), read_with_mcap(res.bag)
    assert a == b and a["/lvws/changes"] >= 10 and a["/lvws/task_graph"] == 1  # the first snapshot, then changes
    run = read_run(res.bag)
    retired = [tid for ch in run.changes for tid in ch.retired]
    assert len(retired) >= 7 and len(set(retired)) == len(retired)  # done work left the live cell, once each
    assert len(run.graphs[-1].tasks) < 14
    rep = report(res.bag)  # the bag keeps everything: the retired tasks are in the report
    assert rep.complete and len(rep.schedule.assignments) == 14
    assert check_schedule(rep.instance, rep.schedule) == []
    assert rep.schedule.makespan == pytest.approx(s["makespan"], abs=1e-6)


STREAM_DONE = 2500  # tasks done over DDS before the stream stops: a few thousand, in about a minute


def _rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return 0.0


class StreamOverDds:
    """The stream world (sim/stream.py) on the wire: its first snapshots on the latched
    topics, then one CellChanges per tick, the resync service; the node's assignments
    started in it."""

    def __init__(self, probe: Any, world: Any) -> None:
        self.probe, self.world, self.seq = probe, world, 0
        self.pub = probe.node.create_publisher(CellChanges, topics.CHANGES_TOPIC, topics.CHANGES_QOS)
        probe.node.create_service(Resync, topics.RESYNC_SERVICE, self.on_resync)
        self.started: set[str] = set()
        self.twice = 0
        self.sent = world.snapshots()

    def on_resync(self, _req: Any, res: Any) -> Any:
        team, graph = self.sent  # as of the last batch (the assignments since go out in the next)
        res.team, res.graph, res.seq = convert.team_to_msg(team), convert.graph_to_msg(graph), self.seq
        return res

    def tick(self) -> bool:
        """One tick of the world; whether the node answered it (or had nothing to do)."""
        w, probe = self.world, self.probe
        w.advance()
        self.seq += 1
        self.pub.publish(convert.changes_to_msg(w.changes(self.seq)))
        self.sent = w.snapshots()
        seen = len(probe.got)
        due = any(r.available for r in w.robots.values()) and any(t.status == 1 for t in w.tasks.values())
        probe.spin(1.0 if due else 0.01, answered(probe.got, seen, w.time) if due else lambda: False)
        for m in probe.got[seen:]:
            for a in m.assignments:
                self.twice += a.task_id in self.started
                self.started.add(a.task_id)
                w.assign(a.task_id, tuple(a.robot_ids))  # AssignmentRejected: the test fails
        return not due or len(probe.got) > seen


def test_a_stream_of_thousands_of_tasks_over_dds_all_done_none_twice_the_node_flat_and_the_bag_verifies(
        ros_context, tmp_path):
    """A world that never stops (sim/stream.py) over DDS, recorded: done work retires, none
    is assigned twice, the node's resident memory from a third of the tasks done to the end
    stays within a few MiB (the figures are the stream benchmark's); then the stream stops,
    the cell drains, and the bag's report holds every task, done, valid."""
    import math

    from lvws_ros.sim.stream import StreamWorld

    bag = tmp_path / "stream"
    rec = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag)], stdout=subprocess.PIPE,
                           text=True)
    assert rec.stdout is not None and "recording to" in rec.stdout.readline()
    world = StreamWorld(100, 0.4, seed=2)
    with scheduler_probe(ros_context, "stream_world", ["-p", "policy:=grp", "-p", "ack_timeout:=60.0"]) as probe:
        wire = StreamOverDds(probe, world)
        probe.spin(60.0, lambda: wire.pub.get_subscription_count() >= 2)  # the node and the recorder
        team, graph = world.snapshots()  # a world may mix: snapshots at start, changes after
        probe.team_pub.publish(convert.team_to_msg(team))
        probe.graph_pub.publish(convert.graph_to_msg(graph))
        rss: dict[int, float] = {}
        unanswered = 0
        while unanswered < 20 and any(t.end is None for t in world.tasks.values()) | (world.counts.done < STREAM_DONE):
            unanswered = 0 if wire.tick() else unanswered + 1
            for mark in (STREAM_DONE // 3, STREAM_DONE):
                if world.counts.done >= mark and mark not in rss:
                    rss[mark] = _rss_mib(probe.proc.pid)
                    if mark == STREAM_DONE:
                        world.next_arrival = math.inf  # the stream stops: the cell drains
        probe.spin(1.5)
    rec.send_signal(signal.SIGINT)
    rec.wait(timeout=60)
    c = world.counts
    assert wire.twice == 0 and c.rejected == 0, (wire.twice, c)
    assert c.done == c.added >= STREAM_DONE, (c, probe.diags[-10:], probe.output[-4000:])
    assert c.retired > STREAM_DONE // 2 and max(int(v.get("retired", 0)) for v in probe.values) > STREAM_DONE // 2
    assert rss[STREAM_DONE] - rss[STREAM_DONE // 3] < 30, rss
    rep = report(bag)
    assert rep.complete and len(rep.schedule.assignments) == c.added
    assert check_schedule(rep.instance, rep.schedule) == []
    n, bad = verify(bag)  # the decisions replayed offline from the bag's rebuilt states
    assert n > 100 and bad == [], (n, bad[:3])


@pytest.mark.parametrize("cmd", [["lvws_ros.cli", "launch", "--retire-after", "0"],
                                 ["lvws_ros.ros.cell_sim_node", "--ros-args", "-p", "retire_after:=0.0"],
                                 ["lvws_ros.ros.cell_sim_node", "--ros-args", "-p", "protocol:=deltas"]])
def test_retirement_without_changes_and_an_unknown_protocol_are_refused_with_exit_2(cmd):
    out = subprocess.run([sys.executable, "-m", *cmd], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert "protocol" in out.stderr


def test_a_changes_bag_whose_world_sent_its_graph_alone_first_rebuilds_the_pair_the_node_decided_on(tmp_path):
    """A dispatcher publishes its TaskGraph alone until a robot is up, then the pair: the
    decisions name the pair's stamps, which the bag's rebuilt states must hold."""
    from lvws_ros.cli.report import decision_inputs
    from lvws_ros.core.changes import CellChanges as Batch
    from lvws_ros.core.online import GraphSnapshot, OnlineDecision, RobotInfo, TaskInfo, TeamSnapshot
    from lvws_ros.ros.bag import Run, _replay_changes

    task = TaskInfo("t1", 1, (1,), 1.0, 2.0)
    robot = RobotInfo("r1", "amr", True, (1,), 2.0)
    alone = GraphSnapshot(5.0, ("lift",), (task,))
    run = Run(tmp_path, {}, teams=[TeamSnapshot(7.0, ("lift",), (robot,))],
              graphs=[alone, GraphSnapshot(7.0, ("lift",), (task,))],
              changes=[Batch(1, 8.0, robots=(RobotInfo("r1", "amr", False, (1,), 2.0, "t1", 2.0),))])
    run.decisions = [OnlineDecision(0, (("t1", ("r1",)),), (), 0.001, 7.0, 7.0)]
    _replay_changes(run)
    [(_d, team, graph, _state)] = list(decision_inputs(run))
    assert team.stamp == graph.stamp == 7.0 and [t.id for t in graph.tasks] == ["t1"]
    assert run.teams[-1].stamp == run.graphs[-1].stamp == 8.0  # and the batch after it


def test_a_wall_clock_bag_that_missed_the_first_state_counts_from_the_first_start(tmp_path):
    """A recorder that joined a dispatcher's cell late: its first TeamState is after the
    first task started; the report's times count from that start, never below 0."""
    from lvws_ros.cli.report import report_run
    from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot
    from lvws_ros.ros.bag import Run

    t0 = 1.8e9  # seconds since 1970
    done = TaskInfo("t1", 3, (1,), 1.0, 2.0, (), ("r1",), t0, t0 + 2.0)
    run = Run(tmp_path, {}, teams=[TeamSnapshot(t0 + 0.4, ("lift",), (RobotInfo("r1", "amr", True, (1,), 2.0),))],
              graphs=[GraphSnapshot(t0 + 2.0, ("lift",), (done,))])
    rep = report_run(run)
    assert rep.complete and not rep.problems
    assert rep.schedule.assignments[0].start == 0.0 and rep.schedule.makespan == 2.0
