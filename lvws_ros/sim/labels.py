"""Where labels go so that they never overlap: one rule for every picture of the cell (the
GIF and PNG frames of :mod:`lvws_ros.sim.render`, the dashboard's cell view). Plain Python:
no drawing library."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["place_labels"]


def place_labels(anchors: Sequence[tuple[float, float]], widths: Sequence[float], height: float,
                 dx: float = 0.6, dy: float = 0.3) -> list[tuple[float, float]]:
    """The top-left corner of each anchor's label box (width, height in data units): right
    of the anchor, at y + dy, y + dy - height, ... the first that overlaps no label placed
    before (labels never overlap, wherever the robots stand)."""
    placed: list[tuple[float, float, float]] = []  # (left, top, width)
    out = []
    for (x, y), w in zip(anchors, widths, strict=True):
        left, top = x + dx, y + dy
        while any(left < pl + pw and pl < left + w and abs(top - pt) < height for pl, pt, pw in placed):
            top -= height
        placed.append((left, top, w))
        out.append((left, top))
    return out
