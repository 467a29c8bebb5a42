"""Recorder: ``ros2 run lvws_ros recorder``, every /lvws/* topic to an MCAP rosbag2 bag.

Built by the ROS runtime issue; this entry point exists so that the executable resolves
as ros2run expects.
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        prog="recorder",
        description="Record /lvws/*, /clock and /diagnostics to a rosbag2 bag with MCAP storage.",
    )
    parser.parse_args(argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv)
    sys.stderr.write("recorder: not implemented yet (ROS runtime issue)\n")
    return 2


if __name__ == "__main__":
    sys.exit(main())
