"""``python -m lvws_ros.cli`` = ``lvws``."""

import sys

from lvws_ros.cli.main import main

sys.exit(main())
