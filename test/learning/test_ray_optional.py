"""Ray is optional at run time (requirements-dev.txt, not requirements.txt): asking for it
where it is not installed is a clear error, not a traceback."""

from __future__ import annotations

import sys

import pytest

from lvws_ros.errors import ConfigError
from lvws_ros.learning.demonstrations import run_jobs


def test_a_ray_address_without_ray_installed_says_how_to_install_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails as where it is not installed
    with pytest.raises(ConfigError, match=r"--ray-address needs Ray.*make env-dev installs it"):
        run_jobs([1, 2], str, ray_address="local", progress=False)


def test_without_a_ray_address_the_jobs_run_in_local_processes(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    assert run_jobs([1, 2], str, processes=1, progress=False) == ["1", "2"]
