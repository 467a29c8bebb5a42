"""The ``main`` of every node: arguments (rclpy's split off with
``rclpy.utilities.remove_ros_args``), ``rclpy.init``, the node, spinning, shutdown.

Bad parameters or files (an :class:`~lvws_ros.errors.LvwsError` while the node is
made) exit 2 with the message; Ctrl-C or an external shutdown ends the spin quietly.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from typing import Any, TypeVar

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.utilities import remove_ros_args

from lvws_ros.errors import LvwsError
from lvws_ros.rosbase.spin import RCLError, spin_once

__all__ = ["node_main", "spin", "spin_once"]

N = TypeVar("N", bound=Node)
SHUTDOWN_CHECK = 0.5  # wall seconds between two looks at shutdown while nothing happens


def spin(node: Node, until: Callable[[], bool] = lambda: False) -> int:
    """Spin until shutdown, or until ``until()`` holds (looked at every turn)."""
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    while node.context.ok() and not until():
        spin_once(node, SHUTDOWN_CHECK, executor)
    return 0


def node_main(prog: str, argv: list[str] | None, parser: argparse.ArgumentParser,
              make_node: Callable[[argparse.Namespace], N], run: Callable[[N], int] = spin,
              interrupted: int = 0, **init_options: Any) -> int:
    """Parse, init, make the node, ``run`` it (default: spin until shutdown); its exit code."""
    argv = sys.argv[1:] if argv is None else argv
    args = parser.parse_args(remove_ros_args(argv))
    rclpy.init(args=[prog, *argv], **init_options)
    try:
        node = make_node(args)
    except LvwsError as exc:
        sys.stderr.write(f"{prog}: {exc}\n")
        rclpy.try_shutdown()
        return 2
    try:
        return run(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        return interrupted
    except RCLError:
        if rclpy.ok():
            raise
        # a signal shut the context down while the executor was making its wait set (an
        # rclpy race under load): the same as ExternalShutdownException
        return interrupted
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
