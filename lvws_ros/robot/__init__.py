"""The robot's side of the dispatcher's ``ExecuteTask`` action (rclpy, lvws_msgs):
:class:`~lvws_ros.robot.server.TaskServer`, the base class of one robot's
``<robot id>/execute_task`` action server, and :func:`~lvws_ros.robot.server.serve`
(:mod:`lvws_ros.robot.server`); fake robots that travel and work as a cell file says
(:mod:`lvws_ros.robot.fake`, ``lvws fake-robots``).

The names below are imported on first use, so that ``lvws_ros.robot.options`` (the fake
robots' arguments) loads without ROS.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = ["FakeRobot", "TaskCanceled", "TaskFailed", "TaskFeedback", "TaskServer", "serve"]

_HOME = {"FakeRobot": "fake", "TaskCanceled": "server", "TaskFailed": "server", "TaskFeedback": "server",
         "TaskServer": "server", "serve": "server"}


def __getattr__(name: str) -> Any:
    if name in _HOME:
        return getattr(importlib.import_module(f"{__name__}.{_HOME[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
