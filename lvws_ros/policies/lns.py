"""Large-neighbourhood search: CP-SAT over a window of an incumbent schedule, the rest fixed.

For cells too big for the exact expert's whole model (hundreds of tasks and robots), a
schedule is improved one neighbourhood at a time. Each round picks a window of the
incumbent: the ``window`` tasks that start first at or after a chosen time ``t0``.

* tasks that start before ``t0`` (and, from a mid-run state, those done or in progress)
  stay as they are: each robot is free from the end of its last one on;
* the window's tasks choose their subteams anew (the boolean formulation of the exact
  expert: a robot-task boolean, a holder of each needed capability and payloads adding
  up, Eqs. 10-11) and their starts;
* the next ``LATER`` windows' worth of later tasks keep their subteams and, per robot, their
  order; their starts move with the window (a left or right shift); the tasks after them
  are not in the model (the left shift below places them);
* precedence, one task at a time per robot (no-overlap over the window's optional
  intervals and the later tasks' fixed ones), the makespan.

With travel (sequence-dependent set-ups) the model is the exact expert's travel model
(:func:`~lvws_ros.policies.exact._add_travel`) over the window's and the later tasks: each
task sets out at a departure once it is ready and its members are free, and starts when
the last member is there; per robot, a circuit from where its last task before the
window leaves it (and when) through the window's tasks it may do and the later tasks it
does, whose arcs carry the travel; with the objective "return", the way home. Only one
window's worth of later tasks is in the model then (the circuits grow with the square of
a robot's tasks in the model), and the window holds DEFAULT_WINDOW_TRAVEL tasks by default.
CP-SAT is hinted with the incumbent timed on the model's ticks
(:func:`~lvws_ros.policies.exact._hint_travel`), a solution of the model.

The window adapts (``adaptive``): a task more after a neighbourhood CP-SAT proved within its
round, a task fewer (down to MIN_WINDOW) after one it could not: the neighbourhoods fit a
round whatever the team's size.

When most robots are interchangeable (:func:`~lvws_ros.policies.exact.pools_apply`: no
travel) and the team has more than MAX_ENUMERATED robots (where the exact expert solves
its pool model too), the windows are over pools: the window's tasks choose a count per pool (the exact
expert's pool model) and their starts, the later tasks keep their counts per pool (not
their robots) and move, and per pool one cumulative holds the counts, each robot taking a
unit until the prefix leaves it free; the robots are given afterwards, exactly. Without a
model per robot a window holds far more tasks (DEFAULT_WINDOW_POOLS).

The objective is the makespan, then the sum of the tasks' ends (so that a window off the
critical path can still make room). CP-SAT is hinted with the incumbent. The solution's
subteams and per-robot orders are left-shifted in real time
(:func:`~lvws_ros.policies.exact.left_shift`) and kept only when shorter (or as short with
a smaller sum of ends). Four kinds of neighbourhood (KINDS) choose the window's tasks:
consecutive tasks from a random time on; the tasks that end the schedule; the critical
chain's tasks around a random one of them (:func:`critical_chain`: what holds the
makespan up) with the tasks sharing their robots; the tasks of the robot, or over pools the
pool, busiest over a random stretch. Over pools, each round draws a kind by its weight, and
a kind's weight follows how often its neighbourhoods shortened the schedule (adaptive
large-neighbourhood search), never below MIN_WEIGHT. Per robot the windows are the first
two kinds only, a third of them at the end of the schedule: there (a public coalition
benchmark with the way home, ``examples/dcmrta``; the ``traits-roles`` family) the chain
and busy windows shortened less in the same number of rounds. The result is valid by
construction and checked by :func:`~lvws_ros.core.schedule.check_schedule`.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from ortools.sat.python import cp_model

from lvws_ros.core.executor import State, TaskStatus
from lvws_ros.core.pools import Pool, assign_units, pools
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.core.subteams import MAX_ENUMERATED, TOLERANCE, covers, prune
from lvws_ros.errors import ExpertError
from lvws_ros.policies.exact import (
    _add_travel,
    _hint_travel,
    _Horizon,
    _payload_units,
    _pool_cover,
    _time_scale,
    _travel_times,
    _upper,
    covering_members,
    left_shift,
    pools_apply,
)

DEFAULT_WINDOW = 12  # tasks re-planned per neighbourhood
DEFAULT_WINDOW_TRAVEL = 6  # the same with travel (chosen on the training family traits-return, 30 x 100)
DEFAULT_WINDOW_POOLS = 48  # the same over pools (chosen on PSPLIB j1202_1, j1203_1, j1204_1 from GRP, 10 s)
ROUND_LIMIT = 0.5  # seconds CP-SAT may take for one neighbourhood
LATER = 2  # tasks after the window in the model (shifted, not re-planned), in windows
LATER_TRAVEL = 1  # the same with travel
MIN_WINDOW = 2  # the adaptive window never holds fewer tasks
KINDS = ("time", "tail", "chain", "busy")  # how a neighbourhood's tasks are chosen (_neighbourhood)
REACTION, MIN_WEIGHT = 0.2, 0.1  # a kind's weight moves this far towards 1 (shortened) or 0 per round; its floor
NOT_RUN, OPEN, CLOSED = 0, 1, 2  # a neighbourhood: no time left to solve it; solved, not proven; proven optimal

__all__ = ["DEFAULT_WINDOW", "DEFAULT_WINDOW_POOLS", "DEFAULT_WINDOW_TRAVEL", "KINDS", "LNSResult", "critical_chain",
           "improve"]


@dataclass
class LNSResult:
    schedule: Schedule
    rounds: int  # neighbourhoods solved
    improved: int  # of them that shortened the schedule (or kept it and ended its tasks earlier)
    start_makespan: float
    seconds: float
    window: int = DEFAULT_WINDOW  # the window of the last neighbourhood (adapted: see improve)


def _score(s: Schedule) -> tuple[float, float]:
    return float(s.makespan), float(sum(a.end for a in s.assignments))


def _better(a: tuple[float, float], b: tuple[float, float]) -> bool:
    """``a`` shorter than ``b``, or as short with its tasks ending earlier in all."""
    if a[0] < b[0] - TOLERANCE:
        return True
    return abs(a[0] - b[0]) <= TOLERANCE and a[1] < b[1] - TOLERANCE * max(1.0, abs(b[1]))


def _prefix(inst: Instance, state: State, inc: Schedule, prefix: list[int], free: list[int],
            scale: int) -> tuple[dict[int, int], dict[int, int], dict[int, list[int]], np.ndarray,
                                 np.ndarray | None, np.ndarray, int, int]:
    """What the fixed prefix leaves: the free tasks' durations in ticks, the prefix's ends
    in ticks (rounded up: nothing starts before a real end), the incumbent's subteams, when
    each robot's last task ends (seconds; the way home) and where it is then, when it is
    free for the window in ticks (rounded up too), now and a horizon in ticks."""
    by_task = inc.by_task()
    dur = {j: max(1, round(float(inst.durations[j]) * scale)) for j in free}
    fixed_end = {j: math.ceil(by_task[inst.tasks[j].id].end * scale - 1e-9) for j in prefix}
    incumbent_team = {j: [inst.robot_index[name] for name in by_task[inst.tasks[j].id].robots]
                      for j in [*prefix, *free]}
    free_from = state.robot_free_at.astype(float)
    site = None if state.robot_site is None else state.robot_site.copy()
    for j in sorted(prefix, key=lambda k: (by_task[inst.tasks[k].id].end, k)):
        for k in incumbent_team[j]:
            free_from[k] = max(free_from[k], by_task[inst.tasks[j].id].end)
            if site is not None and inst.travel is not None and state.task_status[j] < TaskStatus.ASSIGNED:
                site[k] = inst.travel.task_to[j]
    release = np.ceil(np.maximum(free_from, state.time) * scale - 1e-9).astype(np.int64)
    t0 = math.ceil(state.time * scale - 1e-9)
    upper = int(sum(dur.values()) + max([t0, *release.tolist(), *fixed_end.values()]))
    return dur, fixed_end, incumbent_team, free_from, site, release, t0, upper


def _window_model(inst: Instance, state: State, inc: Schedule, prefix: list[int], window: list[int],
                  later: list[int], scale: int, solve_by: float, workers: int,
                  seed: int, work: float | None = None) -> tuple[Schedule | None, int]:
    """One neighbourhood: the window's subteams and starts free, the later tasks' subteams
    and per-robot orders fixed, the prefix as it is (tasks after ``later`` are not in the
    model: the left shift places them); the left-shifted solution (None: none found by
    ``solve_by``, a perf_counter value the building of the model counts against), and
    whether the solver ran at all (False: the model's building took the round's time).
    ``work``: CP-SAT's deterministic time limit instead (the same result every run)."""
    by_task = inc.by_task()
    dur, fixed_end, incumbent_team, free_from, site, release, t0, upper = _prefix(inst, state, inc, prefix,
                                                                                  window + later, scale)
    free = set(window) | set(later)
    if inst.travel is not None:  # the incumbent fits: its moves rounded up add under a tick each
        upper = max(upper, math.ceil(inc.makespan * scale) + len(free) + 2)
    model = cp_model.CpModel()
    start = {j: model.new_int_var(t0, upper, f"S_{j}") for j in free}
    end = {j: start[j] + dur[j] for j in free}
    makespan = model.new_int_var(max([t0, *fixed_end.values()]), upper, "C")
    per_robot: list[list[cp_model.IntervalVar]] = [[] for _ in inst.robots]
    pay_int, need_int = _payload_units(inst)
    member: dict[int, dict[int, cp_model.IntVar]] = {}
    for j in window:
        member[j] = covering_members(model, inst, j, pay_int, need_int)
        for r, y in member[j].items():
            per_robot[r].append(model.new_optional_fixed_size_interval_var(start[j], dur[j], y, f"I_{r}_{j}"))
            model.add(start[j] >= int(release[r])).only_enforce_if(y)
            model.add_hint(y, r in incumbent_team[j])
    _keep_later(model, sorted(later, key=lambda k: (by_task[inst.tasks[k].id].start, k)), incumbent_team, start, end,
                dur, release, per_robot)
    for j in free:
        for p in inst.prerequisites[j]:
            model.add(start[j] >= (end[p] if p in free else fixed_end[p]))
        model.add(makespan >= end[j])
    if inst.travel is not None:  # the exact expert's travel model, from where the prefix leaves each robot
        after = state.copy()
        after.robot_site, after.robot_free_at = site, free_from
        h = _Horizon(window + later, {j: by_task[inst.tasks[j].id].end for j in prefix}, scale, False, dur,
                     release.tolist(), None, {}, {}, t0, upper)
        _window_travel(model, inst, after, inc, h, start, member, later, incumbent_team, makespan)
    for intervals in per_robot:
        if len(intervals) > 1:
            model.add_no_overlap(intervals)
    weight = len(free) * (upper + 1) + 1
    model.minimize(weight * makespan + sum(end.values()))
    model.add_hint(makespan, upper)
    if inst.travel is None:  # the incumbent, on the tick scale, as the hint (with travel: timed by _hint_travel)
        for j in free:
            model.add_hint(start[j], min(upper, max(t0, round(by_task[inst.tasks[j].id].start * scale))))
    solver, closed = _solve(model, solve_by, work, workers, seed)
    if solver is None:
        return None, closed
    out = _outside(inst, inc, prefix, free, {j: solver.value(start[j]) / scale for j in free})
    for j in free:
        t = inst.tasks[j]
        robots = _solved_team(inst, solver, j, member[j]) if j in member else by_task[t.id].robots
        s0 = solver.value(start[j]) / scale
        out.append(Assignment(t.id, robots, s0, s0 + t.duration))
    return left_shift(inst, Schedule.from_assignments(inst, inc.policy, out), state), closed


