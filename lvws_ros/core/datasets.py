"""Dataset generators for the LVWS paper's three datasets (section IV-A).

Every instance follows the paper's recipe:
  * 2 or 3 capabilities (uniform); each robot a random non-zero capability vector, and
    every capability held by at least one robot;
  * robot payload capacity: integer, uniform in 1..30;
  * task payload need: Poisson(TASK_PAYLOAD_MEAN) clipped to 1..30, redrawn while it
    exceeds the whole team's payload (so every task is coverable);
  * task capability need: a random non-zero vector;
  * task duration (our choice, the paper gives none): integer, uniform in 1..10 s;
  * prerequisites: a random DAG; task j takes 0, 1 or 2 prerequisites (probabilities
    PREREQ_PROBS) drawn uniformly among tasks 0..j-1.

Instance ``k`` of a dataset is drawn from ``numpy.random.default_rng([seed, dataset, k])``,
so every instance is reproducible on its own and the files are byte-identical for a seed.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.core.formats import dumps, save_instance
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.subteams import covers
from lvws_ros.core.travel import build_travel

TASK_PAYLOAD_MEAN = 10.0
PAYLOAD_RANGE = (1, 30)
DURATION_RANGE = (1, 10)
PREREQ_PROBS = (0.35, 0.40, 0.25)
CAPABILITY_NAMES = ("manipulation", "mobility", "sensing")


@dataclass(frozen=True)
class DatasetSpec:
    key: str
    code: int
    count: int
    train: int
    robots: tuple[int, int]
    tasks: tuple[int, int]
    description: str
    travel: bool = False  # Dataset IV: :func:`travel_instance`


DATASETS = {
    "I": DatasetSpec("I", 1, 1000, 800, (6, 6), (18, 18), "6 robots, 18 tasks (6r-18t)"),
    "II": DatasetSpec("II", 2, 10000, 8000, (3, 8), (8, 20), "3-8 robots, 8-20 tasks (8r-20t-var)"),
    "III": DatasetSpec("III", 3, 20, 0, (6, 6), (100, 100), "6 robots, 100 tasks (6r-100t)"),
    "IV": DatasetSpec("IV", 4, 2200, 2000, (3, 6), (6, 12), "3-6 robots, 6-12 tasks, 3-5 sites, travel (ours)",
                      travel=True),
}


def _nonzero_vector(rng: np.random.Generator, k: int) -> tuple[int, ...]:
    while True:
        v = rng.integers(0, 2, size=k)
        if v.any():
            return tuple(int(x) for x in v)


def random_instance(rng: np.random.Generator, num_robots: int, num_tasks: int, name: str,
                    num_capabilities: int | None = None) -> Instance:
    """One feasible instance drawn as described in the module docstring."""
    k = int(rng.integers(2, 4)) if num_capabilities is None else num_capabilities
    while True:
        robot_caps = [_nonzero_vector(rng, k) for _ in range(num_robots)]
        if np.array(robot_caps).any(axis=0).all():
            break
    payloads = rng.integers(PAYLOAD_RANGE[0], PAYLOAD_RANGE[1] + 1, size=num_robots)
    robots = tuple(
        Robot(f"r{i}", robot_caps[i], float(payloads[i])) for i in range(num_robots)
    )
    total = float(payloads.sum())
    tasks = []
    for j in range(num_tasks):
        caps = _nonzero_vector(rng, k)
        while True:
            need = float(np.clip(rng.poisson(TASK_PAYLOAD_MEAN), *PAYLOAD_RANGE))
            if need <= total:
                break
        duration = float(rng.integers(DURATION_RANGE[0], DURATION_RANGE[1] + 1))
        n_pre = min(j, int(rng.choice(len(PREREQ_PROBS), p=PREREQ_PROBS)))
        pre = sorted(int(p) for p in rng.choice(j, size=n_pre, replace=False)) if n_pre else []
        tasks.append(Task(f"t{j}", caps, need, duration, tuple(f"t{p}" for p in pre)))
    return Instance(name, CAPABILITY_NAMES[:k], robots, tuple(tasks))


SUBTEAM_ROBOT_PAYLOAD = (1, 10)
SUBTEAM_TASK_PAYLOAD_MEAN = 16.0


def subteam_heavy_instance(rng: np.random.Generator, num_robots: int, num_tasks: int, name: str,
                           num_capabilities: int = 3) -> Instance:
    """A fleet-style instance where most tasks need 2-6 robots: robot payloads uniform in
    1..10, task payloads Poisson(16) clipped to 1..60 (and to the team's payload), three
    capabilities held by about half of the robots each, the same random DAG as the
    paper's datasets. Used by the scale benchmarks."""
    k = num_capabilities
    robot_caps = (rng.random((num_robots, k)) < 0.5).astype(int)
    robot_caps[~robot_caps.any(axis=1), 0] = 1
    robot_caps[rng.integers(num_robots, size=k), np.arange(k)] = 1  # every capability held
    payloads = rng.integers(SUBTEAM_ROBOT_PAYLOAD[0], SUBTEAM_ROBOT_PAYLOAD[1] + 1, size=num_robots)
    robots = tuple(Robot(f"r{i}", tuple(int(c) for c in robot_caps[i]), float(payloads[i])) for i in range(num_robots))
    total = float(payloads.sum())
    tasks = []
    for j in range(num_tasks):
        caps = _nonzero_vector(rng, k)
        need = float(min(np.clip(rng.poisson(SUBTEAM_TASK_PAYLOAD_MEAN), 1, 60), total))
        duration = float(rng.integers(DURATION_RANGE[0], DURATION_RANGE[1] + 1))
        n_pre = min(j, int(rng.choice(len(PREREQ_PROBS), p=PREREQ_PROBS)))
        pre = sorted(int(p) for p in rng.choice(j, size=n_pre, replace=False)) if n_pre else []
        tasks.append(Task(f"t{j}", caps, need, duration, tuple(f"t{p}" for p in pre)))
    return Instance(name, CAPABILITY_NAMES[:k] if k <= len(CAPABILITY_NAMES) else tuple(f"c{c}" for c in range(k)),
                    robots, tuple(tasks))


SITE_COUNT = (3, 5)
SITE_GRID = 6  # site coordinates: integers in 0..SITE_GRID
ROBOT_SPEEDS = (0.5, 1.0)  # mobile robots; integer distances / these speeds are integer travel times
FIXED_SHARE = 1 / 3  # robots fixed at a site (arms)
TRANSPORT_SHARE = 0.25  # tasks whose subteam ends at another site


def travel_instance(rng: np.random.Generator, num_robots: int, num_tasks: int, name: str) -> Instance:
    """Dataset IV (ours; the travel extension of formats.md): the paper's recipe for robots,
    payloads, durations and prerequisites, plus 3-5 sites at distinct integer points of a
    0..6 grid with Manhattan distances (aisles; integer, so integer travel times and exact
    proofs); a third of the robots fixed at a random site (arms), the rest mobile at speed
    0.5 or 1 starting at a random site; a quarter of the tasks transports (from one site to
    another, so only mobile robots can do them), the rest at one site. Each task is drawn
    again until the robots that can reach it cover it (Eqs. 10-11), so every instance is
    feasible; mobile robots hold every capability between them."""
    k = int(rng.integers(2, 4))
    num_sites = int(rng.integers(SITE_COUNT[0], SITE_COUNT[1] + 1))
    cells = rng.choice((SITE_GRID + 1) ** 2, size=num_sites, replace=False)
    coords = {f"s{i}": [int(c) // (SITE_GRID + 1), int(c) % (SITE_GRID + 1)] for i, c in enumerate(cells)}
    names = list(coords)
    distances = {a: {b: float(abs(coords[a][0] - coords[b][0]) + abs(coords[a][1] - coords[b][1]))
                     for b in names if b != a} for a in names}
    while True:
        caps = np.array([_nonzero_vector(rng, k) for _ in range(num_robots)], dtype=bool)
        fixed = rng.random(num_robots) < FIXED_SHARE
        fixed[: min(2, num_robots)] = False  # at least two mobile robots
        if caps[~fixed].any(axis=0).all():
            break
    payloads = rng.integers(PAYLOAD_RANGE[0], PAYLOAD_RANGE[1] + 1, size=num_robots).astype(float)
    robot_site = [names[int(i)] for i in rng.integers(num_sites, size=num_robots)]
    speeds = [None if fixed[i] else float(rng.choice(ROBOT_SPEEDS)) for i in range(num_robots)]
    robots = tuple(Robot(f"r{i}", tuple(int(c) for c in caps[i]), float(payloads[i])) for i in range(num_robots))
    tasks, sites = [], []
    for j in range(num_tasks):
        while True:
            a, b = (names[int(i)] for i in rng.choice(num_sites, size=2, replace=False))
            if rng.random() >= TRANSPORT_SHARE:
                b = a
            able = ~fixed if a != b else ~fixed | (np.array(robot_site) == a)  # who can reach it
            need_caps = np.array(_nonzero_vector(rng, k), dtype=bool)
            need = float(np.clip(rng.poisson(TASK_PAYLOAD_MEAN), *PAYLOAD_RANGE))
            if covers(caps[able], payloads[able], need_caps, need):
                break
        duration = float(rng.integers(DURATION_RANGE[0], DURATION_RANGE[1] + 1))
        n_pre = min(j, int(rng.choice(len(PREREQ_PROBS), p=PREREQ_PROBS)))
        pre = sorted(int(p) for p in rng.choice(j, size=n_pre, replace=False)) if n_pre else []
        tasks.append(Task(f"t{j}", tuple(int(c) for c in need_caps), need, duration, tuple(f"t{p}" for p in pre)))
        sites.append((f"t{j}", a, b))
    travel = build_travel(coords, distances, [(r.id, s, v) for r, s, v in zip(robots, robot_site, speeds, strict=True)],
                          sites)
    return Instance(name, CAPABILITY_NAMES[:k], robots, tuple(tasks), travel=travel)


def dataset_instance(spec: DatasetSpec, index: int, seed: int) -> Instance:
    rng = np.random.default_rng([seed, spec.code, index])
    n = int(rng.integers(spec.robots[0], spec.robots[1] + 1))
    m = int(rng.integers(spec.tasks[0], spec.tasks[1] + 1))
    make = travel_instance if spec.travel else random_instance
    return make(rng, n, m, f"{n}r-{m}t-{spec.key}-{index:05d}")


def iter_dataset(key: str, seed: int, count: int | None = None) -> Iterator[tuple[str, Instance]]:
    """(split, instance) pairs of dataset ``key``; the first ``spec.train`` are training."""
    spec = DATASETS[key]
    for index in range(spec.count if count is None else min(count, spec.count)):
        yield ("train" if index < spec.train else "test"), dataset_instance(spec, index, seed)


def write_dataset(key: str, out_dir: str | Path, seed: int, count: int | None = None,
                  progress: Callable[[Iterable[Any], int], Iterable[Any]] | None = None) -> dict[str, int]:
    """Write dataset ``key`` as lvws-instance/1 files under out_dir/{train,test}/;
    ``progress(items, total)`` may wrap the loop (a progress bar)."""
    spec = DATASETS[key]
    out = Path(out_dir)
    counts = {"train": 0, "test": 0}
    total = spec.count if count is None else min(count, spec.count)
    items: Iterable[tuple[str, Instance]] = iter_dataset(key, seed, count)
    for split, inst in (progress(items, total) if progress else items):
        (out / split).mkdir(parents=True, exist_ok=True)
        save_instance(inst, out / split / f"{inst.name}.json")
        counts[split] += 1
    manifest = {
        "dataset": key,
        "description": spec.description,
        "seed": seed,
        "counts": counts,
        "generator": {
            "task_payload_mean": TASK_PAYLOAD_MEAN,
            "payload_range": list(PAYLOAD_RANGE),
            "duration_range": list(DURATION_RANGE),
            "prereq_probs": list(PREREQ_PROBS),
        },
    }
    (out / "manifest.json").write_text(dumps(manifest), encoding="utf-8")
    return counts
