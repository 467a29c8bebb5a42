"""Files the package installs under ``share/``: found through the ament index (as
``ros2 run`` finds them), else under this Python's prefix (a pip install without
``AMENT_PREFIX_PATH``), else in the source tree (a checkout)."""

from __future__ import annotations

import sys
from pathlib import Path

from ament_index_python.packages import PackageNotFoundError, get_package_share_directory

__all__ = ["case_study_config", "events_example", "msg_dir", "share_path"]

SOURCE_TREE = Path(__file__).resolve().parents[2]


def share_path(package: str, relative: str, source: str) -> Path:
    """``<share>/<package>/<relative>`` when installed, else ``<source tree>/<source>``."""
    try:
        p = Path(get_package_share_directory(package)) / relative
        if p.exists():
            return p
    except (PackageNotFoundError, LookupError, ValueError, OSError):  # OSError: AMENT_PREFIX_PATH unset
        pass
    p = Path(sys.prefix) / "share" / package / relative
    return p if p.exists() else SOURCE_TREE / source


def case_study_config() -> Path:
    """The paper's assembly-cell case study, ``config/assembly_cell.yaml``."""
    return share_path("lvws_ros", "config/assembly_cell.yaml", "config/assembly_cell.yaml")


def events_example() -> Path:
    """Scripted world events for the case study, ``config/events_example.yaml``."""
    return share_path("lvws_ros", "config/events_example.yaml", "config/events_example.yaml")


def msg_dir() -> Path:
    """lvws_msgs' .msg files."""
    return share_path("lvws_msgs", "msg", "msg_defs/msg")
