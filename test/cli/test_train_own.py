"""`lvws train --instances DIR [--init ...]`: a user's own cell labelled by the expert and
trained on, end to end through the CLI (tiny model, one epoch), then fine-tuned from that
checkpoint; the result schedules the user's instances validly."""

from __future__ import annotations

import json
import subprocess
import sys

from conftest import REPO

MY_CELL = REPO / "examples" / "my_cell"


def lvws(*args, check=True):
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", *map(str, args)], capture_output=True, text=True,
                         timeout=600)
    if check:
        assert res.returncode == 0, res.stderr
    return res


def test_train_on_own_instances_then_fine_tune(tmp_path):
    base = tmp_path / "base.pt"
    tiny = ["--datasets", "", "--families", "", "--epochs", "1", "--dagger-rounds", "0", "--validation", "1",
            "--label-time-limit", "2", "--processes", "1", "--quiet"]
    lvws("train", "--instances", MY_CELL, "--out", base, "--hidden", "16", *tiny)
    tuned = tmp_path / "tuned.pt"
    res = lvws("train", "--instances", MY_CELL, "--init", base, "--out", tuned, "--wait-head", *tiny)
    assert f"fine-tuning {base}" in res.stdout
    assert "a wait head added" in res.stdout and "wait threshold 0.5 -> suboptimality" in res.stdout
    for f in sorted(MY_CELL.glob("*.json"))[:2]:
        out = tmp_path / f"{f.stem}.sched.json"
        lvws("solve", f, "--policy", "lvws", "--model", tuned, "--out", out)
        assert lvws("check", f, out).returncode == 0
    assert json.loads(out.read_text())["policy"] == "lvws"


def test_training_on_a_held_out_family_is_refused():
    res = lvws("train", "--out", "x.pt", "--families", "assembly", check=False)
    assert res.returncode == 2 and "not training families" in res.stderr and "Traceback" not in res.stderr
