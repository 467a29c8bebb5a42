"""Exact expert: minimum-makespan schedules with OR-Tools CP-SAT, with proofs.

Model (per remaining task j, start S_j):
  * exactly one inclusion-minimal covering subteam per task (Eqs. 10-11); since a task's
    duration does not depend on its subteam, supersets are never needed for an optimum;
  * per robot, an optional interval of length d_j at S_j present when the robot is in
    the chosen subteam, and a no-overlap constraint over those intervals;
  * precedence S_j >= S_i + d_i; makespan C >= S_j + d_j; minimise C;
  * with travel (the travel extension of formats.md), the executor's model: a task's
    subteam sets out together at its departure D_j, once the task is ready and every
    member is free, and the task starts when the last member is there; per robot, a
    circuit over its possible tasks and its start (per-robot successor literals,
    AddCircuit), a chosen arc i -> j meaning D_j >= S_i + d_i and S_j >= D_j +
    travel(to_i, from_j) (sequence-dependent set-up times, rounded up to ticks). Proofs
    are about this model over minimal subteams: rule 7 also accepts schedules where robots
    set out before a task is ready, and a superset subteam (a rider on a transport) can
    pay with travel; neither is modelled;
  * redundant cumulatives (robots in use, payload in use, holders of each capability in
    use), start windows from longest paths before/after each task, and a hint from the
    best heuristic schedule, which also bounds the horizon.

When most robots are interchangeable (:mod:`~lvws_ros.core.pools`: the same trait
amounts and payload; :func:`pools_apply`), there is no travel and the team is too large
to list its minimal coalitions, the *pool model* replaces the per-robot boolean one:
per task an integer count per pool (at most what an inclusion-minimal subteam holds)
whose summed amounts cover it (with roles, counts per pool and required trait, a
matching of members to required units), per pool a cumulative over the tasks' intervals
with the counts as demands and the pool's size as capacity (a busy robot holds one unit
until it is free), precedence and makespan as above. It has none of the per-robot
model's symmetric copies (a task needing 5 of 40 identical robots is one count, not
C(40, 5) subteams). The individual robots are given afterwards, exactly: for identical
units on intervals every feasible cumulative has an assignment, found by giving each
task, by start time, free robots of the pool. :attr:`ExpertResult.model` says which
model was solved.

The *assignment model* is the per-robot boolean one with a literal per pair of tasks that
may overlap (they then share no member), as in Young, Feydy and Schutt's multi-skill model.
With roles its search finds short schedules where the coalition model's does not, and its
bound is weak; on small teams with roles ``auto`` solves both at the same time
(:func:`_side_by_side`; measured on the multi-skill library: ``docs/benchmarks.md``).

It also solves from a mid-run :class:`~lvws_ros.core.executor.State`: tasks done or in
progress stay as they are, busy robots are free only from their given time on, and
nothing new starts before the state's time.

An answer is called optimal only when CP-SAT proved it on exactly scaled durations;
otherwise the status is ``feasible`` with the best bound and the gap.

:func:`exact_match` solves one decision step's matching (Eqs. 7-11) exactly, for
comparison with the greedy matching. This module and :mod:`~lvws_ros.policies.lns` (the
large-neighbourhood search built on it) are the only ones that import OR-Tools.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from ortools.sat.python import cp_model

from lvws_ros.core.executor import (
    Decision,
    SimulationResult,
    State,
    TaskStatus,
    plan_step_near,
    schedule_from_state,
    simulate,
)
from lvws_ros.core.matching import Match, check_shapes, match_reward
from lvws_ros.core.pools import Pool, assign_units, pools, trivial
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.subteams import (
    MAX_ENUMERATED,
    TOLERANCE,
    AmountArray,
    BoolArray,
    FloatArray,
    covers,
    minimal_subteams,
    prune,
)
from lvws_ros.errors import ExpertError
from lvws_ros.policies.baselines import GreedyPayloadPolicy, RandomSubteamPolicy

SCALES = (1, 10, 100, 1000)
COALITION_LIMIT = 20_000  # coalitions listed in all before the boolean model is used


@dataclass
class ExpertResult:
    schedule: Schedule | None
    status: str  # optimal | feasible | unknown
    makespan: float | None
    bound: float
    seconds: float
    exact_scale: bool
    model: str = ""  # the formulation solved: coalition | boolean | pool ("" when nothing was left to place)

    @property
    def proven(self) -> bool:
        return self.status == "optimal"

    @property
    def gap(self) -> float:
        """(makespan - bound) / makespan; 0 when proven optimal."""
        if self.makespan is None or self.makespan <= 0:
            return float("inf")
        return max(0.0, (self.makespan - self.bound) / self.makespan)


def proves_executor_bound(inst: Instance, result: ExpertResult) -> bool:
    """Whether CP-SAT's bound (and "optimal") hold for the executor's model too, not only
    for the expert's: without travel (minimal subteams then lose no optimum) and on an
    exact time scale (no rounding to ticks). With travel, a rider on a transport or a
    superset subteam can beat the expert's model, so its bound bounds only that model."""
    return inst.travel is None and result.exact_scale


def _time_scale(values: np.ndarray) -> tuple[int, bool]:
    for s in SCALES:
        scaled = values * s
        if np.all(np.abs(scaled - np.round(scaled)) < TOLERANCE):
            return s, True
    return SCALES[-1], False


def heuristic_schedule(inst: Instance, state: State | None = None, seeds: int = 4) -> Schedule:
    """Best of GRP and a few seeded RAND-w/-subteams runs (the expert's warm start)."""
    runs: list[SimulationResult] = [simulate(inst, GreedyPayloadPolicy(), state=state)]
    runs += [simulate(inst, RandomSubteamPolicy(seed=s), state=state) for s in range(seeds)]
    return min(runs, key=lambda res: res.schedule.makespan).schedule


def left_shift(inst: Instance, sched: Schedule, state: State | None = None) -> Schedule:
    """Start every task as early as its prerequisites and robots allow, keeping each
    robot's task order. The makespan never grows. Without travel every start falls on
    time 0 (or the state's time) or on some task's end, i.e. on a decision step of the
    executor; with travel, the subteam sets out at such a step, as the executor does,
    and the task starts when its last member is there (:func:`departures`). With
    ``"departure": "each"`` a task is given at the step it is ready and its members' tasks
    before it are given, and each member sets out then or once free, whichever is later."""
    return _shift(inst, sched, state)[0]


def departures(inst: Instance, sched: Schedule, state: State | None = None) -> dict[str, float]:
    """When each task's subteam sets out in the left-shifted schedule (its start, without
    travel): the decision step at which the executor must assign it."""
    return _shift(inst, sched, state)[1]


def _shift(inst: Instance, sched: Schedule, state: State | None) -> tuple[Schedule, dict[str, float]]:
    t0 = state.time if state is not None else 0.0
    robot_free = state.robot_free_at.copy() if state is not None else np.zeros(inst.num_robots)
    tr = inst.travel
    site = None if tr is None else (State.initial(inst) if state is None else state).robot_site
    site = None if site is None else site.copy()
    end: dict[str, float] = {}
    fixed: set[str] = set()
    if state is not None:
        for k in np.flatnonzero(state.task_status >= TaskStatus.ASSIGNED):
            end[inst.tasks[k].id] = float(state.task_start[k] + inst.durations[k])
            fixed.add(inst.tasks[k].id)
    # tasks done or in progress as the state has them (the world may run ahead of the plan)
    out = [] if state is None else [
        Assignment(inst.tasks[k].id, tuple(inst.robots[r].id for r in state.task_team[k]),
                   float(state.task_start[k]), float(state.task_start[k] + inst.durations[k]))
        for k in np.flatnonzero(state.task_status >= TaskStatus.ASSIGNED)]
    leave: dict[str, float] = {}
    ahead = inst.departure == "each"
    given = np.full(inst.num_robots, t0)  # "each": when each robot's last task was given to it
    for a in sorted((a for a in sched.assignments if a.task not in fixed), key=lambda a: (a.start, a.task)):
        j = inst.task_index[a.task]
        robots = [inst.robot_index[r] for r in a.robots]
        ready = [t0, *(end[inst.tasks[p].id] for p in inst.prerequisites[j])]
        if ahead:  # given once ready and its members' tasks before it are given; each sets out once free
            depart = max([*ready, *(given[r] for r in robots)])
            leaves = [max(depart, robot_free[r]) for r in robots]
        else:  # the executor's rule: given once ready and every member is free; all set out then
            depart = max([*ready, *(robot_free[r] for r in robots)])
            leaves = [depart] * len(robots)
        start = max(leaves)
        if tr is not None and site is not None:  # each arrives after its travel; the task starts with the last
            start = max(t + tr.arrival([r], [int(site[r])], j) for r, t in zip(robots, leaves, strict=True))
            site[robots] = tr.task_to[j]
        stop = start + inst.durations[j]
        end[a.task] = stop
        robot_free[robots] = stop
        given[robots] = depart
        leave[a.task] = float(depart)
        out.append(Assignment(a.task, a.robots, float(start), float(stop)))
    return Schedule.from_assignments(inst, sched.policy, out, sched.decisions, sched.compute_seconds), leave


