"""colcon and rosdep as a ROS 2 user meets them: every dependency key of both package.xml
files is a key rosdep resolves (ros/rosdistro's rosdep files and Jazzy's packages,
vendored in test/data), and the colcon steps of docs/install.md build both packages from a clean
copy, install the executables where ``ros2 run`` looks, and ``colcon test`` runs the
pytest suite (a selection of it, to keep CI short)."""

from __future__ import annotations

import gzip
import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from conftest import REPO

KEYS = REPO / "test" / "data" / "rosdistro-jazzy-keys.txt.gz"
OURS = {"lvws_ros", "lvws_msgs"}


def rosdep_keys() -> set[str]:
    with gzip.open(KEYS, "rt") as f:
        return {line.strip() for line in f if line.strip() and not line.startswith("#")}


@pytest.mark.parametrize("manifest", ["package.xml", "msg_defs/package.xml"])
def test_every_dependency_key_is_one_rosdep_resolves(manifest: str):
    root = ET.parse(REPO / manifest).getroot()
    deps = {e.text.strip() for e in root if e.tag.endswith("depend") and e.text}
    assert deps, manifest
    unknown = sorted(deps - rosdep_keys() - OURS)
    assert not unknown, f"{manifest}: not rosdep keys in ros/rosdistro: {unknown}"


def test_the_readme_colcon_steps_build_install_and_test(tmp_path: Path):
    colcon = shutil.which("colcon", path=str(Path(sys.executable).parent))
    assert colcon, "colcon is pinned in requirements-dev.txt"
    src = tmp_path / "src" / "lvws_ros"
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    for name in files:  # a clean copy of what is committed
        if (REPO / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, src / name)
    env = {**os.environ, "CMAKE_PREFIX_PATH": sys.prefix, "AMENT_PREFIX_PATH": sys.prefix}
    build = subprocess.run([colcon, "build", "--paths", "src/lvws_ros", "src/lvws_ros/msg_defs", "--cmake-args",
                            f"-DPython3_EXECUTABLE={sys.executable}", "-DBUILD_TESTING=OFF"],
                           cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)
    assert build.returncode == 0, build.stdout[-3000:] + build.stderr[-3000:]
    lib = tmp_path / "install" / "lvws_ros" / "lib" / "lvws_ros"
    assert {p.name for p in lib.iterdir()} >= {"scheduler", "cell_sim", "recorder", "lvws"}  # ros2 run looks here
    site = "lib/python{}.{}/site-packages".format(*sys.version_info[:2])
    paths = [str(tmp_path / "install" / pkg / site) for pkg in ("lvws_msgs", "lvws_ros")]
    probe = subprocess.run([sys.executable, "-c", "import lvws_msgs.srv, lvws_ros; print(lvws_msgs.__file__); "
                            "print(lvws_ros.__file__)"], env={**env, "PYTHONPATH": os.pathsep.join(paths)},
                           cwd=tmp_path, capture_output=True, text=True, timeout=60)
    assert probe.returncode == 0 and str(tmp_path / "install") in probe.stdout, probe.stderr
    test = subprocess.run([colcon, "test", "--packages-select", "lvws_ros", "--pytest-args", "-q", "-m", "not ros",
                           "-k", "test_problem or test_formats"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=900)
    assert test.returncode == 0, test.stdout[-3000:] + test.stderr[-3000:]
    result = subprocess.run([colcon, "test-result", "--all"], cwd=tmp_path, env=env, capture_output=True, text=True)
    summary = result.stdout.strip().splitlines()[-1]
    assert summary.startswith("Summary: ") and " 0 errors, 0 failures" in summary, result.stdout
    assert int(summary.split()[1]) > 20, summary  # tests ran (the issue found 0)
