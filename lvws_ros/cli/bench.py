"""Benchmarks (``make bench``); figures are printed, never asserted.

* matching decision time (greedy, Eqs. 7-11) for N x M free robots x ready tasks;
* the exact expert on Dataset I test instances: share proven optimal, solve times;
* the baselines' suboptimality on the Dataset I test split beside the paper's figures;
* Fig. 5: LVWS decision rate and accumulated runtime for N robots x M tasks (PNG);
* the ROS runtime, and a dynamic world (scripted cancel, late order, failures, repairs):
  decision latency under events, replanning and restart after each failure;
* scale (:mod:`lvws_ros.cli.bench_scale`): whole schedules at 100 x 500 and 1000 x 5000 on
  our generator and a subteam-heavy family, node decision latency, the expert on large teams;
* anytime (:mod:`lvws_ros.cli.bench_anytime`): the planner's plan and its gap to the bound
  against planning time at 100 x 500 and 1000 x 5000, beside GRP and LVWS (PNG);
* stream (:mod:`lvws_ros.cli.bench_stream`): a cell that never stops, 1000 robots, until
  100,000 tasks are done: decision p50/p99, memory and live tasks per 10,000 (PNG).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.matching import greedy_match
from lvws_ros.core.metrics import run_policy, suboptimality
from lvws_ros.policies.exact import exact_match, solve_exact
from lvws_ros.registry import make_policy

PAPER_TABLE_I = {"rand": 23.0, "rand_subteam": 11.8, "grp": 15.8}


def machine() -> str:
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def random_matching_case(rng: np.random.Generator, n: int, m: int, k: int = 3) -> tuple[np.ndarray, ...]:
    """(R ~ N(0, 1), robot caps, robot payloads, task caps, task payloads) for n free
    robots and m ready tasks, drawn like the datasets (payloads 1-30, Poisson(10))."""
    robot_caps = rng.integers(0, 2, size=(n, k)).astype(bool)
    robot_caps[~robot_caps.any(axis=1), 0] = True
    task_caps = rng.integers(0, 2, size=(m, k)).astype(bool)
    task_caps[~task_caps.any(axis=1), 1] = True
    robot_payload = rng.integers(1, 31, size=n).astype(float)
    task_payload = np.clip(rng.poisson(10, size=m), 1, 30).astype(float)
    return rng.normal(size=(n, m + 1)), robot_caps, robot_payload, task_caps, task_payload


def bench_matching(repeats: int, seed: int) -> None:
    print(f"\n## Greedy subteam matching (Eqs. 7-11), seed {seed}, median of {repeats}")
    print("| N robots | M tasks | ms / decision |")
    print("|---|---|---|")
    rng = np.random.default_rng(seed)
    for n in (25, 50, 100):
        for m in (50, 100, 500):
            _, *problem = random_matching_case(rng, n, m)
            times = []
            for _ in range(repeats):
                r = rng.normal(size=(n, m + 1))
                t0 = time.perf_counter()
                greedy_match(r, *problem)
                times.append(time.perf_counter() - t0)
            print(f"| {n} | {m} | {1000 * statistics.median(times):.2f} |")


def bench_greedy_vs_exact(cases: int, seed: int) -> None:
    """How often the greedy reaches the optimum of Eqs. 7-11 (CP-SAT) on random rewards."""
    rng = np.random.default_rng(seed)
    equal, ratios = 0, []
    for _ in range(cases):
        n, m = int(rng.integers(2, 9)), int(rng.integers(1, 7))
        _, *problem = random_matching_case(rng, n, m)
        args = (rng.uniform(0, 1, size=(n, m + 1)), *problem)
        g, e = greedy_match(*args), exact_match(*args)
        equal += abs(g.reward - e.reward) < 1e-5
        ratios.append(g.reward / e.reward if e.reward > 0 else 1.0)
    print(f"\n## Greedy vs exact matching on {cases} random cases (N 2-8, M 1-6, rewards U(0,1), seed {seed})")
    print(f"greedy reaches the exact optimum in {equal}/{cases} ({100 * equal / cases:.1f} %); "
          f"mean greedy/exact reward {statistics.fmean(ratios):.4f}, worst {min(ratios):.4f}")


def bench_expert(count: int, workers: int, time_limit: float, seed: int) -> dict[str, float]:
    spec = DATASETS["I"]
    print(f"\n## Exact expert (CP-SAT) on {count} Dataset I test instances "
          f"(seed {seed}, {workers} workers, limit {time_limit:g} s)")
    optimal: dict[str, float] = {}
    times = []
    proven = 0
    for k in range(spec.train, spec.train + count):
        inst = dataset_instance(spec, k, seed)
        res = solve_exact(inst, workers=workers, time_limit=time_limit)
        times.append(res.seconds)
        if res.proven and res.makespan is not None:
            proven += 1
            optimal[inst.name] = res.makespan
    print(f"proven optimal: {proven}/{count} ({100 * proven / count:.1f} %); "
          f"solve time median {statistics.median(times):.3f} s, max {max(times):.3f} s")
    return optimal


def bench_mspsp(folder: str, workers: int, time_limit: float, limit: int | None = None,
                results: str | None = None) -> None:
    """The exact expert on multi-skill project scheduling files (``*.dzn`` under ``folder``,
    imported with :func:`~lvws_ros.core.importers.import_mspsp`); with ``results`` (a folder
    holding the library's results files, ``instNum,optimal,...,makespan`` per group of
    instances), the optimum they report is printed beside."""
    import csv
    from pathlib import Path

    from lvws_ros.core.importers import import_mspsp

    files = sorted(Path(folder).rglob("*.dzn"))[:limit]
    print(f"\n## Multi-skill project scheduling: {len(files)} files under {folder} "
          f"(exact expert, {workers} workers, limit {time_limit:g} s)")
    print("| file | robots x tasks | ours | status | bound | seconds | their optimum |\n|---|---|---|---|---|---|---|")
    proven = equal = 0
    for path in files:
        inst = import_mspsp(path)
        res = solve_exact(inst, workers=workers, time_limit=time_limit)
        group, _, index = path.stem.rpartition("_")
        theirs = "-"
        for found in Path(results).rglob(f"{group.replace('inst_', 'results_')}*.txt") if results else ():
            with found.open() as f:
                rows = [r for r in csv.DictReader(f) if r.get("instNum") == str(int(index))]
            if rows and rows[0].get("optimal") == "1":
                theirs = rows[0]["makespan"]
        proven += res.proven
        equal += res.proven and theirs != "-" and float(theirs) == res.makespan
        print(f"| {path.stem} | {inst.num_robots} x {inst.num_tasks} | {res.makespan:g} | {res.status} | "
              f"{res.bound:g} | {res.seconds:.1f} | {theirs} |")
    print(f"proven optimal: {proven}/{len(files)}; equal to the optimum the library reports: {equal}")


def bench_baselines(count: int, seed: int, workers: int, time_limit: float) -> None:
    spec = DATASETS["I"]
    print(f"\n## Baselines on the Dataset I test split ({count} instances, dataset seed {seed}, policy seed 0)")
    instances = [dataset_instance(spec, k, seed) for k in range(spec.train, spec.train + count)]
    optimal = {}
    for inst in instances:
        res = solve_exact(inst, workers=workers, time_limit=time_limit)
        if res.proven and res.makespan is not None:
            optimal[inst.name] = res.makespan
    print(f"optima proven for {len(optimal)}/{count} instances (suboptimality over those)")
    print("| policy | ours: suboptimality % | paper: suboptimality % | valid % |")
    print("|---|---|---|---|")
    for policy in ("rand", "rand_subteam", "grp"):
        pol = make_policy(policy, seed=0)
        runs = [run_policy(inst, pol) for inst in instances]
        subs = [suboptimality(r.makespan, optimal[r.instance]) for r in runs if r.valid and r.instance in optimal]
        valid = 100 * sum(r.valid for r in runs) / len(runs)
        print(f"| {policy} | {statistics.fmean(subs):.2f} | {PAPER_TABLE_I[policy]:.2f} | {valid:.1f} |")


def bench_fig5(model_path: str | None, seed: int, out_png: str, sizes_n: Sequence[int] = (25, 50, 100),
               sizes_m: Sequence[int] = (50, 100, 200, 500)) -> None:
    """Fig. 5 of the paper: LVWS decision rate (Hz) and accumulated runtime of a whole
    schedule (s) for N robots x M tasks, plus a PNG of both."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import torch

    from lvws_ros.cli.bench_scale import make_instance
    from lvws_ros.core.datasets import random_instance
    from lvws_ros.core.executor import simulate
    from lvws_ros.learning.policies import LVWSPolicy

    policy = LVWSPolicy(model_path=model_path)
    # torch's first forward passes allocate and pick kernels; time the steady state, as a
    # scheduler that runs for a whole shift sees it
    simulate(random_instance(np.random.default_rng([seed, 0]), 10, 20, "warm-up", num_capabilities=3), policy)
    rate: dict[int, list[float]] = {}
    total: dict[int, list[float]] = {}
    for family in ("ours", "subteam-heavy"):
        print(f"\n## Fig. 5 ({family} instances): LVWS decision rate and accumulated runtime (seed {seed}, "
              f"{torch.get_num_threads()} torch threads, after one untimed warm-up schedule)")
        print("| N | M | decisions | decision rate Hz | accumulated runtime s | makespan |")
        print("|---|---|---|---|---|---|")
        for n in sizes_n:
            for m in sizes_m:
                inst = (random_instance(np.random.default_rng([seed, n, m]), n, m, f"{n}r-{m}t", num_capabilities=3)
                        if family == "ours" else make_instance(family, n, m, seed))
                sched = simulate(inst, policy).schedule
                hz = sched.decisions / sched.compute_seconds
                if family == "ours":  # the plot: our generator, as before
                    rate.setdefault(n, []).append(hz)
                    total.setdefault(n, []).append(sched.compute_seconds)
                print(f"| {n} | {m} | {sched.decisions} | {hz:.2f} | {sched.compute_seconds:.2f} | "
                      f"{sched.makespan:g} |", flush=True)
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    for n in sizes_n:
        ax1.plot(sizes_m, rate[n], marker="o", label=f"N = {n}")
        ax2.plot(sizes_m, total[n], marker="o", label=f"N = {n}")
    ax1.set(xlabel="number of tasks M", ylabel="decision rate [Hz]", yscale="log", title="execution speed")
    ax2.set(xlabel="number of tasks M", ylabel="accumulated runtime [s]", title="accumulated runtime")
    for ax in (ax1, ax2):
        ax.grid(True, alpha=0.3)
        ax.legend()
    fig.suptitle(f"LVWS on {machine()}")
    fig.tight_layout()
    Path(out_png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_png, dpi=120)
    plt.close(fig)
    print(f"plot: {out_png}")


