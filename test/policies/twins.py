"""Small instances with interchangeable robots, for the tests of the pool model and of
symmetry (imported by the test modules beside this one)."""

from __future__ import annotations

import numpy as np


def with_twins(inst, copies):
    """``inst`` with ``copies[i]`` extra copies of robot i (the same for the plan)."""
    from dataclasses import replace

    robots = list(inst.robots)
    for i, k in enumerate(copies):
        robots += [replace(inst.robots[i], id=f"{inst.robots[i].id}_twin{c}") for c in range(k)]
    return replace(inst, robots=tuple(robots))


def twin_instances(count, roles=False, objective="makespan"):
    """Small trait instances with interchangeable robots (two to three kinds, two to three
    of each), tasks needing one to three units."""
    from lvws_ros.core.problem import Instance, Robot, Task

    out = []
    for seed in range(count):
        rng = np.random.default_rng(7000 + seed)
        kinds = [tuple((t, float(rng.integers(1, 3))) for t in ("weld", "lift", "scan") if rng.random() < 0.6)
                 or (("weld", 1.0),) for _ in range(int(rng.integers(2, 4)))]
        robots = tuple(Robot(f"k{k}_{u}", (), 0.0, traits=traits) for k, traits in enumerate(kinds)
                       for u in range(int(rng.integers(2, 4))))
        tasks = []
        for j in range(int(rng.integers(4, 7))):
            need = tuple((t, float(rng.integers(1, 3))) for t in ("weld", "lift", "scan") if rng.random() < 0.5) \
                or (("weld", 1.0),)
            after = tuple(f"t{p}" for p in range(j) if rng.random() < 0.25)
            tasks.append(Task(f"t{j}", (), 0.0, float(rng.integers(1, 6)), after, requires=need))
        team = {t: sum(a for r in robots for n, a in r.traits if n == t) for t in ("weld", "lift", "scan")}
        tasks = [t for t in tasks if all(team[n] >= a for n, a in t.requires)]
        keep = {t.id for t in tasks}
        tasks = [replace_after(t, keep) for t in tasks]
        try:
            out.append(Instance(f"twins{seed}", (), robots, tuple(tasks), traits=("weld", "lift", "scan"),
                                roles=roles, objective=objective))
        except Exception:  # a task no team covers with roles: leave it out
            continue
    return out


def replace_after(task, keep):
    from dataclasses import replace

    return replace(task, after=tuple(p for p in task.after if p in keep))
