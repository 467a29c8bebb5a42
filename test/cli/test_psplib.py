"""`lvws evaluate --psplib`: the PSPLIB table beside the published optima, the exact
expert's pool model and the plain cumulative CP-SAT model; `--paper` keeps the section."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from lvws_ros.cli.paper import kept_psplib_section
from lvws_ros.core.importers import import_psplib
from lvws_ros.policies.cumulative import solve_cumulative

ROOT = Path(__file__).resolve().parents[2]
PSPLIB = ROOT / "examples" / "psplib"


def test_evaluate_psplib_writes_the_table(tmp_path):
    folder = tmp_path / "psplib"
    folder.mkdir()
    for name in ("j301_1.sm", "j301_2.sm", "pat1.rcp", "optima.csv"):
        shutil.copy(PSPLIB / name, folder / name)
    done = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "evaluate", "--psplib", str(folder), "--time-limit",
                           "20", "--workers", "2", "--out-dir", str(tmp_path / "out"), "--quiet"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    text = (tmp_path / "out" / "psplib.md").read_text()
    assert "| j301_1 | 41 | 30 | 43 |" in text and "| 43* |" in text and "| 47* |" in text
    assert "| pat1 | 10 | 12 | 19 |" in text and "| 19* |" in text
    assert "| J30 | 2 |" in text and "| Patterson | 1 |" in text


def test_the_plain_cumulative_model_proves_a_j30_optimum_and_refuses_other_instances():
    res = solve_cumulative(import_psplib(PSPLIB / "j301_3.sm"), time_limit=20, workers=2)
    assert res.proven and res.makespan == 47
    from lvws_ros.core.datasets import DATASETS, dataset_instance
    from lvws_ros.errors import ExpertError

    try:
        solve_cumulative(dataset_instance(DATASETS["I"], 0, 0))
    except ExpertError as exc:
        assert "plain cumulative model" in str(exc)
    else:
        raise AssertionError("a capability instance is not a project")


def test_the_paper_report_keeps_the_psplib_section(tmp_path):
    out = tmp_path / "results.md"
    out.write_text("# Results\n\n## Table I\n\nx\n\n## PSPLIB — projects\n\n| a |\n\n## Later\n\ny\n")
    assert kept_psplib_section(out) == ["", "## PSPLIB — projects", "", "| a |", ""]
    assert kept_psplib_section(tmp_path / "none.md") == []
