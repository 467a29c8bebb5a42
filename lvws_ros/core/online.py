"""Online scheduling from team and task-graph snapshots (the scheduler node's logic, ROS-free).

The scheduler node converts ``lvws_msgs/TeamState`` and ``lvws_msgs/TaskGraph`` into
the snapshots below and calls :class:`OnlineScheduler`; the simulator produces the
same snapshots directly, and ``lvws verify`` feeds recorded ones back. A decision step
happens whenever a robot becomes available or a task becomes ready (section III-A).

Robustness: snapshots older than the newest one seen are dropped (out of order);
repeated snapshots trigger nothing (no new free robot, no new ready task); a robot is
free only if the team says it is available *and* no running or just-assigned task
holds it, so a stale team message never lets a busy robot be assigned; assignments
the world has not acknowledged within ``ack_timeout`` seconds are released.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from lvws_ros.core.executor import Decision, Policy, State, TaskStatus, check_decision
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.errors import InstanceError

BUSY_EPS = 1e-3  # a busy robot with an overdue estimate is still busy


@dataclass(frozen=True)
class RobotInfo:
    id: str
    kind: str
    available: bool
    capabilities: tuple[int, ...]
    payload: float
    current_task: str = ""
    busy_for: float = 0.0
    pose: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TaskInfo:
    id: str
    status: int  # TaskStatus
    capabilities: tuple[int, ...]
    payload: float
    duration: float
    prerequisites: tuple[str, ...] = ()
    assigned_robots: tuple[str, ...] = ()
    start: float | None = None
    end: float | None = None


@dataclass(frozen=True)
class TeamSnapshot:
    stamp: float
    capability_names: tuple[str, ...]
    robots: tuple[RobotInfo, ...]


@dataclass(frozen=True)
class GraphSnapshot:
    stamp: float
    capability_names: tuple[str, ...]
    tasks: tuple[TaskInfo, ...]


@dataclass(frozen=True)
class OnlineDecision:
    """A :class:`~lvws_ros.core.executor.Decision` by ids, as published on
    ``lvws/assignments`` and read back from bags."""

    step: int
    assignments: tuple[tuple[str, tuple[str, ...]], ...]
    waiting: tuple[str, ...]
    latency: float  # wall seconds spent deciding
    team_stamp: float
    graph_stamp: float
    policy: str = ""


def build_instance(team: TeamSnapshot, graph: GraphSnapshot, name: str = "online") -> Instance:
    """The scheduling instance the snapshots describe (InstanceError on bad content)."""
    if tuple(team.capability_names) != tuple(graph.capability_names):
        raise InstanceError(f"team capabilities {list(team.capability_names)} differ from the task graph's "
                            f"{list(graph.capability_names)}")
    robots = tuple(Robot(r.id, tuple(int(c) for c in r.capabilities), float(r.payload)) for r in team.robots)
    tasks = tuple(Task(t.id, tuple(int(c) for c in t.capabilities), float(t.payload), float(t.duration),
                       tuple(t.prerequisites)) for t in graph.tasks)
    return Instance(name, tuple(graph.capability_names), robots, tasks)


def build_state(inst: Instance, team: TeamSnapshot, graph: GraphSnapshot,
                pending: Mapping[str, Sequence[str]] = {}) -> State:
    """The executor state at the newer snapshot's time, with ``pending`` (task -> robots
    assigned but not yet acknowledged) counted as running."""
    now = max(team.stamp, graph.stamp)
    m, n = inst.num_tasks, inst.num_robots
    status = np.array([t.status for t in graph.tasks], dtype=np.int8)
    teams: list[tuple[int, ...]] = [tuple(inst.robot_index[r] for r in t.assigned_robots if r in inst.robot_index)
                                    for t in graph.tasks]
    for tid, robots in pending.items():
        j = inst.task_index.get(tid)
        if j is not None and status[j] == TaskStatus.READY:
            status[j] = TaskStatus.ASSIGNED
            teams[j] = tuple(inst.robot_index[r] for r in robots)
    free_at = np.full(n, now)
    for i, r in enumerate(team.robots):
        if not r.available:
            free_at[i] = now + max(float(r.busy_for), BUSY_EPS)
    start = np.full(m, np.nan)
    for j, t in enumerate(graph.tasks):
        if status[j] == TaskStatus.ASSIGNED:
            idx = list(teams[j])
            busy = [free_at[i] for i in idx if free_at[i] > now]
            end = max(busy) if busy else now + inst.durations[j]  # just assigned, or an unacknowledged team
            free_at[idx] = np.maximum(free_at[idx], end)
            start[j] = end - inst.durations[j]
        elif status[j] == TaskStatus.DONE:
            start[j] = t.start if t.start is not None else now - inst.durations[j]
    return State(inst, now, free_at, status, start, teams)


def still_pending(pending: Mapping[str, tuple[tuple[str, ...], float]], graph: GraphSnapshot, now: float,
                  ack_timeout: float) -> dict[str, tuple[tuple[str, ...], float]]:
    """The assignments (task -> (robots, time sent)) the world has not acknowledged yet:
    a task no longer READY was acknowledged (or is gone); one older than ``ack_timeout``
    was never taken and is offered again."""
    status = {t.id: t.status for t in graph.tasks}
    return {k: v for k, v in pending.items() if status.get(k) == TaskStatus.READY and now - v[1] <= ack_timeout}


class OnlineScheduler:
    """Decides when a robot became available or a task became ready; see the module doc."""

    def __init__(self, policy: Policy, ack_timeout: float = 5.0) -> None:
        self.policy = policy
        self.ack_timeout = ack_timeout
        self.team: TeamSnapshot | None = None
        self.graph: GraphSnapshot | None = None
        self.pending: dict[str, tuple[tuple[str, ...], float]] = {}  # task -> (robots, when)
        self.step = 0
        self.dropped = 0  # out-of-order snapshots
        self._inst: Instance | None = None
        self._key: object = None
        self._seen_free: frozenset[str] = frozenset()
        self._seen_ready: frozenset[str] = frozenset()

    def offer_team(self, snap: TeamSnapshot) -> bool:
        if self.team is not None and snap.stamp < self.team.stamp:
            self.dropped += 1
            return False
        self.team = snap
        return True

    def offer_graph(self, snap: GraphSnapshot) -> bool:
        if self.graph is not None and snap.stamp < self.graph.stamp:
            self.dropped += 1
            return False
        self.graph = snap
        return True

    def instance(self) -> Instance:
        assert self.team is not None and self.graph is not None
        key = (self.team.capability_names, tuple((r.id, r.capabilities, r.payload) for r in self.team.robots),
               tuple((t.id, t.capabilities, t.payload, t.duration, t.prerequisites) for t in self.graph.tasks))
        if key != self._key or self._inst is None:
            self._inst = build_instance(self.team, self.graph)
            self._key = key
            self.policy.reset(self._inst)
        return self._inst

    def decide(self) -> OnlineDecision | None:
        """A decision if one is due (a new free robot or a new ready task), else None."""
        if self.team is None or self.graph is None:
            return None
        inst = self.instance()
        now = max(self.team.stamp, self.graph.stamp)
        self.pending = still_pending(self.pending, self.graph, now, self.ack_timeout)
        state = build_state(inst, self.team, self.graph, {k: v[0] for k, v in self.pending.items()})
        free = frozenset(inst.robots[i].id for i in state.free_robots())
        ready = frozenset(inst.tasks[j].id for j in state.ready_tasks())
        due = bool(free - self._seen_free) or bool(ready - self._seen_ready)
        due |= not (state.task_status == TaskStatus.ASSIGNED).any()  # nothing runs: waiting would stall
        self._seen_free, self._seen_ready = free, ready
        if not (due and free and ready):
            return None
        decision = self.decide_state(state)
        for task, robots in decision.assignments:
            self.pending[task] = (robots, now)
        self._seen_free = free - {r for _, team in decision.assignments for r in team}
        self._seen_ready = ready - {t for t, _ in decision.assignments}
        return decision

    def decide_state(self, state: State) -> OnlineDecision:
        """Run the policy on ``state`` (checked against Eqs. 8-11) and name the result."""
        inst = state.instance
        t0 = time.perf_counter()
        decision: Decision = self.policy.decide(state)
        latency = time.perf_counter() - t0
        check_decision(state, decision, self.policy.name)
        assigned = {r for _, team in decision.assignments for r in team}
        out = OnlineDecision(
            self.step,
            tuple((inst.tasks[j].id, tuple(inst.robots[r].id for r in team)) for j, team in decision.assignments),
            tuple(inst.robots[r].id for r in state.free_robots() if r not in assigned),
            latency,
            self.team.stamp if self.team else state.time,
            self.graph.stamp if self.graph else state.time,
            self.policy.name,
        )
        self.step += 1
        return out
