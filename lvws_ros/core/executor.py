"""Event-driven schedule executor (LVWS paper, section III-A).

Decision steps happen at time 0 and whenever a task finishes. At each step the policy
sees the state vectors of the paper (robot availability a^r; task ready / assigned /
incomplete s^t) and returns subteam assignments of free robots to ready tasks; free
robots it leaves out take the idle task t_{M+1} (they wait until the next step).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Protocol, runtime_checkable

import numpy as np
import numpy.typing as npt

from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.core.subteams import TOLERANCE, FloatArray, cover_with, covers
from lvws_ros.errors import PolicyError


class TaskStatus(IntEnum):
    """Values match lvws_msgs/Task STATUS_* constants."""

    QUEUED = 0
    READY = 1
    ASSIGNED = 2
    DONE = 3


@dataclass
class State:
    """What a policy sees at a decision step (also a mid-run state for the expert)."""

    instance: Instance
    time: float
    robot_free_at: FloatArray  # (N,) time each robot becomes free
    task_status: npt.NDArray[np.int8]  # (M,) TaskStatus
    task_start: FloatArray  # (M,) nan until started
    task_team: list[tuple[int, ...]]  # robots of each started task
    step: int = 0
    # travel extension: the site each robot is at (or will be, when its task is done); None: no travel
    robot_site: npt.NDArray[np.int64] | None = None

    def __post_init__(self) -> None:
        if self.robot_site is None and self.instance.travel is not None:  # no sites given: where robots start
            self.robot_site = np.array(self.instance.travel.robot_site, dtype=np.int64)

    @classmethod
    def initial(cls, inst: Instance) -> State:
        m = inst.num_tasks
        state = cls(
            instance=inst,
            time=0.0,
            robot_free_at=np.zeros(inst.num_robots),
            task_status=np.full(m, TaskStatus.QUEUED, dtype=np.int8),
            task_start=np.full(m, np.nan),
            task_team=[() for _ in range(m)],
        )
        state.refresh()
        return state

    @property
    def task_end(self) -> FloatArray:
        return self.task_start + self.instance.durations

    def robot_available(self) -> npt.NDArray[np.bool_]:
        """a^r: robots free at the current time."""
        return self.robot_free_at <= self.time + TOLERANCE

    def free_robots(self) -> list[int]:
        return np.flatnonzero(self.robot_available()).tolist()

    def ready_tasks(self) -> list[int]:
        return np.flatnonzero(self.task_status == TaskStatus.READY).tolist()

    def tasks_to_do(self) -> list[int]:
        """Tasks not started yet (queued or ready): what a schedule from here still places."""
        return np.flatnonzero(self.task_status <= TaskStatus.READY).tolist()

    def task_state_vectors(self) -> npt.NDArray[np.float32]:
        """s^t = [ready, assigned, incomplete] per task (section III-A)."""
        s = self.task_status
        return np.stack(
            [s == TaskStatus.READY, s == TaskStatus.ASSIGNED, s != TaskStatus.DONE], axis=1
        ).astype(np.float32)

    def busy_remaining(self) -> FloatArray:
        return np.maximum(self.robot_free_at - self.time, 0.0)

    def done(self) -> bool:
        return bool(np.all(self.task_status == TaskStatus.DONE))

    def refresh(self) -> None:
        """Finish tasks whose end has come, then mark tasks with all prerequisites done ready."""
        inst = self.instance
        running = self.task_status == TaskStatus.ASSIGNED
        finished = running & (self.task_end <= self.time + TOLERANCE)
        self.task_status[finished] = TaskStatus.DONE
        queued = self.task_status == TaskStatus.QUEUED
        if queued.any():
            task, pre = inst.prerequisite_edges
            waiting = np.zeros(len(queued), dtype=bool)  # a prerequisite not done yet
            waiting[task[self.task_status[pre] != TaskStatus.DONE]] = True
            self.task_status[queued & ~waiting] = TaskStatus.READY

    def arrival(self, task: int, team: Sequence[int]) -> float:
        """Seconds until the last member of ``team`` can be at ``task`` (0 without travel;
        inf if a fixed member is elsewhere)."""
        tr = self.instance.travel
        if tr is None or self.robot_site is None:
            return 0.0
        return tr.arrival(team, [int(self.robot_site[r]) for r in team], task)

    def arrival_each(self, task: int, team: Sequence[int]) -> float:
        """When the last member of ``team`` can be at ``task`` if each sets out as soon as
        it is free (now, or when the tasks it was given end) from where it is then
        (``"departure": "each"``; inf if a fixed member is elsewhere)."""
        tr = self.instance.travel
        leave = np.maximum(self.robot_free_at[list(team)], self.time)
        if tr is None or self.robot_site is None:
            return float(leave.max())
        return max(float(t) + tr.arrival([r], [int(self.robot_site[r])], task) for r, t in zip(team, leave, strict=True))

    def arrivals(self, robots: npt.ArrayLike, tasks: npt.ArrayLike) -> FloatArray:
        """(len(robots), len(tasks)): seconds each robot needs to reach each task alone
        (zeros without travel; inf where it never can)."""
        tr = self.instance.travel
        if tr is None or self.robot_site is None:
            return np.zeros((np.size(robots), np.size(tasks)))
        return tr.arrivals(robots, self.robot_site[np.asarray(robots, dtype=np.int64)], tasks)

    def reachable(self, robots: npt.ArrayLike, tasks: npt.ArrayLike) -> npt.NDArray[np.bool_]:
        """(len(robots), len(tasks)): which robot can reach which task at all (all True
        without travel; a fixed robot only tasks at its site that do not move it)."""
        return np.isfinite(self.arrivals(robots, tasks))

    def start(self, task: int, team: Sequence[int]) -> None:
        """The subteam is busy from now: it travels to the task (travel extension), which
        starts when its slowest member is there. With ``"departure": "each"`` a member may
        be busy still (given earlier tasks): it sets out from where those leave it once it
        is free (:meth:`arrival_each`)."""
        if self.instance.departure == "each":
            start = self.arrival_each(task, team)
        else:
            start = self.time + self.arrival(task, team)
        self.task_status[task] = TaskStatus.ASSIGNED
        self.task_start[task] = start
        self.task_team[task] = tuple(sorted(team))
        self.robot_free_at[list(team)] = start + self.instance.durations[task]
        if self.robot_site is not None and self.instance.travel is not None:
            self.robot_site[list(team)] = self.instance.travel.task_to[task]

    def next_event_time(self) -> float | None:
        running = self.task_status == TaskStatus.ASSIGNED
        if not running.any():
            return None
        return float(self.task_end[running].min())

    def copy(self) -> State:
        return State(
            instance=self.instance,
            time=self.time,
            robot_free_at=self.robot_free_at.copy(),
            task_status=self.task_status.copy(),
            task_start=self.task_start.copy(),
            task_team=list(self.task_team),
            step=self.step,
            robot_site=None if self.robot_site is None else self.robot_site.copy(),
        )


@dataclass(frozen=True)
class Decision:
    """Subteam assignments (task index, robot indices) and the robots that wait."""

    assignments: tuple[tuple[int, tuple[int, ...]], ...] = ()
    waiting: tuple[int, ...] = ()


PLAN_DRIFT = 0.01  # share of a plan's makespan by which the world may run early or late at a step


def plan_step_near(times: Sequence[float], now: float, makespan: float) -> float | None:
    """The time in ``times`` (a plan's step times) that is the world's step at ``now``:
    the nearest, if within TOLERANCE or PLAN_DRIFT x the plan's makespan (online, a
    simulator or real robots run a little early or late: the world integrates travel, the
    plan computes it); None when none is. A policy that follows a plan re-plans when this
    is None, not at every step at which the world is a little off."""
    if not times:
        return None
    nearest = min(times, key=lambda x: abs(x - now))
    return nearest if abs(nearest - now) <= max(TOLERANCE, PLAN_DRIFT * makespan) else None


class Policy(Protocol):
    name: str

    def reset(self, instance: Instance) -> None: ...

    def decide(self, state: State) -> Decision: ...


@runtime_checkable
class Budgeted(Protocol):
    """A policy with a time budget per decision (``budget_ms``; None: no budget). A caller
    that began the decision's work earlier (the scheduler node: when the message that
    made the decision due arrived, before converting it) sets ``clock`` to that
    perf_counter time just before ``decide``, and the budget counts from it."""

    clock: float | None

    @property
    def budget_ms(self) -> float | None: ...


def decision_deadline(policy: Budgeted) -> float | None:
    """The perf_counter time by which ``policy``'s decision is due: its budget counted from
    its ``clock`` (then cleared: it holds for one decision) or from now; None without a
    budget."""
    start = policy.clock if policy.clock is not None else time.perf_counter()
    policy.clock = None
    return None if policy.budget_ms is None else start + policy.budget_ms / 1000


@dataclass
class StepRecord:
    time: float
    free_robots: tuple[int, ...]
    ready_tasks: tuple[int, ...]
    decision: Decision
    seconds: float
    state: State | None = None


@dataclass
class SimulationResult:
    schedule: Schedule
    steps: list[StepRecord] = field(default_factory=list)


def check_decision(state: State, decision: Decision, policy: str = "policy") -> None:
    """Raise PolicyError unless the decision obeys Eqs. 8-11 in this state. With
    ``"departure": "each"`` a task may also be given to busy robots, and a robot several
    tasks of one step (in the decision's order: it does them one after the other)."""
    inst = state.instance
    ahead = inst.departure == "each"
    free = np.ones(inst.num_robots, dtype=bool) if ahead else state.robot_available()
    used: set[int] = set()
    seen_tasks: set[int] = set()
    for task, team in decision.assignments:
        if not 0 <= task < inst.num_tasks:
            raise PolicyError(f"{policy}: unknown task index {task}")
        tid = inst.tasks[task].id
        if state.task_status[task] != TaskStatus.READY:
            raise PolicyError(f"{policy}: task {tid!r} is not ready (status {TaskStatus(state.task_status[task]).name})")
        if task in seen_tasks:
            raise PolicyError(f"{policy}: task {tid!r} assigned twice in one step")
        seen_tasks.add(task)
        if not team:
            raise PolicyError(f"{policy}: task {tid!r} assigned to an empty subteam")
        for r in team:
            if not 0 <= r < inst.num_robots:
                raise PolicyError(f"{policy}: unknown robot index {r}")
            if not free[r]:
                raise PolicyError(f"{policy}: robot {inst.robots[r].id!r} is busy until {state.robot_free_at[r]:g}")
            if r in used and not ahead:
                raise PolicyError(f"{policy}: robot {inst.robots[r].id!r} given two tasks (Eq. 9)")
            used.add(r)
        idx = list(team)
        if math.isinf(state.arrival(task, idx)):
            raise PolicyError(f"{policy}: task {tid!r}: a fixed robot of {[inst.robots[r].id for r in team]} is at "
                              "another site (travel extension)")
        if not covers(inst.robot_amounts[idx], inst.robot_payload[idx], inst.task_needs[task], inst.tasks[task].payload,
                      bool(inst.task_roles[task])):
            raise PolicyError(f"{policy}: subteam {[inst.robots[r].id for r in team]} does not cover task {tid!r} (Eqs. 10-11)")


def voluntary_waits(state: State, decision: Decision) -> dict[int, tuple[int, ...]]:
    """Robots the decision keeps waiting although they could start a ready task now.

    A wait is voluntary (the paper's behaviour, section III-A) when some ready task the
    decision leaves unassigned has a covering subteam (Eqs. 10-11) among the robots it
    leaves free that includes the robot and needs it (found constructively,
    :func:`~lvws_ros.core.subteams.cover_with`); with travel, among those that can reach
    the task at all. Returns robot index -> those task indices.
    """
    inst = state.instance
    taken = {r for _, team in decision.assignments for r in team}
    left = [r for r in state.free_robots() if r not in taken]
    started = {task for task, _ in decision.assignments}
    out: dict[int, list[int]] = {}
    if not left:
        return {}
    ready = [j for j in state.ready_tasks() if j not in started]
    reach = state.reachable(left, ready)
    for c, j in enumerate(ready):
        able = [r for r, ok in zip(left, reach[:, c], strict=True) if ok]
        caps, payloads, roles = inst.robot_amounts[able], inst.robot_payload[able], bool(inst.task_roles[j])
        if not able or not covers(caps, payloads, inst.task_needs[j], inst.tasks[j].payload, roles):
            continue
        for k, r in enumerate(able):
            if cover_with(caps, payloads, inst.task_needs[j], inst.tasks[j].payload, k, roles) is not None:
                out.setdefault(r, []).append(j)
    return {r: tuple(ts) for r, ts in sorted(out.items())}


def simulate(
    inst: Instance,
    policy: Policy,
    *,
    record_states: bool = False,
    state: State | None = None,
    max_steps: int | None = None,
) -> SimulationResult:
    """Run ``policy`` on ``inst`` from time 0 (or from ``state``) until every task is done."""
    policy.reset(inst)
    state = State.initial(inst) if state is None else state.copy()
    steps: list[StepRecord] = []
    compute = 0.0
    limit = max_steps if max_steps is not None else 4 * (inst.num_tasks + 1) * (inst.num_robots + 1)
    while not state.done():
        if len(steps) >= limit:
            raise PolicyError(f"{policy.name}: no schedule after {limit} decision steps")
        snapshot = state.copy() if record_states else None
        t0 = time.perf_counter()
        decision = policy.decide(state)
        seconds = time.perf_counter() - t0
        compute += seconds
        check_decision(state, decision, policy.name)
        steps.append(
            StepRecord(state.time, tuple(state.free_robots()), tuple(state.ready_tasks()), decision, seconds, snapshot)
        )
        for task, team in decision.assignments:
            state.start(task, team)
        nxt = state.next_event_time()
        if nxt is None:
            free = [inst.robots[r].id for r in state.free_robots()]
            ready = [inst.tasks[j].id for j in state.ready_tasks()]
            raise PolicyError(
                f"{policy.name}: no progress at t={state.time:g}: nothing is running and no task was "
                f"started (free robots {free}, ready tasks {ready})"
            )
        state.time = nxt
        state.step += 1
        state.refresh()
    return SimulationResult(schedule_from_state(state, policy.name, len(steps), compute), steps)


def advance(state: State, decision: Decision) -> State | None:
    """The state at the next decision step after ``decision`` (as :func:`simulate` moves
    on), None if the decision would stall the schedule."""
    s = state.copy()
    for task, team in decision.assignments:
        s.start(task, team)
    nxt = s.next_event_time()
    if nxt is None:
        return None
    s.time, s.step = nxt, s.step + 1
    s.refresh()
    return s


def final_makespan(state: State) -> float:
    """The makespan of a finished run by the instance's objective: the last task's end, or
    (``"objective": "return"``) when the last robot is home."""
    if state.instance.objective != "return":
        return float(np.nanmax(state.task_end))
    return schedule_from_state(state, "").makespan


def schedule_from_state(state: State, policy: str, decisions: int = 0, compute: float = 0.0) -> Schedule:
    inst = state.instance
    out = [
        Assignment(
            task=t.id,
            robots=tuple(inst.robots[r].id for r in state.task_team[j]),
            start=float(state.task_start[j]),
            end=float(state.task_start[j] + t.duration),
        )
        for j, t in enumerate(inst.tasks)
        if not np.isnan(state.task_start[j])
    ]
    return Schedule.from_assignments(inst, policy, out, decisions, compute)
