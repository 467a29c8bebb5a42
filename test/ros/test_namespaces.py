"""Two cells side by side on one DDS domain (``lvws launch --namespace``): each completes
without a rejected assignment, and each bag holds only its own cell's topics, stamped in
its own sim time."""

from __future__ import annotations

import json
import random
import subprocess
import sys
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from lvws_ros.cli.report import report
from lvws_ros.core.schedule import check_schedule
from lvws_ros.ros.bag import read_run

pytestmark = pytest.mark.ros


def test_two_namespaced_cells_on_one_domain_complete_side_by_side(tmp_path: Path):
    domain = random.SystemRandom().randint(1, 101)
    cells = {"cellA": "grp", "cellB": "lvws"}
    params = tmp_path / "params.yaml"  # cellA's policy comes from its own section of a params file
    params.write_text("scheduler:\n  ros__parameters: {policy: dbgm}\n"
                      "/cellA/scheduler:\n  ros__parameters: {policy: grp}\n")
    choose = {"cellA": ["--params-file", str(params)], "cellB": ["--policy", "lvws"]}
    procs = {
        cell: subprocess.Popen(
            [sys.executable, "-m", "lvws_ros.cli", "launch", "--namespace", cell, "--domain-id", str(domain),
             *choose[cell], "--rate", "20", "--no-gif", "--name", cell, "--bag-dir", str(tmp_path / "bags"),
             "--out-dir", str(tmp_path / "out"), "--timeout", "400"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        for cell, policy in cells.items()}
    outputs = {cell: p.communicate(timeout=500)[0] for cell, p in procs.items()}
    for cell, p in procs.items():
        assert p.returncode == 0, outputs[cell]
        assert f"in /{cell}" in outputs[cell] and "tasks done" in outputs[cell]  # progress while it ran
    for cell, policy in cells.items():
        summary = json.loads((tmp_path / "out" / cell / "summary.json").read_text())
        assert summary["tasks_done"] == 14 and summary["rejected"] == [] and summary["error"] == ""
        bag = tmp_path / "bags" / cell
        run = read_run(bag)
        assert run.namespace == f"/{cell}"
        assert all(t.startswith(f"/{cell}/") for t in run.topics), run.topics
        assert run.decisions and {d.policy for d in run.decisions} == {policy}
        assert {d["hardware_id"] for d in run.diagnostics} == {f"/{cell}/scheduler"}
        rep = report(bag)
        assert rep.complete and check_schedule(rep.instance, rep.schedule) == []
        assert rep.schedule.makespan == pytest.approx(summary["makespan"], abs=1e-6)
        with AnyReader([bag]) as reader:  # stamped in sim time (minutes), not wall time (decades since 1970)
            assert 0 <= reader.start_time and reader.end_time <= (summary["sim_time"] + 1) * 1e9