@dataclass
class _Horizon:
    """The remaining tasks of a state in integer ticks: durations, release times of the
    robots, minimal subteams, start windows (heads and tails) and makespan bounds."""

    todo: list[int]
    fixed_end: dict[int, float]
    scale: int
    exact_scale: bool
    dur: dict[int, int]
    free_at: list[int]
    teams: dict[int, list[tuple[int, ...]]] | None  # minimal coalitions (coalition model) or None
    head: dict[int, int]
    tail: dict[int, int]
    lower: int
    upper: int

    def ticks(self, x: float) -> int:
        return round(x * self.scale)

    def up(self, seconds: float) -> int:
        """Travel in ticks, rounded up (a schedule of the model is valid in real time)."""
        return int(np.ceil(seconds * self.scale - 1e-9))


def _travel_times(inst: Instance, state: State) -> np.ndarray:
    """The travel times a schedule from ``state`` can use (empty without travel): from
    where each robot is and from each task's end site, to each task's start site."""
    tr = inst.travel
    if tr is None or state.robot_site is None:
        return np.zeros(0)
    ends = np.array(tr.task_from)
    if inst.objective == "return":  # and the ways home
        ends = np.concatenate([ends, [tr.home(r) for r in range(inst.num_robots)]])
    origins = np.unique(np.concatenate([state.robot_site, tr.task_to]))
    speeds = np.unique([v for v in tr.robot_speed if v > 0])
    if not len(speeds):
        return np.zeros(0)
    return (tr.distance[np.ix_(origins, np.unique(ends))][..., None] / speeds).reshape(-1)


@dataclass
class _TravelVars:
    """The travel model's variables: each task's departure, and per robot its circuit's
    arcs by (from, to) task (None: the robot's start node)."""

    depart: dict[int, cp_model.IntVar]
    arcs: dict[int, dict[tuple[int | None, int | None], cp_model.IntVar]]


def _add_travel(model: cp_model.CpModel, inst: Instance, state: State, h: _Horizon, start: dict[int, cp_model.IntVar],
                member: dict[int, dict[int, cp_model.IntVar]], makespan: cp_model.IntVar) -> _TravelVars | None:
    """The executor's travel. Each task has a departure D_j: its subteam sets out once the
    task is ready and every member is free, and the task starts when the last member is
    there (with ``"departure": "each"``, D_j is when the task is given: once it is ready and
    each member's task before it is given; each member sets out then or when its task
    before ends, whichever is later). Per robot, a circuit through its start (node 0) and the tasks it may do; its
    successor literals carry the travel between consecutive tasks (rounded up to ticks,
    so a schedule of the model is valid in real time). With the objective "return" the arc
    back to the start node carries the way home: the makespan is when the last robot is
    home (a robot given nothing more goes home from where it is when its last task ended,
    which may be before now, as the executor counts it)."""
    tr = inst.travel
    if tr is None or state.robot_site is None:
        return None
    site = state.robot_site
    up = h.up
    now = h.ticks(state.time)
    depart = {j: model.new_int_var(now, h.upper, f"D_{j}") for j in h.todo}
    for j in h.todo:
        model.add(start[j] >= depart[j])
        for p in inst.prerequisites[j]:  # ready when it sets out
            model.add(depart[j] >= (start[p] + h.dur[p] if p in h.dur else h.ticks(h.fixed_end[p])))
    back = inst.objective == "return"
    ahead = inst.departure == "each"
    out = _TravelVars(depart, {})
    for r in range(inst.num_robots):
        tasks = [j for j in h.todo if r in member[j]]
        home_at = h.ticks(float(state.robot_free_at[r])) + up(tr.time(r, int(site[r]), tr.home(r))) if back else 0
        if not tasks:
            if back:
                model.add(makespan >= home_at)
            continue
        node = {j: k + 1 for k, j in enumerate(tasks)}
        idle = model.new_bool_var(f"idle_{r}")
        arcs: list[tuple[int, int, Any]] = [(0, 0, idle)]
        named = out.arcs[r] = {(None, None): idle}
        if back:
            model.add(makespan >= home_at).only_enforce_if(idle)
        for j in tasks:
            y = member[j][r]
            arcs.append((node[j], node[j], y.Not()))
            reach = tr.arrival([r], [int(site[r])], j)
            if np.isinf(reach):  # a fixed robot elsewhere, or on a transport: never in this subteam
                model.add(y == 0)
                continue
            first = model.new_bool_var(f"first_{r}_{j}")
            last = model.new_bool_var(f"last_{r}_{j}")
            arcs += [(0, node[j], first), (node[j], 0, last)]
            named[None, j], named[j, None] = first, last
            if back:
                model.add(makespan >= start[j] + h.dur[j] + up(tr.time(r, tr.task_to[j], tr.home(r)))).only_enforce_if(last)
            if ahead:  # sets out once free, even before the task is given
                model.add(start[j] >= h.free_at[r] + up(reach)).only_enforce_if(first)
            else:
                model.add(depart[j] >= h.free_at[r]).only_enforce_if(first)
            model.add(start[j] >= depart[j] + up(reach)).only_enforce_if(first)
            for k in tasks:
                move = tr.time(r, tr.task_to[j], tr.task_from[k])
                if k == j or np.isinf(move):
                    continue
                lit = model.new_bool_var(f"next_{r}_{j}_{k}")
                arcs.append((node[j], node[k], lit))
                named[j, k] = lit
                if ahead:  # given after the task before it; sets out when that one ends
                    model.add(depart[k] >= depart[j]).only_enforce_if(lit)
                    model.add(start[k] >= start[j] + h.dur[j] + up(move)).only_enforce_if(lit)
                else:
                    model.add(depart[k] >= start[j] + h.dur[j]).only_enforce_if(lit)
                model.add(start[k] >= depart[k] + up(move)).only_enforce_if(lit)
        model.add_circuit(arcs)
    return out


def _hint_travel(inst: Instance, state: State, model: cp_model.CpModel, tv: _TravelVars, h: _Horizon,
                 start: dict[int, Any], sched: Schedule, teams: dict[int, set[int]]) -> None:
    """Hint the travel model with ``sched``'s subteams (``teams``) and per-robot orders,
    timed on the model's own ticks: a forward pass in ``sched``'s order of starts, each
    task setting out once it is ready and its members are free and starting when the last
    one is there, travel rounded up as the model rounds it. The hint is then a solution of
    the model; starts rounded from real times are not always one (a start a tick before its
    last member arrives), and CP-SAT then spends a neighbourhood's time repairing the hint."""
    tr = inst.travel
    assert tr is not None and state.robot_site is not None
    by_task = sched.by_task()
    order = sorted((j for j in h.todo if inst.tasks[j].id in by_task),
                   key=lambda j: (by_task[inst.tasks[j].id].start, j))
    now = h.ticks(state.time)
    free, prev = list(h.free_at), [-1] * inst.num_robots
    given = [now] * inst.num_robots  # "each": when each robot's task before was given
    ahead = inst.departure == "each"
    end: dict[int, int] = {}
    for j in order:
        members = sorted(teams.get(j, ()))
        ready = [end[p] if p in end else h.ticks(h.fixed_end.get(p, state.time)) for p in inst.prerequisites[j]]
        depart = max([now, *ready, *((given if ahead else free)[r] for r in members)])
        at = [max(depart, free[r]) + h.up(tr.arrival([r], [int(state.robot_site[r])], j) if prev[r] < 0
                                          else tr.time(r, tr.task_to[prev[r]], tr.task_from[j])) for r in members]
        begin = max([depart, model.proto.variables[start[j].index].domain[0], *at])
        end[j] = begin + h.dur[j]
        model.add_hint(start[j], begin)
        if j in tv.depart:
            model.add_hint(tv.depart[j], depart)
        for r in members:
            free[r], prev[r], given[r] = end[j], j, depart
    for r, named in tv.arcs.items():
        mine = [j for a, j in named if a is None and j is not None]  # the tasks in the robot's circuit
        robot_order = sorted((j for j in mine if r in teams.get(j, ())),
                             key=lambda j: (by_task[inst.tasks[j].id].start, j))
        used = set(zip([None, *robot_order], [*robot_order, None], strict=True)) if robot_order else {(None, None)}
        for pair, lit in named.items():
            model.add_hint(lit, pair in used)


