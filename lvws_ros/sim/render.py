"""Pictures of the assembly-cell world: PNG frames and an animated GIF (matplotlib)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.patches import Circle, Patch, Rectangle, RegularPolygon

from lvws_ros.sim.config import ARM_KINDS, CellConfig
from lvws_ros.sim.world import Frame

COLORS = {"panda": "tab:orange", "jackal": "tab:blue", "husky": "tab:green"}


def _extent(cfg: CellConfig) -> tuple[float, float, float, float]:
    xs = [c.position[0] for c in cfg.cells.values()] + [r.start[0] for r in cfg.robots]
    ys = [c.position[1] for c in cfg.cells.values()] + [r.start[1] for r in cfg.robots]
    return min(xs) - 3, max(xs) + 3, min(ys) - 3, max(ys) + 3


def draw_frame(ax: Axes, cfg: CellConfig, frame: Frame, total_tasks: int) -> None:
    ax.clear()
    x0, x1, y0, y1 = _extent(cfg)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.set_title(f"t = {frame.time:6.1f} s   tasks done {frame.done}/{total_tasks}", fontsize=9)
    for cell in cfg.cells.values():
        (cx, cy), (w, h) = cell.position, cell.size
        ax.add_patch(Rectangle((cx - w / 2, cy - h / 2), w, h, fc="0.92", ec="0.5"))
        ax.text(cx, cy + h / 2 + 0.2, cell.id, ha="center", fontsize=7)
    for o in cfg.objects.values():
        x, y = frame.positions[o.id]
        s = 0.4 + 0.08 * o.weight
        ax.add_patch(Rectangle((x - s / 2, y - s / 2), s, s, fc="tab:red", ec="k", lw=0.5, zorder=3))
        ax.text(x, y, o.id[-1], ha="center", va="center", fontsize=6, color="w", zorder=4)
    for r in cfg.robots:
        x, y = frame.positions[r.id]
        task = frame.robot_task.get(r.id)
        patch: Patch
        if r.kind in ARM_KINDS:
            patch = RegularPolygon((x, y), 3, radius=0.5, fc=COLORS[r.kind], ec="k", lw=0.5, zorder=2)
        else:
            patch = Circle((x, y), 0.35 if r.kind == "jackal" else 0.5, fc=COLORS[r.kind], ec="k", lw=0.5,
                           alpha=1.0 if task else 0.5, zorder=5)
        ax.add_patch(patch)
        ax.text(x, y - 0.85, f"{r.id}\n{task or 'wait'}", ha="center", va="top", fontsize=5, zorder=6)
    ax.set_xticks([])
    ax.set_yticks([])


def render_png(cfg: CellConfig, frame: Frame, total_tasks: int, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5, 4.5), dpi=100)
    draw_frame(ax, cfg, frame, total_tasks)
    fig.savefig(out)
    plt.close(fig)
    return out


def render_gif(cfg: CellConfig, frames: Sequence[Frame], total_tasks: int, path: str | Path, fps: int = 8) -> Path:
    """An animated GIF of the recorded frames (matplotlib's Pillow writer)."""
    if not frames:
        raise ValueError("no frames recorded")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(4, 3.6), dpi=70)
    anim = FuncAnimation(fig, lambda k: draw_frame(ax, cfg, frames[k], total_tasks), frames=len(frames))
    anim.save(str(out), writer=PillowWriter(fps=fps))
    plt.close(fig)
    return out


def render_frames(cfg: CellConfig, frames: Sequence[Frame], total_tasks: int, folder: str | Path) -> list[Path]:
    """One PNG per recorded frame: frame_0000.png, frame_0001.png, ..."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5, 4.5), dpi=100)
    paths = []
    for k, frame in enumerate(frames):
        draw_frame(ax, cfg, frame, total_tasks)
        paths.append(out / f"frame_{k:04d}.png")
        fig.savefig(paths[-1])
    plt.close(fig)
    return paths
