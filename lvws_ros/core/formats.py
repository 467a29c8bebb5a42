"""The two file formats of ``shared/spec/formats.md``: ``lvws-instance/1`` (problems) and
``lvws-schedule/1`` (schedules), read and written here and nowhere else.

Structural problems of a file raise :class:`~lvws_ros.errors.InstanceError` or
:class:`~lvws_ros.errors.ScheduleError` naming the file and the item; whether a
schedule obeys the six validity rules is :func:`lvws_ros.core.schedule.check_schedule`.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Callable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any, TypeVar

from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.travel import Travel, build_travel
from lvws_ros.errors import InstanceError, LvwsError, ScheduleError

__all__ = [
    "INSTANCE_FORMAT",
    "SCHEDULE_FORMAT",
    "dumps",
    "instance_from_dict",
    "instance_key",
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
    """Parse a JSON file strictly; anything unreadable is an ``error`` naming the file.

    Rejected: invalid UTF-8, NaN/Infinity, numbers that overflow a float (``1e400``),
    integers of more than MAX_INT_DIGITS digits, nesting deeper than MAX_DEPTH.
    """
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise error(f"{p}: cannot read {what}: {exc.strerror or exc}") from exc
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{p}: {what} is not UTF-8 text (byte {exc.start}: {exc.reason})") from None
    try:
        data = json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float, parse_int=_bounded_int)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: malformed JSON {what}: {exc}") from None
    except RecursionError:
        raise error(f"{p}: malformed JSON {what}: nested too deeply") from None
    except _NumberError as exc:
        raise error(f"{p}: {exc}") from None
    if _depth(data) > MAX_DEPTH:
        raise error(f"{p}: {what} is nested deeper than {MAX_DEPTH} levels")
    return data


MAX_DEPTH = 32  # the formats need 4 levels
MAX_INT_DIGITS = 30


class _NumberError(ValueError):
    pass


def _reject_constant(name: str) -> float:
    # json accepts NaN/Infinity by default; the format does not.
    raise _NumberError(f"non-finite number {name} is not allowed")


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise _NumberError(f"number {text[:40]} is out of range (not a finite float)")
    return value


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INT_DIGITS:
        raise _NumberError(f"integer of {digits} digits is out of range")
    return int(text)


def _depth(data: Any) -> int:
    """Nesting depth, without recursion (a hostile file may nest a thousand levels)."""
    deepest, stack = 0, [(data, 1)]
    while stack:
        item, d = stack.pop()
        deepest = max(deepest, d)
        if d > MAX_DEPTH:
            break
        if isinstance(item, dict):
            stack += [(v, d + 1) for v in item.values()]
        elif isinstance(item, list):
            stack += [(v, d + 1) for v in item]
    return deepest


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


def _type(value: Any) -> str:
    return {dict: "an object", list: "a list", str: "a string", bool: "a boolean", type(None): "null",
            int: "a number", float: "a number"}.get(type(value), type(value).__name__)


def _list(value: Any, where: str) -> list[Any]:
    if not isinstance(value, list):
        raise InstanceError(f"{where}: expected a list, got {_type(value)}")
    return value


def _object(value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise InstanceError(f"{where}: expected an object, got {_type(value)}")
    return value


def _string(value: Any, where: str, what: str = "a string") -> str:
    if not isinstance(value, str):
        raise InstanceError(f"{where}: expected {what}, got {_type(value)}")
    return value


def _bits(value: Any, where: str) -> tuple[int, ...]:
    for n, v in enumerate(_list(value, where)):
        if isinstance(v, bool) or v not in (0, 1):
            raise InstanceError(f"{where}[{n}]: expected 0 or 1, got {_type(v) if not isinstance(v, int) else v}")
    return tuple(value)


def _num(value: Any, where: str) -> float | int:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise InstanceError(f"{where}: expected a number, got {_type(value)}")
    return value


def _amounts(value: Any, where: str) -> tuple[tuple[str, float], ...]:
    """A ``traits``/``requires`` object: trait name -> amount (validated against the
    instance's traits in :func:`~lvws_ros.core.problem.validate_instance`)."""
    return tuple((name, _num(v, f"{where}.{name}")) for name, v in _object(value, where).items())


def _roles(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise InstanceError(f"{where}: expected true or false, got {_type(value)}")
    return value


def _robot(r: Any, where: str, traits_only: bool) -> Robot:
    r = _object(r, where)
    rid = _string(_require(r, "id", where), f"{where}.id", "a robot id")
    try:
        return Robot(
            id=rid,
            capabilities=() if traits_only and "capabilities" not in r else
            _bits(_require(r, "capabilities", where), f"{where}.capabilities"),
            payload=_num(r.get("payload", 0.0) if traits_only else _require(r, "payload", where), f"{where}.payload"),
            extra={k: v for k, v in r.items() if k not in {"id", "capabilities", "payload", "traits"}},
            traits=_amounts(r.get("traits", {}), f"{where}.traits"),
        )
    except InstanceError as exc:
        raise InstanceError(f"{exc} (robot {rid[:40]!r})") from None


_TASK_KEYS = {"id", "capabilities", "payload", "duration", "after", "requires", "roles"}


def _task(t: Any, where: str, traits_only: bool) -> Task:
    t = _object(t, where)
    tid = _string(_require(t, "id", where), f"{where}.id", "a task id")
    try:
        after = _list(t.get("after", []), f"{where}.after")
        return Task(
            id=tid,
            capabilities=() if traits_only and "capabilities" not in t else
            _bits(_require(t, "capabilities", where), f"{where}.capabilities"),
            payload=_num(t.get("payload", 0.0) if traits_only else _require(t, "payload", where), f"{where}.payload"),
            duration=_num(_require(t, "duration", where), f"{where}.duration"),
            after=tuple(_string(p, f"{where}.after[{n}]", "a task id") for n, p in enumerate(after)),
            extra={k: v for k, v in t.items() if k not in _TASK_KEYS},
            requires=_amounts(t.get("requires", {}), f"{where}.requires"),
            roles=_roles(t["roles"], f"{where}.roles") if "roles" in t else None,
        )
    except InstanceError as exc:
        raise InstanceError(f"{exc} (task {tid[:40]!r})") from None


def instance_from_dict(data: Any) -> Instance:
    """Build a validated Instance from parsed ``lvws-instance/1`` JSON; an
    InstanceError names the item (``tasks[3].after[0]: expected a task id, got a list``)."""
    data = _object(data, "instance")
    fmt = data.get("format")
    if fmt != INSTANCE_FORMAT:
        raise InstanceError(f"format: expected {INSTANCE_FORMAT!r}, got {str(fmt)[:40]!r}")
    name = _string(data.get("name", ""), "name")
    traits = tuple(_string(c, f"traits[{n}]", "a trait name")
                   for n, c in enumerate(_list(data.get("traits", []), "traits")))
    traits_only = bool(traits) and "capabilities" not in data  # a file written in traits alone
    caps = () if traits_only else tuple(
        _string(c, f"capabilities[{n}]", "a capability name")
        for n, c in enumerate(_list(_require(data, "capabilities", "instance"), "capabilities")))
    robots = [_robot(r, f"robots[{n}]", traits_only)
              for n, r in enumerate(_list(_require(data, "robots", "instance"), "robots"))]
    tasks = [_task(t, f"tasks[{n}]", traits_only)
             for n, t in enumerate(_list(_require(data, "tasks", "instance"), "tasks"))]
    objective = _string(data.get("objective", "makespan"), "objective")
    roles = _roles(data["roles"], "roles") if "roles" in data else False
    departure = _string(data.get("departure", "together"), "departure")
    if "sites" not in data:  # no travel extension: zero travel, as in every file before it
        homes = [n for n, r in enumerate(robots) if "home" in r.extra]
        if homes:
            raise InstanceError(f"robots[{homes[0]}].home: a home site needs the instance's sites "
                                f"(robot {robots[homes[0]].id[:40]!r})")
        return Instance(name=name, capabilities=caps, robots=tuple(robots), tasks=tuple(tasks), traits=traits,
                        objective=objective, roles=roles, departure=departure)
    travel = _travel(data, robots, tasks)
    robots = [replace(r, extra={k: v for k, v in r.extra.items() if k not in _ROBOT_TRAVEL_KEYS}) for r in robots]
    tasks = [replace(t, extra={k: v for k, v in t.extra.items() if k not in _TASK_TRAVEL_KEYS}) for t in tasks]
    return Instance(name=name, capabilities=caps, robots=tuple(robots), tasks=tuple(tasks), travel=travel,
                    traits=traits, objective=objective, roles=roles, departure=departure)


_ROBOT_TRAVEL_KEYS = {"site", "speed", "home"}
_TASK_TRAVEL_KEYS = {"site", "from", "to"}


def _travel(data: dict[str, Any], robots: list[Robot], tasks: list[Task]) -> Travel:
    """The travel extension of an instance with ``sites`` (formats.md)."""
    sites = _object(data["sites"], "sites")
    distances = _object(data.get("distances", {}), "distances")
    for a, row in distances.items():
        _object(row, f"distances.{a}")
    robot_sites, homes = [], []
    for n, r in enumerate(robots):
        where = f"robots[{n}]"
        site = _string(_require(r.extra, "site", f"{where} (the instance has sites)"), f"{where}.site", "a site name")
        speed = r.extra.get("speed")
        robot_sites.append((r.id, site, None if speed is None else _num(speed, f"{where}.speed")))
        homes.append(_string(r.extra["home"], f"{where}.home", "a site name") if "home" in r.extra else None)
    task_sites = []
    for n, t in enumerate(tasks):
        where = f"tasks[{n}]"
        if "site" in t.extra:
            site = _string(t.extra["site"], f"{where}.site", "a site name")
            task_sites.append((t.id, site, site))
        elif "from" in t.extra and "to" in t.extra:
            task_sites.append((t.id, _string(t.extra["from"], f"{where}.from", "a site name"),
                               _string(t.extra["to"], f"{where}.to", "a site name")))
        else:
            raise InstanceError(f"{where}: missing key 'site' (or 'from' and 'to'): the instance has sites "
                                f"(task {t.id[:40]!r})")
    return build_travel(sites, distances, robot_sites, task_sites, homes)


def instance_to_dict(inst: Instance) -> dict[str, Any]:
    """The ``lvws-instance/1`` object of ``inst``: a file without traits exactly as before
    them; one written in traits alone (no capabilities) again without capabilities and
    with payloads only where not 0."""
    traits_only = bool(inst.traits) and not inst.capabilities
    out: dict[str, Any] = {"format": INSTANCE_FORMAT, "name": inst.name}
    if not traits_only:
        out["capabilities"] = list(inst.capabilities)
    if inst.traits:
        out["traits"] = list(inst.traits)
    if inst.objective != "makespan":
        out["objective"] = inst.objective
    if inst.roles:
        out["roles"] = True
    if inst.departure != "together":
        out["departure"] = inst.departure
    out["robots"] = [{**_needs(r.id, r.capabilities, r.payload, "traits", r.traits, traits_only), **r.extra}
                     for r in inst.robots]
    out["tasks"] = [{**_needs(t.id, t.capabilities, t.payload, "requires", t.requires, traits_only),
                     **({} if t.roles is None else {"roles": t.roles}),
                     "duration": float(t.duration), "after": list(t.after), **t.extra} for t in inst.tasks]
    tr = inst.travel
    if tr is not None:
        out["sites"] = {s: list(xy) for s, xy in zip(tr.sites, tr.coordinates, strict=True)}
        if tr.overrides:
            out["distances"] = {}
            for a, b, d in tr.overrides:
                out["distances"].setdefault(a, {})[b] = d
        for k, r in enumerate(out["robots"]):
            r["site"] = tr.sites[tr.robot_site[k]]
            if tr.robot_speed[k] > 0:
                r["speed"] = tr.robot_speed[k]
            if tr.home(k) != tr.robot_site[k]:
                r["home"] = tr.sites[tr.home(k)]
        for k, t in enumerate(out["tasks"]):
            a, b = tr.sites[tr.task_from[k]], tr.sites[tr.task_to[k]]
            t.update({"site": a} if a == b else {"from": a, "to": b})
    return out


def _needs(item: str, caps: tuple[int, ...], payload: float, key: str, amounts: tuple[tuple[str, float], ...],
           traits_only: bool) -> dict[str, Any]:
    """A robot's or task's id, capabilities, payload and trait amounts (under ``key``) as
    written: without capabilities, and without a payload of 0, in a file of traits alone."""
    out: dict[str, Any] = {"id": item}
    if not traits_only:
        out["capabilities"] = list(caps)
    if not traits_only or payload:
        out["payload"] = float(payload)
    if amounts:
        out[key] = dict(amounts)
    return out


def instance_key(inst: Instance) -> str:
    """A hash of the instance's content (its name left out): caches are keyed by what an
    instance is, so two different instances never share a record, whatever their names."""
    data = instance_to_dict(inst)
    data.pop("name")
    return hashlib.sha256(dumps(data).encode()).hexdigest()[:32]


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


def _sched_number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ScheduleError(f"{where}: expected a number, got {_type(value)}")
    if isinstance(value, int) and abs(value) > 1e300:
        raise ScheduleError(f"{where}: number out of range")
    return float(value)


def _sched_string(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise ScheduleError(f"{where}: expected a string, got {_type(value)}")
    return value


def _assignment(a: Any, where: str) -> Assignment:
    if not isinstance(a, dict):
        raise ScheduleError(f"{where}: expected an object, got {_type(a)}")
    missing = [k for k in ("task", "robots", "start", "end") if k not in a]
    if missing:
        raise ScheduleError(f"{where}: missing key(s) {missing} (needs task, robots, start and end)")
    if not isinstance(a["robots"], list):
        raise ScheduleError(f"{where}.robots: expected a list, got {_type(a['robots'])}")
    return Assignment(_sched_string(a["task"], f"{where}.task"),
                      tuple(_sched_string(r, f"{where}.robots[{n}]") for n, r in enumerate(a["robots"])),
                      _sched_number(a["start"], f"{where}.start"), _sched_number(a["end"], f"{where}.end"))


_SCHEDULE_KEYS = {"format", "instance", "policy", "makespan", "assignments", "decisions", "compute_seconds"}


def schedule_from_dict(data: Any) -> Schedule:
    """Parse ``lvws-schedule/1``; structural problems (types, missing keys, null where a
    number belongs) raise ScheduleError naming the item.

    Semantic problems (overlaps, coverage, ...) are left to
    :func:`~lvws_ros.core.schedule.check_schedule`, so that ``lvws check`` can list
    every violated rule.
    """
    if not isinstance(data, dict):
        raise ScheduleError(f"schedule: expected an object at the top level, got {_type(data)}")
    if data.get("format") != SCHEDULE_FORMAT:
        raise ScheduleError(f"format: expected {SCHEDULE_FORMAT!r}, got {str(data.get('format'))[:40]!r}")
    for key in ("instance", "policy", "makespan", "assignments"):
        if key not in data:
            raise ScheduleError(f"schedule: missing key {key!r}")
    if not isinstance(data["assignments"], list):
        raise ScheduleError(f"assignments: expected a list, got {_type(data['assignments'])}")
    out = [_assignment(a, f"assignments[{n}]") for n, a in enumerate(data["assignments"])]
    decisions = _sched_number(data.get("decisions", 0), "decisions")
    return Schedule(
        instance=_sched_string(data["instance"], "instance"),
        policy=_sched_string(data["policy"], "policy"),
        assignments=out,
        makespan=_sched_number(data["makespan"], "makespan"),
        decisions=int(decisions) if math.isfinite(decisions) else 0,
        compute_seconds=_sched_number(data.get("compute_seconds", 0.0), "compute_seconds"),
        extra={k: v for k, v in data.items() if k not in _SCHEDULE_KEYS},
    )


def load_schedule(path: str | Path) -> Schedule:
    return _load(path, "schedule", schedule_from_dict, ScheduleError)


def save_schedule(s: Schedule, path: str | Path) -> None:
    _write(dumps(schedule_to_dict(s)), path)