def _coalitions(inst: Instance, todo: list[int]) -> dict[int, list[tuple[int, ...]]] | None:
    """The minimal covering coalitions of each task when the team is small enough to list
    them (MAX_ENUMERATED robots, COALITION_LIMIT coalitions in all), else None: the
    robot-task boolean model is used instead."""
    if inst.num_robots > MAX_ENUMERATED:
        return None
    teams: dict[int, list[tuple[int, ...]]] = {}
    for j in todo:
        teams[j] = minimal_subteams(inst.robot_amounts, inst.robot_payload, inst.task_needs[j], inst.tasks[j].payload,
                                    bool(inst.task_roles[j]))
        if not teams[j]:
            raise ExpertError(f"task {inst.tasks[j].id!r} has no covering subteam")
        if sum(len(t) for t in teams.values()) > COALITION_LIMIT:
            return None
    return teams


def _horizon(inst: Instance, state: State, todo: list[int], hint: Schedule, coalitions: bool = True) -> _Horizon:
    status = state.task_status
    fixed_end = {j: float(state.task_start[j] + inst.durations[j]) for j in range(inst.num_tasks)
                 if status[j] in (TaskStatus.ASSIGNED, TaskStatus.DONE)}
    t0 = state.time
    travel_times = _travel_times(inst, state)
    times = np.concatenate([inst.durations, state.robot_free_at, [t0], np.array(list(fixed_end.values())),
                            travel_times])
    scale, exact_scale = _time_scale(times)

    def ticks(x: float) -> int:
        return round(x * scale)

    dur = {j: max(1, ticks(inst.durations[j])) for j in todo}
    free_at = [max(ticks(b), ticks(t0)) for b in state.robot_free_at]
    teams = _coalitions(inst, todo) if coalitions else None
    free = np.array(free_at)
    # Start windows: heads (earliest start) in topological order, tails backwards. A task
    # cannot start before a holder of each capability it needs is free (or, with the
    # coalitions listed, before its earliest coalition is).
    head: dict[int, int] = {}
    for j in inst.topological_order:
        if j in dur:
            lb = ticks(t0)
            for p in inst.prerequisites[j]:
                lb = max(lb, head[p] + dur[p] if p in dur else ticks(fixed_end[p]))
            for c in np.flatnonzero(inst.task_needs[j] > TOLERANCE):  # a holder of each needed trait
                lb = max(lb, int(free[inst.robot_amounts[:, c] > 0].min()))
            if teams is not None:
                lb = max(lb, min(max(free_at[r] for r in team) for team in teams[j]))
            head[j] = lb
    tail: dict[int, int] = {}
    for j in reversed(inst.topological_order):
        if j in dur:
            tail[j] = dur[j] + max((tail[s] for s in inst.successors[j] if s in dur), default=0)
    lower = max([ticks(t0), *(head[j] + tail[j] for j in todo), *(ticks(e) for e in fixed_end.values())])
    # travel rounded up to ticks adds less than a tick per move along any chain of tasks (and the way home)
    slack = len(todo) + 2 if inst.travel is not None and not exact_scale else 0
    upper = max(ticks(hint.makespan) + slack, lower)
    return _Horizon(todo, fixed_end, scale, exact_scale, dur, free_at, teams, head, tail, lower, upper)


@dataclass
class _Model:
    model: cp_model.CpModel
    start: dict[int, cp_model.IntVar]
    member: dict[int, dict[int, cp_model.IntVar]]  # task -> robot -> in its subteam
    choice: dict[int, list[cp_model.IntVar]] | None  # coalition model: task -> one bool per coalition
    makespan: cp_model.IntVar


def _sequencing(model: cp_model.CpModel, inst: Instance, h: _Horizon, start: dict[int, cp_model.IntVar],
                makespan: cp_model.IntVar, per_robot: list[list[cp_model.IntervalVar]]) -> None:
    """What both formulations share: precedence, the makespan, one task at a time per robot."""
    for j in h.todo:
        for p in inst.prerequisites[j]:
            if p in h.dur:
                model.add(start[j] >= start[p] + h.dur[p])
        model.add(makespan >= start[j] + h.dur[j])
    for intervals in per_robot:
        if len(intervals) > 1:
            model.add_no_overlap(intervals)


def _build_model(inst: Instance, h: _Horizon) -> _Model:
    """Start variables, one exactly-one choice of minimal subteam per task, per-robot
    no-overlap, precedence, makespan, and the redundant cumulatives."""
    model = cp_model.CpModel()
    todo, dur = h.todo, h.dur
    teams = h.teams
    assert teams is not None
    start = {j: model.new_int_var(h.head[j], h.upper - h.tail[j], f"S_{j}") for j in todo}
    makespan = model.new_int_var(h.lower, h.upper, "C")
    task_iv = {j: model.new_fixed_size_interval_var(start[j], dur[j], f"I_{j}") for j in todo}
    choice = {j: [model.new_bool_var(f"x_{j}_{k}") for k in range(len(teams[j]))] for j in todo}
    per_robot: list[list[cp_model.IntervalVar]] = [[] for _ in inst.robots]
    robot_count: dict[int, cp_model.IntVar] = {}
    payload_use: dict[int, cp_model.IntVar] = {}
    cap_use: list[dict[int, cp_model.IntVar]] = [{} for _ in inst.cover_names]
    whole = np.all(inst.robot_amounts == np.round(inst.robot_amounts), axis=0)  # traits in whole units
    amount_int = np.round(inst.robot_amounts).astype(np.int64)
    pay_int = np.round(inst.robot_payload * 1000).astype(np.int64)
    member: dict[int, dict[int, cp_model.IntVar]] = {}
    for j in todo:
        model.add_exactly_one(choice[j])
        member[j] = {}
        for r in sorted({r for team in teams[j] for r in team}):
            y = model.new_bool_var(f"y_{r}_{j}")
            member[j][r] = y
            model.add(y == sum(choice[j][k] for k, team in enumerate(teams[j]) if r in team))
            per_robot[r].append(model.new_optional_fixed_size_interval_var(start[j], dur[j], y, f"I_{r}_{j}"))
            if h.free_at[r] > h.head[j]:
                model.add(start[j] >= h.free_at[r]).only_enforce_if(y)
        # Cumulative demands must be single variables in CP-SAT.
        robot_count[j] = _demand(model, [len(team) for team in teams[j]], choice[j], f"n_{j}")
        payload_use[j] = _demand(model, [int(pay_int[list(team)].sum()) for team in teams[j]], choice[j], f"w_{j}")
        for col in np.flatnonzero(whole):
            holders = [int(amount_int[list(team), col].sum()) for team in teams[j]]
            if any(holders):
                cap_use[col][j] = _demand(model, holders, choice[j], f"c{col}_{j}")
    _sequencing(model, inst, h, start, makespan, per_robot)
    ivs = [task_iv[j] for j in todo]
    model.add_cumulative(ivs, [robot_count[j] for j in todo], inst.num_robots)
    model.add_cumulative(ivs, [payload_use[j] for j in todo], int(pay_int.sum()))
    for c, demand_by_task in enumerate(cap_use):
        if demand_by_task:
            model.add_cumulative([task_iv[j] for j in demand_by_task], list(demand_by_task.values()),
                                 int(amount_int[:, c].sum()))
    model.minimize(makespan)
    return _Model(model, start, member, choice, makespan)


def _payload_units(inst: Instance) -> tuple[np.ndarray, np.ndarray]:
    """Payloads as integers for Eq. 11 in the boolean model (:func:`_units`)."""
    return _units(inst.robot_payload, inst.task_payload)


