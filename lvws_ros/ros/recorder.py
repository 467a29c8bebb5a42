"""Recorder: ``ros2 run lvws_ros recorder [-o BAG]``, every topic of a run to an MCAP bag.

Records lvws/team_state, lvws/task_graph, lvws/assignments, lvws/markers, clock and
diagnostics of its namespace (``-r __ns:=/cellA``: that cell's only) with raw
(serialized) subscriptions, so the CDR bytes go to the bag as they came, under their
fully qualified names; each connection keeps its topic's QoS. Messages are stamped with
the node's clock: wall time, or sim time with ``-p use_sim_time:=true`` (``lvws launch``
sets it). On sim time the bag is its own clock: a clock message is stamped with the time
it carries, any other message with the newest clock recorded before it, and every clock
message that has arrived is recorded before the next other message (the executor takes
one message per subscription per turn, so under load the clock queue would otherwise lag
the states behind it). Custom types come from lvws_msgs' .msg
files. SIGINT or SIGTERM at any moment closes the bag: it stays readable with
everything received until then. The signals are Python's, looked at between two turns of
the executor (with rclpy's own, which shut the context down from the signal handler while
the executor may be at work, a recorder under load once died of SIGSEGV as it stopped,
before it closed the bag). Every FLUSH_SECONDS the messages received so far go to disk as
a closed MCAP chunk, so even after SIGKILL at most the last second is lost: ``lvws
reindex BAG`` rebuilds such a bag's index and metadata.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile
from rclpy.serialization import deserialize_message
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription

from lvws_ros.ros.bag import flush, open_writer, qos_to_bag, typestore
from lvws_ros.ros.entry import node_main, spin
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
        self.sim_time = bool(self.get_parameter("use_sim_time").value)
        self.clock_ns = 0  # on sim time: the newest clock recorded
        self.clock_sub: Subscription | None = None
        self._held: tuple[bytes, dict[str, Any]] | None = None  # a clock taken early that came after
        self._clock_conn: object = None
        self._clock_type = message_class(TOPICS[CLOCK_TOPIC][0])
        store = typestore()
        for topic, (type_name, qos) in sorted(TOPICS.items(), key=lambda item: item[0] != CLOCK_TOPIC):
            conn = self.writer.add_connection(self.resolve_topic_name(topic), type_name, typestore=store,
                                              offered_qos_profiles=[qos_to_bag(qos)])
            is_clock = topic == CLOCK_TOPIC
            # a two-argument callback gets the message info too (rclpy; its annotation names one)
            sub = self.create_subscription(message_class(type_name), topic,
                                           self._on_clock if is_clock  # type: ignore[arg-type]
                                           else self._writer_for(conn), recording_qos(qos), raw=True)
            if is_clock:
                self.clock_sub, self._clock_conn = sub, conn
        # on the steady clock: a paused simulator must not stop the flushing
        self.create_timer(FLUSH_SECONDS, lambda: flush(self.writer), clock=Clock(clock_type=ClockType.STEADY_TIME))

    def _on_clock(self, data: bytes, info: dict[str, Any]) -> None:
        """The executor's turn for the clock: a clock held back (it came earlier) first."""
        if self._held is not None:
            self._record_clock(self._held[0])
            self._held = None
        self._record_clock(data)

    def _record_clock(self, data: bytes) -> None:
        t_ns = None
        if self.sim_time:
            stamp = deserialize_message(data, self._clock_type).clock
            t_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
            self.clock_ns = max(self.clock_ns, t_ns)
        self._write(self._clock_conn, data, t_ns)

    def _writer_for(self, conn: object) -> Callable[[bytes, dict[str, Any]], None]:
        def write(data: bytes, info: dict[str, Any]) -> None:
            self._drain_clock(until=int(info.get("received_timestamp", 0)))
            self._write(conn, data)
        return write

    def _drain_clock(self, until: int) -> None:
        """Record the clock messages that arrived no later than ``until`` (the received
        timestamp of the message about to be recorded), so a message is recorded after
        every clock that came before it and before those that came after: the clock
        subscription is taken as rclpy's executor takes it, and the first clock that came
        later is held back for the next turn. A middleware without received timestamps
        (all 0) gets every clock that has arrived first."""
        sub = self.clock_sub
        while sub is not None:
            if self._held is None:
                with sub.handle:
                    self._held = sub.handle.take_message(sub.msg_type, sub.raw)
                if self._held is None:
                    return
            data, info = self._held
            if int(info.get("received_timestamp", 0)) > until:
                return
            self._held = None
            self._record_clock(data)

    def _write(self, conn: object, data: bytes, t_ns: int | None = None) -> None:
        if not self.closed:
            if t_ns is None:
                t_ns = self.clock_ns if self.sim_time else self.get_clock().now().nanoseconds
            self.writer.write(conn, t_ns, data)  # type: ignore[arg-type]
            self.count += 1

    def destroy_node(self) -> None:
        """Close the bag first: it is complete and readable whatever stopped us."""
        if not self.closed:
            self.closed = True
            self.writer.close()
            print(f"recorded {self.count} messages to {self.output}", flush=True)
        super().destroy_node()


def record(node: Recorder) -> int:
    """Spin until SIGINT or SIGTERM, then close the bag (module docstring)."""
    signals: list[int] = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda signum, _frame: signals.append(signum))
    return spin(node, until=lambda: bool(signals))  # node_main then destroys the node: the bag closes first


def main(argv: list[str] | None = None) -> int:
    def make(args: argparse.Namespace) -> Recorder:
        output = Path(args.output) if args.output else Path("bags") / time.strftime("run-%Y%m%d-%H%M%S")
        node = Recorder(output)
        print(f"recording to {output}", flush=True)
        return node

    return node_main("recorder", argv, build_parser(), make, record, signal_handler_options=SignalHandlerOptions.NO)


if __name__ == "__main__":
    sys.exit(main())
