"""State-to-decision time over real DDS, as an outside world sees it
(``python -m lvws_ros.cli.bench_dds FAMILY N M SEED PACE PROTOCOL [POLICY]``).

The scheduler node runs as ``python -m lvws_ros.ros.scheduler_node`` in its own process on a
DDS domain of its own; this process is the world: it executes a whole instance
(:func:`~lvws_ros.cli.bench_scale.make_instance`) step by step, publishes each state (both
snapshots, or the next ``CellChanges`` after the first snapshots, serving ``lvws/resync``),
and when a decision is due (a robot or a task new to the node, as
:meth:`~lvws_ros.core.online.OnlineScheduler.decide` judges it) waits for the decision that
answers the state's stamp and starts its assignments. Measured per decision: the wall time
from the state's publication (its messages already built) to the decision's arrival, and the
node's own ``state_latency``. Between two states the world sleeps PACE wall seconds per unit
of the instance's time, as a cell whose tasks take time does.
"""

from __future__ import annotations

import os
import random
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

ANSWER_WAIT = 30.0  # wall seconds a due decision is waited for (beyond: counted as missing)


@dataclass
class DdsRun:
    first_ms: float = float("nan")
    seen_ms: list[float] = field(default_factory=list)  # the world's: publication to arrival
    node_ms: list[float] = field(default_factory=list)  # the node's state_latency
    missing: int = 0
    skipped: int = 0  # assignments the world could not start (should be 0)
    steps: int = 0