def _units(have: np.ndarray, need: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amounts (robots) and needs (tasks) as integers for a sum in the boolean model,
    never accepting a subteam that does not cover: exact when every value is a multiple
    of 1/SCALES[-1]; else robots rounded down and needs (less the tolerance) rounded up at 1e6."""
    scale, exact = _time_scale(np.concatenate([have, need]))
    if exact:
        return np.round(have * scale).astype(np.int64), np.round(need * scale).astype(np.int64)
    fine = 10**6
    return np.floor(have * fine).astype(np.int64), np.ceil((need - TOLERANCE) * fine).astype(np.int64)


def covering_members(model: cp_model.CpModel, inst: Instance, j: int, pay_int: np.ndarray,
                     need_int: np.ndarray) -> dict[int, cp_model.IntVar]:
    """Task ``j``'s subteam in the boolean formulation: a boolean per robot that could
    help, constrained to cover (Eqs. 10-11; payloads in :func:`_payload_units`' integers;
    each trait's amounts add up, in :func:`_units`' integers). With roles a boolean per
    member and required trait it counts toward, at most one per member."""
    need = inst.task_needs[j]
    amounts = inst.robot_amounts
    cols = np.flatnonzero(need > TOLERANCE)
    useful = np.flatnonzero((amounts[:, cols] > 0).any(axis=1) | (inst.tasks[j].payload > TOLERANCE))
    member = {int(r): model.new_bool_var(f"y_{r}_{j}") for r in useful}
    give: dict[tuple[int, int], cp_model.IntVar] = {(r, int(c)): y for r, y in member.items() for c in cols}
    if inst.task_roles[j]:  # each member counts toward one required trait
        give = {(r, int(c)): model.new_bool_var(f"g_{r}_{j}_{c}") for r in member for c in cols if amounts[r, c] > 0}
        for r, y in member.items():
            model.add(sum(g for (q, _), g in give.items() if q == r) <= y)
    k = len(inst.capabilities)
    for c in cols:
        holders = [r for r in member if amounts[r, c] > 0]
        if c < k and not inst.task_roles[j]:  # Eq. 10: a holder of the capability
            model.add_bool_or([member[r] for r in holders])
            continue
        have, want = _units(amounts[:, c], need[c:c + 1])
        model.add(sum(int(have[r]) * give[r, int(c)] for r in holders) >= int(want[0]))
    if need_int[j] > 0:  # Eq. 11
        model.add(sum(int(pay_int[r]) * y for r, y in member.items()) >= int(need_int[j]))
    return member


def _build_boolean_model(inst: Instance, h: _Horizon) -> _Model:
    """The formulation for large teams, with no coalition listed: a boolean per robot and
    task (in its subteam or not), the coverage of Eqs. 10-11 as linear constraints (a
    holder of each needed capability, payloads adding up), per-robot optional intervals
    with no-overlap, precedence, makespan, and the redundant robots-in-use cumulative.
    Subteams may hold more robots than needed; the solution is trimmed to minimal ones."""
    model = cp_model.CpModel()
    todo, dur = h.todo, h.dur
    start = {j: model.new_int_var(h.head[j], h.upper - h.tail[j], f"S_{j}") for j in todo}
    makespan = model.new_int_var(h.lower, h.upper, "C")
    pay_int, need_int = _payload_units(inst)
    per_robot: list[list[cp_model.IntervalVar]] = [[] for _ in inst.robots]
    member: dict[int, dict[int, cp_model.IntVar]] = {}
    counts = []
    for j in todo:
        member[j] = covering_members(model, inst, j, pay_int, need_int)
        for r, y in member[j].items():
            per_robot[r].append(model.new_optional_fixed_size_interval_var(start[j], dur[j], y, f"I_{r}_{j}"))
            if h.free_at[r] > h.head[j]:
                model.add(start[j] >= h.free_at[r]).only_enforce_if(y)
        n_j = model.new_int_var(1, len(member[j]), f"n_{j}")
        model.add(n_j == sum(member[j].values()))
        counts.append(n_j)
    _sequencing(model, inst, h, start, makespan, per_robot)
    model.add_cumulative([model.new_fixed_size_interval_var(start[j], dur[j], f"I_{j}") for j in todo], counts,
                         inst.num_robots)
    model.minimize(makespan)
    return _Model(model, start, member, None, makespan)


def _add_hint(inst: Instance, h: _Horizon, m: _Model, hint: Schedule, starts: bool = True) -> dict[int, set[int]]:
    """Hint: the left-shifted heuristic schedule, each subteam cut down to a minimal one
    (coalition model); the subteams hinted. ``starts``: the starts too (with travel,
    :func:`_hint_travel` times them on the model's ticks instead)."""
    by_task = hint.by_task()
    teams: dict[int, set[int]] = {}
    for j in h.todo:
        a = by_task.get(inst.tasks[j].id)
        if a is None:
            continue
        if starts:
            m.model.add_hint(m.start[j], min(max(h.ticks(a.start), h.head[j]), h.upper - h.tail[j]))
        robots = {inst.robot_index[r] for r in a.robots}
        if h.teams is not None and m.choice is not None:
            pick = next((k for k, team in enumerate(h.teams[j]) if set(team) <= robots), 0)
            for k, x in enumerate(m.choice[j]):
                m.model.add_hint(x, k == pick)
            robots = set(h.teams[j][pick])
        else:
            for r, y in m.member[j].items():
                m.model.add_hint(y, r in robots)
        teams[j] = robots
    m.model.add_hint(m.makespan, h.upper)
    return teams


def _solution(inst: Instance, state: State, h: _Horizon, m: _Model, solver: cp_model.CpSolver) -> Schedule:
    out = []
    for j, t in enumerate(inst.tasks):
        if j in h.fixed_end:
            s0 = float(state.task_start[j])
            out.append(Assignment(t.id, tuple(inst.robots[r].id for r in state.task_team[j]), s0, s0 + t.duration))
            continue
        team = [r for r, y in m.member[j].items() if solver.boolean_value(y)]
        roles = bool(inst.task_roles[j])
        if not covers(inst.robot_amounts[team], inst.robot_payload[team], inst.task_needs[j], t.payload, roles):
            raise ExpertError(f"task {t.id!r}: the solver's subteam does not cover it (payload rounding)")
        if h.teams is None:  # boolean model: drop members the subteam does not need
            team = prune(team, inst.robot_amounts, inst.robot_payload, inst.task_needs[j], t.payload, roles=roles)
        s0 = solver.value(m.start[j]) / h.scale
        out.append(Assignment(t.id, tuple(inst.robots[r].id for r in sorted(team)), s0, s0 + t.duration))
    return left_shift(inst, Schedule.from_assignments(inst, "exact", out), state)


def _pool_bound(inst: Instance, j: int, pool: Pool) -> int:
    """The most members of ``pool`` an inclusion-minimal covering subteam of task ``j``
    holds: past it a member of the pool is never needed. Without roles, the members
    the pool needs to cover alone what it helps with (each trait it holds and the
    payload); with roles (a member fills one slot) the sum of those."""
    need, amt = inst.task_needs[j], np.array(pool.amounts)
    each = [int(np.ceil((need[c] - TOLERANCE) / amt[c])) for c in np.flatnonzero((need > TOLERANCE) & (amt > 0))]
    if inst.tasks[j].payload > TOLERANCE and pool.payload > 0:
        each.append(int(np.ceil((inst.tasks[j].payload - TOLERANCE) / pool.payload)))
    return min(pool.size, sum(each) if inst.task_roles[j] else max(each, default=0))


def _pool_cover(model: cp_model.CpModel, inst: Instance, j: int, found: Sequence[Pool], pay_int: np.ndarray,
                need_int: np.ndarray) -> dict[int, cp_model.IntVar]:
    """Task ``j``'s subteam as a count per pool (at most :func:`_pool_bound`) whose
    amounts cover it (Eqs. 10-11, each trait in :func:`_units`' integers). With roles, a
    count per pool and required trait of the members filling that trait's slots, at most
    the pool's count in all: a matching of members to required units."""
    need = inst.task_needs[j]
    cols = [int(c) for c in np.flatnonzero(need > TOLERANCE)]
    amounts = np.array([pool.amounts for pool in found]).reshape(len(found), len(need))
    count: dict[int, cp_model.IntVar] = {}
    for p, pool in enumerate(found):
        bound = _pool_bound(inst, j, pool)
        if bound == 1 and pool.size == 1:  # a literal: the robot's optional interval is present with it
            count[p] = model.new_bool_var(f"n_{j}_{p}")
        elif bound > 0:
            count[p] = model.new_int_var(0, bound, f"n_{j}_{p}")
    give: dict[tuple[int, int], Any] = {(p, c): n for p, n in count.items() for c in cols}
    if inst.task_roles[j]:
        give = {(p, c): model.new_int_var(0, _upper(count[p]), f"g_{j}_{p}_{c}")
                for p in count for c in cols if amounts[p, c] > 0}
        for p, n in count.items():
            model.add(sum(g for (q, _), g in give.items() if q == p) <= n)
    for c in cols:
        holders = [p for p in count if amounts[p, c] > 0]
        if not holders:
            raise ExpertError(f"task {inst.tasks[j].id!r}: no robot holds {inst.cover_names[c]}")
        have, want = _units(amounts[:, c], need[c:c + 1])
        model.add(sum(int(have[p]) * give[p, c] for p in holders) >= int(want[0]))
    if need_int[j] > 0:  # Eq. 11
        model.add(sum(int(pay_int[found[p].robots[0]]) * n for p, n in count.items()) >= int(need_int[j]))
    return count


def _upper(var: cp_model.IntVar) -> int:
    """The largest value of an integer variable's domain."""
    domain = var.proto.domain
    return int(domain[len(domain) - 1])


@dataclass
class _PoolModel:
    model: cp_model.CpModel
    start: dict[int, cp_model.IntVar]
    count: dict[int, dict[int, cp_model.IntVar]]  # task -> pool -> members of the pool in its subteam
    makespan: cp_model.IntVar


def _build_pool_model(inst: Instance, h: _Horizon, found: Sequence[Pool], now: int) -> _PoolModel:
    """The model over pools (no travel): per task its start and a count per pool
    (:func:`_pool_cover`); per pool a cumulative over the tasks' intervals with the counts
    as demands and the pool's size as capacity, each busy member holding one unit from
    ``now`` until it is free; precedence and the makespan as in the other formulations."""
    model = cp_model.CpModel()
    start = {j: model.new_int_var(h.head[j], h.upper - h.tail[j], f"S_{j}") for j in h.todo}
    makespan = model.new_int_var(h.lower, h.upper, "C")
    pay_int, need_int = _payload_units(inst)
    count = {j: _pool_cover(model, inst, j, found, pay_int, need_int) for j in h.todo}
    _sequencing(model, inst, h, start, makespan, [])
    task_iv = {j: model.new_fixed_size_interval_var(start[j], h.dur[j], f"I_{j}") for j in h.todo}
    for p, pool in enumerate(found):
        users = [j for j in h.todo if p in count[j]]
        if pool.size == 1:  # a robot of its own: optional intervals and a no-overlap, as per robot
            r = pool.robots[0]
            for j in users:
                if h.free_at[r] > h.head[j]:
                    model.add(start[j] >= h.free_at[r]).only_enforce_if(count[j][p])
            if len(users) > 1:
                model.add_no_overlap([model.new_optional_fixed_size_interval_var(start[j], h.dur[j], count[j][p],
                                                                                 f"I_{p}_{j}") for j in users])
            continue
        ivs = [task_iv[j] for j in users]
        demands: list[Any] = [count[j][p] for j in users]
        for r in pool.robots:  # busy: one unit held until the robot is free
            if h.free_at[r] > now:
                ivs.append(model.new_fixed_size_interval_var(now, h.free_at[r] - now, f"busy_{r}"))
                demands.append(1)
        if ivs:
            model.add_cumulative(ivs, demands, pool.size)
    model.minimize(makespan)
    return _PoolModel(model, start, count, makespan)


def _hint_pools(inst: Instance, h: _Horizon, m: _PoolModel, found: Sequence[Pool], hint: Schedule) -> None:
    """Hint the pool model with the left-shifted heuristic schedule: starts and counts."""
    by_task = hint.by_task()
    of = {r: p for p, pool in enumerate(found) for r in pool.robots}
    for j in h.todo:
        a = by_task.get(inst.tasks[j].id)
        if a is None:
            continue
        m.model.add_hint(m.start[j], min(max(h.ticks(a.start), h.head[j]), h.upper - h.tail[j]))
        used = [of[inst.robot_index[r]] for r in a.robots]
        for p, n in m.count[j].items():
            m.model.add_hint(n, min(used.count(p), _upper(n)))
    m.model.add_hint(m.makespan, h.upper)


def _pool_solution(inst: Instance, state: State, h: _Horizon, m: _PoolModel, found: Sequence[Pool],
                   solver: cp_model.CpSolver) -> Schedule:
    """The robots of each pool given exactly (:func:`~lvws_ros.core.pools.assign_units`),
    each subteam checked to cover and cut down to a minimal one, then left-shifted."""
    teams: dict[int, list[int]] = {j: [] for j in h.todo}
    for p, pool in enumerate(found):
        tasks = [j for j in h.todo if p in m.count[j] and solver.value(m.count[j][p]) > 0]
        uses = [(float(solver.value(m.start[j])), float(solver.value(m.start[j]) + h.dur[j]),
                 int(solver.value(m.count[j][p]))) for j in tasks]
        try:
            given = assign_units(pool.robots, [float(h.free_at[r]) for r in pool.robots], uses, tol=0.0)
        except ValueError as exc:
            raise ExpertError(f"pool of {inst.robots[pool.robots[0]].id!r}: no robots for the counts ({exc})") from None
        for j, robots in zip(tasks, given, strict=True):
            teams[j] += robots
    out = [Assignment(t.id, tuple(inst.robots[r].id for r in state.task_team[j]), float(state.task_start[j]),
                      float(state.task_start[j]) + t.duration) for j, t in enumerate(inst.tasks) if j in h.fixed_end]
    for j in h.todo:
        t, team, roles = inst.tasks[j], teams[j], bool(inst.task_roles[j])
        if not covers(inst.robot_amounts[team], inst.robot_payload[team], inst.task_needs[j], t.payload, roles):
            raise ExpertError(f"task {t.id!r}: the pool model's subteam does not cover it (rounding)")
        team = prune(team, inst.robot_amounts, inst.robot_payload, inst.task_needs[j], t.payload, roles=roles)
        s0 = solver.value(m.start[j]) / h.scale
        out.append(Assignment(t.id, tuple(inst.robots[r].id for r in sorted(team)), s0, s0 + t.duration))
    return left_shift(inst, Schedule.from_assignments(inst, "exact", out), state)


FORMULATIONS = ("auto", "coalition", "boolean", "pool", "assignment")
PAIR_TERMS = 200_000  # the assignment model's pair literals: pairs of tasks times robots at most this many


def pools_apply(inst: Instance, state: State | None = None) -> bool:
    """Whether the pool model stands for the per-robot one: no travel, and at least half
    of the robots interchangeable with another (:mod:`~lvws_ros.core.pools`). With a
    few small pools among robots of their own, the per-robot boolean model's no-overlaps
    did better (a 17-robot instance of the mixed family with pools of 2 and 3, 60 s)."""
    if inst.travel is not None:
        return False
    found = pools(inst, state)
    return not trivial(found) and 2 * sum(p.size for p in found if p.size > 1) >= inst.num_robots


def _check_formulation(inst: Instance, formulation: str) -> None:
    if formulation not in FORMULATIONS:
        raise ExpertError(f"unknown formulation {formulation!r} ({' | '.join(FORMULATIONS)})")
    if formulation == "pool" and inst.travel is not None:
        raise ExpertError("the pool model has no travel: use the coalition or boolean formulation")


def solve_exact(
    inst: Instance,
    *,
    state: State | None = None,
    time_limit: float = 60.0,
    workers: int = 8,
    hint: Schedule | None = None,
    seed: int = 0,
    formulation: str = "auto",
    work: float | None = None,
) -> ExpertResult:
    """Minimise the makespan of ``inst`` (from ``state`` when given) with CP-SAT.

    ``formulation``: "coalition" lists the minimal covering subteams of each task (fast
    for small teams), "boolean" uses a robot-task boolean per pair (any team size),
    "pool" a count per pool of interchangeable robots and task (no travel),
    "assignment" the boolean one with a literal per pair of tasks that may overlap
    (:func:`_overlap_pairs`; with roles its search found shorter schedules on some
    files of the multi-skill library, its bound is weak; beyond PAIR_TERMS pair
    literals it is the boolean model and ``model`` says so), "auto" (default) takes the
    coalition model when the team has at most MAX_ENUMERATED robots and the coalitions
    number at most COALITION_LIMIT (on such small teams it proves faster than the pool
    model, measured on Datasets I-III and the mspsp family), else the pool model when
    most robots are interchangeable and there is no travel (:func:`pools_apply`), else
    the boolean one. With roles on such a small team and two workers or more, "auto" also
    solves the assignment model at the same time, half the workers each
    (:func:`_side_by_side`). The result's ``model`` says which model's schedule it is.
    ``work``: a limit of CP-SAT's deterministic time too (with ``workers`` = 1 the same
    result on every run; side by side, with 2 as well)."""
    _check_formulation(inst, formulation)
    t_start = time.perf_counter()
    state = State.initial(inst) if state is None else state.copy()
    state.refresh()
    hint = left_shift(inst, heuristic_schedule(inst, state) if hint is None else hint, state)
    todo = state.tasks_to_do()
    if not todo:
        sched = schedule_from_state(state, "exact")
        return ExpertResult(sched, "optimal", sched.makespan, sched.makespan, time.perf_counter() - t_start, True)
    run = _Run(time_limit, workers, seed, work, t_start)
    if formulation == "auto" and _side_by_side_applies(inst, todo, workers):
        return _side_by_side(inst, state, todo, hint, run)
    return _solve_model(inst, state, todo, hint, formulation, run)


@dataclass
class _Run:
    """One call's solver settings: the limit (seconds, from ``t_start``), the workers,
    the seed and the deterministic-time limit (None: none); with models solved side by
    side, the solvers running (a proof stops them all)."""

    time_limit: float
    workers: int
    seed: int
    work: float | None
    t_start: float
    solvers: list[cp_model.CpSolver] = field(default_factory=list)
    over: bool = False  # a model proved its answer: the others stop
    lock: threading.Lock = field(default_factory=threading.Lock)

    def left(self) -> float:
        return max(0.01, self.time_limit - (time.perf_counter() - self.t_start))

    def enter(self, solver: cp_model.CpSolver) -> bool:
        """Register ``solver`` before it solves; False when another model already proved."""
        with self.lock:
            self.solvers.append(solver)
            return not self.over

    def proved(self) -> None:
        """A model proved its answer: stop the others (:meth:`stop`). Not under a
        deterministic-time limit: there each runs its course (the same result on every
        run, whichever proves first)."""
        if self.work is None:
            self.stop()

    def stop(self) -> None:
        """Stop every solver's search (each returns its best) and any not started yet."""
        with self.lock:
            self.over = True
            for solver in self.solvers:
                solver.stop_search()


def _side_by_side(inst: Instance, state: State, todo: list[int], hint: Schedule, run: _Run) -> ExpertResult:
    """The "auto" model and the assignment model solved at the same time, each with half the
    workers (at least one), each from ``hint``; a proof by either stops the other. The proven
    answer, else the shorter schedule ("auto"'s on a tie), with the better bound of the two.
    Where one model fails with an ExpertError (its solution not covering after rounding),
    the other's answer alone; any other error is raised, the other model stopped."""
    half = _Run(run.time_limit, max(1, run.workers // 2), run.seed, run.work, run.t_start)
    out: dict[str, ExpertResult] = {}
    errors: dict[str, BaseException] = {}

    def solve(formulation: str) -> None:
        try:
            out[formulation] = _solve_model(inst, state, todo, hint, formulation, half)
        except BaseException as exc:  # handed to the caller's thread
            errors[formulation] = exc
            if not isinstance(exc, ExpertError):
                half.stop()

    threads = [threading.Thread(target=solve, args=(f,), name=f"exact-{f}", daemon=True)
               for f in ("assignment", "auto")]
    try:
        for thread in threads:
            thread.start()
        for thread in threads:
            while thread.is_alive():
                thread.join(0.1)
                if half.over:  # a stop given before a solver's search began is lost: give it again
                    half.stop()
    except BaseException:
        half.stop()
        raise
    for exc in errors.values():
        if not isinstance(exc, ExpertError):
            raise exc
    if not out:
        raise errors["auto"]
    if len(out) == 1:
        return next(iter(out.values()))
    first, other = out["auto"], out["assignment"]
    best = min((first, other), key=lambda r: (not r.proven, r.makespan, r.status == "unknown", r is other))
    assert best.makespan is not None
    bound = best.makespan if best.proven else min(max(first.bound, other.bound), best.makespan)
    proven = best.proven or (best.exact_scale and bound >= best.makespan - TOLERANCE)
    seconds = time.perf_counter() - run.t_start
    if best.schedule is not None:
        best.schedule.compute_seconds = seconds
    return ExpertResult(best.schedule, "optimal" if proven else best.status, best.makespan, bound, seconds,
                        best.exact_scale, best.model)


def _solve_model(inst: Instance, state: State, todo: list[int], hint: Schedule, formulation: str,
                 run: _Run) -> ExpertResult:
    """One CP-SAT solve of ``formulation`` ("auto" chooses, as :func:`solve_exact` says)."""
    h = _horizon(inst, state, todo, hint, coalitions=formulation in ("auto", "coalition"))
    if formulation == "auto" and h.teams is None and pools_apply(inst, state):
        formulation = "pool"  # the horizon without coalitions is the pool model's
    if formulation == "assignment" and not _pairs_fit(inst, todo):
        formulation = "boolean"  # too many pair literals: the model without them
    m, found = _hinted_model(inst, state, h, hint, formulation)
    name = "pool" if isinstance(m, _PoolModel) else "coalition" if h.teams is not None else \
        "assignment" if formulation == "assignment" else "boolean"
    model = m.model
    roles = _slot_cumulatives(model, inst, state, h, m.start)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = run.left()
    solver.parameters.num_workers = run.workers
    solver.parameters.random_seed = run.seed
    if roles and name == "coalition":  # the cumulatives reason with the precedences too (measured: docs/benchmarks.md)
        solver.parameters.use_hard_precedences_in_cumulative = True
        solver.parameters.exploit_all_precedences = True
    if run.work is not None:
        solver.parameters.max_deterministic_time = run.work
    if not run.enter(solver):  # another model solved side by side proved its answer first
        return ExpertResult(hint, "unknown", hint.makespan, h.lower / h.scale, time.perf_counter() - run.t_start,
                            h.exact_scale, name)
    code = solver.solve(model)
    seconds = time.perf_counter() - run.t_start
    found_one = code in (cp_model.OPTIMAL, cp_model.FEASIBLE)
    bound = float(solver.best_objective_bound) / h.scale if found_one else h.lower / h.scale
    if code == cp_model.MODEL_INVALID:
        raise ExpertError(f"invalid CP-SAT model: {model.validate()}")
    if code == cp_model.INFEASIBLE:
        raise ExpertError(f"CP-SAT proved the model infeasible for {inst.name!r}; the hint schedule contradicts it")
    if not found_one:
        return ExpertResult(hint, "unknown", hint.makespan, bound, seconds, h.exact_scale, name)
    sched = _pool_solution(inst, state, h, m, found, solver) if isinstance(m, _PoolModel) else \
        _solution(inst, state, h, m, solver)
    # With rounded durations (no exact scale) the real-time schedule is valid, not proven optimal.
    status = "optimal" if code == cp_model.OPTIMAL and h.exact_scale else "feasible"
    if status == "optimal":
        bound = sched.makespan
        run.proved()  # a model solved beside this one stops
    sched.compute_seconds = seconds
    return ExpertResult(sched, status, sched.makespan, min(bound, sched.makespan), seconds, h.exact_scale, name)


def _hinted_model(inst: Instance, state: State, h: _Horizon, hint: Schedule,
                  formulation: str) -> tuple[_Model | _PoolModel, list[Pool]]:
    """The model of ``formulation`` ("pool", or the coalition or boolean one the horizon
    holds), travel added, hinted with ``hint``; with the pools it is over (none but in the
    pool model)."""
    if formulation == "pool":
        found = pools(inst, state)
        pm = _build_pool_model(inst, h, found, h.ticks(state.time))
        _hint_pools(inst, h, pm, found, hint)
        return pm, list(found)
    m = _build_model(inst, h) if h.teams is not None else _build_boolean_model(inst, h)
    if formulation == "assignment":
        _overlap_pairs(m.model, inst, h, m.start, m.member)
    tv = _add_travel(m.model, inst, state, h, m.start, m.member, m.makespan)
    teams = _add_hint(inst, h, m, hint, starts=tv is None)
    if tv is not None:
        _hint_travel(inst, state, m.model, tv, h, m.start, hint, teams)
    return m, []


def _unordered_pairs(inst: Instance, h: _Horizon) -> list[tuple[int, int]]:
    """Pairs of tasks left that may run at the same time: neither precedes the other
    (directly or not) and their start windows let them overlap."""
    todo = h.todo
    reach = inst.reachability()
    top = 8 * reach.shape[1] - 1  # task k is bit top - k of a row read as one big-endian number
    later = [int.from_bytes(row.tobytes(), "big") for row in reach]
    out = []
    for a, i in enumerate(todo):
        for j in todo[a + 1:]:
            if later[i] >> (top - j) & 1 or later[j] >> (top - i) & 1:
                continue
            if h.upper - h.tail[i] + h.dur[i] <= h.head[j] or h.upper - h.tail[j] + h.dur[j] <= h.head[i]:
                continue
            out.append((i, j))
    return out


def _side_by_side_applies(inst: Instance, todo: list[int], workers: int) -> bool:
    """Whether "auto" solves the assignment model beside its own: two workers or more (one
    is one thread), a task left has roles, a team small enough for the coalition model
    (MAX_ENUMERATED robots; on larger teams the pool model with half the workers lost more
    than the pairs won: docs/benchmarks.md), no travel (not measured with it), and the
    pair literals fit (:func:`_pairs_fit`)."""
    return workers >= 2 and inst.travel is None and inst.num_robots <= MAX_ENUMERATED \
        and bool(np.any(inst.task_roles[todo])) and _pairs_fit(inst, todo)


def _pairs_fit(inst: Instance, todo: list[int]) -> bool:
    """Whether the assignment model's pair literals stay within PAIR_TERMS (pairs of tasks
    left times robots, an upper bound)."""
    return len(todo) * (len(todo) - 1) // 2 * inst.num_robots <= PAIR_TERMS


def _overlap_pairs(model: cp_model.CpModel, inst: Instance, h: _Horizon, start: dict[int, cp_model.IntVar],
                   member: dict[int, dict[int, cp_model.IntVar]]) -> None:
    """The assignment model's pair literals (as Young, Feydy and Schutt's multi-skill
    model has them): for each pair of tasks that may overlap (:func:`_unordered_pairs`)
    and share a robot that could help both, one ends before the other starts, or they
    overlap and then have no member in common. Redundant with the per-robot no-overlaps;
    they give the search a literal per pair to branch on."""
    for i, j in _unordered_pairs(inst, h):
        common = [r for r in member[i] if r in member[j]]
        if not common:
            continue
        first, second, overlap = (model.new_bool_var(f"{name}_{i}_{j}") for name in ("ij", "ji", "ov"))
        model.add(start[i] + h.dur[i] <= start[j]).only_enforce_if(first)
        model.add(start[j] + h.dur[j] <= start[i]).only_enforce_if(second)
        model.add_bool_or([first, second, overlap])
        for r in common:
            model.add_bool_or([member[i][r].Not(), member[j][r].Not(), overlap.Not()])


SLOT_CUMULATIVES = True  # the redundant cumulatives of the multi-skill rule (False: the models without them)
SLOT_SUBSETS = 8  # with roles, a redundant cumulative per subset of the needed traits up to this many (else all and each)
SLOT_TERMS = 200_000  # ... while 2^traits times the tasks left are at most this many (a model of bounded size)


def _slot_cumulatives(model: cp_model.CpModel, inst: Instance, state: State, h: _Horizon,
                      start: dict[int, cp_model.IntVar]) -> bool:
    """Redundant cumulatives of the multi-skill rule (roles: a member fills one slot), on the
    tasks' intervals with fixed demands: for a set S of required traits, a task takes at least
    the members its S-slots need (the sum over S of each need over the largest amount a robot
    has; without roles the largest of those, one robot may fill several), all of them robots
    holding a trait of S, of which there are as many as the capacity (a busy one holds its
    unit until it is free). Every subset of up to SLOT_SUBSETS needed traits while 2^traits
    times the tasks left are at most SLOT_TERMS, else all together and each alone; one per
    distinct set of holders (the largest S). Only when a task left has roles (then True): the
    other models are left as they were."""
    roles = inst.task_roles
    todo = list(h.todo)
    if not SLOT_CUMULATIVES or not any(roles[j] for j in todo):
        return False
    needs, amounts = inst.task_needs[todo], inst.robot_amounts
    cols = [int(c) for c in np.flatnonzero((needs > TOLERANCE).any(axis=0))]
    most = np.maximum(amounts.max(axis=0), TOLERANCE)
    slots = np.where(needs > TOLERANCE, np.ceil((needs - TOLERANCE) / most[None, :]), 0.0)  # (tasks, traits)
    with_roles = np.asarray(roles, dtype=bool)[todo]
    every = len(cols) <= SLOT_SUBSETS and (2 ** len(cols)) * len(todo) <= SLOT_TERMS
    sets = [s for k in range(len(cols), 0, -1) for s in itertools.combinations(cols, k)] \
        if every else [tuple(cols), *((c,) for c in cols)]  # the largest S first
    seen: set[tuple[int, ...]] = set()
    now = h.ticks(state.time)
    intervals = [model.new_fixed_size_interval_var(start[j], h.dur[j], f"slots_{j}") for j in todo]
    held: dict[int, cp_model.IntervalVar] = {}  # a busy robot's unit, until it is free
    for subset in sets:
        holders = tuple(int(r) for r in np.flatnonzero((amounts[:, list(subset)] > 0).any(axis=1)))
        if holders in seen:
            continue
        seen.add(holders)
        part = slots[:, list(subset)]
        demand = np.where(with_roles, part.sum(axis=1), part.max(axis=1)).astype(np.int64)
        users = np.flatnonzero(demand > 0)
        busy = [r for r in holders if h.free_at[r] > now]
        if int(demand.sum()) + len(busy) <= len(holders):
            continue  # never binding
        for r in busy:
            if r not in held:
                held[r] = model.new_fixed_size_interval_var(now, h.free_at[r] - now, f"held_{r}")
        model.add_cumulative([intervals[k] for k in users] + [held[r] for r in busy],
                             [int(demand[k]) for k in users] + [1] * len(busy), len(holders))
    return True


def _demand(model: cp_model.CpModel, values: list[int], choice: Sequence[cp_model.IntVar], name: str) -> cp_model.IntVar:
    """An integer variable equal to the value of the chosen alternative."""
    var = model.new_int_var(min(values), max(values), name)
    model.add(var == sum(v * x for v, x in zip(values, choice, strict=True)))
    return var


class ExactPolicy:
    """Follows the expert's schedule: at each decision step, starts the tasks the
    expert planned to start now, with the planned subteams (the ``exact`` policy). The
    world's step is the plan's step nearest to it within PLAN_DRIFT
    (:func:`~lvws_ros.core.executor.plan_step_near`); when none is, or a task's planned
    departure has passed, it solves again from the state it is in (online use)."""

    name = "exact"

    def __init__(self, time_limit: float = 60.0, workers: int = 8, seed: int = 0, hint: Schedule | None = None) -> None:
        self.time_limit = time_limit
        self.workers = workers
        self.seed = seed
        self.hint = hint  # a schedule to warm-start the first solve from (None: the heuristic's)
        self.result: ExpertResult | None = None
        self._plan: dict[int, Assignment] = {}
        self._leave: dict[str, float] = {}  # when each planned subteam sets out
        self.solves = 0  # plans made since reset (1 when the world followed the plan)

    def reset(self, instance: Instance) -> None:
        self.result = None
        self._plan = {}
        self._leave = {}
        self.solves = 0

    def _plan_time(self, t: float) -> float | None:
        """The plan's departure or end time that the world's step at ``t`` is
        (:func:`~lvws_ros.core.executor.plan_step_near`; always ``t`` in the executor)."""
        assert self.result is not None
        times = [x for a in self._plan.values() for x in (self._leave.get(a.task, a.start), a.end)]
        return plan_step_near(times, t, self.result.makespan or 0.0)

    def _missed(self, state: State, now: float) -> bool:
        """A ready task whose planned departure is before the plan's step ``now`` (the
        world ran late): waiting for it would stall."""
        return any(self._leave.get(a.task, a.start) < now - TOLERANCE
                   for j in state.ready_tasks() if (a := self._plan.get(j)) is not None)

    def follow(self, result: ExpertResult, state: State) -> None:
        """Follow ``result``'s schedule from ``state`` (a schedule made elsewhere, e.g. by
        :mod:`~lvws_ros.policies.lns`) instead of solving; it solves again only when the
        world departs from it."""
        assert result.schedule is not None
        inst = state.instance
        self.result, self.hint = result, None
        self._plan = {inst.task_index[a.task]: a for a in result.schedule.assignments}
        self._leave = departures(inst, result.schedule, state)

    def decide(self, state: State) -> Decision:
        inst = state.instance
        now = self._plan_time(state.time) if self.result is not None else None
        if now is None or self._missed(state, now):
            self.result = None  # the world deviated from the plan (online use): re-solve from here
        if self.result is None:
            self.result = solve_exact(inst, state=state, time_limit=self.time_limit, workers=self.workers, seed=self.seed,
                                      hint=self.hint)
            self.hint = None
            self.follow(self.result, state)  # departures = starts without travel
            now = state.time
            self.solves += 1
        assert now is not None  # the plan's step: the world's, or the state's when just planned
        free = set(state.free_robots())
        ahead = inst.departure == "each"  # busy robots may be given their next tasks, in the plan's order
        out = []
        planned_start = {j: a.start for j, a in self._plan.items()}
        for j in sorted(state.ready_tasks(), key=lambda k: (planned_start.get(k, 0.0), k)):
            a = self._plan.get(j)
            if a is None or abs(self._leave.get(a.task, a.start) - now) > TOLERANCE:
                continue
            team = tuple(inst.robot_index[r] for r in a.robots)
            if ahead or set(team) <= free:
                out.append((j, team))
                free -= set(team)
        return Decision(tuple(out), tuple(sorted(free)))


def exact_match(
    r: FloatArray,
    robot_caps: AmountArray,
    robot_payload: FloatArray,
    task_caps: AmountArray,
    task_payload: FloatArray,
    *,
    time_limit: float = 10.0,
    workers: int = 2,
    necessary_only: bool = True,
    allowed: BoolArray | None = None,
    roles: BoolArray | None = None,
) -> Match:
    """Optimal A* of Eqs. 7-11 with CP-SAT (rewards scaled to integers, 1e-6 resolution).

    With ``necessary_only`` (the default, the same problem :func:`~lvws_ros.core.matching.greedy_match` solves)
    every member of a subteam must be needed: without it the task would lack a capability
    or payload. Without it, any robot may join a covered task when that pays more.
    ``allowed`` (n, m), as for the greedy matching, limits each task to the robots allowed
    for it (with travel: those that can reach it at all); None allows every pair.
    The capability arrays may hold trait amounts (summed, :mod:`~lvws_ros.core.subteams`).
    A task with ``roles`` (m,) gets a boolean per member and needed trait (the member
    fills that slot; one slot per member, :func:`~lvws_ros.core.subteams.role_cover`'s
    rule) and per-trait sums over the slots; with ``necessary_only`` each member fills a
    slot that falls short without it, or the payload does (for the slots found: unlike
    the sums' case, a smaller team whose members take other slots may exist).
    """
    n, m = check_shapes(r, robot_caps, robot_payload, task_caps, task_payload)
    if allowed is not None and allowed.shape != (n, m):
        raise ValueError(f"allowed has shape {allowed.shape}, expected ({n}, {m})")
    model = cp_model.CpModel()
    a = [[model.new_bool_var(f"a_{i}_{j}") for j in range(m + 1)] for i in range(n)]
    if allowed is not None:
        for i, j in zip(*np.nonzero(~allowed), strict=True):
            model.add(a[i][j] == 0)
    z = [model.new_bool_var(f"z_{j}") for j in range(m)]
    units = _MatchUnits.of(robot_caps, robot_payload, task_caps, task_payload)
    for i in range(n):
        model.add_exactly_one(a[i])  # Eq. 9, with the idle column as "no task"
    for j in range(m):
        for i in range(n):
            model.add_implication(a[i][j], z[j])
        _cover_task(model, [a[i][j] for i in range(n)], z[j], j, robot_caps, task_caps, units, necessary_only,
                    roles is not None and bool(roles[j]))
    scaled = np.round(r * 1e6).astype(np.int64)
    model.maximize(sum(int(scaled[i, j]) * a[i][j] for i in range(n) for j in range(m + 1)))
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = time_limit
    solver.parameters.num_workers = workers
    status = solver.solve(model)
    if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        raise ExpertError(f"exact_match: CP-SAT returned {solver.status_name(status)}")
    teams, wait = _read_match(solver, a)
    return Match(teams, wait, match_reward(r, teams, wait))


@dataclass(frozen=True)
class _MatchUnits:
    """The matching's amounts as CP-SAT's integers (:func:`_units`: never accepting a
    subteam short of a need): payloads, trait amounts per robot and per task, and which
    traits are 0/1 capabilities."""

    pay: npt.NDArray[np.int64]  # (n,)
    need: npt.NDArray[np.int64]  # (m,)
    amt: npt.NDArray[np.int64]  # (n, K)
    want: npt.NDArray[np.int64]  # (m, K)
    binary: BoolArray  # (K,)

    @classmethod
    def of(cls, robot_caps: AmountArray, robot_payload: FloatArray, task_caps: AmountArray,
           task_payload: FloatArray) -> _MatchUnits:
        pay, need = _units(np.asarray(robot_payload, dtype=np.float64), np.asarray(task_payload, dtype=np.float64))
        binary = np.all((robot_caps == 0) | (robot_caps == 1), axis=0)  # (K,): capabilities
        amt = np.zeros(np.shape(robot_caps), dtype=np.int64)
        want = np.zeros(np.shape(task_caps), dtype=np.int64)
        for col in range(int(np.shape(robot_caps)[1])):  # each trait in integers never accepting a subteam short of it
            amt[:, col], want[:, col] = _units(np.asarray(robot_caps[:, col], dtype=np.float64),
                                               np.asarray(task_caps[:, col], dtype=np.float64))
        return cls(pay, need, amt, want, binary)


def _cover_task(model: cp_model.CpModel, member: list[cp_model.IntVar], covered: cp_model.IntVar, j: int,
                robot_caps: AmountArray, task_caps: AmountArray, units: _MatchUnits, necessary_only: bool,
                roles: bool) -> None:
    """Task ``j`` (``member``: whether each robot is in its subteam) is ``covered`` only
    by a subteam that covers it (Eqs. 10-11; with ``roles``, :func:`_role_slots`); with
    ``necessary_only``, every member is needed."""
    n = len(member)
    if roles:
        _role_slots(model, member, covered, units.amt, units.want[j], units.pay, int(units.need[j]), necessary_only,
                    f"{j}")
        return
    for k in np.flatnonzero(task_caps[j] > TOLERANCE):  # Eq. 10 (and additive traits)
        holders = [member[i] for i in range(n) if robot_caps[i, k] > 0]
        if not holders:
            model.add(covered == 0)
        elif units.binary[k] and task_caps[j, k] <= 1:
            model.add_bool_or(holders).only_enforce_if(covered)
        else:
            model.add(sum(int(units.amt[i, k]) * member[i] for i in range(n)) >= int(units.want[j, k])
                      ).only_enforce_if(covered)
    carried = sum(int(units.pay[i]) * member[i] for i in range(n))
    model.add(carried >= int(units.need[j])).only_enforce_if(covered)  # Eq. 11
    if necessary_only:
        _only_needed_members(model, member, carried, units.pay, int(units.need[j]), units.amt, units.want[j], f"{j}")


def _read_match(solver: cp_model.CpSolver, a: list[list[cp_model.IntVar]]) -> tuple[dict[int, tuple[int, ...]],
                                                                                    tuple[int, ...]]:
    """The solved matrix A as subteams (task column -> robot rows) and the waiting rows
    (the last, idle, column)."""
    teams: dict[int, tuple[int, ...]] = {}
    waiting = []
    for i, row in enumerate(a):
        m = len(row) - 1
        for j in range(m + 1):
            if solver.boolean_value(row[j]):
                if j == m:
                    waiting.append(i)
                else:
                    teams.setdefault(j, ())
                    teams[j] = (*teams[j], i)
    return teams, tuple(waiting)


def _role_slots(model: cp_model.CpModel, member: list[cp_model.IntVar], covered: cp_model.IntVar,
                amounts: npt.NDArray[np.int64], want: npt.NDArray[np.int64], pay: npt.NDArray[np.int64],
                need: int, necessary_only: bool, tag: str) -> None:
    """A task with roles: member i fills at most one needed trait's slot (and only if it
    is a member); each needed trait's slot amounts add up when the task is ``covered``;
    the payload adds up over all members. With ``necessary_only`` every member fills a
    slot that falls short without it, or the payload falls short without it."""
    cols = [int(k) for k in np.flatnonzero(want > 0)]
    slot = {(i, k): model.new_bool_var(f"y_{i}_{k}_{tag}") for i in range(len(member)) for k in cols
            if amounts[i, k] > 0}
    mine: dict[int, list[cp_model.IntVar]] = {i: [] for i in range(len(member))}  # each member's slots
    for (i, _), v in slot.items():
        mine[i].append(v)
    for i, x in enumerate(member):
        if mine[i]:
            model.add(sum(mine[i]) <= x)
    sums = {k: sum(int(amounts[i, k]) * v for (i, k2), v in slot.items() if k2 == k) for k in cols}
    for k in cols:
        if isinstance(sums[k], int):  # nobody holds it
            model.add(covered == 0)
        else:
            model.add(sums[k] >= int(want[k])).only_enforce_if(covered)
    carried = sum(int(pay[i]) * x for i, x in enumerate(member))
    model.add(carried >= need).only_enforce_if(covered)
    if not necessary_only:
        return
    for (i, k), v in slot.items():  # a slot it fills falls short without it
        model.add(sums[k] - int(amounts[i, k]) < int(want[k])).only_enforce_if(v)
    for i, x in enumerate(member):
        short = model.new_bool_var(f"short_{i}_{tag}")  # the payload would fall short without i
        model.add(carried - int(pay[i]) < need).only_enforce_if(short)
        model.add_bool_or([short, *mine[i]]).only_enforce_if(x)


def _only_needed_members(model: cp_model.CpModel, member: list[cp_model.IntVar], carried: Any,
                         pay: npt.NDArray[np.int64], need: int, amounts: npt.NDArray[np.int64],
                         need_caps: npt.NDArray[np.int64], tag: str) -> None:
    """Each member of the task's subteam is needed: without it the payload falls short,
    or some trait (capability) the task needs: for 0/1 capabilities, it is the only member
    holding it. ``amounts`` (n, K) and ``need_caps`` (K,) in the same integer units."""
    for i, x in enumerate(member):
        short = model.new_bool_var(f"short_{i}_{tag}")  # payload would fall short without i
        model.add(carried - int(pay[i]) < need).only_enforce_if(short)
        reasons = [short]
        for k in np.flatnonzero((need_caps > 0) & (amounts[i] > 0)):
            sole = model.new_bool_var(f"sole_{i}_{tag}_{k}")  # trait k falls short without i
            others = [(int(amounts[q, k]), member[q]) for q in range(len(member)) if q != i and amounts[q, k] > 0]
            if others:
                model.add(sum(v * y for v, y in others) < int(need_caps[k])).only_enforce_if(sole)
            reasons.append(sole)
        model.add_bool_or(reasons).only_enforce_if(x)
