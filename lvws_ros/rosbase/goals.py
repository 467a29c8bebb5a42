"""What the dispatcher and the robots' servers share: the name of each robot's
``ExecuteTask`` server and the topic of the planned starts that moved (relative names: they
resolve under the cell's namespace)."""

from __future__ import annotations

from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

__all__ = ["ACTION_NAME", "PLANNED_STARTS_QOS", "PLANNED_STARTS_TOPIC"]

ACTION_NAME = "execute_task"  # each robot's server: <robot id>/execute_task
PLANNED_STARTS_TOPIC = "lvws/planned_starts"  # lvws_msgs/msg/PlannedStart, from the dispatcher
# latched (the last ones): a server that starts late still learns the start of the goal it gets
PLANNED_STARTS_QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.TRANSIENT_LOCAL)