def _world(protocol: str, inst: Any) -> Any:
    import rclpy
    from lvws_msgs.msg import AssignmentArray, CellChanges, TaskGraph, TeamState
    from lvws_msgs.srv import Resync
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from lvws_ros.ros import convert, topics

    rclpy.init()
    node = rclpy.create_node("dds_latency_world")
    w: dict[str, Any] = {"sent": None, "seq": 0, "got": []}

    def on_resync(_req: Any, res: Any) -> Any:
        team, graph = w["sent"]
        res.team, res.graph, res.seq = convert.team_to_msg(team), convert.graph_to_msg(graph), w["seq"]
        return res

    w["team"] = node.create_publisher(TeamState, topics.TEAM_TOPIC, topics.TEAM_QOS)
    w["graph"] = node.create_publisher(TaskGraph, topics.GRAPH_TOPIC, topics.GRAPH_QOS)
    w["changes"] = node.create_publisher(CellChanges, topics.CHANGES_TOPIC, topics.CHANGES_QOS)
    node.create_service(Resync, topics.RESYNC_SERVICE, on_resync)
    node.create_subscription(AssignmentArray, topics.ASSIGNMENTS_TOPIC,
                             lambda m: w["got"].append((time.perf_counter(), m)),
                             QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
    executor = rclpy.executors.SingleThreadedExecutor()
    executor.add_node(node)
    w["node"], w["executor"], w["protocol"] = node, executor, protocol
    return w


def _spin(w: dict[str, Any], seconds: float, until: Any = lambda: False) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end and not until():
        w["executor"].spin_once(timeout_sec=0.01)


def _publish(w: dict[str, Any], now: tuple[Any, Any]) -> float:
    """The state out; the wall time of its publication (its messages built before)."""
    from lvws_ros.core.changes import changes_between
    from lvws_ros.ros import convert

    if w["sent"] is None or w["protocol"] == "snapshots":
        msgs = [(w["team"], convert.team_to_msg(now[0])), (w["graph"], convert.graph_to_msg(now[1]))]
    else:
        w["seq"] += 1
        msgs = [(w["changes"], convert.changes_to_msg(changes_between(w["sent"], now, w["seq"])))]
    w["sent"] = now
    t0 = time.perf_counter()
    for pub, msg in msgs:
        pub.publish(msg)
    return t0


def _answer(w: dict[str, Any], node: subprocess.Popen[bytes], inst: Any, state: Any, out: DdsRun,
            t0: float) -> tuple[set[int], set[int]]:
    """Wait for the decision answering the state's stamp, count its latency (the first
    apart) and start what it assigns; the robots started and the tasks it named (what the
    world could not start is counted as skipped)."""
    from lvws_ros.ros import convert

    stamp, k = state.time, len(w["got"])

    def hits() -> list[tuple[float, Any]]:
        return [(t, mm) for t, mm in w["got"][k:] if abs(convert.from_time(mm.team_stamp) - stamp) < 1e-9]
    _spin(w, ANSWER_WAIT, lambda: bool(hits()))
    hit = hits()
    if not hit:
        if node.poll() is not None:
            raise RuntimeError(f"the scheduler node exited ({node.returncode}); "
                               "LVWS_DDS_NODE_LOG=FILE keeps its output")
        out.missing += 1
        return set(), set()
    t, mm = hit[0]
    ms = 1000 * (t - t0)
    if out.first_ms != out.first_ms:  # nan: the cell's first decision
        out.first_ms = ms
    else:
        out.seen_ms.append(ms)
        out.node_ms.append(1000 * convert.from_time(mm.state_latency))
    started: set[int] = set()
    for a in mm.assignments:
        j, team = inst.task_index[a.task_id], [inst.robot_index[r] for r in a.robot_ids]
        if j in state.ready_tasks() and all(r in state.free_robots() for r in team):
            state.start(j, team)
            started.update(team)
        else:
            out.skipped += 1
    return started, {inst.task_index[a.task_id] for a in mm.assignments}


def dds_latency(family: str, n: int, m: int, seed: int, pace: float, protocol: str,
                policy: str = "auto") -> DdsRun:
    """The run (module docstring)."""
    from lvws_ros.cli.bench_scale import cell_snapshots, make_instance
    from lvws_ros.core.executor import State, TaskStatus
    from lvws_ros.core.online import is_due

    os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(150, 200))
    log = open(os.environ.get("LVWS_DDS_NODE_LOG", os.devnull), "w")
    node = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.scheduler_node", "--ros-args",
                             "-p", f"policy:={policy}", "-p", f"seed:={seed}", "-p", "ack_timeout:=3600.0"],
                            stdout=log, stderr=subprocess.STDOUT)
    inst = make_instance(family, n, m, seed)
    w = _world(protocol, inst)
    out = DdsRun()
    try:
        wanted = 3 if protocol == "changes" else 2  # the node's subscriptions
        _spin(w, 120.0, lambda: w["team"].get_subscription_count() + w["graph"].get_subscription_count()
              + (w["changes"].get_subscription_count() if protocol == "changes" else 0) >= wanted)
        _spin(w, 10.0)  # the node configured (its planner started) before the cell's first state
        state = State.initial(inst)
        seen_free: set[int] = set()
        seen_ready: set[int] = set()
        while not state.done():
            out.steps += 1
            t0 = _publish(w, cell_snapshots(state))
            free, ready = set(state.free_robots()), set(state.ready_tasks())
            running = bool((state.task_status == TaskStatus.ASSIGNED).any())
            if not is_due(free, ready, seen_free, seen_ready, running, ahead=inst.departure == "each"):
                seen_free, seen_ready = free, ready
                _spin(w, 0.005)
            else:
                started, named = _answer(w, node, inst, state, out, t0)
                seen_free, seen_ready = free - started, ready - named
            nxt = state.next_event_time()
            if nxt is None:
                raise RuntimeError(f"no progress at t={state.time} (missing decisions: {out.missing})")
            if pace > 0:
                time.sleep(pace * (nxt - state.time))
            state.time = nxt
            state.refresh()
    finally:
        node.terminate()
        node.wait(timeout=30)
        log.close()
        w["node"].destroy_node()
        import rclpy

        rclpy.shutdown()
    return out


def row(family: str, n: int, m: int, seed: int, pace: float, protocol: str, policy: str = "auto") -> str:
    r = dds_latency(family, n, m, seed, pace, protocol, policy)

    def p(xs: list[float], q: float) -> str:
        return f"{float(np.percentile(xs, q)):.1f}" if xs else "-"
    med = f"{statistics.median(r.seen_ms):.1f}" if r.seen_ms else "-"
    return (f"| {family} | {n} x {m} | {protocol} | {policy} | {r.first_ms:.0f} | {len(r.seen_ms)} | {med} | "
            f"{p(r.seen_ms, 99)} | {p(r.node_ms, 50)} / {p(r.node_ms, 99)} | {r.missing} | {r.skipped} |")


def main(argv: list[str]) -> None:
    family, n, m, seed, pace, protocol = argv[:6]
    policy = argv[6] if len(argv) > 6 else "auto"
    print(f"seed {seed}; the node in its own process, this process the world, over DDS")
    print("| family | N x M | protocol | policy | first ms | decisions | p50 ms | p99 ms | node's state_latency "
          "p50 / p99 ms | missing | not started |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    print(row(family, int(n), int(m), int(seed), float(pace), protocol, policy), flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
