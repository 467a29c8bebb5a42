"""`lvws evaluate --psplib`: the PSPLIB table beside the published optima, the exact
expert's pool model, the plain cumulative CP-SAT model and `auto` (the planner);
`--paper` keeps the section."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from lvws_ros.cli.paper import PSPLIB_SETS, _psplib_set, kept_psplib_section, read_optima
from lvws_ros.core.importers import import_psplib
from lvws_ros.policies.cumulative import solve_cumulative

ROOT = Path(__file__).resolve().parents[2]
PSPLIB = ROOT / "examples" / "psplib"


def _evaluate(tmp_path: Path, names: tuple[str, ...], time_limit: str) -> str:
    folder = tmp_path / "psplib"
    folder.mkdir()
    for name in (*names, "optima.csv"):
        shutil.copy(PSPLIB / name, folder / name)
    done = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "evaluate", "--psplib", str(folder), "--time-limit",
                           time_limit, "--workers", "2", "--out-dir", str(tmp_path / "out"), "--quiet"],
                          capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr
    return (tmp_path / "out" / "psplib.md").read_text()


def _row(text: str, name: str) -> list[str]:
    """The cells of ``name``'s row in the per-instance table."""
    (line,) = [line for line in text.splitlines() if line.startswith(f"| {name} |")]
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_evaluate_psplib_writes_the_table(tmp_path):
    text = _evaluate(tmp_path, ("j301_1.sm", "j301_2.sm", "pat1.rcp"), "20")
    assert "| j301_1 | 41 | 30 | 43 |" in text and "| 43* |" in text and "| 47* |" in text
    assert "| pat1 | 10 | 12 | 19 |" in text and "| 19* |" in text
    assert "| J30 | 2 |" in text and "| Patterson | 1 |" in text
    header = _row(text, "instance")
    assert header[-4:] == ["plain cumulative", "s", "auto", "s"]
    auto = header.index("auto")
    for name, optimum in (("j301_1", 43), ("j301_2", 47), ("pat1", 19)):
        cells = _row(text, name)
        assert float(cells[auto].rstrip("*")) >= optimum and float(cells[auto + 1]) > 0
    summary = _row(text, "set")
    assert summary[-3:] == ["auto % above", "auto proven", "auto no worse than plain"]
    j30 = _row(text, "J30")
    assert float(j30[summary.index("auto % above")]) >= 0 and j30[-1].endswith("/2")


def test_auto_in_the_table_is_a_valid_schedule_within_a_tiny_time_limit(tmp_path):
    text = _evaluate(tmp_path, ("j1201_1.sm",), "1")  # open: 104..105, nothing can prove it in 1 s
    header, cells = _row(text, "instance"), _row(text, "j1201_1")
    assert cells[header.index("optimum (lower..best known)")] == "104..105"
    auto = cells[header.index("auto")]
    assert not auto.endswith("*") and float(auto) >= 104
    assert "| J120 | 1 |" in text


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


def test_rg300_files_form_a_set_with_their_reference_values():
    assert [_psplib_set(n) for n in ("j301_1", "j1201_3", "RG300_5", "pat1", "x1")] == \
        ["J30", "J120", "RG300", "Patterson", "other"]
    assert "RG300" in PSPLIB_SETS
    optima = read_optima(PSPLIB / "optima.csv")
    shipped = {p.stem for p in PSPLIB.glob("RG300_*.rcp")}
    sample = {f"RG300_{n}" for n in [*range(1, 6), *range(49, 481, 48)]}  # the first five, every 48th after
    assert shipped == sample and all(n in optima for n in shipped)
    assert all(low <= up for low, up in optima.values())
