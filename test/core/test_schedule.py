"""The six validity rules of formats.md, each broken on purpose; `lvws check` finds each."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from lvws_ros.core.formats import instance_from_dict, save_instance, schedule_from_dict, schedule_to_dict
from lvws_ros.core.schedule import Schedule, check_schedule
from samples import BASE

GOOD = {
    "format": "lvws-schedule/1",
    "instance": "tiny",
    "policy": "hand",
    "makespan": 12.5,
    "assignments": [
        {"task": "t0", "robots": ["r0", "r1"], "start": 0.0, "end": 4.0},
        {"task": "t1", "robots": ["r1"], "start": 4.0, "end": 11.0},
        {"task": "t2", "robots": ["r0"], "start": 11.0, "end": 12.5},
    ],
    "decisions": 3,
    "compute_seconds": 0.0,
}


def broken(rule: int) -> dict:
    s = json.loads(json.dumps(GOOD))
    a = s["assignments"]
    if rule == 1:
        a.pop(1)  # t1 missing
    elif rule == 2:
        a[0]["robots"] = ["r0"]  # lacks mobility and payload
    elif rule == 3:
        a[2]["end"] = 13.0
    elif rule == 4:
        a[2]["start"], a[2]["end"] = 10.0, 11.5  # before t1 ends
        s["makespan"] = 11.5
    elif rule == 5:
        a[2]["robots"] = ["r1"]
        a[2]["start"], a[2]["end"] = 4.0, 5.5  # r1 busy with t1; also before t1 ends
    elif rule == 6:
        s["makespan"] = 12.0
    return s


@pytest.fixture
def inst():
    return instance_from_dict(BASE)


def test_good_schedule_is_valid(inst):
    assert check_schedule(inst, schedule_from_dict(GOOD)) == []


@pytest.mark.parametrize("rule", [1, 2, 3, 4, 5, 6])
def test_each_rule_is_caught(inst, rule):
    rules = {v.rule for v in check_schedule(inst, schedule_from_dict(broken(rule)))}
    assert rule in rules


def test_unknown_ids_are_rule_1(inst):
    s = json.loads(json.dumps(GOOD))
    s["assignments"][1]["robots"] = ["r7"]
    s["assignments"].append({"task": "t9", "robots": ["r0"], "start": 0.0, "end": 1.0})
    msgs = [str(v) for v in check_schedule(inst, schedule_from_dict(s))]
    assert any("r7" in m and m.startswith("rule 1") for m in msgs)
    assert any("t9" in m and m.startswith("rule 1") for m in msgs)


def test_roundtrip(inst):
    s = schedule_from_dict(GOOD)
    assert schedule_from_dict(schedule_to_dict(s)) == s
    assert isinstance(Schedule.from_assignments("x", "p", s.assignments).makespan, float)


@pytest.mark.parametrize("rule", [1, 2, 3, 4, 5, 6])
def test_lvws_check_cli_lists_the_rule(tmp_path, inst, rule):
    save_instance(inst, tmp_path / "inst.json")
    (tmp_path / "good.json").write_text(json.dumps(GOOD))
    (tmp_path / "bad.json").write_text(json.dumps(broken(rule)))
    cmd = [sys.executable, "-m", "lvws_ros.cli", "check", str(tmp_path / "inst.json")]
    ok = subprocess.run([*cmd, str(tmp_path / "good.json")], capture_output=True, text=True)
    assert ok.returncode == 0 and ok.stdout.startswith("valid"), ok.stdout + ok.stderr
    bad = subprocess.run([*cmd, str(tmp_path / "bad.json")], capture_output=True, text=True)
    assert bad.returncode == 1
    assert f"rule {rule}:" in bad.stdout
