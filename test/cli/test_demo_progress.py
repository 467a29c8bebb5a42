"""`make demo` never leaves the terminal silent: the comparison step (`lvws sim --compare`)
shows a progress bar (tqdm, on stderr) that advances a policy at a time and redraws its
elapsed time while a policy runs; the table stays alone on stdout."""

from __future__ import annotations

import io
import subprocess
import sys
import time

from tqdm import tqdm

from conftest import REPO


def test_the_compare_step_prints_progress_and_its_table():
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "sim", "--compare", "grp,rand"], cwd=REPO,
                         capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "compare" in res.stderr and "1/2" in res.stderr and "2/2" in res.stderr  # a policy at a time
    assert "grp" in res.stderr and "rand" in res.stderr  # the policy being run is named
    rows = [line for line in res.stdout.splitlines() if line.startswith("| ")]
    assert [r.split("|")[1].strip() for r in rows[1:]] == ["grp", "rand"]  # the table alone on stdout
    assert "compare" not in res.stdout and "%|" not in res.stdout


def test_a_long_step_redraws_its_elapsed_time():
    from lvws_ros.cli.runtime import TICK_SECONDS, _ticking

    out = io.StringIO()
    with tqdm(total=1, desc="step", file=out, mininterval=0) as bar:
        before = out.getvalue().count("\r")
        assert _ticking(bar, lambda: time.sleep(3.5 * TICK_SECONDS) or 42) == 42
        redraws = out.getvalue().count("\r") - before
    assert redraws >= 3  # one a TICK_SECONDS while it ran: never silent for long
    assert "00:03" in out.getvalue()  # the elapsed time shown grew with it


def test_a_failing_step_raises_its_own_error():
    import pytest

    from lvws_ros.cli.runtime import _ticking

    def fails() -> None:
        raise ValueError("the step's own error")

    with tqdm(total=1, file=io.StringIO()) as bar, pytest.raises(ValueError, match="the step's own error"):
        _ticking(bar, fails)


def test_the_gif_reports_each_frame_drawn(tmp_path):
    from lvws_ros.registry import make_policy
    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.sim.config import load_cell_config
    from lvws_ros.sim.render import render_gif
    from lvws_ros.sim.runner import run_offline
    from lvws_ros.sim.world import CellSim

    sim = CellSim(load_cell_config(case_study_config()))
    run_offline(sim, make_policy("grp"), frame_every=30.0)
    seen: list[tuple[int, int]] = []
    render_gif(sim.cfg, sim.trace, 14, tmp_path / "run.gif", progress=lambda k, n: seen.append((k, n)))
    n = len(sim.trace)
    assert n >= 4 and seen == [(k, n) for k in range(1, n + 1)]
