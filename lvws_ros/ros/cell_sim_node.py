"""Assembly-cell simulator node: ``ros2 run lvws_ros cell_sim``.

Publishes TeamState, TaskGraph, /clock and markers and executes assignments. The
simulator is built by the ROS runtime issue; this entry point exists so that the
executable resolves as ros2run expects.
"""

from __future__ import annotations

import argparse
import sys


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(
        prog="cell_sim",
        description="pymunk 2D assembly-cell simulator of the LVWS case study (3 cells, 6 robots, 14 tasks).",
    )
    parser.parse_args(argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv)
    sys.stderr.write("cell_sim: the simulator is not implemented yet (ROS runtime issue)\n")
    return 2


if __name__ == "__main__":
    sys.exit(main())