def _keep_later(model: cp_model.CpModel, later: list[int], incumbent_team: dict[int, list[int]], start: dict[int, Any],
                end: dict[int, Any], dur: dict[int, int], release: np.ndarray,
                per_robot: list[list[cp_model.IntervalVar]]) -> None:
    """The later tasks (in the incumbent's order of starts) keep their subteams and each
    robot's order of them."""
    last: dict[int, int] = {}  # robot -> its latest later task so far (per-robot order kept)
    for j in later:
        for r in incumbent_team[j]:
            per_robot[r].append(model.new_fixed_size_interval_var(start[j], dur[j], f"I_{r}_{j}"))
            model.add(start[j] >= int(release[r]))
            if r in last:
                model.add(start[j] >= end[last[r]])
            last[r] = j


def _window_travel(model: cp_model.CpModel, inst: Instance, after: State, inc: Schedule, h: _Horizon,
                   start: dict[int, Any], member: dict[int, dict[int, cp_model.IntVar]], later: list[int],
                   incumbent_team: dict[int, list[int]], makespan: cp_model.IntVar) -> None:
    """The exact expert's travel model over the window (``member``: its subteams, free) and
    the later tasks (their subteams fixed: members that must be there), from ``after``;
    hinted with the incumbent's teams."""
    members = dict(member)
    for j in later:
        members[j] = {r: model.new_constant(1) for r in incumbent_team[j]}
    tv = _add_travel(model, inst, after, h, start, members, makespan)
    if tv is not None:
        _hint_travel(inst, after, model, tv, h, start, inc, {j: set(incumbent_team[j]) for j in h.todo})


