"""Public coalition benchmarks with the way home, side by side with the peers' plans
(``python -m lvws_ros.cli.bench --only coalitions``): figures printed, nothing asserted.

The instances shipped in ``examples/dcmrta`` (DCMRTA's 20 robots x 50 tasks) and
``examples/heteromrta`` (HeteroMRTA's 15 robots of 5 species x 20 tasks), each folder with a
``peers.csv`` of the makespans its repository publishes. Per instance: GRP and LVWS (their own
whole schedules), ``auto`` (the planner, as ``lvws solve --policy auto --time-limit S`` runs it:
the executed schedule's makespan) and the lower bound; every schedule checked
(``lvws check``'s rules). Then the mean ratio of each of ours to each peer's column, and on how
many instances ours is shorter.
"""

from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
BENCHMARKS = {"dcmrta": ROOT / "examples" / "dcmrta", "heteromrta": ROOT / "examples" / "heteromrta"}


def _peers(folder: Path) -> tuple[list[str], dict[str, list[float]]]:
    with (folder / "peers.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    columns = [c for c in rows[0] if c not in ("instance", "mip_gap", "solver_seconds")]
    return columns, {r["instance"]: [float(r[c]) for c in columns] for r in rows}


def bench_coalitions(name: str, first: int, count: int, time_limit: float, seed: int = 0) -> None:
    """One benchmark's table (module docstring): instances ``env_first`` ... of ``name``."""
    from lvws_ros.core.bounds import lower_bounds
    from lvws_ros.core.executor import simulate
    from lvws_ros.core.formats import load_instance
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.learning.policies import LVWSPolicy
    from lvws_ros.planning.auto import PlannedAutoPolicy
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    folder = BENCHMARKS[name]
    columns, peers = _peers(folder)
    ours = ["grp", "lvws", f"auto {time_limit:g} s"]
    print(f"\n## {name}: instances env_{first}..env_{first + count - 1} (seed {seed}; auto: the planner, "
          f"{time_limit:g} s each)")
    print("| instance | " + " | ".join(columns + ours) + " | lower bound | auto s |")
    print("|" + "---|" * (len(columns) + len(ours) + 3))
    table: list[tuple[list[float], list[float]]] = []
    for k in range(first, first + count):
        key = f"env_{k}"
        inst = load_instance(folder / f"{key}.json")
        got = []
        for policy in (GreedyPayloadPolicy(), LVWSPolicy(), PlannedAutoPolicy(seed=seed, time_limit=time_limit)):
            t0 = time.perf_counter()
            schedule = simulate(inst, policy).schedule
            if errors := check_schedule(inst, schedule):
                raise AssertionError(f"{name} {key} {policy.name}: {errors[0]}")
            got.append(float(schedule.makespan))
        seconds = time.perf_counter() - t0  # auto's, the last
        table.append((peers[key], got))
        print(f"| {key} | " + " | ".join(f"{v:.2f}" for v in peers[key] + got)
              + f" | {lower_bounds(inst).best:.2f} | {seconds:.1f} |", flush=True)
    for c, column in enumerate(columns):
        theirs = np.array([p[c] for p, _ in table])
        parts = []
        for o, mine in enumerate(ours):
            values = np.array([g[o] for _, g in table])
            parts.append(f"{mine} {np.mean(values / theirs):.3f} x (shorter on {int(np.sum(values < theirs - 1e-9))}"
                         f"/{len(table)})")
        print(f"- against {column}: " + "; ".join(parts))
