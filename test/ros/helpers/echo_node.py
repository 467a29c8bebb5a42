"""A separate process for the DDS test: echoes TeamState and AssignmentArray back.

Receives on ``team_state``/``assignments`` and republishes each message unchanged on
``team_state_echo``/``assignments_echo``; exits after ``--seconds``.
"""

from __future__ import annotations

import argparse
import time

import rclpy
from lvws_msgs.msg import AssignmentArray, TeamState
from rclpy.qos import QoSProfile, ReliabilityPolicy


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seconds", type=float, default=30.0)
    args = parser.parse_args()
    rclpy.init()
    node = rclpy.create_node("lvws_echo")
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    team_echo = node.create_publisher(TeamState, "team_state_echo", qos)
    assign_echo = node.create_publisher(AssignmentArray, "assignments_echo", qos)
    node.create_subscription(TeamState, "team_state", team_echo.publish, qos)
    node.create_subscription(AssignmentArray, "assignments", assign_echo.publish, qos)
    deadline = time.monotonic() + args.seconds
    while time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.1)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
