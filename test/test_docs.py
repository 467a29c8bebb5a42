"""The documentation site builds with Sphinx + MyST, warnings as errors (what ``make docs``
runs), every page of the guide and the API reference is there, the API pages carry the
code's docstrings, and no link between the site's pages points nowhere."""

from __future__ import annotations

from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import urldefrag

import pytest
from sphinx.cmd.build import build_main

DOCS = Path(__file__).resolve().parents[1] / "docs"
PAGES = ("index", "install", "offline", "ros", "robots", "dashboard", "formats", "architecture", "learning", "results", "scale",
         "sampling_and_self_improvement", "benchmarks", "wait_head_experiment", "api/index", "api/core",
         "api/policies", "api/learning", "api/sim", "api/planning", "api/ros", "api/robot", "tutorials/own_cell",
         "tutorials/fleet", "tutorials/fine_tune")


class _Links(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.hrefs: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        href = dict(attrs).get("href")
        if tag == "a" and href:
            self.hrefs.append(href)


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    assert build_main(["-q", "-W", "--keep-going", "-b", "html", str(DOCS), str(out)]) == 0
    return out


def test_every_page_is_built(site: Path) -> None:
    for page in PAGES:
        assert (site / f"{page}.html").is_file(), page
    index = (site / "index.html").read_text(encoding="utf-8")
    for page in ("install", "offline", "ros", "formats", "learning", "api/index"):
        assert f'href="{page}.html"' in index, page


def test_the_api_reference_carries_the_docstrings(site: Path) -> None:
    policies = (site / "api" / "policies.html").read_text(encoding="utf-8")
    assert "Large-neighbourhood search" in policies and "solve_exact" in policies
    core = (site / "api" / "core.html").read_text(encoding="utf-8")
    assert "OnlineScheduler" in core and "lower_bounds" in core
    ros = (site / "api" / "ros.html").read_text(encoding="utf-8")
    assert "SchedulerNode" in ros  # the node modules import (rclpy, lvws_msgs) while the site builds


def test_no_link_between_pages_points_nowhere(site: Path) -> None:
    checked = 0
    for page in site.rglob("*.html"):
        parser = _Links()
        parser.feed(page.read_text(encoding="utf-8"))
        for href in parser.hrefs:
            target, _ = urldefrag(href)
            if not target or "://" in target or target.startswith(("mailto:", "#")):
                continue
            assert (page.parent / target).resolve().exists(), f"{page.relative_to(site)} -> {href}"
            checked += 1
    assert checked > 100
