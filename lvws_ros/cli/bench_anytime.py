"""Anytime benchmark of the planner (``python -m lvws_ros.cli.bench --only anytime``): the
plan's makespan and its gap to the lower bound against planning wall time, beside GRP's
and LVWS's whole schedules; figures printed and a PNG drawn, nothing asserted.

For each family (ours, subteam-heavy, the held-out depot with travel, traits-return: traits,
travel and the way home, and the held-out warehouse) at 100 x 500, 200 x 1000 and 1000 x 5000,
one run of the planner (:class:`~lvws_ros.planning.planner.Planner`, one thread) for ``limit``
seconds in a child process of its own; the best plan at 1, 5, 15 and 60 s (the quick plans
arrive cheapest first on the cell, each when it is done) and each quick plan's own makespan
and time.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

FAMILIES = ("ours", "subteam-heavy", "depot", "traits-return", "warehouse")
SIZES = ((100, 500), (200, 1000), (1000, 5000))
MARKS = (1.0, 5.0, 15.0, 60.0)
HELD_OUT = ("subteam-heavy", "depot", "warehouse")  # never trained or tuned on (the model's training: ours, traits-return)


def make_instance(family: str, n: int, m: int, seed: int) -> Any:
    from lvws_ros.cli.bench_scale import make_instance as scale_instance
    from lvws_ros.core.families import family_instance

    if family in ("traits-return", "warehouse"):
        return family_instance(family, 0, seed, num_robots=n, num_tasks=m)
    return scale_instance(family, n, m, seed)


def one_run(family: str, n: int, m: int, seed: int, limit: float) -> dict[str, Any]:
    """The planner on one instance in this process (the child's side)."""
    from lvws_ros.core.executor import State
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.planning.planner import Planner, PlanReport

    inst = make_instance(family, n, m, seed)
    planner = Planner(seed=seed, workers=1)
    planner.lvws()  # the model loaded before the clock starts
    trace: list[tuple[float, float, str]] = []

    def heard(r: PlanReport) -> None:
        trace.append((r.seconds, r.makespan, r.source))

    t0 = time.perf_counter()
    report = planner.run(State.initial(inst), time_limit=limit, on_report=heard)
    seconds = time.perf_counter() - t0
    assert planner.plan is not None
    quick = {name: {"makespan": makespan, "seconds": took, "at": planner.quick_at[name]}
             for name, (makespan, took) in planner.quick.items()}
    return {"family": family, "n": n, "m": m, "seed": seed, "limit": limit, "seconds": seconds,
            "makespan": report.makespan, "bound": report.bound, "gap": report.gap, "rounds": report.rounds,
            "improved": report.improved, "trace": trace, "quick": quick,
            "valid": not check_schedule(inst, planner.plan.schedule)}


def run_in_child(family: str, n: int, m: int, seed: int, limit: float) -> dict[str, Any]:
    cmd = [sys.executable, "-m", "lvws_ros.cli.bench_anytime", "--one", family, str(n), str(m), str(seed),
           str(limit)]
    try:
        res = subprocess.run(cmd, capture_output=True, text=True, timeout=limit * 4 + 600)
    except subprocess.TimeoutExpired:
        return {"family": family, "n": n, "m": m, "error": "did not finish"}
    if res.returncode != 0:
        return {"family": family, "n": n, "m": m, "error": res.stderr.strip().splitlines()[-1:]}
    return dict(json.loads(res.stdout.strip().splitlines()[-1]))


def best_by(run: dict[str, Any], t: float) -> float:
    """The best plan's makespan by ``t`` seconds of planning (nan: none yet)."""
    points = [(q["at"], q["makespan"]) for q in run["quick"].values()] + [(s, mk) for s, mk, _ in run["trace"]]
    got = [mk for s, mk in points if s <= t]
    return min(got) if got else float("nan")


def print_table(runs: list[dict[str, Any]]) -> None:
    print("| family | N x M | GRP (s) | GRP critical path (s) | LVWS (s) | " +
          " | ".join(f"plan at {t:g} s" for t in MARKS) + " | final / best quick | bound | gap | valid |")
    print("|---|---|---|---|---|" + "---|" * len(MARKS) + "---|---|---|---|")
    for r in runs:
        if "error" in r:
            print(f"| {r['family']} | {r['n']} x {r['m']} | {r['error']} |")
            continue
        q = r["quick"]

        def cell(name: str, q: dict[str, Any] = q) -> str:
            return f"{q[name]['makespan']:g} ({q[name]['seconds']:.1f})" if name in q else "not within the limit"

        best_quick = min(v["makespan"] for v in q.values())
        marks = " | ".join("none yet" if math.isnan(b := best_by(r, t)) else f"{b:g}" for t in MARKS)
        held = " (held out)" if r["family"] in HELD_OUT else ""
        print(f"| {r['family']}{held} | {r['n']} x {r['m']} | {cell('grp')} | {cell('grp-critical-path')} | "
              f"{cell('lvws')} | {marks} | {r['makespan'] / best_quick:.3f} | {r['bound']:g} | "
              f"{100 * r['gap']:.1f} % | {'yes' if r['valid'] else 'NO'} |", flush=True)


def plot(runs: list[dict[str, Any]], out_png: str | Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    fig, axes = plt.subplots(1, len(SIZES), figsize=(6 * len(SIZES), 4.2))
    for ax, (n, m) in zip(np.atleast_1d(axes), SIZES, strict=True):
        for r in (r for r in runs if r.get("n") == n and "error" not in r):
            ts = np.geomspace(0.1, r["limit"], 200)
            gaps = [(best_by(r, t) - r["bound"]) / best_by(r, t) * 100 for t in ts]
            ax.plot(ts, gaps, label=r["family"], marker="o", markevery=[len(ts) - 1], linewidth=1.8)
        ax.set(xscale="log", xlabel="planning wall time [s]", ylabel="gap to the lower bound [%]",
               title=f"{n} robots x {m} tasks")
        ax.set_xticks([1, 5, 15, 60], labels=["1", "5", "15", "60"])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.grid(alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def main(seed: int = 0, limit: float = 60.0, out_png: str | Path | None = None,
         sizes: tuple[tuple[int, int], ...] = SIZES, out_json: str | Path | None = None) -> list[dict[str, Any]]:
    print(f"\n## The planner, anytime (seed {seed}; {limit:g} s of planning per instance, one thread, each "
          "run in its own process)")
    print("Each quick plan: its makespan (its seconds). 'plan at T s': the best plan after T s of planning "
          "(quick plans included). Bound: core/bounds.py; gap: (plan - bound) / plan.")
    runs = []
    for n, m in sizes:
        for family in FAMILIES:
            runs.append(run_in_child(family, n, m, seed, limit))
    print_table(runs)
    if out_json is not None:
        Path(out_json).write_text(json.dumps(runs, indent=1))
    if out_png is not None:
        plot(runs, out_png)
        print(f"curves: {out_png}")
    return runs


if __name__ == "__main__":
    if len(sys.argv) > 1 and sys.argv[1] == "--one":
        family, n, m, seed, limit = sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5]), float(sys.argv[6])
        print(json.dumps(one_run(family, n, m, seed, limit)))
    else:
        import argparse

        parser = argparse.ArgumentParser(description="the planner's anytime benchmark")
        parser.add_argument("--seed", type=int, default=0)
        parser.add_argument("--limit", type=float, default=60.0)
        parser.add_argument("--png", default=None)
        parser.add_argument("--json", default=None)
        parser.add_argument("--small", action="store_true", help="100 x 500 only")
        a = parser.parse_args()
        main(a.seed, a.limit, a.png, SIZES[:1] if a.small else SIZES, a.json)
