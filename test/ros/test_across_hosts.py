"""Across hosts: the scheduler and the simulator in two network namespaces of this
machine (two test hosts) joined by a veth pair, DDS discovering over UDP across it (no
shared memory, no loopback), complete the case study. Skipped, with the reason, only
where network namespaces cannot be created."""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros


def ip(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)


@contextmanager
def two_hosts() -> Iterator[tuple[str, str, str]]:
    """(host A, host B, A's veth): two network namespaces on 10.77.x.1/2 over a veth pair."""
    if shutil.which("ip") is None:
        pytest.skip("no `ip` (iproute2) on this machine: cannot make network namespaces")
    tag = f"{os.getpid() % 10000}{random.SystemRandom().randint(0, 99)}"
    a, b, va, vb = f"lvwsA{tag}", f"lvwsB{tag}", f"lva{tag}", f"lvb{tag}"
    made = ip("netns", "add", a)
    if made.returncode != 0:
        pytest.skip(f"cannot create a network namespace here: {made.stderr.strip()}")
    try:
        net = 1 + int(tag) % 250
        steps = [("netns", "add", b), ("link", "add", va, "type", "veth", "peer", "name", vb),
                 ("link", "set", va, "netns", a), ("link", "set", vb, "netns", b),
                 ("-n", a, "addr", "add", f"10.77.{net}.1/24", "dev", va),
                 ("-n", b, "addr", "add", f"10.77.{net}.2/24", "dev", vb),
                 ("-n", a, "link", "set", "lo", "up"), ("-n", b, "link", "set", "lo", "up"),
                 ("-n", a, "link", "set", va, "up"), ("-n", b, "link", "set", vb, "up"),
                 ("-n", a, "route", "add", "224.0.0.0/4", "dev", va),  # DDS discovery multicast
                 ("-n", b, "route", "add", "224.0.0.0/4", "dev", vb)]
        for step in steps:
            done = ip(*step)
            assert done.returncode == 0, f"ip {' '.join(step)}: {done.stderr}"
        yield a, b, va
    finally:
        ip("netns", "del", a)
        ip("netns", "del", b)


def rx_bytes(host: str, dev: str) -> int:
    out = ip("-n", host, "-s", "-j", "link", "show", dev)
    return int(json.loads(out.stdout)[0]["stats64"]["rx"]["bytes"])


def test_scheduler_and_simulator_on_two_hosts_complete_the_case_study(tmp_path: Path):
    env = {**os.environ, "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 101)),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET", "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4",
           "AMENT_PREFIX_PATH": sys.prefix, "PYTHONUNBUFFERED": "1"}
    summary = tmp_path / "summary.json"
    with two_hosts() as (a, b, va):
        sched = subprocess.Popen(["ip", "netns", "exec", a, sys.executable, "-m", "lvws_ros.ros.scheduler_node",
                                  "--ros-args", "-p", "policy:=lvws", "-p", "use_sim_time:=true",
                                  "-p", "expect_subscribers:=1"], env=env, stdout=subprocess.PIPE,
                                 stderr=subprocess.STDOUT, text=True)
        try:
            sim = subprocess.run(["ip", "netns", "exec", b, sys.executable, "-m", "lvws_ros.ros.cell_sim_node",
                                  "--ros-args", "-p", "rate:=20.0", "-p", "expect_subscribers:=1",
                                  "-p", f"summary:={summary}"], env=env, capture_output=True, text=True, timeout=300)
            crossed = rx_bytes(a, va)
        finally:
            sched.send_signal(signal.SIGINT)
            sched_out = sched.communicate(timeout=30)[0]
    assert sim.returncode == 0, sim.stdout[-2000:] + sim.stderr[-2000:] + sched_out[-2000:]
    s = json.loads(summary.read_text())
    assert s["tasks_done"] == 14 and s["rejected"] == [] and s["decisions_received"] >= 9, s
    assert "step 0:" in sched_out  # the decisions came from the scheduler on the other host
    assert crossed > 50_000, crossed  # the run's traffic went over the veth pair