def _solved_team(inst: Instance, solver: cp_model.CpSolver, j: int, member: dict[int, cp_model.IntVar]
                 ) -> tuple[str, ...]:
    """Task ``j``'s subteam as the solver chose it, made inclusion-minimal (ExpertError when
    it does not cover the task: payload rounding)."""
    t = inst.tasks[j]
    team = [r for r, y in member.items() if solver.boolean_value(y)]
    if not covers(inst.robot_amounts[team], inst.robot_payload[team], inst.task_needs[j], t.payload,
                  bool(inst.task_roles[j])):
        raise ExpertError(f"task {t.id!r}: the solver's subteam does not cover it (payload rounding)")
    team = prune(team, inst.robot_amounts, inst.robot_payload, inst.task_needs[j], t.payload,
                 roles=bool(inst.task_roles[j]))
    return tuple(inst.robots[r].id for r in sorted(team))


def _solver(solve_by: float, work: float | None, workers: int, seed: int) -> cp_model.CpSolver | None:
    """CP-SAT for one neighbourhood, until ``solve_by`` (the model's building counts
    against the round's time) or for ``work`` deterministic time; None: no time left."""
    solver = cp_model.CpSolver()
    time_limit = solve_by - time.perf_counter()
    if work is not None:
        solver.parameters.max_deterministic_time = work
    elif time_limit <= 0.01:
        return None
    else:
        solver.parameters.max_time_in_seconds = time_limit
    solver.parameters.num_workers = workers
    solver.parameters.random_seed = seed
    solver.parameters.cp_model_probing_level = 0  # a neighbourhood's time goes to search, not to probing
    return solver


