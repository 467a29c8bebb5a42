"""Scale benchmarks (``python -m lvws_ros.cli.bench --only scale``): figures printed,
nothing asserted.

* whole-schedule time, peak memory and validity of every policy at 100 x 500 and
  1000 x 5000 (robots x tasks) on our generator, on the subteam-heavy family and, with
  travel, on the held-out depot family (:mod:`lvws_ros.core.families`; 4-7 stations),
  each run in a child process of its own (peak RSS per run, a wall-time limit per run);
* scheduler-node decision latency p50/p99 at 100 x 500: the node's work without DDS
  (message -> snapshot conversion of both messages, OnlineScheduler.decide) at each
  decision step of a whole run, with travel (sites in the messages) on the depot family;
  the node's ``auto`` also split by what decided (the first decision, GRP before the first
  plan, the plan), back to back and paced as a cell whose tasks take time
  (``python -m lvws_ros.cli.bench_scale --latency FAMILY N M SEED PACE`` for one row);
* the exact expert on 24-40 robots x 30 tasks (subteam-heavy): status, bound and gap in 60 s;
* large-neighbourhood search from GRP's schedule at 30 x 100 and 100 x 500 (60 s each).
"""

from __future__ import annotations

import gc
import json
import statistics
import subprocess
import sys
import time
from typing import Any

import numpy as np

FAMILIES = ("ours", "subteam-heavy")
TRAVEL_FAMILIES = ("depot",)
POLICIES = ("grp", "rand", "rand_subteam", "dbgm", "lvws", "lvws_rollout", "auto")
ROLLOUT_BUDGET_MS = 100.0  # the rollout at scale: per decision step


def make_instance(family: str, n: int, m: int, seed: int) -> Any:
    from lvws_ros.core.datasets import random_instance, subteam_heavy_instance
    from lvws_ros.core.families import family_instance

    if family in TRAVEL_FAMILIES:
        return family_instance(family, 0, seed, num_robots=n, num_tasks=m)
    rng = np.random.default_rng([seed, n, m])
    if family == "ours":
        return random_instance(rng, n, m, f"ours-{n}r-{m}t", num_capabilities=3)
    return subteam_heavy_instance(rng, n, m, f"heavy-{n}r-{m}t")


def one_run(policy: str, family: str, n: int, m: int, seed: int) -> dict[str, Any]:
    """One whole schedule in this process (the child's side of :func:`run_in_child`)."""
    from lvws_ros.core.executor import simulate
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.registry import make_policy

    inst = make_instance(family, n, m, seed)
    pol = make_policy(policy, seed=seed, **({"budget_ms": ROLLOUT_BUDGET_MS} if policy == "lvws_rollout" else {}))
    if policy in ("lvws", "dbgm", "lvws_rollout"):  # torch's first passes: warm up on a small instance
        simulate(make_instance(family, 10, 20, seed + 1), pol)
    t0 = time.perf_counter()
    res = simulate(inst, pol)
    seconds = time.perf_counter() - t0
    from lvws_ros.core.bounds import gap, lower_bounds

    bound = lower_bounds(inst).best
    return {"seconds": seconds, "decisions": res.schedule.decisions, "makespan": res.schedule.makespan,
            "valid": not check_schedule(inst, res.schedule), "bound": bound,
            "gap": gap(res.schedule.makespan, bound), "peak_mib": _peak_mib()}


