"""TeamState and AssignmentArray cross process boundaries over real DDS (Fast DDS).

The echo process and this test share only the isolated domain set in conftest.py.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from geometry_msgs.msg import Pose2D
from lvws_msgs.msg import Assignment, AssignmentArray, RobotState, TeamState
from rclpy.qos import QoSProfile, ReliabilityPolicy

pytestmark = pytest.mark.ros  # crosses processes over real DDS

HELPER = Path(__file__).parent / "helpers" / "echo_node.py"


def test_two_processes_exchange_team_state_and_assignments(ros_context):
    echo = subprocess.Popen([sys.executable, str(HELPER), "--seconds", "60"])
    node = rclpy.create_node("lvws_dds_test", context=ros_context)
    executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        team_pub = node.create_publisher(TeamState, "team_state", qos)
        assign_pub = node.create_publisher(AssignmentArray, "assignments", qos)
        got: dict[str, object] = {}
        node.create_subscription(TeamState, "team_state_echo", lambda m: got.setdefault("team", m), qos)
        node.create_subscription(
            AssignmentArray, "assignments_echo", lambda m: got.setdefault("assign", m), qos
        )
        team = TeamState(
            capability_names=["manipulation", "mobility"],
            robots=[
                RobotState(id="husky_1", kind="husky", available=True, capabilities=[0, 1],
                           payload=6.0, pose=Pose2D(x=1.0, y=2.0, theta=0.5)),
                RobotState(id="panda_1", kind="panda", available=False, capabilities=[1, 0],
                           payload=3.0, current_task="t4", busy_for=2.0),
            ],
        )
        decision = AssignmentArray(
            decision_step=7,
            policy="grp",
            assignments=[Assignment(task_id="t3", robot_ids=["jackal_1", "husky_1"])],
            waiting_robot_ids=["jackal_2"],
        )
        deadline = time.monotonic() + 45.0
        while len(got) < 2 and time.monotonic() < deadline:
            assert echo.poll() is None, "echo process died"
            team_pub.publish(team)
            assign_pub.publish(decision)
            executor.spin_once(timeout_sec=0.2)
        assert set(got) == {"team", "assign"}, f"received only {sorted(got)} across processes"
        assert got["team"] == team
        assert got["assign"] == decision
        assert got["assign"].assignments[0].robot_ids == ["jackal_1", "husky_1"]
    finally:
        executor.shutdown()
        node.destroy_node()
        echo.terminate()
        echo.wait(timeout=10)