def _solve(model: cp_model.CpModel, solve_by: float, work: float | None, workers: int,
           seed: int) -> tuple[cp_model.CpSolver | None, int]:
    """Solve one neighbourhood (:func:`_solver`): the solver holding a solution (None when
    none was found) and NOT_RUN (no time left), OPEN or CLOSED (proven optimal, or no
    solution exists)."""
    solver = _solver(solve_by, work, workers, seed)
    if solver is None:
        return None, NOT_RUN
    status = solver.solve(model)
    if status not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        return None, CLOSED if status == cp_model.INFEASIBLE else OPEN
    return solver, CLOSED if status == cp_model.OPTIMAL else OPEN


def _outside(inst: Instance, inc: Schedule, prefix: list[int], free: set[int],
             starts: dict[int, float]) -> list[Assignment]:
    """The incumbent's tasks outside the model: the prefix as it is, and the tasks after
    the model after every task in it (a common offset), in their own order: the left shift
    keeps each robot's order by start, as they had it in the incumbent."""
    fixed = set(prefix)
    offset = max([0.0, *(starts[j] + float(inst.durations[j]) for j in free)])
    return [a if inst.task_index[a.task] in fixed else Assignment(a.task, a.robots, a.start + offset, a.end + offset)
            for a in inc.assignments if inst.task_index[a.task] not in free]


