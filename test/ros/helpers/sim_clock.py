"""A separate process publishing a simulated ``/clock``: it starts at ``--start`` seconds
and runs ``--rate`` times faster than wall time, 100 messages a wall second."""

from __future__ import annotations

import argparse
import time

import rclpy
from builtin_interfaces.msg import Time
from rosgraph_msgs.msg import Clock


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--start", type=float, default=100.0)
    parser.add_argument("--rate", type=float, default=4.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("lvws_test_sim_clock")
    pub = node.create_publisher(Clock, "/clock", 10)
    t0 = time.monotonic()
    try:
        while rclpy.ok():
            now = args.start + (time.monotonic() - t0) * args.rate
            pub.publish(Clock(clock=Time(sec=int(now), nanosec=int(now % 1 * 1e9))))
            time.sleep(0.01)
    except KeyboardInterrupt:
        pass
    finally:
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
