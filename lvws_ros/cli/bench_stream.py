"""The stream benchmark: a cell that never stops (``python -m lvws_ros.cli.bench --only stream``).

1000 robots; jobs of 5-20 tasks with precedence arrive as a Poisson stream
(:class:`~lvws_ros.sim.stream.StreamWorld`) until ``target`` tasks are done. The world sends
one change batch per tick (the change-only protocol); the node's work is what the scheduler
node does with it, in this process, without DDS: the batch's message read
(``convert.changes_from_msg``), taken by a ``ChangeFollower``, offered to the
``OnlineScheduler``, decided, its notices dropped and the garbage collector paced after
each decision (``collect_after_decision``), as the node does. Printed per 10,000 tasks done: state-to-decision p50/p99, the
process's resident memory, the live tasks, tasks per wall second; and at the end every task
accounted for. A PNG of the same.
"""

from __future__ import annotations

import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvws_ros.core.changes import ChangeFollower
from lvws_ros.core.online import OnlineScheduler
from lvws_ros.errors import AssignmentRejected
from lvws_ros.registry import make_policy
from lvws_ros.ros import convert
from lvws_ros.ros.scheduler_node import collect_after_decision
from lvws_ros.sim.stream import StreamWorld

BUCKET = 10_000  # tasks done per row


def rss_mib() -> float:
    """This process's resident memory (Linux ``/proc``; 0 where there is none)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return 0.0


@dataclass
class Row:
    done: int
    p50_ms: float
    p99_ms: float
    rss_mib: float
    live: int
    tasks_per_s: float


@dataclass
class StreamRun:
    rows: list[Row] = field(default_factory=list)
    wall: float = 0.0
    decisions: int = 0
    added: int = 0
    done: int = 0
    live_not_done: int = 0
    retired: int = 0
    rejected: int = 0
    assigned_twice: int = 0


def run_stream(robots: int = 1000, target: int = 100_000, jobs_per_unit: float = 4.0, seed: int = 0,
               policy: str = "grp", retire_after: float = 0.0, log: bool = True) -> StreamRun:
    """The stream until ``target`` tasks are done (module docstring)."""
    world = StreamWorld(robots, jobs_per_unit, seed, retire_after=retire_after)
    follower = ChangeFollower()
    follower.resync(*world.snapshots(), 0)
    core = OnlineScheduler(make_policy(policy, seed=seed), ack_timeout=1e9)
    out, lat, seq, started = StreamRun(), [], 0, set()
    t_start = t_bucket = time.perf_counter()
    next_row = BUCKET
    while world.counts.done < target:
        world.advance()
        seq += 1
        msg = convert.changes_to_msg(world.changes(seq))  # the world's work
        t0 = time.perf_counter()
        follower.take(convert.changes_from_msg(msg))
        assert follower.cell is not None and not follower.needs_resync
        core.offer_cell(*follower.cell.view())  # as the scheduler node offers it
        decision = core.decide(started=t0)
        core.changes.clear()  # what the node reports on /diagnostics, then drops
        core.notices.clear()
        if decision is None:
            continue
        lat.append(time.perf_counter() - t0)
        out.decisions += 1
        collect_after_decision(out.decisions)  # the node's pacing of the garbage collector
        for task, team_ids in decision.assignments:
            out.assigned_twice += task in started
            started.add(task)
            try:
                world.assign(task, team_ids)
            except AssignmentRejected:
                pass
        if world.counts.done >= next_row:
            now = time.perf_counter()
            row = Row(world.counts.done, 1000 * statistics.median(lat), 1000 * float(np.percentile(lat, 99)),
                      rss_mib(), world.live, BUCKET / (now - t_bucket))
            out.rows.append(row)
            if log:
                print(f"| {row.done:,} | {row.p50_ms:.1f} | {row.p99_ms:.1f} | {row.rss_mib:.0f} | {row.live:,} | "
                      f"{row.tasks_per_s:.0f} |", flush=True)
            lat, t_bucket, next_row = [], now, next_row + BUCKET
        started.intersection_update(world.tasks)  # what retired cannot be assigned again: forget it
    out.wall = time.perf_counter() - t_start
    c = world.counts
    out.added, out.done, out.retired, out.rejected = c.added, c.done, c.retired, c.rejected
    out.live_not_done = sum(1 for t in world.tasks.values() if t.end is None)
    return out


def plot(run: StreamRun, path: str | Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    done = [r.done / 1000 for r in run.rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.6))
    a.plot(done, [r.p50_ms for r in run.rows], "o-", label="p50")
    a.plot(done, [r.p99_ms for r in run.rows], "s-", label="p99")
    a.set_xlabel("tasks done (thousands)")
    a.set_ylabel("state to decision (ms)")
    a.set_ylim(bottom=0)
    a.legend()
    b.plot(done, [r.rss_mib for r in run.rows], "o-", color="C2", label="resident memory (MiB)")
    b.set_xlabel("tasks done (thousands)")
    b.set_ylabel("MiB")
    b.set_ylim(bottom=0)
    b2 = b.twinx()
    b2.plot(done, [r.live for r in run.rows], "^--", color="C3", label="live tasks")
    b2.set_ylabel("live tasks")
    b2.set_ylim(bottom=0)
    fig.suptitle("A cell that never stops: 1000 robots, a Poisson stream of jobs")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(seed: int = 0, png: str | Path = "docs/scale_stream.png", target: int = 100_000) -> None:
    print(f"\n## A cell that never stops (seed {seed}; 1000 robots, jobs of 5-20 tasks, 4 jobs per time unit, "
          "a change batch per time unit, GRP deciding, done work retiring at once)")
    print("| tasks done | p50 ms | p99 ms | RSS MiB | live tasks | tasks / s |")
    print("|---|---|---|---|---|---|")
    run = run_stream(target=target, seed=seed)
    first, last = run.rows[0], run.rows[-1]
    print(f"\n{run.done:,} tasks done in {run.wall:.0f} s ({run.done / run.wall:.0f} per s), {run.decisions:,} "
          f"decisions; added {run.added:,} = done {run.done:,} + not done yet {run.live_not_done:,}; retired "
          f"{run.retired:,}; refused by the world {run.rejected}; assigned twice {run.assigned_twice}")
    print(f"p99 of the last {BUCKET:,} / the first {BUCKET:,}: {last.p99_ms / first.p99_ms:.2f}; RSS growth from "
          f"{first.done:,} to {last.done:,} tasks done: {last.rss_mib - first.rss_mib:+.0f} MiB")
    plot(run, png)
    print(f"(figure: {png})")


if __name__ == "__main__":
    main(target=int(sys.argv[1]) if len(sys.argv) > 1 else 100_000)
