"""The environment is an ament prefix in which ros2run would find our executables."""

from __future__ import annotations

import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

from ament_index_python.packages import get_package_prefix, get_package_share_directory

from conftest import REPO

EXECUTABLES = ["scheduler", "cell_sim", "recorder", "lvws", "fake_robots", "dispatcher"]


def test_package_prefix_resolves_like_ros2run():
    prefix = Path(get_package_prefix("lvws_ros"))
    assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "lvws_ros").is_file()
    for exe in EXECUTABLES:
        path = prefix / "lib" / "lvws_ros" / exe
        # ros2run: an executable file in <prefix>/lib/<package>/
        assert path.is_file() and os.access(path, os.X_OK), path
    result = subprocess.run(
        [str(prefix / "lib" / "lvws_ros" / "scheduler"), "--help"],
        capture_output=True, text=True, timeout=60,
    )
    assert result.returncode == 0, result.stderr
    assert "lvws/assignments" in result.stdout


def test_every_executable_answers_help():
    prefix = Path(get_package_prefix("lvws_ros"))
    for exe in EXECUTABLES:
        result = subprocess.run([str(prefix / "lib" / "lvws_ros" / exe), "--help"],
                                capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, (exe, result.stderr)
        assert "usage:" in result.stdout


def test_share_holds_manifest_and_config():
    share = Path(get_package_share_directory("lvws_ros"))
    manifest = ET.parse(share / "package.xml").getroot()
    assert manifest.get("format") == "3"
    assert manifest.findtext("name") == "lvws_ros"
    assert (share / "config" / "scheduler.yaml").is_file()


def test_manifest_declares_ros_dependencies():
    manifest = ET.parse(REPO / "package.xml").getroot()
    deps = {e.text for e in manifest if e.tag in {"depend", "exec_depend"}}
    for needed in ["rclpy", "lvws_msgs", "std_msgs", "geometry_msgs", "visualization_msgs",
                   "rosgraph_msgs", "diagnostic_msgs", "python3-numpy", "python3-yaml", "python3-matplotlib"]:
        assert needed in deps, needed
    # what rosdep cannot install or pin is pinned for pip (docs/install.md, "colcon")
    pinned = {line.split("==")[0] for line in (REPO / "requirements-python.txt").read_text().splitlines()
              if "==" in line and not line.startswith("#")}
    assert {"torch", "ortools", "pymunk", "rosbags", "mcap", "mcap-ros2-support"} <= pinned
    assert manifest.find("export/build_type").text == "ament_python"


def test_interface_package_is_installed():
    share = Path(get_package_share_directory("lvws_msgs"))
    names = {p.name for p in (share / "msg").glob("*.msg")}
    assert {"RobotState.msg", "TeamState.msg", "Task.msg", "TaskGraph.msg",
            "Assignment.msg", "AssignmentArray.msg"} <= names