def _pool_window_model(inst: Instance, state: State, inc: Schedule, found: tuple[Pool, ...], prefix: list[int],
                       window: list[int], later: list[int], scale: int, solve_by: float, workers: int,
                       seed: int, work: float | None = None) -> tuple[Schedule | None, int]:
    """One neighbourhood over pools of interchangeable robots (no travel): the window's
    tasks choose a count per pool (the exact expert's pool model) and their starts; the
    later tasks keep their counts per pool and move; per pool one cumulative, each robot
    holding a unit until the prefix leaves it free. The robots of each pool are given
    afterwards (:func:`~lvws_ros.core.pools.assign_units`), then left-shifted."""
    by_task = inc.by_task()
    dur, fixed_end, team0, _, _, release, t0, upper = _prefix(inst, state, inc, prefix, window + later, scale)
    free = set(window) | set(later)
    of = {r: p for p, pool in enumerate(found) for r in pool.robots}
    model = cp_model.CpModel()
    start = {j: model.new_int_var(t0, upper, f"S_{j}") for j in free}
    end = {j: start[j] + dur[j] for j in free}
    makespan = model.new_int_var(max([t0, *fixed_end.values()]), upper, "C")
    pay_int, need_int = _payload_units(inst)
    count: dict[int, dict[int, Any]] = {}
    for j in window:
        count[j] = _pool_cover(model, inst, j, found, pay_int, need_int)
        for p, n in count[j].items():
            model.add_hint(n, min(sum(of[r] == p for r in team0[j]), _upper(n)))
    for j in later:  # their counts fixed
        count[j] = {p: sum(of[r] == p for r in team0[j]) for p in {of[r] for r in team0[j]}}
    for p, pool in enumerate(found):
        ivs = [model.new_fixed_size_interval_var(start[j], dur[j], f"I_{p}_{j}") for j in free if p in count[j]]
        demands = [count[j][p] for j in free if p in count[j]]
        for r in pool.robots:
            if release[r] > t0:
                ivs.append(model.new_fixed_size_interval_var(t0, int(release[r]) - t0, f"busy_{r}"))
                demands.append(1)
        if ivs:
            model.add_cumulative(ivs, demands, pool.size)
    for j in free:
        for q in inst.prerequisites[j]:
            model.add(start[j] >= (end[q] if q in free else fixed_end[q]))
        model.add(makespan >= end[j])
        model.add_hint(start[j], min(upper, max(t0, round(by_task[inst.tasks[j].id].start * scale))))
    model.minimize((len(free) * (upper + 1) + 1) * makespan + sum(end.values()))  # the makespan, then the ends
    solver, closed = _solve(model, solve_by, work, workers, seed)
    if solver is None:
        return None, closed
    teams: dict[int, list[int]] = {j: [] for j in free}
    for p, pool in enumerate(found):
        tasks = [j for j in free if int(solver.value(count[j][p]) if p in count[j] else 0) > 0]
        uses = [(float(solver.value(start[j])), float(solver.value(start[j]) + dur[j]), int(solver.value(count[j][p])))
                for j in tasks]
        for j, robots in zip(tasks, assign_units(pool.robots, [float(release[r]) for r in pool.robots], uses, 0.0),
                             strict=True):
            teams[j] += robots
    out = _outside(inst, inc, prefix, free, {j: solver.value(start[j]) / scale for j in free})
    for j in free:
        t, roles = inst.tasks[j], bool(inst.task_roles[j])
        if not covers(inst.robot_amounts[teams[j]], inst.robot_payload[teams[j]], inst.task_needs[j], t.payload, roles):
            raise ExpertError(f"task {t.id!r}: the pool window's subteam does not cover it (payload rounding)")
        team = prune(teams[j], inst.robot_amounts, inst.robot_payload, inst.task_needs[j], t.payload, roles=roles)
        s0 = solver.value(start[j]) / scale
        out.append(Assignment(t.id, tuple(inst.robots[r].id for r in sorted(team)), s0, s0 + t.duration))
    return left_shift(inst, Schedule.from_assignments(inst, inc.policy, out), state), closed


