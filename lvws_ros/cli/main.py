"""The user-facing ``lvws`` command: offline scheduling (generate, solve, check, evaluate,
gantt, train), the case study (sim, launch, scheduler) and recorded runs (report,
verify, replay).

Errors: an :class:`~lvws_ros.errors.LvwsError` (bad input: a malformed file, an unknown
name) or an ``OSError`` on a user's path exits 2 with its message; anything else is a
bug and shows as one, with its traceback.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence

from lvws_ros import __version__
from lvws_ros.cli import dispatch, offline, robots, runtime
from lvws_ros.errors import LvwsError


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lvws",
        description="LVWS heterogeneous multi-robot scheduling with subteams and waiting.",
    )
    parser.add_argument("--version", action="version", version=f"lvws_ros {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    def add(name: str, func: Callable[[argparse.Namespace], int] | None, help_text: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(func=func)
        return p

    offline.add_parsers(add)
    runtime.add_parsers(add)
    robots.add_parsers(add)
    dispatch.add_parsers(add)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["scheduler"] and "-h" not in argv and "--help" not in argv:
        from lvws_ros.ros.scheduler_node import main as scheduler_main

        return scheduler_main(argv[1:])  # rclpy parses --ros-args itself
    if argv[:1] == ["dispatcher"] and "-h" not in argv and "--help" not in argv:
        return dispatch.run(argv[1:])
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_usage(sys.stderr)
        print("lvws: error: a COMMAND is needed (lvws --help lists them)", file=sys.stderr)
        return 2
    try:
        return int(args.func(args))
    except (LvwsError, OSError) as exc:
        print(f"lvws {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
