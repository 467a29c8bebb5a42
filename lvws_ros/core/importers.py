"""Importers for the files users already have, into ``lvws-instance/1`` (formats.md,
"Importing"): the multi-skill project scheduling (MSPSP) instances of the MiniZinc data
format, the resource-constrained project scheduling (RCPSP) instances of PSPLIB (its
``.sm`` and the Patterson ``.rcp`` formats), and a plain CSV of robots and one of tasks.

Every error is an :class:`~lvws_ros.errors.InstanceError` naming the file and the line.
Nothing in a file is evaluated: the DataZinc reader accepts only the assignments the MSPSP
files hold (integers, booleans, arrays, 2-D arrays ``[| ... |]``, sets), the CSV reader is
the standard library's.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.travel import build_travel
from lvws_ros.errors import InstanceError

__all__ = ["import_csv", "import_mspsp", "import_psplib", "parse_dzn"]

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
    """An MSPSP instance (the MiniZinc data files of the multi-skill project scheduling
    benchmarks: ``nActs``, ``dur``, ``nSkills``, ``sreq``, ``nResources``, ``mastery``,
    ``pred``/``succ``) as traits with roles, exactly: each resource is a robot with amount 1
    of each skill it masters, each activity a task requiring ``sreq`` units of each skill,
    and with roles each member fills one skill slot. Activities without duration (the
    source and sink, and any other: they hold no worker for any time) are dropped, their
    precedences kept through them."""
    p = Path(path)
    where = str(p)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InstanceError(f"{where}: cannot read the MSPSP file: {exc}") from None
    data = parse_dzn(text, where)
    for key in ("nActs", "nSkills", "nResources"):
        if not isinstance(data.get(key), int) or isinstance(data.get(key), bool) or data[key] < 0:
            raise InstanceError(f"{where}: {key} must be a non-negative integer")
    n_acts, n_skills, n_res = data["nActs"], data["nSkills"], data["nResources"]
    dur = _ints(data, "dur", where, n_acts)
    sreq = _table(data, "sreq", where, n_acts, n_skills, int)
    mastery = _table(data, "mastery", where, n_res, n_skills, bool)
    pred, succ = _ints(data, "pred", where), _ints(data, "succ", where, len(_ints(data, "pred", where)))
    skills = [f"skill{s + 1}" for s in range(n_skills)]
    keep = [a for a in range(n_acts) if dur[a] > 0]
    for a in keep:
        if not any(sreq[a]):
            raise InstanceError(f"{where}: activity {a + 1} lasts {dur[a]} but needs no worker: lvws schedules "
                                "tasks done by subteams")
    before: dict[int, set[int]] = {a: set() for a in range(n_acts)}
    for n, (a, b) in enumerate(zip(pred, succ, strict=True)):
        if not (1 <= a <= n_acts and 1 <= b <= n_acts):
            raise InstanceError(f"{where}: precedence {n + 1} ({a} -> {b}) names an activity outside 1..{n_acts}")
        before[b - 1].add(a - 1)
    kept_before = _kept_before(before, set(keep))
    robots = tuple(Robot(f"res{r + 1}", (), 0.0, traits=tuple((skills[s], 1.0) for s in range(n_skills)
                                                               if mastery[r][s]))
                   for r in range(n_res))
    tasks = tuple(Task(f"act{a + 1}", (), 0.0, float(dur[a]),
                       tuple(f"act{q + 1}" for q in sorted(kept_before(a))),
                       requires=tuple((skills[s], float(sreq[a][s])) for s in range(n_skills) if sreq[a][s]))
                  for a in keep)
    try:
        return Instance(p.stem, (), robots, tasks, traits=tuple(skills), roles=True)
    except InstanceError as exc:
        raise InstanceError(f"{where}: {exc}") from None


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
    sites: dict[str, list[float]] = {}
    if sites_csv is not None:
        sp = Path(sites_csv)
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
    robots, robot_sites, homes = [], [], []
    for line, row in r_rows:
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
    tasks, task_sites = [], []
    known = {row["id"].strip() for _, row in t_rows}
    for line, row in t_rows:
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
    try:
        travel = build_travel(sites, {}, robot_sites, task_sites, homes) if sites else None
        return Instance(name or tp.stem, (), tuple(robots), tuple(tasks), travel=travel, traits=tuple(traits),
                        objective=objective)
    except InstanceError as exc:  # what needs the whole instance (a cycle, a task no robot can cover)
        raise InstanceError(f"{rp} and {tp}: {exc}") from None


def _coord(text: str, where: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise InstanceError(f"{where}: expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise InstanceError(f"{where}: expected a finite number, got {text!r}")
    return value
