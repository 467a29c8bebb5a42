"""The dashboard: its view of the reference bag (every executed task on the Gantt, the
critical path a longest chain, the cell's sites and robots, diagnostics and latency), and
the page in a real browser (Debian's Chromium driven by Playwright): from the bag, with
its time slider; and live beside the case study, where the Gantt gains bars as the run
goes on and the cancel button cancels a task in the simulator."""

from __future__ import annotations

import itertools
import re
import shutil
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pytest

from lvws_ros.ros.dashboard import CellView

REPO = Path(__file__).resolve().parents[2]
REFERENCE_BAG = REPO / "bags" / "reference" / "case-study-lvws"
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


def _chains(view: dict[str, Any]) -> float:
    """The longest chain of tasks not done, by duration (an independent recursion)."""
    nodes = {n["id"]: n for n in view["graph"]["nodes"]}
    before: dict[str, list[str]] = {k: [] for k in nodes}
    for a, b in view["graph"]["edges"]:
        before[b].append(a)
    duration = {t["id"]: t["duration"] for t in view["durations"]}
    memo: dict[str, float] = {}

    def longest(k: str) -> float:
        if k not in memo:
            left = 0.0 if nodes[k]["status"] == "done" else duration[k]
            memo[k] = left + max((longest(p) for p in before[k]), default=0.0)
        return memo[k]

    return max((longest(k) for k in nodes), default=0.0)


def test_the_view_of_the_reference_bag():
    cell = CellView.from_bag(REFERENCE_BAG)
    end = cell.view()
    assert all(t["status"] == "done" for t in end["tasks"]) and len(end["tasks"]) == 14
    graph = cell.graphs[-1]
    pairs = {(x.id, r) for x in graph.tasks for r in x.assigned_robots}
    assert {(b["task"], b["robot"]) for b in end["gantt"] if b["kind"] == "executed"} == pairs
    planned = {(b["task"], b["robot"]) for b in end["gantt"] if b["kind"] == "planned"}
    assert planned == {(t, r) for d in cell.decisions for t, team in d.assignments for r in team}
    assert end["graph"]["critical"] == []  # nothing left to do
    assert len(end["cell"]["sites"]) > 0 and len(end["robots"]) == 6
    assert end["latency"] and all(p["ms"] > 0 for p in end["latency"])

    start = cell.view(0.0)  # the first tasks have just started: bars of no length yet, running
    first = [b for b in start["gantt"] if b["kind"] == "executed"]
    assert first and all(b["running"] and b["start"] == b["end"] == 0.0 for b in first)
    crit = start["graph"]["critical"]
    edges = {tuple(e) for e in start["graph"]["edges"]}
    assert all((a, b) in edges for a, b in itertools.pairwise(crit))  # a chain of the graph
    durations = {x.id: x.duration for x in cell.graphs[0].tasks}
    start["durations"] = [{"id": k, "duration": v} for k, v in durations.items()]
    assert sum(durations[k] for k in crit) == pytest.approx(_chains(start))  # and a longest one


def _boxes_overlap(a: dict[str, Any], b: dict[str, Any]) -> bool:
    return (a["x"] < b["x"] + b["width"] and b["x"] < a["x"] + a["width"]
            and a["y"] - a["height"] < b["y"] and b["y"] - b["height"] < a["y"])


def test_the_cell_labels_never_overlap_where_robots_share_a_site():
    cell = CellView.from_bag(REFERENCE_BAG)
    shared = 0
    for t in [*sorted({s.stamp for s in cell.teams})[::5], 0.0, cell.end_time()]:
        c = cell.view(t)["cell"]
        marks = [(s["x"], s["y"]) for s in c["sites"]] + [(r["x"], r["y"]) for r in c["robots"]]
        shared += len(marks) - len(set(marks))
        labels = c["labels"]
        assert [lb["text"] for lb in labels] == [s["name"] for s in c["sites"]] + [r["id"] for r in c["robots"]]
        assert all(lb["anchor"] == [x, y] for lb, (x, y) in zip(labels, marks, strict=True))
        assert not [(a["text"], b["text"]) for a, b in itertools.combinations(labels, 2) if _boxes_overlap(a, b)]
        (x0, x1), (y0, y1) = c["range"]["x"], c["range"]["y"]
        assert all(x0 <= lb["x"] and lb["x"] + lb["width"] <= x1 and y0 <= lb["y"] - lb["height"]
                   and lb["y"] <= y1 for lb in labels)  # every label inside the picture
    assert shared > 0  # robots stood on sites, and on each other's: the case the rule is for


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextmanager
def _browser() -> Iterator[Any]:
    if CHROMIUM is None:
        pytest.skip("Debian's chromium is not installed (make browser installs it as root with apt-get)")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=["--no-sandbox"])
        try:
            yield browser.new_page(viewport={"width": 1400, "height": 1100})
        finally:
            browser.close()


