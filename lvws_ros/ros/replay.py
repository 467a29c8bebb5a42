"""``lvws replay BAG [--rate X]``: republish a bag's messages on their topics with the
recorded timing and QoS, like ``ros2 bag play``. Messages go out as the recorded CDR
bytes (rclpy publishes serialized data), so nothing is re-encoded, except a TeamState or
TaskGraph recorded with an older definition of lvws_msgs (before the travel fields): it
is read with the bag's own definition and converted to the current one (ros.convert),
the new fields empty, as current nodes expect.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
from rclpy.duration import Duration
from rclpy.utilities import remove_ros_args
from rosbags.highlevel import AnyReader

from lvws_ros.errors import BagError, LvwsError
from lvws_ros.ros.bag import LVWS_TYPES, qos_from_bag, typestore
from lvws_ros.ros.convert import (
    decision_from_msg,
    decision_to_msg,
    from_time,
    graph_from_msg,
    graph_to_msg,
    team_from_msg,
    team_to_msg,
    to_time,
)
from lvws_ros.ros.topics import message_class

# Replay publishes faster than the recording at --rate > 1; a deeper history than the
# recorded one keeps reliable subscribers from losing messages to overwrites.
REPLAY_MIN_DEPTH = 1000
DRAIN_SECONDS = 5.0  # at the end, how long a publisher waits for its reliable subscribers' acknowledgements


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lvws replay", description=__doc__)
    p.add_argument("bag", help="rosbag2 folder (metadata.yaml + .mcap)")
    p.add_argument("--rate", type=float, default=1.0, help="speed-up of the recorded timing (default 1)")
    p.add_argument("--wait-for-subscribers", type=float, default=2.0,
                   help="wall seconds at most to let subscribers discover the publishers first (over as soon "
                        "as every topic has one)")
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
        with AnyReader([path], default_typestore=typestore()) as reader:
            conns = [c for c in reader.connections if topics is None or c.topic in topics]
            convert = _converters(reader, conns, path)
            pubs = {c.id: node.create_publisher(message_class(c.msgtype), c.topic, qos_from_bag(c, REPLAY_MIN_DEPTH))
                    for c in conns}
            end = time.monotonic() + wait  # until every topic has a subscriber, or the wait is over
            while time.monotonic() < end and not all(p.get_subscription_count() for p in pubs.values()):
                rclpy.spin_once(node, timeout_sec=0.05)
            t_bag0: int | None = None
            t_wall0 = time.monotonic()
            for conn, t_ns, raw in reader.messages(connections=conns):
                if t_bag0 is None:
                    t_bag0 = t_ns
                delay = (t_ns - t_bag0) / 1e9 / rate - (time.monotonic() - t_wall0)
                if delay > 0:
                    time.sleep(delay)
                if conn.msgtype in convert:
                    pubs[conn.id].publish(convert[conn.msgtype](reader.deserialize(raw, conn.msgtype)))
                else:
                    pubs[conn.id].publish(bytes(raw))
                sent[conn.topic] = sent.get(conn.topic, 0) + 1
            for pub in pubs.values():  # a reliable message is delivered before the publisher goes
                pub.wait_for_all_acked(Duration(seconds=DRAIN_SECONDS))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    log(f"replayed {sum(sent.values())} messages: " + ", ".join(f"{k} {v}" for k, v in sorted(sent.items())))
    return sent


_CONVERT = {
    "lvws_msgs/msg/TeamState": lambda m: team_to_msg(team_from_msg(m), m.header.frame_id),
    "lvws_msgs/msg/TaskGraph": lambda m: graph_to_msg(graph_from_msg(m), m.header.frame_id),
    "lvws_msgs/msg/AssignmentArray": lambda m: _decision(m),
}


def _decision(m: Any) -> Any:
    msg = decision_to_msg(decision_from_msg(m), to_time(from_time(m.header.stamp)))
    msg.header.frame_id = m.header.frame_id
    return msg


def _converters(reader: AnyReader, conns: list[Any], path: Path) -> dict[str, Any]:
    """msgtype -> conversion, for the lvws_msgs topics recorded with a definition other
    than the current one (BagError when such a type has no conversion)."""
    if not any(c.msgtype.startswith("lvws_msgs/") for c in conns):
        return {}
    current = typestore().fielddefs
    changed = {f"lvws_msgs/msg/{n}" for n in LVWS_TYPES
               if f"lvws_msgs/msg/{n}" in reader.typestore.fielddefs
               and reader.typestore.fielddefs[f"lvws_msgs/msg/{n}"] != current[f"lvws_msgs/msg/{n}"]}
    if not changed:
        return {}
    out = {}
    for c in conns:
        if c.msgtype in _CONVERT:
            out[c.msgtype] = _CONVERT[c.msgtype]
        elif c.msgtype.startswith("lvws_msgs/") and c.msgtype in changed:
            raise BagError(f"{path}: {c.topic} ({c.msgtype}) was recorded with another definition of the type; "
                           "it cannot be replayed to current nodes")
    return out


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(remove_ros_args(sys.argv[1:] if argv is None else argv))
    replay(args.bag, args.rate, args.wait_for_subscribers, args.topics)
    return 0


if __name__ == "__main__":
    sys.exit(main())
