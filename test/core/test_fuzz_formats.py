"""Property-based fuzzing of the two file formats with hypothesis.

Instance and schedule files are mutated (structure, types, numbers, encodings, nesting)
and fed through the code ``lvws solve`` and ``lvws check`` use. The properties:

* loading either succeeds or raises the format's own error (InstanceError /
  ScheduleError): never any other exception, so never a traceback;
* an instance that loads is scheduled by GRP into a schedule ``lvws check`` accepts
  (the loader lets nothing through that breaks the policies);
* ``check_schedule`` never accepts a schedule that breaks a rule of formats.md (an
  independent oracle below): no false accepts, NaN and infinities included.

CI runs a few hundred examples per property (LVWS_FUZZ_EXAMPLES); ``make fuzz`` runs
10^4 per property and prints the counts.
"""

from __future__ import annotations

import copy
import json
import math
import os
from collections import Counter
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lvws_ros.core.executor import simulate
from lvws_ros.core.formats import instance_from_dict, load_instance, load_schedule, schedule_to_dict
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.errors import InstanceError, ScheduleError
from lvws_ros.policies.baselines import GreedyPayloadPolicy
from samples import BASE

pytestmark = pytest.mark.fuzz
EXAMPLES = int(os.environ.get("LVWS_FUZZ_EXAMPLES", "250"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])
COUNTS: Counter[str] = Counter()

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-(10**40), 10**40), st.integers(-3, 3),
    st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0, 1, 0.5, -1, 1e9, 1e9 + 1, 1e308, 5e-324]),
    st.text(max_size=8), st.sampled_from(["t0", "t1", "t2", "r0", "r1", "", "manipulation"]),
)
values = st.recursive(scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.text(max_size=6), inner, max_size=4)),
                      max_leaves=12)


def _paths(node: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for k, v in enumerate(node):
            out += _paths(v, (*prefix, k))
    return out


@st.composite
def mutated(draw: st.DrawFn, base: dict[str, Any]) -> Any:
    """The base document with one to three edits: a value replaced, a key deleted, or
    a value wrapped in lists."""
    doc: Any = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, 3))):
        paths = _paths(doc)
        path = draw(st.sampled_from(paths))
        action = draw(st.sampled_from(["replace", "delete", "wrap"]))
        if not path:
            doc = draw(values) if action == "replace" else [doc]
            continue
        parent = doc
        for k in path[:-1]:
            parent = parent[k]
        key = path[-1]
        if action == "replace":
            parent[key] = draw(values)
        elif action == "delete":
            del parent[key]
        else:
            parent[key] = [parent[key]]
    return doc


def _text(doc: Any) -> str:
    return json.dumps(doc, allow_nan=True)  # NaN/Infinity constants on purpose


@st.composite
def raw_files(draw: st.DrawFn, base: dict[str, Any]) -> bytes:
    """Bytes that are not the format: invalid UTF-8, huge numbers, deep nesting, junk."""
    text = _text(base)
    kind = draw(st.sampled_from(["utf8", "bignum", "exponent", "nesting", "junk", "truncate"]))
    if kind == "utf8":
        cut = draw(st.integers(0, len(text)))
        return text[:cut].encode() + draw(st.sampled_from([b"\xff", b"\xc3\x28", b"\xed\xa0\x80"])) + text[cut:].encode()
    if kind == "bignum":
        return text.replace("12.0", "1" + "0" * draw(st.integers(20, 5000)), 1).encode()
    if kind == "exponent":
        return text.replace("4.0", draw(st.sampled_from(["1e400", "-1e400", "1e308", "4e-400", "1E+999"])), 1).encode()
    if kind == "nesting":
        depth = draw(st.integers(30, 3000))
        return text.replace('"after": []', '"after": ' + "[" * depth + "]" * depth, 1).encode()
    if kind == "truncate":
        return text[: draw(st.integers(0, len(text)))].encode()
    return draw(st.binary(max_size=64))


