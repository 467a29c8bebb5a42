"""``lvws fake-robots``: the robots of a cell file as ExecuteTask action servers, for the
dispatcher to drive (:mod:`lvws_ros.robot.fake`)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from lvws_ros.robot.options import add_arguments


def cmd_fake_robots(args: argparse.Namespace) -> int:
    from lvws_ros.robot.fake import run

    return run(args)


def add_parsers(add: Callable[..., argparse.ArgumentParser]) -> None:
    p = add("fake-robots", cmd_fake_robots,
            "fake robots of a cell file: one <robot id>/execute_task action server per robot, "
            "travelling and working as the file says (docs/robots.md)")
    add_arguments(p)
