"""Importers for the files users already have, into ``lvws-instance/1`` (formats.md,
"Importing"): the multi-skill project scheduling (MSPSP) instances of the MiniZinc data
format (two layouts), the resource-constrained project scheduling (RCPSP) instances of PSPLIB (its
``.sm`` and the Patterson ``.rcp`` formats), a plain CSV of robots and one of tasks, and
the coalition benchmarks of DCMRTA / CTAS-D (YAML documents, read by the caller with a
safe loader: :func:`dcmrta_instance`).

Every error is an :class:`~lvws_ros.errors.InstanceError` naming the file and the line.
Nothing in a file is evaluated: the DataZinc reader accepts only the assignments the MSPSP
files hold (integers, booleans, arrays, 2-D arrays ``[| ... |]``, sets), the CSV reader is
the standard library's.
"""

from __future__ import annotations

import csv
import itertools
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.core.formats import instance_from_dict
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.subteams import covers
from lvws_ros.core.travel import build_travel
from lvws_ros.errors import InstanceError

__all__ = ["ctas_plan", "dcmrta_instance", "import_csv", "import_mspsp", "import_psplib", "parse_dzn"]

# ---------------------------------------------------------------- DataZinc (MSPSP)

_TOKEN = re.compile(r"\s*(?:(?P<num>-?\d+)|(?P<word>(?:true|false)(?![A-Za-z0-9_]))|(?P<name>[A-Za-z_][A-Za-z0-9_]*)|"
                    r"(?P<sym>\[\||\|\]|[\[\]{},|=;]))")