def _load_instance(tmp_path: Path, data: bytes) -> Instance | None:
    p = tmp_path / "instance.json"
    p.write_bytes(data)
    try:
        inst = load_instance(p)
    except InstanceError as exc:
        assert str(p) in str(exc), f"the error does not name the file: {exc}"
        COUNTS["instance rejected"] += 1
        return None
    COUNTS["instance accepted"] += 1
    return inst


def _schedules_validly(inst: Instance) -> None:
    sched = simulate(inst, GreedyPayloadPolicy()).schedule
    assert check_schedule(inst, sched) == [], "GRP's schedule of an accepted instance is rejected"


@FUZZ
@given(doc=mutated(BASE))
def test_mutated_instances_load_or_fail_cleanly(tmp_path, doc):
    inst = _load_instance(tmp_path, _text(doc).encode())
    if inst is not None:
        _schedules_validly(inst)


@FUZZ
@given(data=raw_files(BASE))
def test_malformed_instance_files_fail_cleanly(tmp_path, data):
    inst = _load_instance(tmp_path, data)
    if inst is not None:
        _schedules_validly(inst)


@st.composite
def numeric_instances(draw: st.DrawFn) -> dict[str, Any]:
    """Well-formed instance documents with any capability count (1-200) and numbers
    from the whole float range, the limits of formats.md included."""
    k = draw(st.sampled_from([1, 2, 3, 8, 63, 64, 65, 200]))
    n, m = draw(st.integers(1, 5)), draw(st.integers(1, 6))
    numbers = st.one_of(st.floats(1e-3, 1e3), st.integers(1, 30), st.floats(1e-3, 1e9),
                        st.sampled_from([1e9, 5e-324, 0.1, 30]))
    if draw(st.integers(0, 9)) == 0:  # now and then a number out of the limits
        numbers = st.one_of(numbers, st.sampled_from([0, -1, 1e9 + 1, 1e308, 10**400]))

    def bits(nonzero: bool) -> list[int]:
        v = draw(st.lists(st.integers(0, 1), min_size=k, max_size=k))
        if nonzero and not any(v):
            v[draw(st.integers(0, k - 1))] = 1
        return v

    robots = [{"id": f"r{i}", "capabilities": bits(False), "payload": draw(numbers)} for i in range(n)]
    tasks = [{"id": f"t{j}", "capabilities": bits(True), "payload": draw(numbers), "duration": draw(numbers),
              "after": [f"t{p}" for p in range(j) if draw(st.booleans())]} for j in range(m)]
    return {"format": "lvws-instance/1", "name": "fuzz", "capabilities": [f"c{c}" for c in range(k)],
            "robots": robots, "tasks": tasks}


@FUZZ
@given(doc=numeric_instances())
def test_any_capability_count_and_number_loads_or_fails_cleanly(tmp_path, doc):
    inst = _load_instance(tmp_path, _text(doc).encode())
    if inst is not None:
        _schedules_validly(inst)


VALID_INSTANCE = instance_from_dict(BASE)
VALID_SCHEDULE = schedule_to_dict(simulate(VALID_INSTANCE, GreedyPayloadPolicy()).schedule)


def oracle_violations(inst: Instance, s: Schedule) -> bool:
    """True when the schedule breaks a rule of formats.md: an independent, plain
    reading of the six rules (tolerance 1e-6), for the false-accept property."""
    tol = 1e-6
    nums = [s.makespan, *(x for a in s.assignments for x in (a.start, a.end))]
    if not all(math.isfinite(x) for x in nums):
        return True
    tasks = {t.id: t for t in inst.tasks}
    robots = {r.id: r for r in inst.robots}
    if sorted(a.task for a in s.assignments) != sorted(tasks):
        return True  # every task exactly once, no unknown task
    by = {a.task: a for a in s.assignments}
    for a in s.assignments:
        t = tasks[a.task]
        if not a.robots or len(set(a.robots)) != len(a.robots) or any(r not in robots for r in a.robots):
            return True
        for k, need in enumerate(t.capabilities):
            if need and not any(robots[r].capabilities[k] for r in a.robots):
                return True
        if sum(robots[r].payload for r in a.robots) < t.payload - tol:
            return True
        if abs(a.end - a.start - t.duration) > tol or a.start < -tol:
            return True
        if any(a.start < by[p].end - tol for p in t.after):
            return True
    for x in s.assignments:
        for y in s.assignments:
            if x is not y and set(x.robots) & set(y.robots) and x.start < y.end - tol and y.start < x.end - tol:
                return True
    return abs(s.makespan - max(a.end for a in s.assignments)) > tol


