"""Shared test set-up: an isolated DDS domain for every test run.

Cross-process ROS tests must not see other runs on the same machine: a random
ROS_DOMAIN_ID and localhost-only discovery, set before any rclpy.init().
"""

from __future__ import annotations

import os
import random
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CASE_STUDY = REPO / "config" / "assembly_cell.yaml"

os.environ["ROS_DOMAIN_ID"] = str(random.SystemRandom().randint(1, 101))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("AMENT_PREFIX_PATH", sys.prefix)


@pytest.fixture
def ros_context():
    """A fresh rclpy context, shut down after the test."""
    rclpy = pytest.importorskip("rclpy")
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    context.try_shutdown()
