"""Problem model of heterogeneous collaborative scheduling (LVWS paper, section III-A).

A team of N robots r_i = [a_i, c_i, w_i] (availability, capability vector, payload
capacity) and M tasks t_j = [s_j, c_j, w_j] (status, required capabilities, payload
need) with durations and a precedence DAG P. :func:`validate_instance` rejects bad
input with an :class:`~lvws_ros.errors.InstanceError` that names the problem and the
offending ids; reading and writing files is :mod:`lvws_ros.core.formats`.
"""

from __future__ import annotations

import graphlib
import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import InitVar, dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt

from lvws_ros.core.subteams import BoolArray, FloatArray, covers, shortfall
from lvws_ros.core.travel import Travel
from lvws_ros.errors import InstanceError

# Durations and payloads are at most this (formats.md, "Limits"): far above any real cell,
# and low enough that sums and products of them never overflow or lose all precision.
MAX_VALUE = 1e9

# A capability named "@<site>" is a location: robots there hold it, tasks there need it.
# The matching enforces it like any capability; the network's node features leave it out.
SITE_PREFIX = "@"


# Additive traits (formats.md, "Traits"): at most this many per instance.
MAX_TRAITS = 256
OBJECTIVES = ("makespan", "return")  # the last task's end; the last robot home
# when a subteam's members set out: together, once the task is given and all are free (the
# executor's rule, this product's worlds); each, as soon as it is free (formats.md, "departure")
DEPARTURES = ("together", "each")


@dataclass(frozen=True)
class Robot:
    id: str
    capabilities: tuple[int, ...]
    payload: float
    extra: Mapping[str, Any] = field(default_factory=dict, compare=False)
    traits: tuple[tuple[str, float], ...] = ()  # (trait, amount): what it brings to a subteam's sums


@dataclass(frozen=True)
class Task:
    id: str
    capabilities: tuple[int, ...]
    payload: float
    duration: float
    after: tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict, compare=False)
    requires: tuple[tuple[str, float], ...] = ()  # (trait, amount) its subteam's members add up to
    roles: bool | None = None  # each member counts toward one required trait; None: the instance's