@FUZZ
@given(doc=mutated(VALID_SCHEDULE))
def test_check_never_accepts_a_broken_schedule(tmp_path, doc):
    p = tmp_path / "schedule.json"
    p.write_text(_text(doc))
    try:
        sched = load_schedule(p)
    except ScheduleError as exc:
        assert str(p) in str(exc)
        COUNTS["schedule rejected on load"] += 1
        return
    problems = check_schedule(VALID_INSTANCE, sched)
    broken = oracle_violations(VALID_INSTANCE, sched)
    assert not (broken and not problems), f"false accept: {doc}"
    assert not (problems and not broken), f"false reject: {problems}"
    COUNTS["schedule invalid (lvws check: violations)" if problems else "schedule valid"] += 1


@st.composite
def edited_schedules(draw: st.DrawFn) -> Schedule:
    """A valid schedule with one to three semantic edits: a time or the makespan set to
    any float (NaN and infinities included), a subteam redrawn, an assignment dropped,
    duplicated or renamed."""
    doc = copy.deepcopy(VALID_SCHEDULE)
    rows = doc["assignments"]
    numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, 4.0, 11.0, 12.5]),
                        st.floats(-1.0, 20.0))
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["time", "makespan", "robots", "drop", "duplicate", "rename"]))
        k = draw(st.integers(0, len(rows) - 1)) if rows else None
        if kind == "makespan" or k is None:
            doc["makespan"] = draw(numbers)
        elif kind == "time":
            rows[k][draw(st.sampled_from(["start", "end"]))] = draw(numbers)
        elif kind == "robots":
            rows[k]["robots"] = draw(st.lists(st.sampled_from(["r0", "r1", "r9"]), max_size=3))
        elif kind == "drop":
            rows.pop(k)
        elif kind == "duplicate":
            rows.append(copy.deepcopy(rows[k]))
        else:
            rows[k]["task"] = draw(st.sampled_from(["t0", "t1", "t2", "t9"]))
    return Schedule(doc["instance"], doc["policy"], [
        Assignment(a["task"], tuple(a["robots"]), float(a["start"]), float(a["end"])) for a in rows],
        float(doc["makespan"]))


@FUZZ
@given(sched=edited_schedules())
def test_check_never_accepts_an_edited_schedule(sched):
    problems = check_schedule(VALID_INSTANCE, sched)
    broken = oracle_violations(VALID_INSTANCE, sched)
    assert not (broken and not problems), f"false accept: {sched}"
    assert not (problems and not broken), f"false reject: {problems}"
    COUNTS["edited schedule invalid" if problems else "edited schedule valid"] += 1


@FUZZ
@given(data=raw_files(VALID_SCHEDULE))
def test_malformed_schedule_files_fail_cleanly(tmp_path, data):
    p = tmp_path / "schedule.json"
    p.write_bytes(data)
    try:
        sched = load_schedule(p)
    except ScheduleError:
        COUNTS["schedule rejected on load"] += 1
        return
    assert not (check_schedule(VALID_INSTANCE, sched) == [] and oracle_violations(VALID_INSTANCE, sched))
    COUNTS["schedule loaded"] += 1


def teardown_module() -> None:
    total = sum(COUNTS.values())
    print(f"\nfuzz: {total} inputs ({EXAMPLES} per property), 0 tracebacks, 0 false accepts: "
          + ", ".join(f"{k} {v}" for k, v in sorted(COUNTS.items())))
