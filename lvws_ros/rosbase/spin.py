"""One turn of an executor, as every node and the robots' servers take it: a service
answer the middleware would not send is logged on the node, not fatal (as in rclcpp).

:data:`RCLError` is rclpy's error of the middleware layer, imported here only (rclpy
keeps it in a private module).
"""

from __future__ import annotations

import rclpy
from rclpy._rclpy_pybind11 import RCLError
from rclpy.executors import Executor
from rclpy.node import Node

from lvws_ros.errors import dropped_answer

__all__ = ["RCLError", "spin_once"]


def spin_once(node: Node, timeout_sec: float, executor: Executor | None = None) -> None:
    """One turn of ``executor`` (default: rclpy's global one, with ``node``); a service
    answer the middleware would not send (:func:`~lvws_ros.errors.dropped_answer`) is
    logged on ``node`` and the node goes on, as rclcpp does."""
    try:
        if executor is None:
            rclpy.spin_once(node, timeout_sec=timeout_sec)
        else:
            executor.spin_once(timeout_sec=timeout_sec)
    except RCLError as exc:
        if not dropped_answer(exc) or not node.context.ok():
            raise
        node.get_logger().warning(f"a service answer was not sent ({exc}); the client may ask again")