def critical_chain(inst: Instance, inc: Schedule) -> list[int]:
    """The tasks that hold ``inc``'s makespan up, last first: from the task that ends it
    (with the objective "return", the one after which a robot is home last), back through
    what each one waited for: the prerequisite or member's task before it that ended last,
    when that is when its subteam set out (the executor's rule: a subteam sets out once
    the task is ready and every member is free, and starts when the last one is there).
    It stops at a task that nothing held up (it started when the state let it)."""
    start = {inst.task_index[a.task]: a.start for a in inc.assignments}
    end = {inst.task_index[a.task]: a.end for a in inc.assignments}
    team = {inst.task_index[a.task]: [inst.robot_index[r] for r in a.robots] for a in inc.assignments}
    if not end:
        return []
    previous: dict[tuple[int, int], int] = {}  # (robot, task): the robot's task before it
    last_of: dict[int, int] = {}
    for j in sorted(end, key=lambda k: (start[k], k)):
        for r in team[j]:
            if r in last_of:
                previous[r, j] = last_of[r]
            last_of[r] = j
    travel = inst.travel
    ahead = inst.departure == "each"

    def way(r: int, j: int) -> float:  # from where the robot's task before j leaves it (or where it starts)
        if travel is None:
            return 0.0
        k = previous.get((r, j))
        return travel.time(r, travel.robot_site[r] if k is None else travel.task_to[k], travel.task_from[j])

    finish = dict(end)
    if travel is not None and inst.objective == "return":
        for r, j in last_of.items():
            finish[j] = max(finish[j], end[j] + travel.time(r, travel.task_to[j], travel.home(r)))
    j = max(finish, key=lambda k: (finish[k], k))
    chain = [j]
    while True:
        # the subteam sets out once the task is ready and every member is free, and starts
        # when the last member is there (the executor's rule)
        departs = start[j] - max(way(r, j) for r in team[j])
        held = [(end[q] - departs, q) for q in inst.prerequisites[j] if q in end]
        if ahead:  # each member sets out once free: a member's task before holds it up by its own way
            held += [(end[k] - (start[j] - way(r, j)), k) for r in team[j] if (k := previous.get((r, j))) is not None]
        else:
            held += [(end[k] - departs, k) for r in team[j] if (k := previous.get((r, j))) is not None]
        if not held:
            break
        slack, k = max(held)
        if slack < -TOLERANCE * max(1.0, abs(departs)) or k in chain:
            break
        chain.append(k)
        j = k
    return chain


