"""Who may see and act on a cell through its dashboard: the token the dashboard generates
(or is given), this page's origin, and ``--read-only``; a refused request gets 403 and
changes nothing. Live: a real case-study run (cell_sim, scheduler, recorder) and a
dashboard listening on an address of this machine that is not loopback; every request
goes to this machine's own addresses."""

from __future__ import annotations

import contextlib
import json
import os
import random
import re
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

REPO = Path(__file__).resolve().parents[2]
REFERENCE_BAG = REPO / "bags" / "reference" / "case-study-lvws"
NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))  # this machine's addresses, directly
URL_LINE = re.compile(r"dashboard: (http://\S+?)/(?:\?token=(\S+))? ")


def _own_address() -> str | None:
    """An IPv4 address of this machine that is not loopback, and that a server can listen on."""
    found: list[str] = []
    with contextlib.suppress(OSError):
        found += [a[4][0] for a in socket.getaddrinfo(socket.gethostname(), None, socket.AF_INET)]
    with contextlib.suppress(OSError), socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.connect(("192.0.2.254", 9))  # a UDP "connect" sends nothing: it picks the outgoing address
        found.append(probe.getsockname()[0])
    for address in found:
        if address.startswith("127.") or address == "0.0.0.0":
            continue
        with contextlib.suppress(OSError), socket.socket() as s:
            s.bind((address, 0))
            return address
    return None


def _free_port(host: str) -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def _request(url: str, *, body: dict[str, Any] | None = None, headers: dict[str, str] | None = None
             ) -> tuple[int, dict[str, Any]]:
    """(HTTP status, JSON answer) of a GET, or of a POST of ``body`` as JSON."""
    data = None if body is None else json.dumps(body).encode()
    req = urllib.request.Request(url, data=data, method="GET" if body is None else "POST",
                                 headers={**({"Content-Type": "application/json"} if body is not None else {}),
                                          **(headers or {})})
    try:
        with NO_PROXY.open(req, timeout=30) as res:
            return res.status, json.loads(res.read())
    except urllib.error.HTTPError as exc:
        return exc.code, json.loads(exc.read() or b"{}")


