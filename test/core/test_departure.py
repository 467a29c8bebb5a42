"""``"departure"``: when a subteam's members set out. ``together`` (the default, every file
before the field): a task is given to free robots, who set out at once; ``each``: a task may
be given to busy robots too, each setting out from where its tasks leave it once it is free,
and a robot may be given several tasks of one step, done in order. The field reads and
writes back, a bad value is refused naming it, and the executor times both as documented."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

from lvws_ros.core.executor import Decision, State, check_decision
from lvws_ros.core.formats import instance_from_dict, instance_to_dict
from lvws_ros.errors import PolicyError

ROOT = Path(__file__).resolve().parents[2]
CELL = {
    "format": "lvws-instance/1", "name": "two-sites", "traits": ["lift"], "departure": "each",
    "sites": {"a": [0, 0], "b": [4, 0], "c": [0, 3]},
    "robots": [{"id": "near", "traits": {"lift": 1}, "site": "a", "speed": 1.0},
               {"id": "far", "traits": {"lift": 1}, "site": "c", "speed": 1.0}],
    "tasks": [{"id": "first", "requires": {"lift": 1}, "duration": 5, "after": [], "site": "a"},
              {"id": "both", "requires": {"lift": 2}, "duration": 1, "after": [], "site": "b"},
              {"id": "again", "requires": {"lift": 1}, "duration": 1, "after": [], "site": "a"}],
}


def test_the_field_reads_writes_back_and_defaults_to_together():
    inst = instance_from_dict(CELL)
    assert inst.departure == "each" and instance_to_dict(inst)["departure"] == "each"
    plain = instance_from_dict({k: v for k, v in CELL.items() if k != "departure"})
    assert plain.departure == "together" and "departure" not in instance_to_dict(plain)


def test_a_bad_departure_is_refused_naming_the_field_with_exit_2(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({**CELL, "departure": "whenever"}))
    res = subprocess.run([sys.executable, "-m", "lvws_ros.cli", "solve", str(path), "--policy", "grp"],
                         capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 2 and "departure" in res.stderr and "whenever" in res.stderr
    assert "Traceback" not in res.stderr


def test_together_refuses_a_busy_member_and_each_times_every_member_from_its_own_free_time():
    each = instance_from_dict(CELL)
    together = replace(each, departure="together")
    for inst in (each, together):
        state = State.initial(inst)
        state.start(0, [0])  # near works on "first" at a until 5
        give = Decision(((1, (0, 1)),))  # "both" at b to near (busy) and far (free)
        if inst.departure == "together":
            with pytest.raises(PolicyError, match="busy"):
                check_decision(state, give)
            continue
        check_decision(state, give)
        state.start(1, [0, 1])
        # near leaves a at 5 and needs 4 s to b; far leaves c at once and needs 5 s: the last is there at 9
        assert state.task_start[1] == pytest.approx(9.0)
        assert state.robot_free_at.tolist() == pytest.approx([10.0, 10.0])


def test_with_each_a_robot_takes_several_tasks_of_one_step_in_order():
    inst = instance_from_dict(CELL)
    state = State.initial(inst)
    chain = Decision(((0, (0,)), (2, (0,))))  # near: "first", then "again" (both at a)
    check_decision(state, chain)
    for task, team in chain.assignments:
        state.start(task, team)
    assert state.task_start[0] == pytest.approx(0.0) and state.task_start[2] == pytest.approx(5.0)
    with pytest.raises(PolicyError, match="two tasks"):
        check_decision(State.initial(replace(inst, departure="together")), chain)
