"""A fixed arm driven by ros2_control: a :class:`~lvws_ros.robot.server.TaskServer` that
runs one ``control_msgs/action/FollowJointTrajectory`` per task.

    python examples/robots/arm_robot.py arm examples/robots/arm_tasks.yaml \\
        --controller /arm/joint_trajectory_controller/follow_joint_trajectory \\
        --ros-args -r __ns:=/cellA

serves ``/cellA/arm/execute_task``. The arm is fixed at its site: it rejects a goal at
another site or one that would carry it away (``site_to`` elsewhere), with the reason
logged (:meth:`ArmRobot.refuse`). For an accepted goal it sends the trajectory the tasks
file gives for the task (or its ``default``), reports ``working`` with the share of the
trajectory's time done, and ends when the controller does. A cancel cancels the
controller's goal; a trajectory the controller rejects or fails to follow (its
``error_code`` and ``error_string``) aborts the task.

Needs ``control_msgs``, which comes with a ROS 2 install of ros2_control
(``ros-jazzy-control-msgs``) and is not among the pip wheels this repository's environment
uses: it is imported when an arm is made, not when this module is.
``trajectory_msgs`` is in the wheels. The tasks file (YAML)::

    site: c                        # where the arm stands
    joints: [shoulder, elbow, wrist]
    tasks:                         # task id (or default) -> points: [positions..., seconds]
      weld: [[0.0, 0.5, 0.2, 2.0], [0.3, 0.9, 0.1, 5.0], [0.0, 0.0, 0.0, 8.0]]
      default: [[0.0, 0.4, 0.0, 2.0], [0.0, 0.0, 0.0, 4.0]]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import rclpy
import yaml
from builtin_interfaces.msg import Duration
from lvws_msgs.action import ExecuteTask
from rclpy.action import ActionClient
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.utilities import remove_ros_args
from trajectory_msgs.msg import JointTrajectory, JointTrajectoryPoint

from lvws_ros.errors import ConfigError
from lvws_ros.robot.server import TaskFailed, TaskFeedback, TaskServer, serve

WORKING = ExecuteTask.Feedback.PHASE_WORKING


def load_tasks(path: str | Path) -> tuple[str, list[str], dict[str, JointTrajectory]]:
    """The arm's site, joint names and a trajectory per task id; ConfigError names the
    file and the task."""
    try:
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f"{path}: cannot read the arm's tasks: {exc}") from None
    joints = [str(j) for j in data.get("joints") or []]
    if not joints:
        raise ConfigError(f"{path}: joints: name the arm's joints")
    trajectories = {}
    for task, points in (data.get("tasks") or {}).items():
        traj = JointTrajectory(joint_names=joints)
        for k, row in enumerate(points or []):
            if not (isinstance(row, list) and len(row) == len(joints) + 1):
                raise ConfigError(f"{path}: tasks.{task}[{k}]: expected {len(joints)} positions and seconds")
            sec = float(row[-1])
            traj.points.append(JointTrajectoryPoint(
                positions=[float(v) for v in row[:-1]],
                time_from_start=Duration(sec=int(sec), nanosec=int((sec % 1) * 1e9))))
        trajectories[str(task)] = traj
    return str(data.get("site", "")), joints, trajectories


class ArmRobot(TaskServer):
    def __init__(self, robot_id: str, tasks_file: str,
                 controller: str = "/joint_trajectory_controller/follow_joint_trajectory", **kwargs: Any):
        try:
            from control_msgs.action import FollowJointTrajectory
        except ImportError:
            raise ConfigError("control_msgs is not installed: ArmRobot needs a ROS 2 install with ros2_control "
                              "(ros-jazzy-control-msgs)") from None
        super().__init__(robot_id, **kwargs)
        self.site, self.joints, self.trajectories = load_tasks(tasks_file)
        self._controller_name = controller
        self._controller = ActionClient(self, FollowJointTrajectory, controller,
                                        callback_group=ReentrantCallbackGroup())
        self._goal_type = FollowJointTrajectory.Goal

    def refuse(self, goal: Any) -> str | None:
        for site in (goal.site, goal.site_to):
            if site and self.site and site != self.site:
                return f"the arm is fixed at {self.site!r}: it cannot work at {site!r}"
        if goal.task_id not in self.trajectories and "default" not in self.trajectories:
            return f"no trajectory for task {goal.task_id!r} (and no default)"
        return None

    def execute(self, goal: Any, feedback: TaskFeedback) -> Any:
        traj = self.trajectories.get(goal.task_id) or self.trajectories["default"]  # refuse() saw one
        total = max((p.time_from_start.sec + p.time_from_start.nanosec / 1e9 for p in traj.points), default=0.0)
        if not self._controller.wait_for_server(timeout_sec=5.0):
            raise TaskFailed(f"{self.robot_id}: the controller's {self._controller_name} is not there")
        feedback.send(WORKING, 0.0, site=self.site)

        def forward(msg: Any) -> None:
            t = msg.feedback.desired.time_from_start
            done = (t.sec + t.nanosec / 1e9) / total if total > 0 else 1.0
            feedback.send(WORKING, done, site=self.site)

        sent = self._controller.send_goal_async(self._goal_type(trajectory=traj), feedback_callback=forward)
        handle = self._wait(sent, feedback, None)
        if not handle.accepted:
            raise TaskFailed(f"{self.robot_id}: the controller rejected the trajectory of {goal.task_id!r}")
        answer = self._wait(handle.get_result_async(), feedback, handle)
        if answer.status != 4 or answer.result.error_code != 0:  # STATUS_SUCCEEDED, FollowJointTrajectory SUCCESSFUL
            raise TaskFailed(f"{self.robot_id}: trajectory of {goal.task_id!r} failed (status {answer.status}, "
                             f"error {answer.result.error_code}: {answer.result.error_string})")
        feedback.send(WORKING, 1.0, site=self.site)
        return f"{self.robot_id} did {goal.task_id!r}"

    def _wait(self, future: Any, feedback: TaskFeedback, handle: Any) -> Any:
        """The future's result; on a cancel, cancel the controller's goal and stop."""
        while not future.done():
            if feedback.cancelled and handle is not None:
                handle.cancel_goal_async()
            feedback.check()
            time.sleep(0.05)
        return future.result()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(description="an arm's ExecuteTask server over FollowJointTrajectory")
    parser.add_argument("robot_id")
    parser.add_argument("tasks", help="YAML: site, joints, and tasks: id -> [[positions..., seconds], ...]")
    parser.add_argument("--controller", default="/joint_trajectory_controller/follow_joint_trajectory",
                        help="the FollowJointTrajectory action of the arm's controller")
    args = parser.parse_args(remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    try:
        robot = ArmRobot(args.robot_id, args.tasks, args.controller)
    except ConfigError as exc:
        print(f"arm_robot: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    return serve([robot])


if __name__ == "__main__":
    sys.exit(main())
