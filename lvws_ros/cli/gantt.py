"""Gantt charts of schedules with matplotlib: one row per robot, subteams and waiting visible."""

from __future__ import annotations

from pathlib import Path

from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule


def plot_gantt(schedule: Schedule, out: str | Path, instance: Instance | None = None, title: str | None = None) -> Path:
    """Write a PNG: a bar per (robot, task); bars of one subteam share a colour, carry
    the subteam size and are joined by a line; idle stretches are hatched as waiting."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    robots = [r.id for r in instance.robots] if instance is not None else sorted(
        {r for a in schedule.assignments for r in a.robots})
    row = {r: k for k, r in enumerate(robots)}
    cmap = plt.get_cmap("tab20")
    fig, ax = plt.subplots(figsize=(10.0, 0.6 * len(robots) + 1.6))
    busy: dict[str, list[tuple[float, float]]] = {r: [] for r in robots}
    for n, a in enumerate(schedule.assignments):
        color = cmap(n % 20)
        ys = []
        for r in a.robots:
            y = row[r]
            ys.append(y)
            busy[r].append((a.start, a.end))
            ax.barh(y, a.end - a.start, left=a.start, height=0.6, color=color, edgecolor="black", linewidth=0.6)
            label = a.task if len(a.robots) == 1 else f"{a.task} ×{len(a.robots)}"
            ax.text((a.start + a.end) / 2, y, label, ha="center", va="center", fontsize=7)
        if len(ys) > 1:
            ax.plot([a.start + 0.1, a.start + 0.1], [min(ys), max(ys)], color=color, linewidth=2.5, alpha=0.9)
    for r, spans in busy.items():
        t = 0.0
        for s, e in sorted(spans):
            if s > t + 1e-9:
                ax.barh(row[r], s - t, left=t, height=0.3, color="none", edgecolor="grey", hatch="///", linewidth=0)
            t = max(t, e)
        if schedule.makespan > t + 1e-9:
            ax.barh(row[r], schedule.makespan - t, left=t, height=0.3, color="none", edgecolor="lightgrey",
                    hatch="...", linewidth=0)
    ax.set_yticks(range(len(robots)), robots)
    ax.invert_yaxis()
    ax.set_xlabel("time [s]")
    ax.set_xlim(0, max(schedule.makespan, 1e-9) * 1.02)
    ax.axvline(schedule.makespan, color="black", linestyle="--", linewidth=1)
    ax.set_title(title or f"{schedule.instance} — {schedule.policy}, makespan {schedule.makespan:g} s")
    ax.legend(handles=[Patch(facecolor="none", edgecolor="grey", hatch="///", label="waiting"),
                       Patch(facecolor="none", edgecolor="lightgrey", hatch="...", label="done")],
              loc="lower right", fontsize=7)
    fig.tight_layout()
    path = Path(out)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path
