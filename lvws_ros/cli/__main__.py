"""``python -m lvws_ros.cli`` = ``lvws``."""

import sys

from lvws_ros.cli.main import main

if __name__ == "__main__":  # a process started by ``spawn`` (the planner's) imports this module too
    sys.exit(main())