@dataclass(frozen=True)
class Instance:
    """A validated problem instance; array views are indexed like ``robots``/``tasks``."""

    name: str
    capabilities: tuple[str, ...]
    robots: tuple[Robot, ...]
    tasks: tuple[Task, ...]
    travel: Travel | None = None  # the travel extension (formats.md); None: zero travel
    traits: tuple[str, ...] = ()  # additive traits (formats.md, "Traits"), beside the capabilities
    objective: str = "makespan"  # "return": the makespan ends when the last robot is home
    roles: bool = False  # the default of each task's ``roles``
    departure: str = "together"  # DEPARTURES: "each" lets a task be given to busy robots, who set out when free
    # True: built from snapshots that passed online.check_team / check_graph, which
    # checked each robot and task and found no cycle; the rest is still checked
    prechecked: InitVar[bool] = False

    def __post_init__(self, prechecked: bool) -> None:
        validate_instance(self, prechecked=prechecked)

    @property
    def num_robots(self) -> int:
        return len(self.robots)

    @property
    def num_tasks(self) -> int:
        return len(self.tasks)

    @cached_property
    def robot_index(self) -> dict[str, int]:
        return {r.id: i for i, r in enumerate(self.robots)}

    @cached_property
    def task_index(self) -> dict[str, int]:
        return {t.id: j for j, t in enumerate(self.tasks)}

    @cached_property
    def robot_caps(self) -> BoolArray:
        """c^r as an N x K boolean matrix."""
        return _caps_matrix([r.capabilities for r in self.robots], len(self.capabilities))

    @cached_property
    def task_caps(self) -> BoolArray:
        """c^t as an M x K boolean matrix."""
        return _caps_matrix([t.capabilities for t in self.tasks], len(self.capabilities))

    @cached_property
    def skill_columns(self) -> tuple[int, ...]:
        """Capability columns that are skills, not sites (see SITE_PREFIX)."""
        return tuple(k for k, name in enumerate(self.capabilities) if not name.startswith(SITE_PREFIX))

    @cached_property
    def cover_names(self) -> tuple[str, ...]:
        """The columns of :attr:`robot_amounts` and :attr:`task_needs`: capabilities, then traits."""
        return tuple(self.capabilities) + tuple(self.traits)

    @cached_property
    def robot_amounts(self) -> FloatArray:
        """N x (K + L): each capability as an amount of 0 or 1, then each trait's amount;
        what :mod:`~lvws_ros.core.subteams`' coverage rule sums over a subteam."""
        return np.hstack([self.robot_caps.astype(np.float64), _amounts([r.traits for r in self.robots], self.traits)])

    @cached_property
    def task_needs(self) -> FloatArray:
        """M x (K + L): each needed capability as 1 (the OR of Eq. 10 is a sum reaching 1),
        then each trait's requirement."""
        return np.hstack([self.task_caps.astype(np.float64), _amounts([t.requires for t in self.tasks], self.traits)])

    @cached_property
    def task_roles(self) -> BoolArray:
        """(M,): the tasks whose members each count toward one required trait only."""
        return np.array([self.roles if t.roles is None else t.roles for t in self.tasks], dtype=bool)

    @cached_property
    def robot_payload(self) -> FloatArray:
        return np.array([r.payload for r in self.robots], dtype=np.float64)

    @cached_property
    def task_payload(self) -> FloatArray:
        return np.array([t.payload for t in self.tasks], dtype=np.float64)

    @cached_property
    def durations(self) -> FloatArray:
        return np.array([t.duration for t in self.tasks], dtype=np.float64)

    @cached_property
    def prerequisites(self) -> tuple[tuple[int, ...], ...]:
        """Indices of each task's prerequisites (the in-edges of P)."""
        return tuple(tuple(self.task_index[p] for p in t.after) for t in self.tasks)

    @cached_property
    def prerequisite_edges(self) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """The edges of P as two arrays (task, prerequisite): what a vectorised readiness
        test needs."""
        pairs = [(j, i) for j, pre in enumerate(self.prerequisites) for i in pre]
        edges = np.array(pairs, dtype=np.int64).reshape(-1, 2)
        return edges[:, 0].copy(), edges[:, 1].copy()

    @cached_property
    def successors(self) -> tuple[tuple[int, ...], ...]:
        succ: list[list[int]] = [[] for _ in self.tasks]
        for j, pre in enumerate(self.prerequisites):
            for i in pre:
                succ[i].append(j)
        return tuple(tuple(s) for s in succ)

    @cached_property
    def precedence_matrix(self) -> BoolArray:
        """P with P[i, j] = True when task i is a prerequisite of task j."""
        p = np.zeros((self.num_tasks, self.num_tasks), dtype=bool)
        for j, pre in enumerate(self.prerequisites):
            p[list(pre), j] = True
        return p

    @cached_property
    def critical_tail(self) -> FloatArray:
        """Longest duration path from each task to the end of the DAG, its own duration included."""
        tail = self.durations.copy()
        for j in reversed(self.topological_order):
            if self.successors[j]:
                tail[j] += max(tail[s] for s in self.successors[j])
        return tail

    def reachability(self) -> npt.NDArray[np.uint8]:
        """(M, ceil(M / 8)) bit sets in np.packbits order: bit k of row j is set where task k
        depends on task j, directly or not (M^2 / 8 bytes, 3 MB at 5,000 tasks; built
        anew each call, O(M E / 8) time)."""
        m = self.num_tasks
        reach = np.zeros((m, (m + 7) // 8), dtype=np.uint8)
        bit = np.uint8(1) << (7 - np.arange(m) % 8).astype(np.uint8)
        for j in reversed(self.topological_order):
            for s in self.successors[j]:
                reach[j] |= reach[s]
                reach[j, s // 8] |= bit[s]
        return reach

    @cached_property
    def descendant_count(self) -> npt.NDArray[np.int64]:
        """How many tasks depend on each task, directly or not (:meth:`reachability`)."""
        m = self.num_tasks
        reach = self.reachability()
        count = np.zeros(m, dtype=np.int64)
        for a in range(0, m, 1024):  # popcount in row blocks: bounded memory
            count[a:a + 1024] = np.unpackbits(reach[a:a + 1024], axis=1).sum(axis=1)
        return count

    @cached_property
    def topological_order(self) -> tuple[int, ...]:
        """A topological order of the task indices (set by validation, which computes it
        anyway; for a prechecked instance, computed when first asked)."""
        return _topological_order(self)


def _amounts(rows: Sequence[Sequence[tuple[str, float]]], names: Sequence[str]) -> FloatArray:
    col = {name: k for k, name in enumerate(names)}
    out = np.zeros((len(rows), len(names)), dtype=np.float64)
    for i, row in enumerate(rows):
        for name, amount in row:
            out[i, col[name]] = amount
    return out


def _caps_matrix(rows: Sequence[Sequence[int]], k: int) -> BoolArray:
    if not rows:
        return np.zeros((0, k), dtype=bool)
    return np.array(rows, dtype=np.int8).astype(bool).reshape(len(rows), k)


def _topological_order(inst: Instance) -> tuple[int, ...]:
    """A deterministic topological order of the task indices (graphlib); InstanceError
    naming one cycle when the prerequisites have one."""
    index = {t.id: j for j, t in enumerate(inst.tasks)}
    graph = {j: [index[p] for p in t.after] for j, t in enumerate(inst.tasks)}
    try:
        return tuple(graphlib.TopologicalSorter(graph).static_order())
    except graphlib.CycleError as exc:
        cycle = [inst.tasks[j].id for j in exc.args[1]]  # each one a prerequisite of the next
        raise InstanceError(f"cyclic prerequisites: {' -> '.join(cycle)}") from None


def _check_number(value: Any, what: str, *, positive: bool) -> None:
    """A finite number in [0, MAX_VALUE] (> 0 when ``positive``), whatever type it came as."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise InstanceError(f"{what} must be a number, got {value!r}")
    if isinstance(value, (float, np.floating)) and not math.isfinite(value):
        raise InstanceError(f"{what} must be finite, got {value!r}")
    if value > MAX_VALUE:  # compared before any float conversion: a huge int stays exact
        raise InstanceError(f"{what} must be at most {MAX_VALUE:g}, got {_short(value)}")
    if positive and value <= 0:
        raise InstanceError(f"{what} must be > 0, got {value!r}")
    if not positive and value < 0:
        raise InstanceError(f"{what} must be >= 0, got {value!r}")


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:20]}...({len(text)} characters)"


def _check_vector(vec: Any, k: int, what: str) -> None:
    if not isinstance(vec, (tuple, list)):
        raise InstanceError(f"{what} must be a list of 0/1, got {_short(vec)}")
    if len(vec) != k:
        raise InstanceError(f"{what} has {len(vec)} entries, expected {k} (one per capability)")
    if any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v not in (0, 1) for v in vec):
        raise InstanceError(f"{what} must hold only 0 or 1, got {_short(list(vec))}")


def validate_instance(inst: Instance, prechecked: bool = False) -> None:
    """Raise InstanceError naming every kind of problem of section 'Problem instance'
    (``prechecked``: each robot and task on its own, and the absence of cycles, were
    checked before; the rest is)."""
    k = len(inst.capabilities)
    if not all(isinstance(c, str) and c for c in inst.capabilities):
        raise InstanceError(f"capabilities: names must be non-empty strings, got {_short(list(inst.capabilities))}")
    if k < 1 and not inst.traits:
        raise InstanceError("capabilities: at least one capability name (or a trait) is needed")
    if len(set(inst.capabilities)) != k:
        raise InstanceError(f"capabilities: duplicate names in {list(inst.capabilities)}")
    _check_traits(inst)
    if not inst.robots:
        raise InstanceError("robots: the team is empty")
    _no_duplicates([r.id for r in inst.robots], "robot")
    _no_duplicates([t.id for t in inst.tasks], "task")
    tr = inst.travel
    if tr is not None and (len(tr.robot_site) != len(inst.robots) or len(tr.task_from) != len(inst.tasks)):
        raise InstanceError(f"travel: {len(tr.robot_site)} robot and {len(tr.task_from)} task sites for "
                            f"{len(inst.robots)} robots and {len(inst.tasks)} tasks")
    if tr is not None:  # the limits of formats.md: finite travel times, exact to well below the tolerance
        if not np.all(np.abs(np.array(tr.coordinates)) <= MAX_VALUE) or not np.all(tr.distance <= MAX_VALUE):
            raise InstanceError(f"sites: coordinates and distances must be at most {MAX_VALUE:g}")
        bad = [inst.robots[r].id for r, v in enumerate(tr.robot_speed) if v != 0 and not 1 / MAX_VALUE <= v <= MAX_VALUE]
        if bad:
            raise InstanceError(f"robot {bad[0]!r} speed: must be between {1 / MAX_VALUE:g} and {MAX_VALUE:g}")
    if not prechecked:
        _check_items(inst)
        inst.__dict__["topological_order"] = _topological_order(inst)  # prime the cached_property (cycles found)
    if not isinstance(inst.roles, bool):
        raise InstanceError(f"roles: expected true or false, got {_short(inst.roles)}")
    _check_coverable(inst)
    if inst.objective not in OBJECTIVES:
        raise InstanceError(f"objective: expected one of {list(OBJECTIVES)}, got {_short(inst.objective)}")
    if inst.departure not in DEPARTURES:
        raise InstanceError(f"departure: expected one of {list(DEPARTURES)}, got {_short(inst.departure)}")


def _check_items(inst: Instance) -> None:
    """Each robot and task on its own: capabilities, traits, numbers, prerequisites."""
    k = len(inst.capabilities)
    for r in inst.robots:
        _check_vector(r.capabilities, k, f"robot {r.id!r} capabilities")
        _check_number(r.payload, f"robot {r.id!r} payload", positive=not inst.traits)
        _check_amounts(r.traits, inst.traits, f"robot {r.id!r} traits")
    task_ids = {t.id for t in inst.tasks}
    for t in inst.tasks:
        _check_vector(t.capabilities, k, f"task {t.id!r} capabilities")
        _check_amounts(t.requires, inst.traits, f"task {t.id!r} requires")
        if not any(t.capabilities) and not any(a > 0 for _, a in t.requires):
            raise InstanceError(f"task {t.id!r} capabilities: needs at least one capability"
                                + (" or trait" if inst.traits else ""))
        if t.roles is not None and not isinstance(t.roles, bool):
            raise InstanceError(f"task {t.id!r} roles: expected true or false, got {_short(t.roles)}")
        _check_number(t.payload, f"task {t.id!r} payload", positive=False)
        _check_number(t.duration, f"task {t.id!r} duration", positive=True)
        if not isinstance(t.after, (tuple, list)) or not all(isinstance(p, str) for p in t.after):
            raise InstanceError(f"task {t.id!r} after: expected a list of task ids, got {_short(t.after)}")
        unknown = [p for p in t.after if p not in task_ids]
        if unknown:
            raise InstanceError(f"task {t.id!r} after: unknown task id(s) {unknown}")
        if t.id in t.after:
            raise InstanceError(f"task {t.id!r} after: a task cannot be its own prerequisite")
        if len(set(t.after)) != len(t.after):
            raise InstanceError(f"task {t.id!r} after: duplicate prerequisite ids")


def _check_coverable(inst: Instance) -> None:
    """Every task can be covered by the whole team (Eqs. 10-11 on its sums, once for all
    tasks; with roles the matching, per task with roles); the first that cannot, named."""
    k = len(inst.capabilities)
    amounts = inst.robot_amounts
    team = amounts.sum(axis=0)
    team_payload = float(inst.robot_payload.sum())
    missing, short = shortfall(team[None, :], team_payload, inst.task_needs, inst.task_payload)
    bad = (missing > 0).any(axis=1) | (short > 0)
    for j in np.flatnonzero(bad | inst.task_roles):
        t = inst.tasks[j]
        caps = [inst.cover_names[c] for c in np.flatnonzero(missing[j, :k])]
        if caps:
            raise InstanceError(f"task {t.id!r} can never be covered: no robot has capability {caps}")
        for c in np.flatnonzero(missing[j, k:]):
            raise InstanceError(f"task {t.id!r} can never be covered: needs {inst.traits[c]} "
                                f"{inst.task_needs[j, k + c]:g}, the whole team has {team[k + c]:g}")
        if short[j] > 0:
            raise InstanceError(
                f"task {t.id!r} can never be covered: needs payload {t.payload}, "
                f"the whole team carries {team_payload}"
            )
        if inst.task_roles[j] and not covers(amounts, inst.robot_payload, inst.task_needs[j], t.payload, roles=True):
            raise InstanceError(f"task {t.id!r} can never be covered: with roles (each member counts toward one "
                                f"required trait) the whole team does not reach "
                                f"{_needs_text(inst.cover_names, inst.task_needs[j])}")


def _needs_text(names: Sequence[str], need: FloatArray) -> str:
    return "{" + ", ".join(f"{names[int(c)]}: {need[c]:g}" for c in np.flatnonzero(need > 0)) + "}"


def _check_traits(inst: Instance) -> None:
    names = inst.traits
    if not isinstance(names, tuple) or not all(isinstance(c, str) and c for c in names):
        raise InstanceError(f"traits: names must be non-empty strings, got {_short(list(names))}")
    if len(names) > MAX_TRAITS:
        raise InstanceError(f"traits: at most {MAX_TRAITS} traits, got {len(names)}")
    if len(set(names)) != len(names):
        raise InstanceError(f"traits: duplicate names in {_short(list(names))}")
    both = sorted(set(names) & set(inst.capabilities))
    if both:
        raise InstanceError(f"traits: {both} also named as capabilities (a name is one or the other)")


def _check_amounts(pairs: Any, names: Sequence[str], what: str) -> None:
    """(trait, amount) pairs: known traits, each once, amounts in [0, MAX_VALUE]."""
    if not isinstance(pairs, tuple):
        raise InstanceError(f"{what}: expected trait amounts, got {_short(pairs)}")
    known = set(names)
    seen: set[str] = set()
    for pair in pairs:
        if not (isinstance(pair, tuple) and len(pair) == 2 and isinstance(pair[0], str)):
            raise InstanceError(f"{what}: expected (trait, amount) pairs, got {_short(pair)}")
        name, amount = pair
        if name not in known:
            raise InstanceError(f"{what}: unknown trait {_short(name)} (traits: {_short(list(names))})")
        if name in seen:
            raise InstanceError(f"{what}: trait {name!r} given twice")
        seen.add(name)
        _check_number(amount, f"{what}.{name}", positive=False)


def _no_duplicates(ids: Sequence[str], kind: str) -> None:
    for i in ids:
        if not isinstance(i, str) or not i:
            raise InstanceError(f"{kind} ids must be non-empty strings, got {i!r}")
    dups = sorted(i for i, count in Counter(ids).items() if count > 1)
    if dups:
        raise InstanceError(f"duplicate {kind} id(s): {dups}")
