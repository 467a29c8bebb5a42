"""``lvws dispatcher CELL.json``: the world of a cell of real robots
(:mod:`lvws_ros.ros.dispatcher_node`): it publishes the cell's TeamState and TaskGraph for
the scheduler and sends each assignment to the members' ExecuteTask servers. It takes
``--ros-args`` as ``ros2 run lvws_ros dispatcher`` does."""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence


def run(argv: Sequence[str]) -> int:
    """The node itself (rclpy parses ``--ros-args``); a bad cell file exits 2 naming it."""
    from lvws_ros.ros.dispatcher_node import main

    return main(list(argv), prog="lvws dispatcher")


def add_parsers(add: Callable[..., argparse.ArgumentParser]) -> None:
    p = add("dispatcher", None,
            "the world of a cell of real robots: TeamState and TaskGraph for the scheduler, each assignment sent "
            "as ExecuteTask goals to <robot id>/execute_task (docs/ros.md, 'Real robots: the dispatcher')")
    p.add_argument("cell", help="the cell: an lvws-instance/1 file (robots, sites, speeds, tasks or none yet)")
    p.epilog = ("ROS parameters after --ros-args: robot_timeout, rejoin_after, state_period, frame_id, "
                "exit_when_done, summary, use_sim_time; -r __ns:=/cellA for a namespace")