def bench_runtime(policy: str = "lvws", rate: float = 20.0, flood: int = 5000) -> None:
    """The ROS runtime: wall time of the whole demo, the simulator's real-time factor,
    decision latency p50/p99 read from the bag, and recorder throughput without loss."""
    import tempfile

    from lvws_ros.ros.launcher import launch

    print(f"\n## ROS runtime (case study, policy {policy}, requested rate {rate:g}x)")
    with tempfile.TemporaryDirectory() as tmp:
        res = launch(policy=policy, rate=rate, bag_dir=Path(tmp) / "bags", out_dir=Path(tmp) / "out", name="bench",
                     gif=False, log=lambda _t: None)
        from lvws_ros.cli.report import report

        rep = report(res.bag)
        s = res.summary
        print("| figure | value |\n|---|---|")
        print(f"| demo wall time (launch to summary) | {s['wall_seconds_total']:.1f} s |")
        print(f"| makespan (sim time) | {s['makespan']:.2f} s |")
        print(f"| simulator real-time factor (sim s / wall s, paused at decisions included) | "
              f"{s['sim_time'] / s['wall_seconds']:.1f}x |")
        print(f"| decision latency p50 / p99 (from the bag) | {rep.latency_ms_p50:.2f} / {rep.latency_ms_p99:.2f} ms |")
        print(f"| messages in the bag | {sum(rep.topics.values())} |")
    for hz in (500, 1000, 2000, 4000):
        with tempfile.TemporaryDirectory() as tmp:
            sent, got, seconds = _flood_recorder(Path(tmp) / "flood", hz, 2.0)
        print(f"| recorder at {hz} TeamState msg/s offered ({sent} sent in {seconds:.2f} s) | {got} recorded, "
              f"{'no loss' if got == sent else f'{sent - got} lost'} |")


