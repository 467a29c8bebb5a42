"""Regression tests: each malformed file that once ended in a traceback, an overflow or
a false "valid" now gets a clear error naming the file and the item."""

from __future__ import annotations

import copy
import json
import re

import pytest

from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict, load_instance, load_schedule, schedule_to_dict
from lvws_ros.core.problem import MAX_VALUE
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.errors import InstanceError, ScheduleError
from lvws_ros.policies.baselines import GreedyPayloadPolicy, RandomSubteamPolicy
from samples import BASE


def _file(tmp_path, text: str | bytes, name: str = "f.json"):
    p = tmp_path / name
    p.write_bytes(text if isinstance(text, bytes) else text.encode())
    return p


def test_a_list_where_a_prerequisite_id_belongs(tmp_path):
    doc = copy.deepcopy(BASE)
    doc["tasks"][2]["after"] = [[]]
    with pytest.raises(InstanceError, match=r"tasks\[2\]\.after\[0\]: expected a task id, got a list"):
        load_instance(_file(tmp_path, json.dumps(doc)))


def test_a_payload_of_a_1_and_400_zeros(tmp_path):
    text = json.dumps(BASE).replace("12.0", "1" + "0" * 400, 1)
    with pytest.raises(InstanceError, match=r"f\.json.*out of range"):
        load_instance(_file(tmp_path, text))


def test_a_payload_above_the_limit_names_the_item():
    doc = copy.deepcopy(BASE)
    doc["robots"][0]["payload"] = 10**12
    with pytest.raises(InstanceError, match=re.escape(f"robot 'r0' payload must be at most {MAX_VALUE:g}")):
        instance_from_dict(doc)


def test_invalid_utf8_is_named(tmp_path):
    with pytest.raises(InstanceError, match=r"f.json: instance is not UTF-8 text \(byte 3"):
        load_instance(_file(tmp_path, b'{"a\xff": 1}'))


def test_nesting_of_a_thousand_levels(tmp_path):
    text = json.dumps(BASE).replace('"after": []', '"after": ' + "[" * 1000 + "]" * 1000)
    with pytest.raises(InstanceError, match=r"f\.json.*nested"):
        load_instance(_file(tmp_path, text))
    deeper = "[" * 100_000 + "]" * 100_000  # deeper than the interpreter's recursion limit
    with pytest.raises(InstanceError, match=r"f\.json"):
        load_instance(_file(tmp_path, deeper))


def test_an_integer_of_five_thousand_digits(tmp_path):
    text = json.dumps(BASE).replace("4.0", "9" * 5000, 1)
    with pytest.raises(InstanceError, match=r"f.json: integer of 500\d digits is out of range"):
        load_instance(_file(tmp_path, text))


@pytest.mark.parametrize("number", ["1e400", "-1e400", "NaN", "Infinity"])
def test_non_finite_numbers_however_written(tmp_path, number):
    text = json.dumps(BASE).replace("4.0", number, 1)
    with pytest.raises(InstanceError, match=r"f\.json"):
        load_instance(_file(tmp_path, text))


def test_a_duration_of_1e308_is_refused_before_any_policy_sees_it():
    doc = copy.deepcopy(BASE)
    doc["tasks"][0]["duration"] = 1e308
    with pytest.raises(InstanceError, match="task 't0' duration must be at most"):
        instance_from_dict(doc)


@pytest.mark.parametrize("k", [1, 8, 64, 200])
def test_any_capability_count_is_scheduled_validly(k):
    """K >= 64 once broke the baselines (an int64 bit shift)."""
    doc = {"format": "lvws-instance/1", "name": f"k{k}", "capabilities": [f"c{c}" for c in range(k)],
           "robots": [{"id": f"r{i}", "capabilities": [int(c % 3 == i) for c in range(k)], "payload": 5.0}
                      for i in range(3)],
           "tasks": [{"id": f"t{j}", "capabilities": [int(c == (k - 1 - j) % k) for c in range(k)],
                      "payload": 7.0, "duration": 2.0, "after": [f"t{j - 1}"] if j else []} for j in range(4)]}
    inst = instance_from_dict(doc)
    for policy in (GreedyPayloadPolicy(), RandomSubteamPolicy(seed=1)):
        sched = simulate(inst, policy).schedule
        assert check_schedule(inst, sched) == []
        assert all(len(a.robots) >= 2 for a in sched.assignments)  # payload 7 > 5: subteams


def _valid_schedule() -> tuple[object, dict]:
    inst = instance_from_dict(BASE)
    return inst, schedule_to_dict(simulate(inst, GreedyPayloadPolicy()).schedule)


@pytest.mark.parametrize("number", ["1e400", "NaN", "-Infinity"])
def test_check_never_says_valid_for_non_finite_times_in_a_file(tmp_path, number):
    _, doc = _valid_schedule()
    text = json.dumps(doc)
    for key in ("start", "end", "makespan"):
        text = text.replace(f'"{key}": ', f'"{key}": {number}, "_{key}": ')
    with pytest.raises(ScheduleError, match=r"f\.json"):
        load_schedule(_file(tmp_path, text))


def test_check_reports_non_finite_times_given_in_code():
    inst, doc = _valid_schedule()
    inf = float("inf")
    s = Schedule(doc["instance"], "x", [Assignment(a["task"], tuple(a["robots"]), inf, inf)
                                        for a in doc["assignments"]], inf)
    problems = check_schedule(inst, s)
    assert {p.rule for p in problems} == {3, 6}
    nan = float("nan")
    s = Schedule(doc["instance"], "x", [Assignment(a["task"], tuple(a["robots"]), a["start"], nan)
                                        for a in doc["assignments"]], nan)
    assert check_schedule(inst, s)


@pytest.mark.parametrize("field", ["decisions", "makespan", "compute_seconds"])
def test_null_where_a_number_belongs(tmp_path, field):
    _, doc = _valid_schedule()
    doc[field] = None
    with pytest.raises(ScheduleError, match=f"f.json: {field}: expected a number, got null"):
        load_schedule(_file(tmp_path, json.dumps(doc)))
