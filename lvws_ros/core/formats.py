"""The two file formats of ``shared/spec/formats.md``: ``lvws-instance/1`` (problems) and
``lvws-schedule/1`` (schedules), read and written here and nowhere else.

Structural problems of a file raise :class:`~lvws_ros.errors.InstanceError` or
:class:`~lvws_ros.errors.ScheduleError` naming the file and the item; whether a
schedule obeys the six validity rules is :func:`lvws_ros.core.schedule.check_schedule`.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.errors import InstanceError, LvwsError, ScheduleError

__all__ = [
    "INSTANCE_FORMAT",
    "SCHEDULE_FORMAT",
    "dumps",
    "instance_from_dict",
    "instance_to_dict",
    "load_instance",
    "load_schedule",
    "read_json",
    "save_instance",
    "save_schedule",
    "schedule_from_dict",
    "schedule_to_dict",
]

INSTANCE_FORMAT = "lvws-instance/1"
SCHEDULE_FORMAT = "lvws-schedule/1"


# ---------------------------------------------------------------- JSON text


def read_json(path: str | Path, what: str, error: type[LvwsError] = InstanceError) -> Any:
    """Parse a JSON file; a missing or malformed file is an ``error`` naming it."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{p}: cannot read {what}: {exc.strerror or exc}") from exc
    try:
        return json.loads(text, parse_constant=_reject_constant)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: malformed JSON {what}: {exc}") from exc
    except LvwsError as exc:
        raise error(f"{p}: {exc}") from None


def _reject_constant(name: str) -> float:
    # json accepts NaN/Infinity by default; the format does not.
    raise InstanceError(f"non-finite number {name} is not allowed")


def dumps(data: Mapping[str, Any]) -> str:
    """Canonical JSON text (same object, same bytes): one line per top-level key, and
    one line per element of a list of objects (robots, tasks, assignments)."""
    lines = []
    for key, value in data.items():
        if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
            items = ",\n".join("    " + json.dumps(v, allow_nan=False) for v in value)
            lines.append(f"  {json.dumps(key)}: [\n{items}\n  ]")
        else:
            lines.append(f"  {json.dumps(key)}: {json.dumps(value, allow_nan=False)}")
    return "{\n" + ",\n".join(lines) + "\n}\n"


T = TypeVar("T")


def _load(path: str | Path, what: str, from_dict: Callable[[Any], T], error: type[LvwsError]) -> T:
    """Read a JSON file and build from it; every error names the file."""
    data = read_json(path, what, error)
    try:
        return from_dict(data)
    except error as exc:
        raise error(f"{path}: {exc}") from None


def _write(text: str, path: str | Path) -> None:
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    Path(path).write_text(text, encoding="utf-8")


# ---------------------------------------------------------------- lvws-instance/1


