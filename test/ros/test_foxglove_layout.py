"""The Foxglove layout in config/ is a well-formed layout whose panels show the run's
topics: markers in a 3D panel, the assignments, the task graph and the diagnostics."""

from __future__ import annotations

import json

from conftest import REPO
from lvws_ros.ros.topics import TOPICS


def _panels(node) -> list[str]:
    if isinstance(node, str):
        return [node]
    assert node["direction"] in ("row", "column") and 0 < node["splitPercentage"] < 100
    return _panels(node["first"]) + _panels(node["second"])


def test_the_foxglove_layout_shows_markers_assignments_graph_and_diagnostics():
    layout = json.loads((REPO / "config" / "foxglove_layout.json").read_text())
    panels = _panels(layout["layout"])
    assert sorted(panels) == sorted(layout["configById"])  # every panel placed once, every config used
    kinds = {p.split("!")[0] for p in panels}
    assert {"3D", "RawMessages", "DiagnosticSummary", "DiagnosticStatusPanel"} <= kinds
    names = {f"/{t}" for t in TOPICS}
    used = {p: c.get("topicPath", c.get("topicToRender", "")).split(".")[0] for p, c in layout["configById"].items()}
    used.update({p: t for p, c in layout["configById"].items() for t in c.get("topics", {})})
    used.update({p: v["value"].split(".")[0] for p, c in layout["configById"].items() for v in c.get("paths", [])})
    assert set(used.values()) <= names and {"/lvws/markers", "/lvws/assignments", "/lvws/task_graph",
                                            "/diagnostics"} <= set(used.values())
