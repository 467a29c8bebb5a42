"""The layering of lvws_ros is enforced: import-linter (``make lint``) keeps the
contracts of .importlinter on the real tree, and breaks them on a tree with a core
module importing torch or rclpy, or with an import cycle."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import REPO

LINT_IMPORTS = Path(sys.executable).parent / "lint-imports"


def lint(tree: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run([str(LINT_IMPORTS), "--no-cache", str(REPO / ".importlinter")], cwd=tree, env=env,
                          capture_output=True, text=True, timeout=120)


@pytest.fixture
def tree(tmp_path: Path) -> Path:
    shutil.copytree(REPO / "lvws_ros", tmp_path / "lvws_ros", ignore=shutil.ignore_patterns("*.pt", "__pycache__"))
    return tmp_path


def test_the_tree_keeps_every_contract(tree):
    res = lint(tree)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "BROKEN" not in res.stdout and "KEPT" in res.stdout


@pytest.mark.parametrize("module", ["torch", "rclpy"])
def test_a_core_module_importing_a_heavy_dependency_breaks_the_lint(tree, module):
    path = tree / "lvws_ros" / "core" / "problem.py"
    path.write_text(path.read_text() + f"\nimport {module}  # deliberate violation\n")
    res = lint(tree)
    assert res.returncode != 0
    assert f"lvws_ros.core is not allowed to import {module}" in res.stdout, res.stdout


def test_an_upward_import_and_a_cycle_break_the_lint(tree):
    # subteams is imported by executor; executor back from subteams is a cycle, and
    # core importing the registry goes up the layers
    path = tree / "lvws_ros" / "core" / "subteams.py"
    path.write_text(path.read_text() + "\nimport lvws_ros.core.executor  # deliberate cycle\n"
                    "import lvws_ros.registry  # deliberate upward import\n")
    res = lint(tree)
    assert res.returncode != 0
    assert "No import cycles among the modules of any package BROKEN" in res.stdout.replace("\n", " "), res.stdout
    assert "Layers:" in res.stdout and res.stdout.count("BROKEN") >= 2, res.stdout