def _require(obj: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in obj:
        raise InstanceError(f"{where}: missing key {key!r}")
    return obj[key]


def _as_list(value: Any, where: str) -> list[Any]:
    if not isinstance(value, list):
        raise InstanceError(f"{where} must be a list, got {type(value).__name__}")
    return value


def _robot(r: Any, where: str) -> Robot:
    if not isinstance(r, dict):
        raise InstanceError(f"{where} must be an object")
    return Robot(
        id=_require(r, "id", where),
        capabilities=tuple(_as_list(_require(r, "capabilities", where), f"{where}.capabilities")),
        payload=_require(r, "payload", where),
        extra={k: v for k, v in r.items() if k not in {"id", "capabilities", "payload"}},
    )


_TASK_KEYS = {"id", "capabilities", "payload", "duration", "after"}


def _task(t: Any, where: str) -> Task:
    if not isinstance(t, dict):
        raise InstanceError(f"{where} must be an object")
    return Task(
        id=_require(t, "id", where),
        capabilities=tuple(_as_list(_require(t, "capabilities", where), f"{where}.capabilities")),
        payload=_require(t, "payload", where),
        duration=_require(t, "duration", where),
        after=tuple(_as_list(t.get("after", []), f"{where}.after")),
        extra={k: v for k, v in t.items() if k not in _TASK_KEYS},
    )


def instance_from_dict(data: Any) -> Instance:
    """Build a validated Instance from parsed ``lvws-instance/1`` JSON."""
    if not isinstance(data, dict):
        raise InstanceError("instance: the top level must be a JSON object")
    fmt = data.get("format")
    if fmt != INSTANCE_FORMAT:
        raise InstanceError(f"format: expected {INSTANCE_FORMAT!r}, got {fmt!r}")
    name = data.get("name", "")
    if not isinstance(name, str):
        raise InstanceError(f"name must be a string, got {name!r}")
    caps = _as_list(_require(data, "capabilities", "instance"), "capabilities")
    if not all(isinstance(c, str) for c in caps):
        raise InstanceError("capabilities must be a list of names")
    robots = [_robot(r, f"robots[{n}]") for n, r in enumerate(_as_list(_require(data, "robots", "instance"), "robots"))]
    tasks = [_task(t, f"tasks[{n}]") for n, t in enumerate(_as_list(_require(data, "tasks", "instance"), "tasks"))]
    return Instance(name=name, capabilities=tuple(caps), robots=tuple(robots), tasks=tuple(tasks))


def instance_to_dict(inst: Instance) -> dict[str, Any]:
    return {
        "format": INSTANCE_FORMAT,
        "name": inst.name,
        "capabilities": list(inst.capabilities),
        "robots": [
            {"id": r.id, "capabilities": list(r.capabilities), "payload": float(r.payload), **r.extra}
            for r in inst.robots
        ],
        "tasks": [
            {
                "id": t.id,
                "capabilities": list(t.capabilities),
                "payload": float(t.payload),
                "duration": float(t.duration),
                "after": list(t.after),
                **t.extra,
            }
            for t in inst.tasks
        ],
    }


def load_instance(path: str | Path) -> Instance:
    return _load(path, "instance", instance_from_dict, InstanceError)


def save_instance(inst: Instance, path: str | Path) -> None:
    _write(dumps(instance_to_dict(inst)), path)


# ---------------------------------------------------------------- lvws-schedule/1


def schedule_to_dict(s: Schedule) -> dict[str, Any]:
    return {
        "format": SCHEDULE_FORMAT,
        "instance": s.instance,
        "policy": s.policy,
        "makespan": float(s.makespan),
        "assignments": [
            {"task": a.task, "robots": list(a.robots), "start": float(a.start), "end": float(a.end)}
            for a in s.assignments
        ],
        "decisions": int(s.decisions),
        "compute_seconds": float(s.compute_seconds),
        **s.extra,
    }


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScheduleError(f"{where} must be a number")
    return float(value)


def _assignment(a: Any, where: str) -> Assignment:
    if not isinstance(a, dict) or not {"task", "robots", "start", "end"} <= a.keys():
        raise ScheduleError(f"{where}: needs task, robots, start and end")
    if not isinstance(a["robots"], list):
        raise ScheduleError(f"{where}.robots must be a list")
    return Assignment(str(a["task"]), tuple(str(r) for r in a["robots"]), _number(a["start"], f"{where}.start"),
                      _number(a["end"], f"{where}.end"))


_SCHEDULE_KEYS = {"format", "instance", "policy", "makespan", "assignments", "decisions", "compute_seconds"}


def schedule_from_dict(data: Any) -> Schedule:
    """Parse ``lvws-schedule/1``; structural problems raise ScheduleError.

    Semantic problems (overlaps, coverage, ...) are left to
    :func:`~lvws_ros.core.schedule.check_schedule`, so that ``lvws check`` can list
    every violated rule.
    """
    if not isinstance(data, dict):
        raise ScheduleError("schedule: the top level must be a JSON object")
    if data.get("format") != SCHEDULE_FORMAT:
        raise ScheduleError(f"format: expected {SCHEDULE_FORMAT!r}, got {data.get('format')!r}")
    for key in ("instance", "policy", "makespan", "assignments"):
        if key not in data:
            raise ScheduleError(f"schedule: missing key {key!r}")
    if not isinstance(data["assignments"], list):
        raise ScheduleError("schedule: assignments must be a list")
    out = [_assignment(a, f"assignments[{n}]") for n, a in enumerate(data["assignments"])]
    return Schedule(
        instance=str(data["instance"]),
        policy=str(data["policy"]),
        assignments=out,
        makespan=_number(data["makespan"], "schedule: makespan"),
        decisions=int(data.get("decisions", 0)),
        compute_seconds=float(data.get("compute_seconds", 0.0)),
        extra={k: v for k, v in data.items() if k not in _SCHEDULE_KEYS},
    )


def load_schedule(path: str | Path) -> Schedule:
    return _load(path, "schedule", schedule_from_dict, ScheduleError)


def save_schedule(s: Schedule, path: str | Path) -> None:
    _write(dumps(schedule_to_dict(s)), path)
