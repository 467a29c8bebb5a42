"""Writes golden_schedules.json: the schedules of fixed samples of Datasets I-IV and the
held-out families under the deterministic policies, as the code that wrote them made them.
test/core/test_traits.py schedules the same samples again and compares, so a change of the
coverage rule that changes any schedule of a file without traits fails (the lvws entries are
written again when a new model ships, so for LVWS they pin that model's schedules). Run from the root
of the checkout whose behaviour is the reference: python test/data/make_golden_schedules.py"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import simulate
from lvws_ros.core.families import family_instance
from lvws_ros.core.formats import dumps, instance_to_dict, schedule_to_dict
from lvws_ros.registry import make_policy

POLICIES = ("grp", "rand", "rand_subteam", "lvws", "dbgm")
SAMPLES = [("I", 0), ("I", 801), ("II", 3), ("II", 8001), ("III", 0), ("IV", 0), ("IV", 2001), ("IV", 2002)]
FAMILY_SAMPLES = [("mixed", 0), ("assembly", 1_000_000), ("mspsp", 1_000_000), ("depot", 1_000_000)]


def samples():
    for key, index in SAMPLES:
        yield dataset_instance(DATASETS[key], index, 0)
    for key, index in FAMILY_SAMPLES:
        yield family_instance(key, index, 0)


def digest(inst, policy_name: str) -> dict:
    policy = make_policy(policy_name, seed=0)
    sched = simulate(inst, policy).schedule
    data = schedule_to_dict(sched)
    data.pop("compute_seconds")
    return {"makespan": sched.makespan, "sha256": hashlib.sha256(dumps(data).encode()).hexdigest()}


def golden() -> dict:
    out = {}
    for inst in samples():
        out[inst.name] = {"instance_sha256": hashlib.sha256(dumps(instance_to_dict(inst)).encode()).hexdigest(),
                          **{p: digest(inst, p) for p in POLICIES}}
    return out


if __name__ == "__main__":
    Path(__file__).with_name("golden_schedules.json").write_text(json.dumps(golden(), indent=1) + "\n")
