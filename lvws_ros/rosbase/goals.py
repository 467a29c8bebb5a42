"""What the dispatcher and the robots' servers share: the name of each robot's
``ExecuteTask`` server and the topic of the planned starts that moved (relative names: they
resolve under the cell's namespace)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["ACTION_NAME", "PLANNED_STARTS_QOS", "PLANNED_STARTS_TOPIC"]

ACTION_NAME = "execute_task"  # each robot's server: <robot id>/execute_task
PLANNED_STARTS_TOPIC = "lvws/planned_starts"  # lvws_msgs/msg/PlannedStart, from the dispatcher
# volatile: a start moved before a server held its goal is in the goal itself
PLANNED_STARTS_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)
