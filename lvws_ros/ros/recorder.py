"""Recorder: ``ros2 run lvws_ros recorder [-o BAG]``, every topic of a run to an MCAP bag.

Records /lvws/team_state, /lvws/task_graph, /lvws/assignments, /lvws/markers, /clock and
/diagnostics with raw (serialized) subscriptions, so the CDR bytes go to the bag as they
came; each connection keeps its topic's QoS. Custom types come from lvws_msgs' .msg
files. SIGINT or SIGTERM at any moment closes the bag: it stays readable with
everything received until then.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from lvws_ros.ros.common import user_args


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="recorder",
        description="Record /lvws/*, /clock and /diagnostics to a rosbag2 bag with MCAP storage.")
    p.add_argument("-o", "--output", default=None, help="bag folder to create (default: bags/run-<time>)")
    return p


def qos_for_bag(qos: Any) -> Any:
    from rclpy.qos import DurabilityPolicy, ReliabilityPolicy

    from lvws_ros.bag import qos_to_bag

    return qos_to_bag(qos.depth, qos.reliability == ReliabilityPolicy.RELIABLE,
                      qos.durability == DurabilityPolicy.TRANSIENT_LOCAL)


RECORDER_DEPTH = 10000  # history per subscription: bursts wait here instead of being overwritten


def recording_qos(qos: Any) -> Any:
    """The topic's reliability and durability with a deep history (the bag keeps the
    topic's own QoS)."""
    from rclpy.qos import HistoryPolicy, QoSProfile

    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORDER_DEPTH, reliability=qos.reliability,
                      durability=qos.durability)


def make_node(output: Path) -> Any:
    from rclpy.node import Node

    from lvws_ros.bag import open_writer, typestore
    from lvws_ros.ros.common import TOPICS, message_class

    class Recorder(Node):
        def __init__(self) -> None:
            super().__init__("recorder")
            self.store = typestore()
            self.writer = open_writer(output)
            self.count = 0
            self.closed = False
            self.conns = {}
            for topic, (type_name, qos) in TOPICS.items():
                self.conns[topic] = self.writer.add_connection(topic, type_name, typestore=self.store,
                                                               offered_qos_profiles=[qos_for_bag(qos)])
                self.create_subscription(message_class(type_name), topic, self._callback(topic), recording_qos(qos),
                                         raw=True)

        def _callback(self, topic: str) -> Any:
            conn = self.conns[topic]

            def write(data: bytes) -> None:
                if not self.closed:
                    self.writer.write(conn, time.time_ns(), data)
                    self.count += 1
            return write

        def close(self) -> None:
            if not self.closed:
                self.closed = True
                self.writer.close()

    return Recorder()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(user_args(argv))
    output = Path(args.output) if args.output else Path("bags") / time.strftime("run-%Y%m%d-%H%M%S")
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=["recorder", *argv], signal_handler_options=SignalHandlerOptions.ALL)
    try:
        node = make_node(output)
    except Exception as exc:
        sys.stderr.write(f"recorder: {exc}\n")
        rclpy.try_shutdown()
        return 1
    print(f"recording to {output}", flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.close()  # the bag is complete and readable whatever stopped us
        print(f"recorded {node.count} messages to {output}", flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