def _wait_for_url(port: int, proc: subprocess.Popen[str], seconds: float = 60.0) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()[0]
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.2)
    raise AssertionError(f"nothing listens on port {port}")


def _executed(page: Any) -> int:
    return int(page.eval_on_selector("#gantt", "e => Number(e.dataset.executed || 0)"))


def _printed_url(log: Path, port: int, proc: subprocess.Popen[str], seconds: float = 120.0) -> str:
    """The page's URL with its token, as printed (by lvws dashboard or lvws launch)."""
    pattern = re.compile(rf"dashboard: (http://127\.0\.0\.1:{port}/\?token=[A-Za-z0-9_-]+)")
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if (m := pattern.search(log.read_text())) is not None:
            return m.group(1)
        assert proc.poll() is None, log.read_text()
        time.sleep(0.2)
    raise AssertionError(f"no URL printed: {log.read_text()}")


def test_the_page_of_a_bag_in_a_real_browser(tmp_path):
    port = _free_port()
    log = tmp_path / "dashboard.txt"
    with open(log, "w") as out:
        proc = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.dashboard", "--bag", str(REFERENCE_BAG),
                                 "--port", str(port)], stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for_url(port, proc)
        url = _printed_url(log, port, proc)
        with _browser() as page:
            page.goto(url)
            page.wait_for_function("() => window.lastView && document.querySelector('#gantt .barlayer')")
            pairs = sum(len(x.assigned_robots) for x in CellView.from_bag(REFERENCE_BAG).graphs[-1].tasks)
            assert _executed(page) == pairs  # a bar per (task, robot) of the run
            assert page.inner_text("#done") == "14/14"
            assert page.is_disabled("#cancel")  # a recorded run: the world cannot be changed
            assert page.locator("#robots tbody tr").count() == 6
            page.eval_on_selector("#slider", "e => { e.value = '0'; e.dispatchEvent(new Event('input')); }")
            page.wait_for_function("() => window.lastView.time === 0")
            assert 0 < _executed(page) < pairs  # only the tasks started at 0
            assert int(page.eval_on_selector("#cell", "e => Number(e.dataset.labels || 0)")) == 12  # 6 sites, 6 robots
            page.screenshot(path=str(tmp_path / "bag.png"), full_page=True)
            page.goto(url.split("?")[0])  # without the token: no view, and the page says why
            page.wait_for_function("() => document.querySelector('#refused').textContent.includes('token')")
            assert not page.evaluate("() => window.lastView")
    finally:
        proc.terminate()
        proc.wait(timeout=30)


def test_the_page_beside_a_live_run_gains_bars_and_cancels_a_task(tmp_path):
    port = _free_port()
    cmd = [sys.executable, "-m", "lvws_ros.cli", "launch", "--policy", "grp", "--rate", "4", "--no-gif",
           "--bag-dir", str(tmp_path / "bags"), "--out-dir", str(tmp_path / "out"), "--name", "dash",
           "--dashboard", str(port), "--protocol", "changes"]  # the page follows the world's changes
    log = tmp_path / "launch.txt"
    with open(log, "w") as out:
        run = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for_url(port, run, 120.0)
        url = _printed_url(log, port, run)  # lvws launch prints the page's URL with the dashboard's token
        with _browser() as page:
            page.goto(url)
            page.wait_for_function("() => Number(document.querySelector('#gantt').dataset.executed) > 0",
                                   timeout=60_000)
            first = _executed(page)
            page.wait_for_function(f"() => Number(document.querySelector('#gantt').dataset.executed) > {first}",
                                   timeout=60_000)
            assert page.inner_text("#source") == "live"
            page.select_option("#task", "t14")  # the last task: not started yet
            page.click("#cancel")
            page.wait_for_function("() => document.querySelector('#answer').textContent.startsWith('done')",
                                   timeout=30_000)
            page.wait_for_function("() => !window.lastView.tasks.some(t => t.id === 't14')", timeout=30_000)
            page.screenshot(path=str(tmp_path / "live.png"), full_page=True)
        assert run.wait(timeout=300) == 0, log.read_text()
        out = log.read_text()
        assert "13/13 tasks" in out, out[-2000:]
        token = url.split("token=")[1]
        assert token not in (tmp_path / "out" / "dash" / "dashboard.log").read_text()  # never in a log file
    finally:
        if run.poll() is None:
            run.terminate()
            run.wait(timeout=60)


@pytest.mark.parametrize("args, says", [(["--bag", "no/such/bag"], "no such bag"),
                                        (["--port", "0", "--bag", str(REFERENCE_BAG)], "--port")])
def test_bad_arguments_exit_2_with_the_reason(args, says):
    out = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "dashboard", *args], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 2 and says in out.stderr and "Traceback" not in out.stderr, out.stderr