def bench_dynamic(policy: str = "lvws", rate: float = 20.0) -> None:
    """The case study with scripted events (config/events_example.yaml: a cancel, a late
    order, two failures mid-task, two repairs) on ROS: decision latency under events, and
    for each failure the replanning decision (sim time after the failure, its latency) and
    when the interrupted task started again."""
    import re
    import tempfile

    from lvws_ros.cli.report import report
    from lvws_ros.ros.bag import read_run
    from lvws_ros.ros.launcher import launch
    from lvws_ros.ros.resources import events_example

    events = events_example()
    print(f"\n## Dynamic world (case study + {events.name}, policy {policy}, rate {rate:g}x, sync)")
    with tempfile.TemporaryDirectory() as tmp:
        res = launch(policy=policy, rate=rate, bag_dir=Path(tmp) / "bags", out_dir=Path(tmp) / "out", name="dyn",
                     gif=False, events=str(events), log=lambda _t: None)
        rep, run, s = report(res.bag), read_run(res.bag), res.summary
        print("| figure | value |\n|---|---|")
        print(f"| tasks done / makespan | {s['tasks_done']}/{s['tasks']}, {s['makespan']:.2f} s (sim) |")
        print(f"| world events | {'; '.join(s['world_events'])} |")
        print(f"| decisions / rejected assignments | {len(run.decisions)} / {len(s['rejected'])} |")
        print(f"| decision latency p50 / p99 under events (from the bag) | {rep.latency_ms_p50:.2f} / "
              f"{rep.latency_ms_p99:.2f} ms |")
        for text in s["world_events"]:
            m = re.match(r"t=([0-9.]+): (\S+) interrupted \(subteam (\S+) released\)", text)
            if not m:
                continue
            t_fail, task = float(m.group(1)), m.group(2)
            after = [d for d in run.decisions if max(d.team_stamp, d.graph_stamp) >= t_fail - 1e-9]
            replan = after[0] if after else None
            again = next((d for d in after if any(t == task for t, _ in d.assignments)), None)
            print(f"| failure at t={t_fail:g} s ({task} interrupted) | replanned at t="
                  f"{max(replan.team_stamp, replan.graph_stamp):.2f} s in {1000 * replan.latency:.2f} ms; "
                  if replan else f"| failure at t={t_fail:g} s ({task} interrupted) | no decision after it; ", end="")
            print(f"{task} restarted at t={max(again.team_stamp, again.graph_stamp):.2f} s with "
                  f"{'+'.join(next(r for t, r in again.assignments if t == task))} |" if again
                  else f"{task} not restarted |")


