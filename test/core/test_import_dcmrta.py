"""The DCMRTA / CTAS-D importer: the shipped instance folder gives exactly the shipped
instance file (sites recovered from the distances, durations, requirements, 20 robots
at the depot with the way home), and malformed folders are refused naming the file and
the item, with exit code 2."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from lvws_ros.core.formats import load_instance

ROOT = Path(__file__).resolve().parents[2]
FOLDER = ROOT / "examples" / "dcmrta" / "env_0"


def _import(*args: object) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "lvws_ros.cli", "import", "dcmrta", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, check=False)


def test_the_shipped_folder_gives_the_shipped_instance(tmp_path):
    out = tmp_path / "env_0.json"
    res = _import(FOLDER, "--name", "dcmrta-20a-50t-env_0", "--out", out)
    assert res.returncode == 0, res.stderr
    assert out.read_text() == (ROOT / "examples" / "dcmrta" / "env_0.json").read_text()
    inst = load_instance(out)
    assert inst.num_robots == 20 and inst.num_tasks == 50 and inst.objective == "return"
    assert inst.tasks[0].duration == 4.830310403920351
    # edge0 of vehicle0 is [0, 1, 0, 0.26923954439491876, 0, 1.3461977219745938]: t0 to t1 in 1.346 s
    tr = inst.travel
    assert tr is not None
    assert np.isclose(tr.time(0, tr.task_from[0], tr.task_from[1]), 1.3461977219745938)


def test_malformed_folders_are_refused_naming_the_file_and_item(tmp_path):
    bad = tmp_path / "bad"
    shutil.copytree(FOLDER, bad)
    text = (bad / "task_param.yaml").read_text()
    (bad / "task_param.yaml").write_text(text.replace("capId: 0", "capId: 3", 1))
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "task0" in res.stderr and "capId 3" in res.stderr and "Traceback" not in res.stderr
    shutil.copy(FOLDER / "task_param.yaml", bad / "task_param.yaml")
    (bad / "planner_param.yaml").write_text("taskNum: [unclosed\n")
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "planner_param.yaml" in res.stderr and "Traceback" not in res.stderr
    (bad / "planner_param.yaml").unlink()
    res = _import(bad, "--out", tmp_path / "x.json")
    assert res.returncode == 2 and "planner_param.yaml" in res.stderr
    assert not (tmp_path / "x.json").exists()
