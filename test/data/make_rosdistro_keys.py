"""Rebuild rosdistro-jazzy-keys.txt.gz: ``python test/data/make_rosdistro_keys.py ROSDISTRO``
with ROSDISTRO a checkout of https://github.com/ros/rosdistro. Keys of rosdep/base.yaml
and rosdep/python.yaml (those migrated to end-of-life left out) and the packages of
jazzy/distribution.yaml, one per line."""

from __future__ import annotations

import gzip
import re
import subprocess
import sys
from pathlib import Path

import yaml


def main(repo: Path) -> None:
    keys: set[str] = set()
    for name in ("rosdep/base.yaml", "rosdep/python.yaml"):
        for line in (repo / name).read_text().splitlines():
            m = re.match(r"^([A-Za-z0-9_.+-]+):(.*)$", line)
            if m and "migrate_eol" not in m.group(2):
                keys.add(m.group(1))
    dist = yaml.safe_load((repo / "jazzy" / "distribution.yaml").read_text())
    for name, entry in dist["repositories"].items():
        release = entry.get("release") or {}
        keys.update(release.get("packages") or ([name] if release else []))
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=repo, capture_output=True, text=True).stdout.strip()
    header = (f"# rosdep keys of ros/rosdistro {commit}: rosdep/base.yaml, rosdep/python.yaml (keys migrated\n"
              "# to end-of-life left out) and the packages of jazzy/distribution.yaml.\n"
              "# Regenerate: python test/data/make_rosdistro_keys.py ROSDISTRO_CHECKOUT\n")
    with gzip.open(Path(__file__).with_name("rosdistro-jazzy-keys.txt.gz"), "wt") as f:
        f.write(header + "\n".join(sorted(keys)) + "\n")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