def _flood_recorder(bag: Path, hz: int, seconds: float) -> tuple[int, int, float]:
    import copy
    import signal
    import subprocess
    import sys

    import rclpy
    from lvws_msgs.msg import RobotState, TeamState

    from lvws_ros.ros.bag import read_run
    from lvws_ros.ros.topics import TEAM_QOS

    rec = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag)], stdout=subprocess.PIPE,
                           text=True)
    assert rec.stdout is not None
    rec.stdout.readline()
    rclpy.init()
    node = rclpy.create_node("lvws_bench_flood")
    count = int(hz * seconds)
    qos = copy.copy(TEAM_QOS)
    qos.depth = count  # the publisher keeps every sample until the recorder acknowledges it
    pub = node.create_publisher(TeamState, "/lvws/team_state", qos)
    while pub.get_subscription_count() == 0:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(0.5)
    msg = TeamState(capability_names=["a", "b"], robots=[
        RobotState(id=f"r{k}", kind="jackal", capabilities=[1, 0], payload=2.0) for k in range(6)])
    t0 = time.perf_counter()
    for k in range(count):
        msg.header.stamp.sec = k
        pub.publish(msg)
        delay = t0 + (k + 1) / hz - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    took = time.perf_counter() - t0
    pub.wait_for_all_acked(rclpy.duration.Duration(seconds=10))
    time.sleep(2.0)  # let the recorder write what it holds
    rec.send_signal(signal.SIGINT)
    rec.communicate(timeout=60)
    node.destroy_node()
    rclpy.shutdown()
    return count, len(read_run(bag).teams), took


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m lvws_ros.cli.bench", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=0, help="dataset and matching seed")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--expert-count", type=int, default=50)
    parser.add_argument("--baseline-count", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--time-limit", type=float, default=60.0)
    parser.add_argument("--model", default=None, help="LVWS checkpoint for Fig. 5 (default: the shipped one)")
    parser.add_argument("--fig5-png", default="docs/fig5.png")
    parser.add_argument("--only", choices=["core", "fig5", "runtime", "dynamic", "scale", "anytime", "stream",
                                           "mspsp", "coalitions"], default=None)
    parser.add_argument("--stream-png", default="docs/scale_stream.png")
    parser.add_argument("--stream-tasks", type=int, default=100_000, help="tasks done before the stream bench stops")
    parser.add_argument("--anytime-png", default="docs/scale_anytime.png")
    parser.add_argument("--anytime-limit", type=float, default=60.0, help="seconds of planning per instance")
    parser.add_argument("--mspsp-dir", default=None,
                        help="a folder of multi-skill project scheduling files (.dzn, e.g. a checkout of the MSPSP "
                             "instance library's instances/set-1/set-1a): the exact expert on each (--only mspsp)")
    parser.add_argument("--mspsp-count", type=int, default=None, help="only the first COUNT files")
    parser.add_argument("--mspsp-results", default=None, help="the library's results folder (their optima)")
    parser.add_argument("--scale-limit", type=float, default=600.0, help="wall seconds per whole-schedule run")
    parser.add_argument("--coalitions", default="dcmrta:0:50,heteromrta:0:50",
                        help="the public coalition benchmarks' instances (NAME:FIRST:COUNT, comma-separated; "
                             "--only coalitions)")
    parser.add_argument("--coalitions-limit", type=float, default=20.0, help="auto's planning seconds per instance")
    args = parser.parse_args(argv)
    print(f"# lvws_ros benchmarks — {machine()}")
    if args.only in (None, "core"):
        bench_matching(args.repeats, args.seed)
        bench_greedy_vs_exact(200, args.seed)
        bench_expert(args.expert_count, args.workers, args.time_limit, args.seed)
        bench_baselines(args.baseline_count, args.seed, args.workers, args.time_limit)
    if args.only in (None, "fig5"):
        bench_fig5(args.model, args.seed, args.fig5_png)
    if args.only in (None, "scale"):
        from lvws_ros.cli.bench_scale import main as bench_scale

        bench_scale(args.seed, args.scale_limit)
    if args.only in (None, "anytime"):
        from lvws_ros.cli.bench_anytime import main as bench_anytime

        bench_anytime(args.seed, args.anytime_limit, args.anytime_png)
    if args.only in (None, "stream"):
        from lvws_ros.cli.bench_stream import main as bench_stream

        bench_stream(args.seed, args.stream_png, args.stream_tasks)
    if args.only in (None, "runtime"):
        bench_runtime()
    if args.only in (None, "dynamic"):
        bench_dynamic()
    if args.only in (None, "coalitions"):
        from lvws_ros.cli.bench_coalitions import bench_coalitions

        for item in args.coalitions.split(","):
            name, first, count = item.split(":")
            bench_coalitions(name, int(first), int(count), args.coalitions_limit, args.seed)
    if args.only == "mspsp" or (args.only is None and args.mspsp_dir):
        if not args.mspsp_dir:
            parser.error("--only mspsp needs --mspsp-dir")
        bench_mspsp(args.mspsp_dir, args.workers, args.time_limit, args.mspsp_count, args.mspsp_results)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
