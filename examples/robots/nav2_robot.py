"""A mobile robot driven by Nav2: a :class:`~lvws_ros.robot.server.TaskServer` that sends
the travel of each task to Nav2's ``navigate_to_pose`` action.

    python examples/robots/nav2_robot.py husky_1 examples/robots/sites.yaml \\
        --nav2-action /husky_1/navigate_to_pose --ros-args -r __ns:=/cellA

serves ``/cellA/husky_1/execute_task``. For each goal the robot

1. drives to ``goal.site`` (its pose from the sites file) through Nav2, reporting
   ``travelling`` with the pose Nav2 reports and the progress over the distance left;
2. works: a transport (``site_to`` differs from ``site``) is the drive to ``site_to``,
   reported as ``working``; any other task is ``planned_duration`` seconds at the site
   (replace :meth:`Nav2Robot.work` with what the robot really does there);
3. ends at ``site_to`` (or ``site``).

A cancel cancels the Nav2 goal too; a Nav2 goal that is rejected or fails aborts the task
with Nav2's status in the message (the dispatcher then fails the task for the subteam and
the scheduler plans it again).

Needs ``nav2_msgs``, which comes with a ROS 2 install of Nav2 (``ros-jazzy-nav2-msgs``)
and is not among the pip wheels this repository's environment uses: it is imported when a
robot is made, not when this module is, so the module loads (and its docs build) without
it. The sites file (YAML)::

    frame: map
    sites:            # name: [x, y, yaw in radians], in the frame
      dock: [0.0, 0.0, 0.0]
      b: [3.0, 4.0, 1.57]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
import yaml
from geometry_msgs.msg import PoseStamped
from lvws_msgs.action import ExecuteTask
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.utilities import remove_ros_args

from lvws_ros.errors import ConfigError
from lvws_ros.robot.server import TaskFailed, TaskFeedback, TaskServer, serve

TRAVELLING = ExecuteTask.Feedback.PHASE_TRAVELLING
WORKING = ExecuteTask.Feedback.PHASE_WORKING


def load_sites(path: str | Path) -> tuple[str, dict[str, tuple[float, float, float]]]:
    """The frame and the site -> (x, y, yaw) table of a sites file; ConfigError names the
    file and the site."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path}: cannot read the sites: {exc}") from None
    sites = {}
    for name, xyt in (data.get("sites") or {}).items():
        if not (isinstance(xyt, list) and len(xyt) in (2, 3) and all(isinstance(v, (int, float)) for v in xyt)):
            raise ConfigError(f"{path}: sites.{name}: expected [x, y] or [x, y, yaw], got {xyt!r}")
        x, y, *yaw = (float(v) for v in xyt)
        sites[str(name)] = (x, y, yaw[0] if yaw else 0.0)
    return str(data.get("frame", "map")), sites


class Nav2Robot(TaskServer):
    def __init__(self, robot_id: str, sites_file: str, nav2_action: str = "/navigate_to_pose", **kwargs: Any):
        try:
            from nav2_msgs.action import NavigateToPose
        except ImportError:
            raise ConfigError("nav2_msgs is not installed: Nav2Robot needs a ROS 2 install with Nav2 "
                              "(ros-jazzy-nav2-msgs)") from None
        super().__init__(robot_id, **kwargs)
        self.frame, self.sites = load_sites(sites_file)
        self.site = ""  # unknown until the first drive; Nav2 knows the pose
        self._nav_name = nav2_action
        self._nav = ActionClient(self, NavigateToPose, nav2_action, callback_group=ReentrantCallbackGroup())
        self._goal_type = NavigateToPose.Goal

    def refuse(self, goal: Any) -> str | None:
        for site in (goal.site, goal.site_to):
            if site and site not in self.sites:
                return f"site {site!r} is not in the sites file"
        return None

    def execute(self, goal: Any, feedback: TaskFeedback) -> Any:
        if goal.site and goal.site != self.site:
            self.drive(goal.site, feedback, TRAVELLING, (0.0, 0.5))
        if goal.site_to and goal.site_to != goal.site:
            self.drive(goal.site_to, feedback, WORKING, (0.5, 1.0))  # a transport: the carry is the work
        else:
            self.work(goal, feedback)
        return f"{self.robot_id} did {goal.task_id!r}"

    def work(self, goal: Any, feedback: TaskFeedback) -> None:
        """The robot's work at the site: here, ``planned_duration`` seconds of waiting."""
        start = self.now()
        while (done := (self.now() - start) / goal.planned_duration if goal.planned_duration > 0 else 1.0) < 1.0:
            feedback.send(WORKING, 0.5 + 0.5 * done, site=self.site)
            feedback.sleep(0.1)
        feedback.send(WORKING, 1.0, site=self.site)

    def drive(self, site: str, feedback: TaskFeedback, phase: str, progress: tuple[float, float]) -> None:
        """Drive to ``site`` through Nav2, forwarding its feedback; cancel it on a cancel."""
        if not self._nav.wait_for_server(timeout_sec=5.0):
            raise TaskFailed(f"{self.robot_id}: Nav2's {self._nav_name} is not there")
        target = PoseStamped()
        target.header.frame_id = self.frame
        target.header.stamp = self.get_clock().now().to_msg()
        x, y, yaw = self.sites[site]
        target.pose.position.x, target.pose.position.y = x, y
        target.pose.orientation.z, target.pose.orientation.w = math.sin(yaw / 2), math.cos(yaw / 2)
        first: list[float] = []

        def forward(msg: Any) -> None:
            nav = msg.feedback
            first.append(first[0] if first else max(nav.distance_remaining, 1e-6))
            share = 1.0 - min(nav.distance_remaining / first[0], 1.0)
            p, q = nav.current_pose.pose.position, nav.current_pose.pose.orientation
            theta = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
            site_now = "" if phase == TRAVELLING else self.site
            feedback.send(phase, progress[0] + (progress[1] - progress[0]) * share, site=site_now, pose=(p.x, p.y, theta))

        sent = self._nav.send_goal_async(self._goal_type(pose=target), feedback_callback=forward)
        handle = self._wait(sent, feedback, None)
        if not handle.accepted:
            raise TaskFailed(f"{self.robot_id}: Nav2 rejected the drive to {site!r}")
        result = self._wait(handle.get_result_async(), feedback, handle)
        if result.status != 4:  # action_msgs/GoalStatus.STATUS_SUCCEEDED
            raise TaskFailed(f"{self.robot_id}: Nav2 did not reach {site!r} (goal status {result.status})")
        self.site = site

    def _wait(self, future: Any, feedback: TaskFeedback, handle: Any) -> Any:
        """The future's result; on a cancel, cancel the Nav2 goal (``handle``) and stop."""
        while not future.done():
            if feedback.cancelled and handle is not None:
                handle.cancel_goal_async()
            feedback.check()
            time.sleep(0.05)
        return future.result()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(description="a mobile robot's ExecuteTask server over Nav2")
    parser.add_argument("robot_id")
    parser.add_argument("sites", help="YAML: frame, and sites: name -> [x, y, yaw]")
    parser.add_argument("--nav2-action", default="/navigate_to_pose", help="Nav2's NavigateToPose action")
    args = parser.parse_args(remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    try:
        robot = Nav2Robot(args.robot_id, args.sites, args.nav2_action)
    except ConfigError as exc:
        print(f"nav2_robot: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    return serve([robot])


if __name__ == "__main__":
    sys.exit(main())
