"""A recorder killed with SIGKILL loses at most its last second: after ``lvws reindex``
both independent readers open the bag, and every message published more than a second
before the kill is in it; ``lvws report``'s reader works on it too."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from lvws_msgs.msg import RobotState, TeamState

from lvws_ros.cli.main import main as lvws
from lvws_ros.ros.bag import read_run
from lvws_ros.ros.topics import TEAM_QOS

pytestmark = pytest.mark.ros


def _stamps_anyreader(bag: Path) -> list[int]:
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        return [reader.deserialize(raw, c.msgtype).header.stamp.nanosec
                for c, _, raw in reader.messages() if c.topic == "/lvws/team_state"]


def _stamps_mcap(bag: Path) -> list[int]:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    (mcap_file,) = bag.glob("*.mcap")
    with open(mcap_file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        return [m.header.stamp.nanosec for _, ch, _, m in reader.iter_decoded_messages() if ch.topic == "/lvws/team_state"]


@pytest.mark.parametrize("kill_after", [1.5, 4.0])
def test_sigkill_loses_at_most_the_last_second(ros_context, tmp_path, kill_after):
    bag = tmp_path / "killed"
    rec = subprocess.Popen([sys.executable, "-m", "lvws_ros.ros.recorder", "-o", str(bag)], stdout=subprocess.PIPE,
                           text=True)
    assert rec.stdout is not None and "recording to" in rec.stdout.readline()
    node = rclpy.create_node("lvws_kill_test", context=ros_context)
    pub = node.create_publisher(TeamState, "/lvws/team_state", TEAM_QOS)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.5)
    msg = TeamState(capability_names=["a"], robots=[RobotState(id="r0", kind="x", capabilities=[1], payload=1.0)])
    sent: list[tuple[float, int]] = []
    t0 = time.monotonic()
    k = 0
    while time.monotonic() - t0 < kill_after:
        msg.header.stamp.nanosec = k  # the message's number
        pub.publish(msg)
        sent.append((time.monotonic(), k))
        k += 1
        time.sleep(0.02)
    killed_at = time.monotonic()
    rec.send_signal(signal.SIGKILL)
    rec.wait(timeout=30)
    node.destroy_node()
    assert not (bag / "metadata.yaml").exists()  # killed: rosbags never wrote it

    assert lvws(["reindex", str(bag)]) == 0
    assert lvws(["reindex", str(bag)]) == 2  # the original is kept: never overwritten by a second rebuild
    expected = {n for t, n in sent if t < killed_at - 1.0}
    for read in (_stamps_anyreader, _stamps_mcap):
        got = read(bag)
        assert expected <= set(got), (read.__name__, sorted(expected - set(got))[:10], len(got), len(sent))
        assert len(got) == len(set(got))
    assert len(read_run(bag).teams) >= len(expected)  # what lvws report and verify read
