"""Small documents shared by the tests of several packages."""

from __future__ import annotations

import numpy as np

from lvws_ros.core.datasets import random_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import check_schedule
from lvws_ros.learning.features import GraphFeatures, encode_state
from lvws_ros.policies.baselines import GreedyPayloadPolicy

# A valid lvws-instance/1 document: three tasks, a subteam needed for t0, a robot with an extra key.
BASE = {
    "format": "lvws-instance/1",
    "name": "tiny",
    "capabilities": ["manipulation", "mobility"],
    "robots": [
        {"id": "r0", "capabilities": [1, 0], "payload": 12.0},
        {"id": "r1", "capabilities": [0, 1], "payload": 3.0, "pose": [1, 2]},
    ],
    "tasks": [
        {"id": "t0", "capabilities": [1, 1], "payload": 14.0, "duration": 4.0, "after": []},
        {"id": "t1", "capabilities": [0, 1], "payload": 2.0, "duration": 7.0, "after": ["t0"]},
        {"id": "t2", "capabilities": [1, 0], "payload": 0.0, "duration": 1.5, "after": ["t0", "t1"]},
    ],
}


# Instance transformations for the invariance tests of the learned model.

def with_k(inst: Instance, k: int, seed: int) -> Instance:
    """``inst`` with K = k capabilities drawn anew (every task coverable)."""
    rng = np.random.default_rng(seed)
    rc = rng.random((inst.num_robots, k)) < 0.5
    rc[np.arange(inst.num_robots), rng.integers(k, size=inst.num_robots)] = True
    robots = tuple(Robot(r.id, tuple(int(c) for c in rc[i]), r.payload) for i, r in enumerate(inst.robots))
    held = np.flatnonzero(rc.any(axis=0))
    tasks = []
    for t in inst.tasks:
        caps = np.zeros(k, dtype=int)
        caps[rng.choice(held, size=min(len(held), int(rng.integers(1, 3))), replace=False)] = 1
        tasks.append(Task(t.id, tuple(int(c) for c in caps), t.payload, t.duration, t.after))
    return Instance(f"{inst.name}-k{k}", tuple(f"c{c}" for c in range(k)), robots, tuple(tasks))


def permuted_caps(inst: Instance, order: np.ndarray) -> Instance:
    return Instance(inst.name, tuple(inst.capabilities[c] for c in order),
                    tuple(Robot(r.id, tuple(r.capabilities[c] for c in order), r.payload) for r in inst.robots),
                    tuple(Task(t.id, tuple(t.capabilities[c] for c in order), t.payload, t.duration, t.after)
                          for t in inst.tasks))


def scaled(inst: Instance, payload: float = 1.0, duration: float = 1.0) -> Instance:
    return Instance(inst.name, inst.capabilities,
                    tuple(Robot(r.id, r.capabilities, r.payload * payload) for r in inst.robots),
                    tuple(Task(t.id, t.capabilities, t.payload * payload, t.duration * duration, t.after)
                          for t in inst.tasks))


def plan(policy, inst):
    sched = simulate(inst, policy).schedule
    assert check_schedule(inst, sched) == []
    return sorted((a.task, a.start, tuple(sorted(a.robots))) for a in sched.assignments)


def features_at(seed: int, n: int, m: int, step: int = 1) -> GraphFeatures:
    """The model's features of a random n x m instance at GRP's ``step``-th decision."""
    inst = random_instance(np.random.default_rng(seed), n, m, "f")
    run = simulate(inst, GreedyPayloadPolicy(), record_states=True)
    state = run.steps[min(step, len(run.steps) - 1)].state
    assert state is not None
    return encode_state(state)


# Scripted world events for the case study (lvws_ros/sim/events.py), out of time order on
# purpose: a file's order never matters, events are sorted by time.
EVENTS = """
events:
  - {at: 8.0, fail: jackal_2}
  - {at: 30.0, repair: jackal_2}
  - {at: 2.0, cancel: t12}
  - at: 20.0
    submit:
      - {id: t15, type: transport, object: obj3, from: cell_3, to: cell_1, after: [t05]}
      - {id: t16, type: assembly, object: obj3, cell: cell_1, duration: 4.0, after: [t15]}
"""


def trait_cell_config(tmp_path, edit=None):
    """The case study cell with a trait: the husky brings battery 2, each jackal 1; every
    transport requires battery 2 (the husky, or both jackals)."""
    import yaml

    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.sim.config import load_cell_config

    data = yaml.safe_load(open(case_study_config()).read())
    data["traits"] = ["battery"]
    for r in data["robots"]:
        if r["kind"] != "panda":
            r["traits"] = {"battery": 2 if r["kind"] == "husky" else 1}
    for t in data["tasks"]:
        if t["type"] == "transport":
            t["requires"] = {"battery": 2}  # the husky, or both jackals
    if edit:
        edit(data)
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_cell_config(path)
