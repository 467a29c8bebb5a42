"""A robot's ExecuteTask action server written against the interface alone (rclpy and
lvws_msgs; nothing from lvws_ros): what a robot in any language or framework has to do
for the dispatcher.

    python examples/robots/plain_server.py r1 --ros-args -r __ns:=/cellA

serves ``/cellA/r1/execute_task``. The robot "works" by waiting ``planned_duration``
seconds (divided by ``--rate``), with feedback every 0.1 s, and ends at the goal's site.
It rejects a goal whose subteam does not name it and a goal that arrives while it is busy;
it accepts every cancel request and stops at once.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time

import rclpy
from lvws_msgs.action import ExecuteTask
from rclpy._rclpy_pybind11 import RCLError
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

Feedback = ExecuteTask.Feedback


class PlainRobot(Node):
    def __init__(self, robot_id: str, rate: float) -> None:
        super().__init__(f"{robot_id}_plain_server")
        self.robot_id = robot_id
        self.rate = rate
        self.site = ""
        self._busy = threading.Lock()
        # a reentrant group and a multi-threaded executor: cancel requests are served
        # while a goal executes
        self._server = ActionServer(self, ExecuteTask, f"{robot_id}/execute_task", self.execute,
                                    goal_callback=self.on_goal, cancel_callback=self.on_cancel,
                                    callback_group=ReentrantCallbackGroup())

    def on_goal(self, goal: ExecuteTask.Goal) -> GoalResponse:
        if self.robot_id not in goal.subteam:
            self.get_logger().warning(f"rejected {goal.task_id!r}: subteam {list(goal.subteam)} omits me")
            return GoalResponse.REJECT
        if not self._busy.acquire(blocking=False):  # released when the goal ends
            self.get_logger().warning(f"rejected {goal.task_id!r}: busy")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def on_cancel(self, goal_handle: object) -> CancelResponse:
        return CancelResponse.ACCEPT

    def execute(self, goal_handle: ServerGoalHandle) -> ExecuteTask.Result:
        goal = goal_handle.request
        try:
            if goal.site and goal.site != self.site:  # a real robot would drive there
                goal_handle.publish_feedback(Feedback(phase=Feedback.PHASE_TRAVELLING, progress=0.0, site=""))
            start = time.monotonic()
            seconds = goal.planned_duration / self.rate
            while (done := (time.monotonic() - start) / seconds if seconds > 0 else 1.0) < 1.0:
                if goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                    return ExecuteTask.Result(success=False, message="canceled", duration=done * goal.planned_duration)
                goal_handle.publish_feedback(Feedback(phase=Feedback.PHASE_WORKING, progress=done, site=goal.site))
                time.sleep(min(0.1, (1.0 - done) * seconds))
            self.site = goal.site_to or goal.site or self.site
            goal_handle.succeed()
            return ExecuteTask.Result(success=True, message=f"{self.robot_id} did {goal.task_id}",
                                      duration=goal.planned_duration)
        finally:
            self._busy.release()


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv if argv is None else argv
    parser = argparse.ArgumentParser(description="one robot's ExecuteTask server")
    parser.add_argument("robot_id")
    parser.add_argument("--rate", type=float, default=1.0, help="work RATE times faster than planned")
    args = parser.parse_args(remove_ros_args(argv)[1:])
    rclpy.init(args=argv)
    node = PlainRobot(args.robot_id, args.rate)
    executor = MultiThreadedExecutor()
    executor.add_node(node)
    try:
        while rclpy.ok():  # looks at shutdown (Ctrl-C, SIGTERM) at least every 0.5 s
            executor.spin_once(timeout_sec=0.5)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:  # the signal came while the executor made its wait set
        if rclpy.ok():
            raise
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
