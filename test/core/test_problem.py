"""lvws-instance/1 reading, writing and every kind of bad input."""

from __future__ import annotations

import copy
import json

import pytest

from conftest import REPO
from lvws_ros.core.formats import instance_from_dict, instance_to_dict, load_instance
from lvws_ros.errors import InstanceError
from samples import BASE


def edited(path: str, value):
    data = copy.deepcopy(BASE)
    *keys, last = path.split(".")
    node = data
    for k in keys:
        node = node[int(k)] if k.isdigit() else node[k]
    node[int(last) if last.isdigit() else last] = value
    return data


def test_roundtrip_keeps_everything_including_extra_keys():
    inst = instance_from_dict(BASE)
    assert inst.num_robots == 2 and inst.num_tasks == 3
    assert inst.prerequisites == ((), (0,), (0, 1))
    assert inst.robot_caps.tolist() == [[True, False], [False, True]]
    out = instance_to_dict(inst)
    assert out["robots"][1]["pose"] == [1, 2]
    assert instance_from_dict(out) == inst


@pytest.mark.parametrize(
    ("data", "words"),
    [
        (edited("tasks.0.after", ["t2"]), ["cyclic", "t0", "t2"]),
        (edited("tasks.1.after", ["t1"]), ["t1", "own prerequisite"]),
        (edited("tasks.1.after", ["t9"]), ["t1", "unknown", "t9"]),
        (edited("robots.1.id", "r0"), ["duplicate robot", "r0"]),
        (edited("tasks.1.id", "t0"), ["duplicate task", "t0"]),
        (edited("robots.0.capabilities", [1, 0, 1]), ["r0", "3 entries", "expected 2"]),
        (edited("tasks.2.capabilities", [1]), ["t2", "1 entries"]),
        (edited("tasks.2.capabilities", [0, 0]), ["t2", "at least one"]),
        (edited("robots.0.capabilities", [2, 0]), ["r0", "0 or 1"]),
        (edited("robots.0.payload", -1.0), ["r0", "payload", "> 0"]),
        (edited("robots.0.payload", 0), ["r0", "payload", "> 0"]),
        (edited("tasks.1.payload", -0.5), ["t1", "payload", ">= 0"]),
        (edited("tasks.1.duration", 0.0), ["t1", "duration", "> 0"]),
        (edited("tasks.1.duration", float("nan")), ["t1", "duration", "finite"]),
        (edited("robots.1.payload", float("inf")), ["r1", "payload", "finite"]),
        (edited("tasks.1.duration", "7"), ["t1", "duration", "number"]),
        (edited("tasks.0.payload", 15.5), ["t0", "never be covered", "payload"]),
        (edited("robots.1.capabilities", [1, 0]), ["never be covered", "mobility"]),
        (edited("format", "lvws-instance/2"), ["format", "lvws-instance/1"]),
        (edited("robots", []), ["team is empty"]),
        (edited("capabilities", []), ["capabilit"]),
    ],
)
def test_bad_input_is_named(data, words):
    with pytest.raises(InstanceError) as err:
        instance_from_dict(data)
    for w in words:
        assert w in str(err.value), (w, str(err.value))


def test_missing_keys_are_named():
    data = copy.deepcopy(BASE)
    del data["tasks"][1]["duration"]
    with pytest.raises(InstanceError, match=r"tasks\[1\].*duration"):
        instance_from_dict(data)


def test_malformed_and_missing_files(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "lvws-instance/1", "robots": [')
    with pytest.raises(InstanceError, match="malformed JSON"):
        load_instance(bad)
    nan = tmp_path / "nan.json"
    nan.write_text(json.dumps(BASE).replace("12.0", "NaN"))
    with pytest.raises(InstanceError, match="NaN"):
        load_instance(nan)
    with pytest.raises(InstanceError, match="cannot read"):
        load_instance(tmp_path / "missing.json")


def test_shipped_example_loads():
    inst = load_instance(REPO / "config" / "example_instance.json")
    assert inst.num_robots == 6 and inst.num_tasks == 18


@pytest.mark.parametrize("seed", range(6))
def test_reachability_is_the_transitive_closure_of_the_prerequisites(seed: int) -> None:
    """Bit k of row j set exactly where task k depends on task j, directly or not (a walk
    over the successors); the descendant counts are its rows' sums."""
    import numpy as np

    from lvws_ros.core.datasets import random_instance

    inst = random_instance(np.random.default_rng(seed), 4, 9 + 11 * seed, "h")
    bits = np.unpackbits(inst.reachability(), axis=1)[:, :inst.num_tasks].astype(bool)
    for j in range(inst.num_tasks):
        seen, stack = set(), list(inst.successors[j])
        while stack:
            k = stack.pop()
            if k not in seen:
                seen.add(k)
                stack.extend(inst.successors[k])
        assert set(np.flatnonzero(bits[j]).tolist()) == seen
    assert inst.descendant_count.tolist() == bits.sum(axis=1).tolist()