def _line(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


MAX_DZN_DEPTH = 8  # the MSPSP files nest 2 levels


def parse_dzn(text: str, where: str) -> dict[str, Any]:
    """The assignments ``name = value;`` of a DataZinc text: integers, booleans, 1-D
    arrays ``[a, b]``, 2-D arrays ``[| a, b | c, d |]`` (rows as lists), sets ``{a, b}``
    (as lists). Comments (``%`` to the end of the line) are skipped. InstanceError names
    ``where`` and the line of anything else."""
    text = re.sub(r"%[^\n]*", lambda m: " " * len(m.group()), text)  # keep positions for line numbers
    tokens: list[tuple[str, Any, int]] = []
    pos = 0
    while pos < len(text):
        if text[pos:].strip() == "":
            break
        m = _TOKEN.match(text, pos)
        if m is None:
            start = pos + len(text[pos:]) - len(text[pos:].lstrip())
            raise InstanceError(f"{where} line {_line(text, start)}: unexpected {text[start:start + 20]!r}")
        kind = m.lastgroup or ""
        value: Any = m.group(kind)
        if kind == "num":
            value = int(value)
        elif kind == "word":
            value = value == "true"
        tokens.append((kind, value, m.start(kind)))
        pos = m.end()
    out: dict[str, Any] = {}
    k = 0

    def take(expect: str | None = None) -> tuple[str, Any, int]:
        nonlocal k
        if k >= len(tokens):
            raise InstanceError(f"{where}: unexpected end of file")
        tok = tokens[k]
        if expect is not None and tok[1] != expect:
            raise InstanceError(f"{where} line {_line(text, tok[2])}: expected {expect!r}, got {tok[1]!r}")
        k += 1
        return tok

    def value_at(depth: int = 0) -> Any:
        kind, val, at = take()
        if kind in ("num", "word"):
            return val
        if depth >= MAX_DZN_DEPTH:
            raise InstanceError(f"{where} line {_line(text, at)}: nested deeper than {MAX_DZN_DEPTH} levels")
        if val in ("[", "{"):
            close = "]" if val == "[" else "}"
            items = []
            while tokens[k][1] != close if k < len(tokens) else False:
                items.append(value_at(depth + 1))
                if k < len(tokens) and tokens[k][1] == ",":
                    take(",")
            take(close)
            return items
        if val == "[|":
            rows: list[list[Any]] = [[]]
            while k < len(tokens) and tokens[k][1] != "|]":
                if tokens[k][1] == "|":
                    take("|")
                    rows.append([])
                    continue
                rows[-1].append(value_at(depth + 1))
                if k < len(tokens) and tokens[k][1] == ",":
                    take(",")
            take("|]")
            return [r for r in rows if r]
        raise InstanceError(f"{where} line {_line(text, at)}: unexpected {val!r}")

    while k < len(tokens):
        kind, name, at = take()
        if kind != "name":
            raise InstanceError(f"{where} line {_line(text, at)}: expected a name, got {name!r}")
        take("=")
        out[name] = value_at()
        take(";")
    return out


def _ints(data: dict[str, Any], key: str, where: str, length: int | None = None) -> list[int]:
    value = data.get(key)
    if not isinstance(value, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise InstanceError(f"{where}: {key} must be an array of integers")
    if length is not None and len(value) != length:
        raise InstanceError(f"{where}: {key} has {len(value)} entries, expected {length}")
    return value


def _table(data: dict[str, Any], key: str, where: str, rows: int, cols: int, kind: type) -> list[list[Any]]:
    value = data.get(key)
    if not isinstance(value, list) or len(value) != rows or \
            not all(isinstance(r, list) and len(r) == cols and all(type(v) is kind for v in r) for r in value):
        raise InstanceError(f"{where}: {key} must be a {rows} x {cols} table of {kind.__name__}s")
    return value


def import_mspsp(path: str | Path) -> Instance:
    """An MSPSP instance (multi-skill project scheduling, MiniZinc data) as traits,
    exactly, in either of two layouts, told apart by their names:

    * the MSPSP benchmark library's (``nActs``, ``dur``, ``nSkills``, ``sreq``,
      ``nResources``, ``mastery``, ``pred``/``succ``): each resource a robot ``res<r>``
      with amount 1 of each skill it masters, each activity a task ``act<a>`` requiring
      ``sreq`` units of each skill, with roles (each member fills one skill slot);
    * the MiniZinc benchmarks' (``mspsp.mzn``: ``n_skills``, ``n_workers``, ``has_skills``,
      ``n_tasks``, ``d``, ``rr``, ``suc``): each worker a robot ``worker<j>`` with amount 1
      of each skill it has, each task a task ``task<i>`` requiring ``rr`` units of each
      skill, without roles (that model counts a worker toward every skill it has).

    Activities without duration (the source and sink, and any other: they hold no worker
    for any time) are dropped, their precedences kept through them."""
    p = Path(path)
    where = str(p)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InstanceError(f"{where}: cannot read the MSPSP file: {exc}") from None
    data = parse_dzn(text, where)
    project = _minizinc_mspsp(data, where) if "n_tasks" in data else _library_mspsp(data, where)
    keep = [a for a in range(len(project.duration)) if project.duration[a] > 0]
    for a in keep:
        if not any(project.demand[a]):
            raise InstanceError(f"{where}: {project.noun} {a + 1} lasts {project.duration[a]} but needs no worker: "
                                "lvws schedules tasks done by subteams")
    kept_before = _kept_before(project.before, set(keep))
    skills = [f"skill{s + 1}" for s in range(project.n_skills)]
    robots = tuple(Robot(f"{project.worker}{r + 1}", (), 0.0,
                         traits=tuple((skills[s], 1.0) for s in range(len(skills)) if has[s]))
                   for r, has in enumerate(project.mastery))
    tasks = tuple(Task(f"{project.act}{a + 1}", (), 0.0, float(project.duration[a]),
                       tuple(f"{project.act}{q + 1}" for q in sorted(kept_before(a))),
                       requires=tuple((skills[s], float(n)) for s, n in enumerate(project.demand[a]) if n))
                  for a in keep)
    try:
        return Instance(p.stem, (), robots, tasks, traits=tuple(skills), roles=project.roles)
    except InstanceError as exc:
        raise InstanceError(f"{where}: {exc}") from None


@dataclass
class _Skilled:
    """A multi-skill project as read (0-based): per activity its duration, the workers it
    needs of each skill and the activities it waits for; per worker the skills it has."""

    n_skills: int
    duration: list[int]
    demand: list[list[int]]
    before: dict[int, set[int]]
    mastery: list[list[bool]]
    roles: bool
    act: str  # the prefix of task ids
    noun: str  # an activity, in messages
    worker: str  # the prefix of robot ids


def _count(data: dict[str, Any], key: str, where: str) -> int:
    value = data.get(key)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        raise InstanceError(f"{where}: {key} must be a non-negative integer")
    return value


def _library_mspsp(data: dict[str, Any], where: str) -> _Skilled:
    """The MSPSP benchmark library's layout (:func:`import_mspsp`)."""
    n_acts, n_skills, n_res = (_count(data, key, where) for key in ("nActs", "nSkills", "nResources"))
    dur = _ints(data, "dur", where, n_acts)
    sreq = _table(data, "sreq", where, n_acts, n_skills, int)
    mastery = _table(data, "mastery", where, n_res, n_skills, bool)
    pred, succ = _ints(data, "pred", where), _ints(data, "succ", where, len(_ints(data, "pred", where)))
    before: dict[int, set[int]] = {a: set() for a in range(n_acts)}
    for n, (a, b) in enumerate(zip(pred, succ, strict=True)):
        if not (1 <= a <= n_acts and 1 <= b <= n_acts):
            raise InstanceError(f"{where}: precedence {n + 1} ({a} -> {b}) names an activity outside 1..{n_acts}")
        before[b - 1].add(a - 1)
    return _Skilled(n_skills, dur, sreq, before, mastery, True, "act", "activity", "res")


def _sets(data: dict[str, Any], key: str, where: str, length: int, top: int, what: str) -> list[set[int]]:
    """``key`` as ``length`` sets of integers in 1..``top`` (``what`` they name)."""
    value = data.get(key)
    if not isinstance(value, list) or not all(isinstance(v, list) for v in value):
        raise InstanceError(f"{where}: {key} must be an array of sets of {what}s")
    if len(value) != length:
        raise InstanceError(f"{where}: {key} has {len(value)} entries, expected {length}")
    for n, items in enumerate(value):
        for v in items:
            if not isinstance(v, int) or isinstance(v, bool) or not 1 <= v <= top:
                raise InstanceError(f"{where}: {key}[{n + 1}] names {what} {v!r}, outside 1..{top}")
    return [set(items) for items in value]


def _minizinc_mspsp(data: dict[str, Any], where: str) -> _Skilled:
    """The MiniZinc benchmarks' layout (``mspsp.mzn``; :func:`import_mspsp`)."""
    n_skills, n_workers, n_tasks = (_count(data, key, where) for key in ("n_skills", "n_workers", "n_tasks"))
    has = _sets(data, "has_skills", where, n_workers, n_skills, "skill")
    dur = _ints(data, "d", where, n_tasks)
    rr = _table(data, "rr", where, n_skills, n_tasks, int)
    suc = _sets(data, "suc", where, n_tasks, n_tasks, "task")
    for i, v in enumerate(dur):
        if v < 0:
            raise InstanceError(f"{where}: d[{i + 1}] is {v}, expected a duration >= 0")
    for k, row in enumerate(rr):
        for i, v in enumerate(row):
            if v < 0:
                raise InstanceError(f"{where}: rr[{k + 1}, {i + 1}] is {v}, expected a number of workers >= 0")
    before: dict[int, set[int]] = {i: set() for i in range(n_tasks)}
    for i, later in enumerate(suc):
        for j in later:
            before[j - 1].add(i)
    demand = [[rr[k][i] for k in range(n_skills)] for i in range(n_tasks)]
    mastery = [[s + 1 in h for s in range(n_skills)] for h in has]
    return _Skilled(n_skills, dur, demand, before, mastery, False, "task", "task", "worker")


def _kept_before(before: dict[int, set[int]], kept: set[int]) -> Callable[[int], set[int]]:
    """The kept activities each activity must wait for, through the dropped ones (those
    without duration: a precedence chain through them still holds)."""

    def kept_before(a: int) -> set[int]:
        out: set[int] = set()
        stack, seen = list(before[a]), set(before[a])
        while stack:
            q = stack.pop()
            if q in kept:
                out.add(q)
                continue
            for p in before[q] - seen:
                seen.add(p)
                stack.append(p)
        return out

    return kept_before


# ---------------------------------------------------------------- PSPLIB (RCPSP)

IDLE_TRAIT = "no_resource"  # held by the stand-ins of activities that need no resource


@dataclass
class _Project:
    """A single-mode RCPSP as read: per job (1-based in the file, 0-based here) its
    duration, demand of each renewable resource and successors, and the lines they are on."""

    capacity: list[int]
    duration: list[int]
    demand: list[list[int]]
    successors: list[list[int]]
    line: list[int]  # of its duration and demands
    succ_line: list[int]  # of its successors


def _numbers(text: str, where: str, line: int) -> list[int]:
    try:
        values = [int(v) for v in text.split()]
    except ValueError:
        raise InstanceError(f"{where} line {line}: expected integers, got {text.strip()[:40]!r}") from None
    if any(v < 0 for v in values):
        raise InstanceError(f"{where} line {line}: expected non-negative integers, got {text.strip()[:40]!r}")
    return values


def _read_rcp(lines: list[str], where: str) -> _Project:
    """The Patterson format: ``jobs resources``, the capacities, then per job its
    duration, its demands, the number of successors and the successors (a job's numbers
    may run on over several lines)."""
    tokens = [(v, n + 1) for n, text in enumerate(lines) for v in _numbers(text, where, n + 1)]
    k = 0

    def take(what: str) -> tuple[int, int]:
        nonlocal k
        if k >= len(tokens):
            raise InstanceError(f"{where} line {len(lines)}: the file ends before {what}")
        k += 1
        return tokens[k - 1]

    n_jobs, n_res = take("the number of jobs")[0], take("the number of resources")[0]
    capacity = [take(f"the capacity of resource {r + 1}")[0] for r in range(n_res)]
    out = _Project(capacity, [], [], [], [], [])
    for job in range(n_jobs):
        d, line = take(f"job {job + 1}")
        out.duration.append(d)
        out.line.append(line)
        out.succ_line.append(line)
        out.demand.append([take(f"job {job + 1}'s demands")[0] for _ in range(n_res)])
        count = take(f"job {job + 1}'s number of successors")[0]
        out.successors.append([take(f"job {job + 1}'s successors")[0] for _ in range(count)])
    if k < len(tokens):
        raise InstanceError(f"{where} line {tokens[k][1]}: more numbers than the {n_jobs} jobs declared")
    return out


def _sm_header(lines: list[str], where: str, label: str) -> tuple[int, int]:
    """The number after ``label :`` on its line of an ``.sm`` file, and that line's index."""
    for n, text in enumerate(lines):
        if text.strip().startswith(label) and ":" in text:
            value = text.split(":", 1)[1].split()
            if not value or not value[0].isdigit():
                raise InstanceError(f"{where} line {n + 1}: expected a number after {label!r}")
            return int(value[0]), n
    raise InstanceError(f"{where}: no {label!r} line (not a PSPLIB .sm file?)")


def _sm_rows(lines: list[str], where: str, section: str, count: int, width: int) -> list[tuple[list[int], int]]:
    """The ``count`` rows of numbers after the line starting with ``section`` (header and
    separator lines skipped), each with at least ``width`` numbers, and their line numbers."""
    at = next((n for n, text in enumerate(lines) if text.strip().startswith(section)), None)
    if at is None:
        raise InstanceError(f"{where}: no {section!r} section")
    rows: list[tuple[list[int], int]] = []
    n = at + 1
    while len(rows) < count:
        if n >= len(lines):
            raise InstanceError(f"{where} line {n}: {section} ends after {len(rows)} of {count} rows")
        text = lines[n].strip()
        n += 1
        if not rows and (not text or not text.split()[0].isdigit()):
            continue  # the column names and separators
        row = _numbers(text, where, n)
        if len(row) < width:
            raise InstanceError(f"{where} line {n}: {section} expected at least {width} numbers, got {len(row)}")
        rows.append((row, n))
    return rows


def _read_sm(lines: list[str], where: str) -> _Project:
    """The PSPLIB ``.sm`` format (single mode): the numbers of jobs and resources from the
    header, the precedence relations, the requests and durations, the availabilities."""
    n_jobs, _ = _sm_header(lines, where, "jobs (incl. supersource/sink )")
    n_res, _ = _sm_header(lines, where, "- renewable")
    n_non, at = _sm_header(lines, where, "- nonrenewable")
    if n_non:
        raise InstanceError(f"{where} line {at + 1}: nonrenewable resources are not supported (renewable only)")
    out = _Project([], [], [], [], [], [])
    for job, (row, line) in enumerate(_sm_rows(lines, where, "PRECEDENCE RELATIONS:", n_jobs, 3)):
        if row[0] != job + 1:
            raise InstanceError(f"{where} line {line}: expected job {job + 1}, got {row[0]}")
        if row[1] != 1:
            raise InstanceError(f"{where} line {line}: job {job + 1} has {row[1]} modes; only single-mode "
                                "files (.sm) are supported")
        if len(row) != 3 + row[2]:
            raise InstanceError(f"{where} line {line}: job {job + 1} lists {len(row) - 3} successors, "
                                f"declares {row[2]}")
        out.successors.append(row[3:])
        out.succ_line.append(line)
    for job, (row, line) in enumerate(_sm_rows(lines, where, "REQUESTS/DURATIONS:", n_jobs, 3 + n_res)):
        if row[0] != job + 1 or len(row) != 3 + n_res:
            raise InstanceError(f"{where} line {line}: expected job {job + 1}, its mode, duration and "
                                f"{n_res} demands")
        out.duration.append(row[2])
        out.demand.append(row[3:])
        out.line.append(line)
    row, line = _sm_rows(lines, where, "RESOURCEAVAILABILITIES:", 1, n_res)[0]
    if len(row) != n_res:
        raise InstanceError(f"{where} line {line}: expected {n_res} availabilities, got {len(row)}")
    out.capacity = row
    return out


def import_psplib(path: str | Path) -> Instance:
    """A resource-constrained project scheduling instance of PSPLIB, in its ``.sm``
    format (single mode) or the Patterson format (``.rcp``; told apart by content), as
    traits, exactly: each unit of renewable resource ``k`` is a robot ``R<k>_<u>`` with
    trait ``R<k>`` at 1, each activity a task ``job<n>`` that requires its demands, and
    the precedence relations as ``after``; no travel. Activities without duration (the
    source and sink) are dropped, their precedences kept through them. An activity that
    lasts but needs no resource requires one ``no_resource`` unit, held by as many
    stand-in robots as there are such activities (it then waits for nothing)."""
    p = Path(path)
    where = str(p)
    try:
        lines = p.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise InstanceError(f"{where}: cannot read the PSPLIB file: {exc}") from None
    sm = any(text.strip().startswith("PRECEDENCE RELATIONS:") for text in lines)
    project = _read_sm(lines, where) if sm else _read_rcp(lines, where)
    return _project_instance(project, p.stem, where)


def _project_instance(project: _Project, name: str, where: str) -> Instance:
    n_jobs, cap = len(project.duration), project.capacity
    traits = [f"R{r + 1}" for r in range(len(cap))]
    before: dict[int, set[int]] = {a: set() for a in range(n_jobs)}
    for a, succ in enumerate(project.successors):
        for b in succ:
            if not 1 <= b <= n_jobs:
                raise InstanceError(f"{where} line {project.succ_line[a]}: job {a + 1}'s successor {b} is outside "
                                    f"1..{n_jobs}")
            before[b - 1].add(a)
    keep = [a for a in range(n_jobs) if project.duration[a] > 0]
    idle = [a for a in keep if not any(project.demand[a])]
    for a in keep:
        for r, d in enumerate(project.demand[a]):
            if d > cap[r]:
                raise InstanceError(f"{where} line {project.line[a]}: job {a + 1} needs {d} of resource {r + 1}, "
                                    f"its capacity is {cap[r]}")
    kept_before = _kept_before(before, set(keep))
    robots = [Robot(f"R{r + 1}_{u + 1}", (), 0.0, traits=((traits[r], 1.0),)) for r in range(len(cap))
              for u in range(cap[r])]
    robots += [Robot(f"{IDLE_TRAIT}_{u + 1}", (), 0.0, traits=((IDLE_TRAIT, 1.0),)) for u in range(len(idle))]
    tasks = tuple(Task(f"job{a + 1}", (), 0.0, float(project.duration[a]),
                       tuple(f"job{q + 1}" for q in sorted(kept_before(a))),
                       requires=tuple((traits[r], float(d)) for r, d in enumerate(project.demand[a]) if d)
                       or ((IDLE_TRAIT, 1.0),))
                  for a in keep)
    if not tasks:
        raise InstanceError(f"{where}: no activity lasts any time")
    try:
        return Instance(name, (), tuple(robots), tasks, traits=tuple(traits) + ((IDLE_TRAIT,) if idle else ()))
    except InstanceError as exc:  # what needs the whole instance (a cycle)
        raise InstanceError(f"{where}: {exc}") from None


# ---------------------------------------------------------------- CSV

_ROBOT_COLUMNS = {"id", "site", "speed", "home"}
_TASK_COLUMNS = {"id", "duration", "after", "site", "from", "to", "roles"}


def _rows(path: Path) -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:  # utf-8-sig: a spreadsheet's byte-order mark
            reader = csv.DictReader(f)
            rows = [(reader.line_num, row) for row in reader]
            header = list(reader.fieldnames or [])
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InstanceError(f"{path}: cannot read the CSV file: {exc}") from None
    if "id" not in header:
        raise InstanceError(f"{path} line 1: the header needs an 'id' column, got {header}")
    if len(set(header)) != len(header):
        raise InstanceError(f"{path} line 1: duplicate column names in {header}")
    seen: dict[str, int] = {}
    for line, row in rows:
        if None in row or any(v is None for v in row.values()):
            raise InstanceError(f"{path} line {line}: {len(header)} columns expected")
        rid = row["id"].strip()
        if not rid:
            raise InstanceError(f"{path} line {line}: id: empty")
        if rid in seen:
            raise InstanceError(f"{path} line {line}: id {rid!r} already on line {seen[rid]}")
        seen[rid] = line
    return header, rows


def _amount(text: str, where: str, positive: bool = False) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InstanceError(f"{where}: expected a number, got {text!r}") from None
    if not math.isfinite(value) or value < 0 or (positive and value == 0):
        raise InstanceError(f"{where}: expected a finite number {'> 0' if positive else '>= 0'}, got {text!r}")
    return value


def import_csv(robots_csv: str | Path, tasks_csv: str | Path, sites_csv: str | Path | None = None,
               name: str | None = None, objective: str = "makespan") -> Instance:
    """An instance in traits from two CSV files (formats.md, "Importing"): robots (``id``,
    optional ``site``, ``speed``, ``home``; every other column a trait amount) and tasks
    (``id``, ``duration``, optional ``after`` (ids separated by spaces or ``;``), ``site``
    or ``from``/``to``, ``roles`` (true/false); every other column a trait requirement).
    With sites (``sites_csv``: ``name,x,y``) the travel extension applies. Empty cells are
    0 or absent. InstanceError names the file and the line."""
    rp, tp = Path(robots_csv), Path(tasks_csv)
    r_head, r_rows = _rows(rp)
    t_head, t_rows = _rows(tp)
    traits = _csv_traits(rp, r_head, tp, t_head)
    sites = _csv_sites(Path(sites_csv)) if sites_csv is not None else {}
    robots, robot_sites, homes = _csv_robots(rp, r_rows, traits, sites)
    tasks, task_sites = _csv_tasks(tp, t_rows, traits, sites)
    try:
        travel = build_travel(sites, {}, robot_sites, task_sites, homes) if sites else None
        return Instance(name or tp.stem, (), tuple(robots), tuple(tasks), travel=travel, traits=tuple(traits),
                        objective=objective)
    except InstanceError as exc:  # what needs the whole instance (a cycle, a task no robot can cover)
        raise InstanceError(f"{rp} and {tp}: {exc}") from None


def _csv_traits(rp: Path, r_head: list[str], tp: Path, t_head: list[str]) -> list[str]:
    """The traits: the robots' columns that are no robot field; InstanceError for a trait
    named as a task field, a task column that is neither, or no ``duration`` column."""
    traits = [c for c in r_head if c not in _ROBOT_COLUMNS]
    taken = [c for c in traits if c in _TASK_COLUMNS]
    if taken:
        raise InstanceError(f"{rp} line 1: column(s) {taken} are task fields, not traits: name the traits otherwise")
    unknown = [c for c in t_head if c not in _TASK_COLUMNS and c not in traits]
    if unknown:
        raise InstanceError(f"{tp} line 1: column(s) {unknown} are neither task fields nor robot traits "
                            f"(traits: {traits})")
    if "duration" not in t_head:
        raise InstanceError(f"{tp} line 1: the header needs a 'duration' column")
    return traits


def _csv_sites(sp: Path) -> dict[str, list[float]]:
    """The sites file (``name,x,y``; a header line ``name,...`` and empty lines skipped)."""
    sites: dict[str, list[float]] = {}
    try:
        with sp.open(newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f)
            for cells in reader:
                where = f"{sp} line {reader.line_num}"
                if not any(c.strip() for c in cells) or \
                        (reader.line_num == 1 and cells and cells[0].strip().lower() == "name"):
                    continue
                if len(cells) != 3:
                    raise InstanceError(f"{where}: expected name,x,y")
                sites[cells[0].strip()] = [_coord(cells[1], f"{where}: x"), _coord(cells[2], f"{where}: y")]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise InstanceError(f"{sp}: cannot read the CSV file: {exc}") from None
    return sites


def _csv_robots(rp: Path, rows: list[tuple[int, dict[str, str]]], traits: list[str], sites: dict[str, list[float]]
                ) -> tuple[list[Robot], list[tuple[str, str, float | None]], list[str | None]]:
    """The robots, and with sites each robot's (id, site, speed) and home."""
    robots, robot_sites, homes = [], [], []
    for line, row in rows:
        where = f"{rp} line {line}"
        rid = row["id"].strip()
        amounts = tuple((c, _amount(row[c], f"{where}: {c}")) for c in traits if row[c].strip())
        robots.append(Robot(rid, (), 0.0, traits=tuple((c, a) for c, a in amounts if a > 0)))
        if sites:
            site, home = row.get("site", "").strip(), row.get("home", "").strip()
            if not site:
                raise InstanceError(f"{where}: site: every robot needs a site when there are sites")
            for what, name in (("site", site), ("home", home)):
                if name and name not in sites:
                    raise InstanceError(f"{where}: {what}: unknown site {name!r} (sites: {', '.join(list(sites)[:10])})")
            speed = row.get("speed", "").strip()
            if home and home != site and not speed:
                raise InstanceError(f"{where}: home: a fixed robot (no speed) stays at its site {site!r}")
            robot_sites.append((rid, site, _amount(speed, f"{where}: speed", positive=True) if speed else None))
            homes.append(home or None)
        elif any(row.get(c, "").strip() for c in ("site", "speed", "home")):
            raise InstanceError(f"{where}: site, speed and home need the sites file (--sites)")
    return robots, robot_sites, homes


def _csv_tasks(tp: Path, rows: list[tuple[int, dict[str, str]]], traits: list[str], sites: dict[str, list[float]]
               ) -> tuple[list[Task], list[tuple[str, str, str]]]:
    """The tasks, and with sites each task's (id, site or from, site or to)."""
    tasks, task_sites = [], []
    known = {row["id"].strip() for _, row in rows}
    for line, row in rows:
        where = f"{tp} line {line}"
        tid = row["id"].strip()
        if not sites and any(row.get(c, "").strip() for c in ("site", "from", "to")):
            raise InstanceError(f"{where}: site, from and to need the sites file (--sites)")
        needs = tuple((c, _amount(row[c], f"{where}: {c}")) for c in traits if c in row and row[c].strip())
        roles_text = row.get("roles", "").strip().lower()
        if roles_text not in ("", "true", "false", "1", "0", "yes", "no"):
            raise InstanceError(f"{where}: roles: expected true or false, got {row['roles']!r}")
        after = tuple(a for a in re.split(r"[\s;]+", row.get("after", "") or "") if a)
        unknown_after = [a for a in after if a not in known]
        if unknown_after:
            raise InstanceError(f"{where}: after: unknown task id(s) {unknown_after}")
        tasks.append(Task(tid, (), 0.0, _amount(row["duration"], f"{where}: duration", positive=True), after,
                          requires=tuple((c, a) for c, a in needs if a > 0),
                          roles=None if not roles_text else roles_text in ("true", "1", "yes")))
        if sites:
            a = row.get("site", "").strip() or row.get("from", "").strip()
            b = row.get("site", "").strip() or row.get("to", "").strip()
            if not a or not b:
                raise InstanceError(f"{where}: site (or from and to): every task needs one when there are sites")
            for name in {a, b} - set(sites):
                raise InstanceError(f"{where}: unknown site {name!r} (sites: {', '.join(list(sites)[:10])})")
            task_sites.append((tid, a, b))
    return tasks, task_sites


def _coord(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InstanceError(f"{where}: expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise InstanceError(f"{where}: expected a finite number, got {text!r}")
    return value


# ---------------------------------------------------------------- DCMRTA / CTAS-D test sets

def _dcmrta_get(data: Any, key: str, where: str) -> Any:
    if not isinstance(data, dict) or key not in data:
        raise InstanceError(f"{where}: '{key}' is missing")
    return data[key]


def _dcmrta_number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InstanceError(f"{where}: expected a number, got {value!r}")
    return float(value)


def _dcmrta_distances(graph: dict[str, Any], n: int, where: str) -> tuple[np.ndarray, float]:
    """The (n + 1) x (n + 1) distances among the tasks and the depot (index n; the graph's
    start and end depot nodes n and n + 1 are one place) and the speed (distance / time)."""
    dist = np.full((n + 1, n + 1), np.nan)
    np.fill_diagonal(dist, 0.0)
    speeds = []
    for key, edge in graph.items():
        if not key.startswith("edge"):
            continue
        at = f"{where} '{key}'"
        if not isinstance(edge, list) or len(edge) != 6:
            raise InstanceError(f"{at}: an edge is [from, to, energy, energy variance, distance, time]")
        a, b = (int(_dcmrta_number(v, at)) for v in edge[:2])
        d, t = _dcmrta_number(edge[3], at), _dcmrta_number(edge[5], at)
        a, b = min(a, n), min(b, n)
        if not (0 <= a <= n and 0 <= b <= n) or d < 0 or t < 0:
            raise InstanceError(f"{at}: node or value out of range ({n} tasks)")
        dist[a, b] = dist[b, a] = d
        if d > 0 and t > 0:
            speeds.append(d / t)
    if np.isnan(dist).any():
        a, b = np.argwhere(np.isnan(dist))[0]
        raise InstanceError(f"{where}: no edge between nodes {a} and {b}")
    if not speeds or max(speeds) - min(speeds) > 1e-6 * max(speeds):
        raise InstanceError(f"{where}: the edges' distance / time ratios differ (one speed per vehicle type)")
    return dist, speeds[0]


def _planar(dist: np.ndarray, where: str) -> np.ndarray:
    """Points in the plane whose straight-line distances are ``dist`` (classical
    multidimensional scaling, exact for points of a plane), the last one at the origin."""
    m = len(dist)
    centre = np.eye(m) - 1.0 / m
    w, v = np.linalg.eigh(-0.5 * centre @ (dist ** 2) @ centre)
    xy: np.ndarray = v[:, -2:] * np.sqrt(np.clip(w[-2:], 0.0, None))
    err = np.abs(np.linalg.norm(xy[:, None] - xy[None], axis=2) - dist).max()
    if err > 1e-6 * max(1.0, float(dist.max())):
        raise InstanceError(f"{where}: the distances are not those of points in a plane (off by {err:.3g})")
    centred: np.ndarray = xy - xy[-1]
    return centred


def _trilaterate(xy: np.ndarray, d: np.ndarray, scale: float) -> np.ndarray:
    """A point of the plane at distances ``d`` from the points ``xy`` (exact for consistent
    data): from the points' own frame (their first point at the origin, their principal
    direction first), the coordinate along each direction the points span is linear in the
    squared distances; across a direction they do not span (collinear points, one point)
    the offset is what the distance leaves (one of two mirror images, both consistent)."""
    if len(xy) == 0:
        return np.zeros(2)
    origin = xy[0]
    _, sv, vt = np.linalg.svd(xy - origin)
    spanned = int(np.sum(sv > 1e-9 * scale))
    frame = (xy - origin) @ vt.T  # coordinates in the frame: (n, 2)
    q = np.zeros(2)
    if spanned:
        # |q - f_j|^2 = d_j^2, less the same for f_0 = 0: 2 f_j . q = |f_j|^2 - d_j^2 + d_0^2
        a = 2.0 * frame[1:, :spanned]
        b = (frame[1:, :spanned] ** 2).sum(axis=1) - d[1:] ** 2 + d[0] ** 2
        q[:spanned] = np.linalg.lstsq(a, b, rcond=None)[0]
    if spanned < 2:
        q[1] = math.sqrt(max(0.0, float(d[0] ** 2 - q[0] ** 2)))
    out: np.ndarray = origin + q @ vt
    return out


def _depot_at(tasks_xy: np.ndarray, dist: np.ndarray, where: str) -> list[float]:
    """The point whose straight-line distances to the tasks' points ``tasks_xy`` are the
    depot row of ``dist`` (a vehicle type's graph, its depot last): trilateration, exact for
    points of a plane; InstanceError when the type's graph places the tasks elsewhere."""
    n = len(tasks_xy)
    err = np.abs(np.linalg.norm(tasks_xy[:, None] - tasks_xy[None], axis=2) - dist[:n, :n]).max()
    scale = max(1.0, float(dist.max()))
    if err > 1e-6 * scale:
        raise InstanceError(f"{where}: its distances among the tasks differ from the first vehicle type's "
                            f"(off by {err:.3g})")
    d = dist[n, :n]
    p = _trilaterate(tasks_xy, d, scale)
    off = np.abs(np.linalg.norm(tasks_xy - p, axis=1) - d).max()
    if off > 1e-6 * scale:
        raise InstanceError(f"{where}: its depot's distances are not those of a point in the tasks' plane "
                            f"(off by {off:.3g})")
    return [float(p[0]), float(p[1])]


def dcmrta_instance(graph: dict[str, Any], tasks: dict[str, Any], vehicles: dict[str, Any],
                    planner: dict[str, Any], name: str, where: str) -> Instance:
    """An instance in traits from the four YAML documents (already read) of one instance of
    the DCMRTA / CTAS-D test sets (``graph.yaml``, ``task_param.yaml``,
    ``vehicle_param.yaml``, ``planner_param.yaml``): ``vehNumPerType`` robots of each
    vehicle type with its ``capVector`` as traits ``cap0``, ``cap1``, ..., all at their
    type's depot and back there at the end (``"objective": "return"``), each setting out for
    its next task as soon as it is free (``"departure": "each"``: the benchmarks' robots
    travel on their own and wait at a task for the rest of its coalition); each task at its own
    site (recovered from the distances: :func:`_planar`), its duration the graph's node
    weight, its requirement the ``capReq`` of each ``and`` clause (one ``or`` alternative
    each). The travel time is distance / speed as the graph's edges give it. Each vehicle
    type's graph has its own depot node: one site ``depot`` where all of them are at one
    place (DCMRTA), else ``depot0``, ``depot1``, ... (HeteroMRTA's test set: a depot per
    species), each placed by its distances to the tasks (:func:`_depot_at`). ``where``
    names the files in errors."""
    n = int(_dcmrta_number(_dcmrta_get(planner, "taskNum", where), where))
    counts = _dcmrta_get(planner, "vehNumPerType", where)
    if not isinstance(counts, list) or not counts:
        raise InstanceError(f"{where}: 'vehNumPerType' must be a list of counts")
    traits = [f"cap{c}" for c in range(int(_dcmrta_number(_dcmrta_get(planner, "capNum", where), where)))]
    sites: dict[str, list[float]] = {}
    depots: list[list[float]] = []
    robots: list[dict[str, Any]] = []
    durations: list[float] = []
    xy = np.zeros((0, 2))
    for k, count in enumerate(counts):
        vk = f"vehicle{k}"
        dist, speed = _dcmrta_distances(_dcmrta_get(graph, vk, where), n, f"{where} {vk}")
        if not sites:
            xy = _planar(dist, where)
            sites = {f"t{j}": [float(xy[j, 0]), float(xy[j, 1])] for j in range(n)}
            durations = [_dcmrta_number(_dcmrta_get(graph[vk], f"node{j}", f"{where} {vk}"), f"{where} node{j}")
                         for j in range(n)]
        depots.append([0.0, 0.0] if k == 0 else _depot_at(xy[:n], dist, f"{where} {vk}"))
        caps = _dcmrta_get(_dcmrta_get(vehicles, vk, where), "capVector", f"{where} {vk}")
        if not isinstance(caps, list) or len(caps) != len(traits):
            raise InstanceError(f"{where} {vk}: 'capVector' must hold {len(traits)} amounts")
        amounts = {t: _dcmrta_number(c, f"{where} {vk} capVector") for t, c in zip(traits, caps, strict=True)}
        robots += [{"id": f"v{k}_{r}", "traits": amounts, "speed": speed}
                   for r in range(int(_dcmrta_number(count, f"{where} vehNumPerType")))]
    one = max(math.dist(p, depots[0]) for p in depots) <= 1e-6 * max(1.0, float(np.abs(xy).max(initial=0.0)))
    sites |= {"depot": depots[0]} if one else {f"depot{k}": p for k, p in enumerate(depots)}
    for robot in robots:
        depot = "depot" if one else f"depot{robot['id'][1:].split('_')[0]}"
        robot |= {"site": depot, "home": depot}
    out_tasks = []
    for j in range(n):
        at = f"{where} task{j}"
        needs: dict[str, float] = {}
        for clause, alternatives in _dcmrta_get(tasks, f"task{j}", where).items():
            if not isinstance(alternatives, dict) or len(alternatives) != 1:
                raise InstanceError(f"{at} {clause}: exactly one 'or' alternative is supported")
            need = next(iter(alternatives.values()))
            cap = int(_dcmrta_number(_dcmrta_get(need, "capId", at), at))
            if not 0 <= cap < len(traits) or not _dcmrta_get(need, "geq", at):
                raise InstanceError(f"{at} {clause}: capId {cap} out of range, or not a 'geq' requirement")
            needs[traits[cap]] = needs.get(traits[cap], 0.0) + _dcmrta_number(_dcmrta_get(need, "capReq", at), at)
        out_tasks.append({"id": f"t{j}", "requires": needs, "duration": durations[j], "after": [], "site": f"t{j}"})
    return instance_from_dict({"format": "lvws-instance/1", "name": name, "traits": traits, "objective": "return",
                               "departure": "each", "sites": sites, "robots": robots, "tasks": out_tasks})


def ctas_plan(results: dict[str, Any], inst: Instance, where: str) -> Schedule:
    """The plan of a CTAS-D ``results.yaml`` (already read: its ``vehicle`` routes, each a
    vehicle ``type`` (1-based) and the ``node`` list it visits, 0 the depot, task ``k`` node
    ``k + 1``) as a schedule of ``inst`` (:func:`dcmrta_instance` of the same folder): the
    vehicles of each type are its robots ``v<type>_0``, ``v<type>_1``, ... in the file's
    order; each task's subteam is the robots that visit it, in each robot's route order.
    Its times are the order alone (a task's start is its rank among the tasks its robots
    visit before it): ``lvws import dcmrta --plan`` has the executor carry it out
    (``"departure": "each"``: each robot sets out once free, the task starts when the last
    is there), and the makespan then equals the file's ``timeCost`` / 100 (its ``nodeTime``
    is not read)."""
    routes = _dcmrta_get(results, "vehicle", where)
    if not isinstance(routes, dict):
        raise InstanceError(f"{where} 'vehicle': expected a mapping of routes")
    used: dict[int, int] = {}
    teams: dict[int, list[str]] = {}
    order: dict[str, list[int]] = {}  # each robot's tasks in its route's order
    for key, route in routes.items():
        at = f"{where} vehicle {key!r}"
        kind = int(_dcmrta_number(_dcmrta_get(route, "type", at), at)) - 1
        rid = f"v{kind}_{used.get(kind, 0)}"
        used[kind] = used.get(kind, 0) + 1
        if rid not in inst.robot_index:
            raise InstanceError(f"{at}: no robot {rid!r} in {inst.name!r} (type {kind + 1})")
        nodes = _dcmrta_get(route, "node", at)
        if not isinstance(nodes, list):
            raise InstanceError(f"{at} 'node': expected a list")
        for node in nodes:
            k = int(_dcmrta_number(node, f"{at} node"))
            if k == 0:
                continue
            if not 1 <= k <= inst.num_tasks:
                raise InstanceError(f"{at}: node {k} is not a task of {inst.name!r}")
            teams.setdefault(k - 1, []).append(rid)
            order.setdefault(rid, []).append(k - 1)
    missing = [inst.tasks[j].id for j in range(inst.num_tasks) if j not in teams]
    if missing:
        raise InstanceError(f"{where}: the plan leaves task {missing[0]!r} out")
    for j, team in sorted(teams.items()):
        idx = [inst.robot_index[r] for r in team]
        if len(set(idx)) != len(idx) or not covers(inst.robot_amounts[idx], inst.robot_payload[idx],
                                                   inst.task_needs[j], inst.tasks[j].payload, bool(inst.task_roles[j])):
            raise InstanceError(f"{where}: the robots visiting task {inst.tasks[j].id!r} ({', '.join(team)}) "
                                "do not cover it (or one visits it twice)")
    rank = {j: 0 for j in teams}
    for _ in range(inst.num_tasks):  # a task after every task any of its robots visits before it
        changed = False
        for tasks in order.values():
            for a, b in itertools.pairwise(tasks):
                if rank[b] <= rank[a]:
                    rank[b], changed = rank[a] + 1, True
        if not changed:
            break
    else:
        raise InstanceError(f"{where}: the routes visit tasks in orders that contradict each other")
    out = [Assignment(inst.tasks[j].id, tuple(sorted(teams[j])), float(rank[j]), rank[j] + 0.5) for j in teams]
    return Schedule.from_assignments(inst, "ctas-d", out)