def _peak_mib() -> float:
    """This process's peak resident memory (VmHWM; ru_maxrss would carry over the
    forking parent's peak across exec)."""
    for line in open("/proc/self/status").read().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def run_in_child(policy: str, family: str, n: int, m: int, seed: int, limit: float) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "lvws_ros.cli.bench_scale", "--one", policy, family, str(n), str(m), str(seed)]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=limit)
    except subprocess.TimeoutExpired:
        return {"error": f"not finished within {limit:g} s"}
    if res.returncode != 0:
        return {"error": (res.stderr.strip().splitlines() or ["?"])[-1][:120]}
    out: dict[str, Any] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def bench_whole_schedules(seed: int, limit: float) -> None:
    print(f"\n## Whole schedules (seed {seed}; each run in its own process, limit {limit:g} s; peak = max RSS)")
    print(f"lvws_rollout runs with a budget of {ROLLOUT_BUDGET_MS:g} ms per decision step.")
    print("Gap: (makespan - lower bound) / makespan, the bound of lvws_ros/core/bounds.py (critical path with the "
          "least travel, workload over capacity): the most the schedule can be above the optimum.")
    print("| family | N x M | policy | seconds | decisions | makespan | lower bound | gap | valid | peak MiB |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for family in (*FAMILIES, *TRAVEL_FAMILIES):
        for n, m in ((100, 500), (1000, 5000)):
            for policy in POLICIES:
                r = run_in_child(policy, family, n, m, seed, limit)
                if "error" in r:
                    print(f"| {family} | {n} x {m} | {policy} | {r['error']} | | | | | | |", flush=True)
                else:
                    print(f"| {family} | {n} x {m} | {policy} | {r['seconds']:.2f} | {r['decisions']} | "
                          f"{r['makespan']:g} | {r['bound']:g} | {100 * r['gap']:.1f} % | "
                          f"{'yes' if r['valid'] else 'NO'} | {r['peak_mib']:.0f} |", flush=True)


def cell_snapshots(state: Any) -> tuple[Any, Any]:
    """The TeamState and TaskGraph snapshots of a cell in the executor state ``state``, as a
    world publishes them (with travel, sites as the simulator's: ``sim/world.py``)."""
    from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot, graph_sites

    inst = state.instance
    names, tr = tuple(inst.capabilities), inst.travel
    sites = ((), ()) if tr is None else graph_sites(tr)

    def where(r: int) -> tuple[str, float]:  # a busy robot: where its task leaves it
        if tr is None or state.robot_site is None:
            return "", 0.0
        return tr.sites[int(state.robot_site[r])], tr.robot_speed[r]

    def task_sites(j: int) -> tuple[str, str]:
        return ("", "") if tr is None else (tr.sites[tr.task_from[j]], tr.sites[tr.task_to[j]])

    free, busy = state.robot_available(), state.busy_remaining()
    team = TeamSnapshot(state.time, names, tuple(
        RobotInfo(r.id, "x", bool(free[i]), r.capabilities, r.payload, "", float(busy[i]), (0.0, 0.0, 0.0), *where(i))
        for i, r in enumerate(inst.robots)))
    graph = GraphSnapshot(state.time, names, tuple(
        TaskInfo(t.id, int(state.task_status[j]), t.capabilities, t.payload, t.duration, t.after,
                 tuple(inst.robots[r].id for r in state.task_team[j]),
                 None if np.isnan(state.task_start[j]) else float(state.task_start[j]), None, *task_sites(j))
        for j, t in enumerate(inst.tasks)), *sites)
    return team, graph


class _SnapshotWire:
    """The world's state as a node gets it from a world of snapshots: both messages'
    serialized bytes, read as the scheduler node reads them."""

    def __init__(self) -> None:
        from lvws_ros.ros import convert

        self.convert = convert
        self.team_reader, self.graph_reader = convert.TeamReader(), convert.GraphReader()

    def send(self, team: Any, graph: Any, raw: bool = True) -> Any:
        """The messages of this state serialized (the world's work), and the node's reading
        of them: of their bytes (``raw``, as it reads the snapshot topics), or of rclpy's
        messages (as it reads a resync answer)."""
        from lvws_msgs.msg import TaskGraph, TeamState
        from rclpy.serialization import deserialize_message, serialize_message

        team_bytes = serialize_message(self.convert.team_to_msg(team))
        graph_bytes = serialize_message(self.convert.graph_to_msg(graph))
        if raw:
            return lambda: (self.team_reader.read_serialized(team_bytes),
                            self.graph_reader.read_serialized(graph_bytes))
        return lambda: (self.team_reader.read(deserialize_message(team_bytes, TeamState)),
                        self.graph_reader.read(deserialize_message(graph_bytes, TaskGraph)))


class _ChangeWire(_SnapshotWire):
    """The same from a world that speaks changes: its first snapshots, then one CellChanges
    per state, taken as the scheduler node takes them (``ChangeFollower``)."""

    def __init__(self) -> None:
        super().__init__()
        from lvws_ros.core.changes import ChangeFollower

        self.follower = ChangeFollower()
        self.sent: tuple[Any, Any] | None = None
        self.seq = 0

    def send(self, team: Any, graph: Any, raw: bool = True) -> Any:
        from lvws_ros.core.changes import changes_between

        follower = self.follower
        if self.sent is None:
            first = super().send(team, graph, raw=False)  # the resync service's answer

            def read() -> Any:
                first_team, first_graph = first()
                follower.resync(first_team, first_graph, 0)
                assert follower.cell is not None
                return follower.cell.view()  # as the scheduler node offers it
        else:
            self.seq += 1
            from rclpy.serialization import serialize_message

            data = serialize_message(self.convert.changes_to_msg(changes_between(self.sent, (team, graph), self.seq)))

            def read() -> Any:
                follower.take(self.convert.changes_from_serialized(data))  # as the node reads them: the bytes
                assert follower.cell is not None
                return follower.cell.view()
        self.sent = (team, graph)
        return read


def node_latency(policy: str, family: str, n: int, m: int, seed: int, warm_up: bool = True,
                 pace: float = 0.0, protocol: str = "snapshots") -> list[tuple[float, str]]:
    """Seconds per decision of the scheduler node's work (both messages converted to
    snapshots, OnlineScheduler.decide), at each decision step of a whole run, with what
    decided it (``auto-planner``: "first" for the cell's first decision, which waits for the
    first plan; "grp" for one taken before any plan arrived; "plan" for one taken from the
    plan; "none" for a step where no decision was due; any other policy: its name); after a
    warm-up run on a small instance (a running node has made decisions before). ``pace``:
    wall seconds per unit of the instance's time between two decisions, as a cell whose
    tasks take time gives its planner (0: none). ``protocol``: how the world sends its state
    (``snapshots`` or ``changes``)."""
    if warm_up:
        node_latency(policy, family, 10, 20, seed + 1, warm_up=False, protocol=protocol)
    from lvws_ros.core.executor import State, TaskStatus
    from lvws_ros.core.online import OnlineScheduler
    from lvws_ros.registry import make_policy
    from lvws_ros.ros.scheduler_node import collect_after_decision

    inst = make_instance(family, n, m, seed)
    planner = policy == "auto-planner"  # auto as the node runs it: its planner in a process beside
    online = OnlineScheduler(make_policy("auto", seed=seed, background=True, first_wait=0.0) if planner  # as the node
                             else make_policy(policy, seed=seed),
                             ack_timeout=1e9)
    gc.freeze()  # as the scheduler node does after start-up
    process = getattr(online.policy, "process", None)
    if process is not None:  # started at the node's configure, so ready before its cell's first state (or the
        process.wait_ready(60.0)  # first decision waits for it: a node started at once with its world)
    state = State.initial(inst)
    lat: list[tuple[float, str]] = []
    wire = _ChangeWire() if protocol == "changes" else _SnapshotWire()
    while not state.done():
        read = wire.send(*cell_snapshots(state))
        t0 = time.perf_counter()
        got = read()
        if len(got) == 3:  # a live cell's view, as the scheduler node offers it
            online.offer_cell(*got)
        else:
            online.offer_team(got[0])
            online.offer_graph(got[1])
        fallbacks = getattr(online.policy, "fallbacks", 0)
        d = online.decide(started=t0)  # the budget counts from the messages' arrival, as in the node
        seconds = time.perf_counter() - t0
        if not planner:
            source = policy
        elif d is None:  # no decision due (nothing ready for the free robots): the messages' reading alone
            source = "none"
        elif all(s == "none" for _, s in lat):
            source = "first"
        else:
            source = "grp" if getattr(online.policy, "fallbacks", 0) > fallbacks else "plan"
        lat.append((seconds, source))
        for tid, robots in d.assignments if d else ():
            state.start(inst.task_index[tid], [inst.robot_index[r] for r in robots])
        online.pending.clear()  # the world took them: the next snapshot says so
        if d is not None:
            collect_after_decision(d.step + 1)  # as the scheduler node does once it has published
        nxt = state.next_event_time()
        if nxt is None:
            raise RuntimeError(f"{policy}: no progress at t={state.time}")
        if pace > 0:  # the tasks take time: the planner works meanwhile
            time.sleep(pace * (nxt - state.time))
        state.time = nxt
        state.refresh()
        if (state.task_status == TaskStatus.ASSIGNED).sum() == 0 and state.done():
            break
    online.close()
    return lat


def bench_node_latency(seed: int) -> None:
    print(f"\n## Scheduler-node decision latency at 100 x 500 (seed {seed}; conversion of both messages + "
          "OnlineScheduler.decide, no DDS)")
    print("| family | policy | decisions | p50 ms | p99 ms | max ms |")
    print("|---|---|---|---|---|---|")
    print("`auto` (1,000 ms per decision) spends its budget at each step; `auto-planner` is the node's `auto`: "
          "its planner in a process beside, each decision dispatched from its latest plan (GRP's until the first "
          "plan comes).")
    for family in (*FAMILIES, *TRAVEL_FAMILIES):
        for policy in ("grp", "lvws", "auto", "auto-planner"):
            lat = [1000 * x for x, _ in node_latency(policy, family, 100, 500, seed)]
            print(f"| {family} | {policy} | {len(lat)} | {statistics.median(lat):.1f} | "
                  f"{float(np.percentile(lat, 99)):.1f} | {max(lat):.1f} |", flush=True)
    print("\n`auto-planner` by what decided (`first`: the cell's first decision; `grp`: no plan had arrived yet; "
          "`plan`: dispatched from it); back to back, and paced as a cell whose time unit takes "
          f"{PACE:g} s of wall time; the world sends snapshots, or changes after its first snapshots")
    print("| family | N x M | protocol | pace s | first ms | grp: decisions, p99 ms | plan: decisions, p50 ms, p99 ms, "
          "max ms |")
    print("|---|---|---|---|---|---|---|")
    for family in (*FAMILIES, *TRAVEL_FAMILIES):
        for pace in (0.0, PACE):
            for protocol in ("snapshots", "changes"):
                print(latency_by_source(family, 100, 500, seed, pace, protocol), flush=True)


PACE = 0.25  # wall seconds per unit of an instance's time in the paced latency rows


def latency_by_source(family: str, n: int, m: int, seed: int, pace: float, protocol: str = "snapshots") -> str:
    """A table row of :func:`node_latency` for the node's ``auto``, split by what decided."""
    lat = node_latency("auto-planner", family, n, m, seed, pace=pace, protocol=protocol)
    first = [1000 * x for x, s in lat if s == "first"]
    grp = [1000 * x for x, s in lat if s == "grp"]
    plan = [1000 * x for x, s in lat if s == "plan"]

    def p99(xs: list[float]) -> str:
        return f"{float(np.percentile(xs, 99)):.1f}" if xs else "-"

    pace_text = f"{pace:g}" if pace > 0 else "back to back"
    return (f"| {family} | {n} x {m} | {protocol} | {pace_text} | {first[0]:.0f} | {len(grp)}, {p99(grp)} | {len(plan)}, "
            f"{statistics.median(plan) if plan else float('nan'):.1f}, {p99(plan)}, {max(plan, default=float('nan')):.1f} |")


def bench_exact_large_teams(seed: int, time_limit: float = 60.0, workers: int = 2) -> None:
    from lvws_ros.core.executor import simulate
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.policies.exact import solve_exact
    from lvws_ros.registry import make_policy

    print(f"\n## Exact expert on large teams (subteam-heavy, 30 tasks, seed {seed}, {workers} workers, "
          f"limit {time_limit:g} s)")
    print("| robots | GRP makespan | exact makespan | status | bound | gap % | seconds | valid |")
    print("|---|---|---|---|---|---|---|---|")
    for n in (24, 32, 40):
        inst = make_instance("subteam-heavy", n, 30, seed)
        grp = simulate(inst, make_policy("grp")).schedule.makespan
        res = solve_exact(inst, time_limit=time_limit, workers=workers, seed=seed)
        assert res.schedule is not None
        print(f"| {n} | {grp:g} | {res.makespan:g} | {res.status} | {res.bound:g} | {100 * res.gap:.1f} | "
              f"{res.seconds:.1f} | {'yes' if not check_schedule(inst, res.schedule) else 'NO'} |", flush=True)


LNS_SECONDS = 60.0


def bench_lns(seed: int, seconds: float = LNS_SECONDS) -> None:
    """Large-neighbourhood search from GRP's schedule (lvws_ros/policies/lns.py), one worker."""
    from lvws_ros.core.bounds import lower_bounds
    from lvws_ros.core.executor import simulate
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.policies.lns import DEFAULT_WINDOW, DEFAULT_WINDOW_TRAVEL, improve
    from lvws_ros.registry import make_policy

    print(f"\n## Large-neighbourhood search from GRP (seed {seed}, {seconds:g} s, 1 worker, window {DEFAULT_WINDOW}, "
          f"{DEFAULT_WINDOW_TRAVEL} with travel)")
    print("| family | N x M | GRP | LNS | LNS / GRP | rounds | improved | lower bound | LNS gap | valid |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for family, n, m in (("subteam-heavy", 30, 100), ("ours", 30, 100), ("depot", 30, 100), ("subteam-heavy", 100, 500),
                         ("ours", 100, 500), ("depot", 100, 500)):
        inst = make_instance(family, n, m, seed)
        grp = simulate(inst, make_policy("grp")).schedule
        bound = lower_bounds(inst).best
        found = improve(inst, grp, time_limit=seconds, seed=seed, bound=bound)  # stops at the bound
        lns = float(found.schedule.makespan)
        print(f"| {family} | {n} x {m} | {grp.makespan:g} | {lns:g} | {lns / grp.makespan:.3f} | {found.rounds} | "
              f"{found.improved} | {bound:g} | {100 * (lns - bound) / lns:.1f} % | "
              f"{'yes' if not check_schedule(inst, found.schedule) else 'NO'} |", flush=True)


def main(seed: int = 0, limit: float = 600.0) -> None:
    bench_lns(seed)
    bench_exact_large_teams(seed)
    bench_node_latency(seed)
    bench_whole_schedules(seed, limit)


if __name__ == "__main__":
    if sys.argv[1:2] == ["--one"]:
        policy, family, n, m, seed = sys.argv[2:7]
        print(json.dumps(one_run(policy, family, int(n), int(m), int(seed))))
    elif sys.argv[1:2] == ["--latency"]:  # one row of the node's auto by what decided: FAMILY N M SEED PACE [PROTOCOL]
        family, n, m, seed, pace = sys.argv[2:7]
        print(latency_by_source(family, int(n), int(m), int(seed), float(pace), *sys.argv[7:8]))
    else:
        main()