def _started(proc: subprocess.Popen[str], log: Path, seconds: float = 90.0) -> tuple[str, str | None]:
    """(base URL, token printed in it or None) from the dashboard's start line."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if (m := URL_LINE.search(log.read_text())) is not None:
            host, port = m.group(1).removeprefix("http://").rsplit(":", 1)
            with contextlib.suppress(OSError), socket.create_connection((host, int(port)), timeout=0.5):
                return m.group(1), m.group(2)
        assert proc.poll() is None, log.read_text()
        time.sleep(0.2)
    raise AssertionError(f"the dashboard did not start: {log.read_text()}")


@contextlib.contextmanager
def _process(cmd: list[str], log: Path, env: dict[str, str] | None = None) -> Iterator[subprocess.Popen[str]]:
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, text=True,
                                env={**os.environ, "PYTHONUNBUFFERED": "1", **(env or {})})
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def _websocket_status(url: str) -> int | None:
    """The HTTP status that refused a websocket handshake at ``url`` (None: it was accepted
    and the first view came)."""
    import asyncio

    from websockets.asyncio.client import connect
    from websockets.exceptions import InvalidStatus

    async def attempt() -> int | None:
        try:
            async with connect(url, open_timeout=20) as ws:
                json.loads(await asyncio.wait_for(ws.recv(), 20))
                return None
        except InvalidStatus as exc:
            return int(exc.response.status_code)

    return asyncio.run(attempt())


def test_a_bag_dashboard_needs_its_given_token_and_has_no_controls(tmp_path):
    port = _free_port("127.0.0.1")
    token = "given-" + os.urandom(12).hex()
    log = tmp_path / "dashboard.txt"
    with _process([sys.executable, "-m", "lvws_ros.ros.dashboard", "--bag", str(REFERENCE_BAG), "--port", str(port)],
                  log, env={"LVWS_DASHBOARD_TOKEN": token}) as proc:
        base, printed = _started(proc, log)
        assert printed is None  # a given token is not printed
        assert _request(f"{base}/view")[0] == 403
        assert _request(f"{base}/view?token=wrong-{token}")[0] == 403
        status, view = _request(f"{base}/view?token={token}")
        assert status == 200 and len(view["tasks"]) == 14 and view["controls"] is False
        status, answer = _request(f"{base}/world", body={"kind": "cancel", "target": "t14"},
                                  headers={"X-LVWS-Token": token})
        assert status == 403 and answer["success"] is False  # views alone
        ws = base.replace("http://", "ws://")
        assert _websocket_status(f"{ws}/ws") == 403
        assert _websocket_status(f"{ws}/ws?token={token}") is None
    assert token not in log.read_text()


def test_a_bad_token_is_refused_with_exit_2():
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "dashboard", "--bag", str(REFERENCE_BAG),
                          "--token", "short"], capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "--token" in res.stderr and "Traceback" not in res.stderr, res.stderr


def _tasks(base: str, token: str) -> dict[str, str]:
    status, view = _request(f"{base}/view?token={token}")
    assert status == 200, view
    return {t["id"]: t["status"] for t in view["tasks"]}


def test_a_live_cell_on_a_network_address_obeys_only_its_token(tmp_path):
    host = _own_address()
    if host is None:
        pytest.skip("this machine has no address but loopback to serve the dashboard on")
    domain = str(random.SystemRandom().randint(120, 200))
    port = _free_port(host)
    run_cmd = [sys.executable, "-m", "lvws_ros.cli", "launch", "--policy", "grp", "--rate", "4", "--no-gif",
               "--domain-id", domain, "--bag-dir", str(tmp_path / "bags"), "--out-dir", str(tmp_path / "out"),
               "--name", "access"]
    dash_cmd = [sys.executable, "-m", "lvws_ros.ros.dashboard", "--host", host, "--port", str(port),
                "--domain-id", domain]
    dash_log, run_log = tmp_path / "dashboard.txt", tmp_path / "launch.txt"
    with _process(dash_cmd, dash_log) as dash:
        base, token = _started(dash, dash_log)
        assert token and base == f"http://{host}:{port}"
        with _process(run_cmd, run_log) as run:
            end = time.monotonic() + 120
            while "t14" not in (tasks := _tasks(base, token)) or not any(s == "done" for s in tasks.values()):
                assert run.poll() is None and time.monotonic() < end, run_log.read_text()
                time.sleep(0.3)
            cancel = {"kind": "cancel", "target": "t14"}
            refused = [_request(f"{base}/world", body=cancel),  # no token
                       _request(f"{base}/world", body=cancel, headers={"X-LVWS-Token": "x" + token[1:]}),
                       _request(f"{base}/world?token=not-{token}", body=cancel),
                       _request(f"{base}/world", body=cancel, headers={"X-LVWS-Token": token,
                                                                        "Origin": "http://elsewhere.example"})]
            assert [status for status, _ in refused] == [403] * 4, refused
            assert not any(answer.get("success") for _, answer in refused)
            assert _request(f"{base}/view")[0] == 403
            assert _websocket_status(f"ws://{host}:{port}/ws") == 403
            assert _tasks(base, token).get("t14") not in (None, "done")  # the world is unchanged: t14 still to run
            status, answer = _request(f"{base}/world", body=cancel, headers={"X-LVWS-Token": token})
            assert status == 200 and answer["success"] is True, answer
            end = time.monotonic() + 60
            while "t14" in _tasks(base, token):
                assert time.monotonic() < end, "t14 was not cancelled"
                time.sleep(0.3)
            assert run.wait(timeout=300) == 0, run_log.read_text()
        assert "13/13 tasks" in run_log.read_text(), run_log.read_text()[-2000:]
    assert dash_log.read_text().count(token) == 1  # in the printed URL only, never logged
