"""Recorder: ``ros2 run lvws_ros recorder [-o BAG]``, every topic of a run to an MCAP bag.

Records lvws/team_state, lvws/task_graph, lvws/assignments, lvws/markers, clock and
diagnostics of its namespace (``-r __ns:=/cellA``: that cell's only) with raw
(serialized) subscriptions, so the CDR bytes go to the bag as they came, under their
fully qualified names; each connection keeps its topic's QoS. Messages are stamped with
the node's clock: sim time with ``-p use_sim_time:=true`` (``lvws launch`` sets it), else
wall time. Custom types come from lvws_msgs' .msg
files. SIGINT or SIGTERM at any moment closes the bag: it stays readable with
everything received until then. Every FLUSH_SECONDS the messages received so far go
to disk as a closed MCAP chunk, so even after SIGKILL at most the last second is lost:
``lvws reindex BAG`` rebuilds such a bag's index and metadata.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.signals import SignalHandlerOptions

from lvws_ros.ros.bag import flush, open_writer, qos_to_bag, typestore
from lvws_ros.ros.entry import node_main
from lvws_ros.ros.topics import CLOCK_TOPIC, TOPICS, message_class

RECORDER_DEPTH = 10000  # history per subscription: bursts wait here instead of being overwritten
FLUSH_SECONDS = 0.5  # a killed recording loses at most this much (lvws reindex opens it again)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="recorder",
        description="Record lvws/*, clock and diagnostics (in the node's namespace) to a rosbag2 bag with MCAP "
                    "storage; stamps in sim time with --ros-args -p use_sim_time:=true.")
    p.add_argument("-o", "--output", default=None, help="bag folder to create (default: bags/run-<time>)")
    return p


def recording_qos(qos: QoSProfile) -> QoSProfile:
    """The topic's reliability and durability with a deep history (the bag keeps the
    topic's own QoS)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=RECORDER_DEPTH, reliability=qos.reliability,
                      durability=qos.durability)


class Recorder(Node):
    def __init__(self, output: Path) -> None:
        super().__init__("recorder")
        self.output = output
        self.writer = open_writer(output)
        self.count = 0
        self.closed = False
        store = typestore()
        # the clock first: a state and its clock arriving together are written clock first
        for topic, (type_name, qos) in sorted(TOPICS.items(), key=lambda item: item[0] != CLOCK_TOPIC):
            conn = self.writer.add_connection(self.resolve_topic_name(topic), type_name, typestore=store,
                                              offered_qos_profiles=[qos_to_bag(qos)])
            self.create_subscription(message_class(type_name), topic, self._writer_for(conn), recording_qos(qos),
                                     raw=True)
        # on the steady clock: a paused simulator must not stop the flushing
        self.create_timer(FLUSH_SECONDS, lambda: flush(self.writer), clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _writer_for(self, conn: object) -> Callable[[bytes], None]:
        def write(data: bytes) -> None:
            if not self.closed:
                self.writer.write(conn, self.get_clock().now().nanoseconds, data)  # type: ignore[arg-type]
                self.count += 1
        return write

    def destroy_node(self) -> None:
        """Close the bag first: it is complete and readable whatever stopped us."""
        if not self.closed:
            self.closed = True
            self.writer.close()
            print(f"recorded {self.count} messages to {self.output}", flush=True)
        super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    def make(args: argparse.Namespace) -> Recorder:
        output = Path(args.output) if args.output else Path("bags") / time.strftime("run-%Y%m%d-%H%M%S")
        node = Recorder(output)
        print(f"recording to {output}", flush=True)
        return node

    return node_main("recorder", argv, build_parser(), make, signal_handler_options=SignalHandlerOptions.ALL)


if __name__ == "__main__":
    sys.exit(main())
