"""``lvws replay BAG [--rate X]``: republish a bag's messages on their topics with the
recorded timing and QoS, like ``ros2 bag play``. Messages go out as the recorded CDR
bytes (rclpy publishes serialized data), so nothing is re-encoded.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.utilities import remove_ros_args
from rosbags.rosbag2 import Reader

from lvws_ros.errors import BagError, LvwsError
from lvws_ros.ros.bag import qos_from_bag
from lvws_ros.ros.topics import message_class

# Replay publishes faster than the recording at --rate > 1; a deeper history than the
# recorded one keeps reliable subscribers from losing messages to overwrites.
REPLAY_MIN_DEPTH = 1000


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lvws replay", description=__doc__)
    p.add_argument("bag", help="rosbag2 folder (metadata.yaml + .mcap)")
    p.add_argument("--rate", type=float, default=1.0, help="speed-up of the recorded timing (default 1)")
    p.add_argument("--wait-for-subscribers", type=float, default=2.0,
                   help="wall seconds to let subscribers discover the publishers first")
    p.add_argument("--topics", nargs="*", default=None, help="only these topics")
    return p


def replay(bag: str | Path, rate: float = 1.0, wait: float = 2.0, topics: list[str] | None = None,
           log: Any = print) -> dict[str, int]:
    """Publish every message of ``bag``; returns the count per topic."""
    if rate <= 0:
        raise LvwsError(f"--rate must be > 0, got {rate}")
    path = Path(bag)
    if not path.exists():
        raise BagError(f"{path}: no such bag")
    rclpy.init(args=["replay"])
    node = rclpy.create_node("lvws_replay")
    sent: dict[str, int] = {}
    try:
        with Reader(path) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            pubs = {c.id: node.create_publisher(message_class(c.msgtype), c.topic, qos_from_bag(c, REPLAY_MIN_DEPTH))
                    for c in conns}
            end = time.monotonic() + wait
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
            t_bag0: int | None = None
            t_wall0 = time.monotonic()
            for conn, t_ns, raw in reader.messages(connections=conns):
                if t_bag0 is None:
                    t_bag0 = t_ns
                delay = (t_ns - t_bag0) / 1e9 / rate - (time.monotonic() - t_wall0)
                if delay > 0:
                    time.sleep(delay)
                pubs[conn.id].publish(bytes(raw))
                sent[conn.topic] = sent.get(conn.topic, 0) + 1
            end = time.monotonic() + 0.5  # let reliable messages drain
            while time.monotonic() < end:
                rclpy.spin_once(node, timeout_sec=0.05)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    log(f"replayed {sum(sent.values())} messages: " + ", ".join(f"{k} {v}" for k, v in sorted(sent.items())))
    return sent


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(remove_ros_args(sys.argv[1:] if argv is None else argv))
    replay(args.bag, args.rate, args.wait_for_subscribers, args.topics)
    return 0


if __name__ == "__main__":
    sys.exit(main())