def _neighbourhood(inst: Instance, inc: Schedule, by_task: dict[str, Assignment], todo: list[int], started: set[int],
                   kind: str, window: int, later_windows: int, rng: np.random.Generator,
                   found: tuple[Pool, ...]) -> tuple[list[int], list[int], list[int]]:
    """A neighbourhood of ``kind`` (KINDS): the prefix (fixed), the window (re-planned) and
    the later tasks (kept, moved). It spans ``window * (1 + later_windows)`` consecutive
    tasks of ``todo`` (sorted by start) from a time on: everything before is the prefix,
    so every prerequisite of a task in it is in it or before it.

    * ``time``: from a random task on, the window the first ``window`` tasks;
    * ``tail``: the last ``window`` tasks (those that end the schedule);
    * ``chain``: around a random task of the critical chain (:func:`critical_chain`), the
      window its chain tasks first, then the tasks sharing a robot with them;
    * ``busy``: from a random task on, the window the tasks of the robot (over pools: the
      pool) busiest over the span first.

    ``by_task``: ``inc``'s assignments by task; ``todo``: the tasks not started, by start."""
    span = window * (1 + later_windows)
    starts = [by_task[inst.tasks[j].id].start for j in todo]
    position = {j: i for i, j in enumerate(todo)}
    first: list[int] = []  # the tasks the window takes first, in this order
    chain = [j for j in critical_chain(inst, inc) if j in position] if kind == "chain" else []
    if kind == "tail":
        first_at = max(0, len(todo) - window)
    elif chain:
        centre = position[chain[int(rng.integers(0, len(chain)))]]
        first_at = max(0, centre - window // 2)
    else:
        first_at = int(rng.integers(0, max(1, len(todo) - window + 1)))
    # A neighbourhood starts at a time: tasks starting then but sorted before it belong to it.
    while first_at > 0 and starts[first_at - 1] >= starts[first_at] - TOLERANCE:
        first_at -= 1
    tasks = todo[first_at:first_at + span]
    if kind == "chain":
        on_chain = set(chain)
        first = [j for j in tasks if j in on_chain]
        robots = {r for j in first for r in by_task[inst.tasks[j].id].robots}
        first += [j for j in tasks if j not in on_chain and robots & set(by_task[inst.tasks[j].id].robots)]
    elif kind == "busy":
        first = _busiest(inst, by_task, tasks, found)
    picked = list(dict.fromkeys([*first, *tasks]))[:window]
    chosen = set(picked)
    later = [j for j in tasks if j not in chosen]
    return sorted(started | set(todo[:first_at])), picked, later


def _busiest(inst: Instance, by_task: dict[str, Assignment], tasks: list[int], found: tuple[Pool, ...]) -> list[int]:
    """The tasks of ``tasks`` that use the robot (or, over pools, the pool: the share of its
    units) with the most work among them, in their order."""
    of = {r: p for p, pool in enumerate(found) for r in pool.robots}
    load: dict[int, float] = {}
    users: dict[int, list[int]] = {}
    for j in tasks:
        members = [inst.robot_index[r] for r in by_task[inst.tasks[j].id].robots]
        for unit in {of[r] for r in members} if found else set(members):
            share = sum(of[r] == unit for r in members) / found[unit].size if found else 1.0
            load[unit] = load.get(unit, 0.0) + share * float(inst.durations[j])
            users.setdefault(unit, []).append(j)
    if not load:
        return []
    return users[max(load, key=lambda u: (load[u], -u))]


def improve(inst: Instance, incumbent: Schedule, *, state: State | None = None, time_limit: float = 10.0,
            window: int | None = None, workers: int = 1, seed: int = 0,
            round_limit: float = ROUND_LIMIT, bound: float | None = None,
            max_rounds: int | None = None, adaptive: bool = True) -> LNSResult:
    """Improve ``incumbent`` (a valid schedule of ``inst``, from ``state`` when given) by
    large-neighbourhood search within ``time_limit`` seconds (module docstring). Never
    returns a schedule longer than the incumbent; the same seed gives the same windows.
    With a lower ``bound`` (:func:`~lvws_ros.core.bounds.lower_bounds`), it stops when the
    schedule reaches it (optimal). ``window``: tasks per neighbourhood (None: DEFAULT_WINDOW,
    DEFAULT_WINDOW_TRAVEL with travel, DEFAULT_WINDOW_POOLS over pools). ``max_rounds``: at most this many neighbourhoods,
    each solved within ``round_limit`` of CP-SAT's deterministic time (not wall time) on
    ``workers`` = 1: the same result on every run and machine (``time_limit`` still holds).
    ``adaptive``: the window grows by a task after a neighbourhood CP-SAT proved within its
    round and shrinks by one (to MIN_WINDOW) after one it could not, up to twice its first
    size: the neighbourhoods fit the round's time whatever the team's size (with travel, the
    model grows with robots x tasks squared). The last window is in the result."""
    t_start = time.perf_counter()
    state = State.initial(inst) if state is None else state
    best = left_shift(inst, incumbent, state)
    first = float(best.makespan)
    search = _Search.start(inst, state, window, seed)
    rounds = improved = 0
    deadline = t_start + time_limit
    after = 0.0  # the longest a round ran past its solve_by so far (a left shift and check after the solve, or
    # a model's building that took the round's time): kept back from the deadline
    while (left := deadline - time.perf_counter() - after) > 0.05:
        if max_rounds is not None and rounds >= max_rounds:
            break
        if bound is not None and best.makespan <= bound + TOLERANCE:
            break  # optimal: nothing left to shorten
        by_task = best.by_task()
        todo = sorted((j for j in range(inst.num_tasks) if j not in search.started),
                      key=lambda j: (by_task[inst.tasks[j].id].start, j))
        if not todo:
            break
        kind = search.kind(rounds)
        prefix, picked, later = _neighbourhood(inst, best, by_task, todo, search.started, kind, search.window,
                                               search.later_windows, search.rng, search.found)
        whole = len(todo) <= search.window  # the whole rest fits one window: one solve says all, with all the time left
        solve_by = time.perf_counter() + (left if whole else min(round_limit, left))
        work = None if max_rounds is None else round_limit
        if work is not None:
            solve_by = deadline
        cand, solved = search.solve(best, prefix, picked, later, solve_by, workers, seed + rounds, work)
        rounds += solved != NOT_RUN
        shorter = cand is not None and _better(_score(cand), _score(best))
        if cand is not None and shorter:
            _check_round(inst, cand, rounds)
            best = cand
            improved += 1
        search.learn(kind, solved, shorter, adaptive)
        after = max(after, time.perf_counter() - solve_by)
        if whole:
            break
    best.policy = incumbent.policy
    return LNSResult(best, rounds, improved, first, time.perf_counter() - t_start, search.window)


def _default_window(pooled: bool, travel: bool) -> int:
    return DEFAULT_WINDOW_POOLS if pooled else DEFAULT_WINDOW if not travel else DEFAULT_WINDOW_TRAVEL


def _check_round(inst: Instance, cand: Schedule, rounds: int) -> None:
    """A neighbourhood's schedule is valid, or ExpertError (a bug)."""
    if check_schedule(inst, cand):
        raise ExpertError(f"lns: neighbourhood {rounds} gave an invalid schedule (a bug): "
                          f"{check_schedule(inst, cand)[0]}")


@dataclass
class _Search:
    """How an :func:`improve` run picks and solves its neighbourhoods: windows over pools
    (``pooled``: mostly interchangeable robots in a team past the coalition model's size)
    or per robot, the window that adapts to CP-SAT's proofs and the weights of the kinds of
    neighbourhood that adapt to what shortens the schedule."""

    inst: Instance
    state: State
    pooled: bool
    found: tuple[Pool, ...]
    window: int
    window_cap: int
    scale: int
    later_windows: int
    rng: np.random.Generator
    weights: np.ndarray  # how often each kind of neighbourhood is chosen (adapted: what shortens)
    started: set[int]

    @classmethod
    def start(cls, inst: Instance, state: State, window: int | None, seed: int) -> _Search:
        pooled = inst.num_robots > MAX_ENUMERATED and pools_apply(inst, state)
        found = pools(inst, state) if pooled else ()
        default = _default_window(pooled, inst.travel is not None)
        if window is None:
            window = default
        if window < 1:
            raise ExpertError(f"lns: the window must hold at least one task, got {window}")
        scale, _ = _time_scale(np.concatenate([inst.durations, [state.time], _travel_times(inst, state)]))
        return cls(inst, state, pooled, found, window, max(window, 2 * default), scale,
                   LATER if inst.travel is None else LATER_TRAVEL, np.random.default_rng(seed), np.ones(len(KINDS)),
                   {j for j in range(inst.num_tasks) if state.task_status[j] >= TaskStatus.ASSIGNED})

    def kind(self, rounds: int) -> str:
        """The kind of the next neighbourhood: over pools drawn by the weights; per robot, a
        third of the windows end the schedule, the rest from random times."""
        if self.pooled:
            return KINDS[int(self.rng.choice(len(KINDS), p=self.weights / self.weights.sum()))]
        return "tail" if rounds % 3 == 2 else "time"

    def solve(self, best: Schedule, prefix: list[int], picked: list[int], later: list[int], solve_by: float,
              workers: int, seed: int, work: float | None) -> tuple[Schedule | None, int]:
        """One neighbourhood's model solved: its schedule (None: none found) and NOT_RUN, OPEN or CLOSED."""
        if self.pooled:
            return _pool_window_model(self.inst, self.state, best, self.found, prefix, picked, later, self.scale,
                                      solve_by, workers, seed, work)
        return _window_model(self.inst, self.state, best, prefix, picked, later, self.scale, solve_by, workers,
                             seed, work)

    def learn(self, kind: str, solved: int, shorter: bool, adaptive: bool) -> None:
        """After a round that ran: with ``adaptive``, a proven neighbourhood makes the window
        larger, an open one smaller; a kind that shortens the schedule is chosen more often
        (never never)."""
        if solved == NOT_RUN:
            return
        if adaptive:
            self.window = min(self.window_cap, self.window + 1) if solved == CLOSED else max(MIN_WINDOW, self.window - 1)
        k = KINDS.index(kind)
        self.weights[k] = max(MIN_WEIGHT, (1 - REACTION) * self.weights[k] + REACTION * float(shorter))
