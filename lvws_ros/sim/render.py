"""Pictures of the assembly-cell world: PNG frames and an animated GIF (matplotlib).

A frame shows the cells, the objects, every robot (busy: opaque; waiting: faded;
failed: grey with a cross), each running task's subteam as links from its members to
the object it works on, a label per robot (id and task) placed so that labels never
overlap (right of the robot, with a leader line; the rule of
:func:`~lvws_ros.sim.labels.place_labels`), a legend, the sim time and the tasks done.
Pictures are 1100 x 800 px.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch, Rectangle, RegularPolygon

from lvws_ros.sim.config import ARM_KINDS, CellConfig
from lvws_ros.sim.labels import place_labels
from lvws_ros.sim.world import Frame

__all__ = ["draw_frame", "place_labels", "render_frames", "render_gif", "render_png"]

COLORS = {"panda": "tab:orange", "jackal": "tab:blue", "husky": "tab:green"}
FIGSIZE, DPI = (11.0, 8.0), 100  # 1100 x 800 px: the world on the left, the legend on the right
AXES_WIDTH = 8.0  # inches of the world's axes
LABEL_SIZE = 9  # points
LINE = 0.55  # data units between stacked labels


def _extent(cfg: CellConfig) -> tuple[float, float, float, float]:
    xs = [c.position[0] for c in cfg.cells.values()] + [r.start[0] for r in cfg.robots]
    ys = [c.position[1] for c in cfg.cells.values()] + [r.start[1] for r in cfg.robots]
    return min(xs) - 3, max(xs) + 3, min(ys) - 3.5, max(ys) + 3


def _legend() -> list[Patch | Line2D]:
    return [
        Line2D([], [], marker="^", ls="", mfc=COLORS["panda"], mec="k", ms=10, label="Panda arm (fixed)"),
        Line2D([], [], marker="o", ls="", mfc=COLORS["jackal"], mec="k", ms=8, label="Jackal"),
        Line2D([], [], marker="o", ls="", mfc=COLORS["husky"], mec="k", ms=11, label="Husky"),
        Line2D([], [], marker="o", ls="", mfc="0.8", mec="0.4", alpha=0.5, ms=9, label="waiting (faded)"),
        Line2D([], [], marker="X", ls="", mfc="0.4", mec="k", ms=10, label="failed"),
        Line2D([], [], marker="s", ls="", mfc="tab:red", mec="k", ms=9, label="object"),
        Line2D([], [], color="tab:purple", lw=2, label="subteam link to its object"),
        Patch(fc="0.92", ec="0.5", label="cell"),
    ]


def draw_frame(ax: Axes, cfg: CellConfig, frame: Frame, total_tasks: int) -> None:
    ax.clear()
    x0, x1, y0, y1 = _extent(cfg)
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    total = frame.total or total_tasks
    ax.set_title(f"t = {frame.time:6.1f} s    tasks done {frame.done}/{total}", fontsize=14)
    for cell in cfg.cells.values():
        (cx, cy), (w, h) = cell.position, cell.size
        ax.add_patch(Rectangle((cx - w / 2, cy - h / 2), w, h, fc="0.92", ec="0.5"))
        ax.text(cx, cy + h / 2 + 0.2, cell.id, ha="center", fontsize=11, weight="bold")
    seen: dict[tuple[float, float], int] = {}
    shown = dict(frame.positions)
    for o in cfg.objects.values():  # objects resting at one spot: side by side
        x, y = frame.positions[o.id]
        k = seen.setdefault((round(x, 1), round(y, 1)), 0)
        seen[(round(x, 1), round(y, 1))] = k + 1
        shown[o.id] = (x + 0.75 * k, y)
    for o in cfg.objects.values():
        x, y = shown[o.id]
        s = 0.4 + 0.08 * o.weight
        ax.add_patch(Rectangle((x - s / 2, y - s / 2), s, s, fc="tab:red", ec="k", lw=0.5, zorder=3))
        ax.text(x, y, o.id.removeprefix("obj"), ha="center", va="center", fontsize=8, color="w", zorder=4)
    teams: dict[str, list[str]] = {}
    for rid, task in frame.robot_task.items():
        if task is not None:
            teams.setdefault(task, []).append(rid)
    for task, members in teams.items():  # the subteam: a link from each member to its object
        obj = frame.task_object.get(task)
        if obj in shown:
            ox, oy = shown[obj]
            for rid in members:
                rx, ry = frame.positions[rid]
                ax.plot([rx, ox], [ry, oy], color="tab:purple", lw=2, alpha=0.8, zorder=2.5)
    anchors, texts = [], []
    for r in cfg.robots:
        x, y = frame.positions[r.id]
        task = frame.robot_task.get(r.id)
        failed = r.id in frame.failed
        color = "0.4" if failed else COLORS[r.kind]
        patch: Patch
        if r.kind in ARM_KINDS:
            patch = RegularPolygon((x, y), 3, radius=0.5, fc=color, ec="k", lw=0.5, zorder=2)
        else:
            patch = Circle((x, y), 0.35 if r.kind == "jackal" else 0.5, fc=color, ec="k", lw=0.5,
                           alpha=1.0 if task or failed else 0.5, zorder=5)
        ax.add_patch(patch)
        if failed:
            ax.plot([x], [y], marker="X", color="k", ms=9, zorder=6)
        anchors.append((x, y))
        texts.append(f"{r.id}: {'FAILED' if failed else task or 'wait'}")
    char = (x1 - x0) / (AXES_WIDTH * 72) * LABEL_SIZE * 0.62  # data units per character, roughly
    for (ax_, ay_), (lx, ly), text in zip(anchors, place_labels(anchors, [len(t) * char for t in texts], LINE),
                                          texts, strict=True):
        ax.plot([ax_, lx], [ay_, ly - LINE / 2], color="0.5", lw=0.6, zorder=6)  # leader line
        ax.text(lx, ly, text, ha="left", va="top", fontsize=LABEL_SIZE, zorder=7,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "0.7", "alpha": 0.9})
    ax.set_xticks([])
    ax.set_yticks([])


def _figure() -> tuple[Figure, Axes]:
    fig, ax = plt.subplots(figsize=FIGSIZE, dpi=DPI)
    fig.subplots_adjust(left=0.01, right=0.01 + AXES_WIDTH / FIGSIZE[0], bottom=0.02, top=0.94)
    fig.legend(handles=_legend(), loc="center right", fontsize=10, framealpha=0.9, title="legend")
    return fig, ax


def render_png(cfg: CellConfig, frame: Frame, total_tasks: int, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = _figure()
    draw_frame(ax, cfg, frame, total_tasks)
    fig.savefig(out)
    plt.close(fig)
    return out


def render_gif(cfg: CellConfig, frames: Sequence[Frame], total_tasks: int, path: str | Path, fps: int = 8,
               progress: Callable[[int, int], None] | None = None) -> Path:
    """An animated GIF of the recorded frames, 1100 x 800 px; ``progress(frames drawn,
    frames)`` after each frame (a long GIF takes a while). Each frame is drawn once and
    given its palette as it is drawn (Pillow's fast octree, no dithering: the pictures are
    flat colours), which keeps the writing short."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames recorded")
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = _figure()
    canvas = FigureCanvasAgg(fig)
    images = []
    for k, frame in enumerate(frames, start=1):
        draw_frame(ax, cfg, frame, total_tasks)
        canvas.draw()
        rgba = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw", "RGBA", 0, 1)
        images.append(rgba.convert("RGB").quantize(256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE))
        if progress is not None:
            progress(k, len(frames))
    plt.close(fig)
    images[0].save(out, save_all=True, append_images=images[1:], duration=round(1000 / fps), loop=0)
    return out


def render_frames(cfg: CellConfig, frames: Sequence[Frame], total_tasks: int, folder: str | Path) -> list[Path]:
    """One PNG per recorded frame: frame_0000.png, frame_0001.png, ..."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    fig, ax = _figure()
    paths = []
    for k, frame in enumerate(frames):
        draw_frame(ax, cfg, frame, total_tasks)
        paths.append(out / f"frame_{k:04d}.png")
        fig.savefig(paths[-1])
    plt.close(fig)
    return paths
