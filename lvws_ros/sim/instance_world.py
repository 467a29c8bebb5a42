"""A world for any instance file whose tasks take longer or shorter than planned: the
policy schedules online, through the same :class:`~lvws_ros.core.online.OnlineScheduler`
the scheduler node uses, from snapshots that give the nominal durations, while each task
takes its duration times a seeded factor in [1 - noise, 1 + noise] (:func:`duration_factor`,
the rule of the cell simulator too). Robots travel as the executor says (travel
extension); decisions happen when tasks end, as in the executor. With noise 0 the run is
the executor's, for either departure: with ``"departure": "each"`` (the TaskGraph carries it)
a task may be given to busy robots, each member sets out for it from where its earlier tasks
leave it as soon as it is free, and the task starts when the last one is there.

``lvws solve INSTANCE --noise 0.3 --noise-seed S`` prints the planned makespan (the
policy in the executor) against the executed one.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from lvws_ros.core.executor import Policy, TaskStatus, simulate
from lvws_ros.core.online import (
    GraphSnapshot,
    OnlineScheduler,
    RobotInfo,
    TaskInfo,
    TeamSnapshot,
    graph_sites,
    roles_code,
)
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.errors import ConfigError, PolicyError

__all__ = ["InstanceWorld", "NoisyRun", "duration_factor", "run_noisy"]


def duration_factor(noise: float, seed: int, task_id: str) -> float:
    """How much longer (or shorter) than its duration task ``task_id`` takes: 1 without
    noise, else 1 + noise x U(-1, 1) drawn from the seed and the task's id (the same
    factor for the same task in every run; tasks added later get theirs)."""
    if noise == 0.0:
        return 1.0
    u = np.random.default_rng([seed, zlib.crc32(task_id.encode())]).random()
    return 1.0 + noise * (2.0 * u - 1.0)


def check_noise(noise: float) -> float:
    if not (isinstance(noise, (int, float)) and 0.0 <= noise < 1.0):
        raise ConfigError(f"duration noise must be in [0, 1), got {noise!r}")
    return float(noise)


@dataclass(frozen=True)
class NoisyRun:
    planned: Schedule  # the policy in the executor, nominal durations
    executed: Schedule  # online in the noisy world; its instance has the durations the world took
    executed_instance: Instance
    decisions: int


class InstanceWorld:
    """The state of the noisy world: which task runs with whom from when to when (``lvws solve
    --noise``; the cell simulator runs it for an instance file, :mod:`lvws_ros.sim.instance_sim`)."""

    def __init__(self, inst: Instance, noise: float, seed: int) -> None:
        self.inst = inst
        self.actual = np.array([t.duration * duration_factor(noise, seed, t.id) for t in inst.tasks])
        self.time = 0.0
        self.status = np.full(inst.num_tasks, TaskStatus.QUEUED, dtype=np.int8)
        self.start = np.full(inst.num_tasks, np.nan)
        self.team: list[tuple[int, ...]] = [() for _ in inst.tasks]
        self.queue: list[list[int]] = [[] for _ in inst.robots]  # each robot's tasks given, not done, in order
        self.free = np.zeros(inst.num_robots)  # when each robot's last task given ends
        tr = inst.travel
        self.site = list(tr.robot_site) if tr is not None else [0] * inst.num_robots  # where it is when free
        self._ready()

    def _ready(self) -> None:
        done = self.status == TaskStatus.DONE
        for j in np.flatnonzero(self.status == TaskStatus.QUEUED):
            if all(done[p] for p in self.inst.prerequisites[j]):
                self.status[j] = TaskStatus.READY

    @property
    def done(self) -> bool:
        return bool((self.status == TaskStatus.DONE).all())

    def executed_instance(self) -> Instance:
        """The instance with the durations the world took."""
        return replace(self.inst, tasks=tuple(replace(t, duration=float(self.actual[j]))
                                              for j, t in enumerate(self.inst.tasks)))

    def assign(self, task: str, robots: tuple[str, ...]) -> None:
        inst, j = self.inst, self.inst.task_index[task]
        team = [inst.robot_index[r] for r in robots]
        ahead = inst.departure == "each"  # a busy member sets out once its earlier tasks end
        if self.status[j] != TaskStatus.READY or (not ahead and any(self.queue[r] for r in team)):
            raise PolicyError(f"task {task!r} with {list(robots)}: not ready, or a member is busy")
        tr = inst.travel
        leave = [max(self.time, float(self.free[r])) if ahead else self.time for r in team]
        arrive = [0.0 if tr is None else tr.arrival([r], [self.site[r]], j) for r in team]
        if math.isinf(max(arrive)):
            raise PolicyError(f"task {task!r}: a fixed member of {list(robots)} is elsewhere")
        self.status[j] = TaskStatus.ASSIGNED
        # together: every member is free now and they set out at once (Travel.arrival's rule)
        self.start[j] = max(a + b for a, b in zip(leave, arrive, strict=True))
        self.team[j] = tuple(sorted(team))
        for r in team:
            self.queue[r].append(j)
            self.free[r] = self.start[j] + self.actual[j]
            if tr is not None:
                self.site[r] = tr.task_to[j]

    def next_end(self) -> float | None:
        """When the next task given ends (None: nothing was given)."""
        running = np.flatnonzero(self.status == TaskStatus.ASSIGNED)
        return float((self.start[running] + self.actual[running]).min()) if len(running) else None

    def step(self) -> list[int]:
        """To the next end of a task; its robots are free where it leaves them. Returns the
        tasks that ended."""
        end = self.next_end()
        if end is None:
            raise PolicyError(f"t={self.time:g}: nothing runs and nothing was started: the run cannot go on")
        self.time = end
        running = np.flatnonzero(self.status == TaskStatus.ASSIGNED)
        ended = running[self.start[running] + self.actual[running] <= end + 1e-9].tolist()
        for j in ended:
            self.status[j] = TaskStatus.DONE
            for r in self.team[j]:
                self.queue[r].remove(j)
        self._ready()
        return ended

    def team_snapshot(self) -> TeamSnapshot:
        inst, tr = self.inst, self.inst.travel
        k = len(inst.capabilities)
        robots = []
        for i, r in enumerate(inst.robots):
            q = self.queue[i]  # busy until its last task given ends (nominally), at that task's site
            busy = 0.0 if not q else max(0.0, float(self.start[q[-1]] + inst.durations[q[-1]] - self.time))
            site = "" if tr is None else tr.sites[self.site[i]]
            robots.append(RobotInfo(r.id, "robot", not q, r.capabilities, r.payload,
                                    "" if not q else inst.tasks[q[0]].id, busy, (0.0, 0.0, 0.0), site,
                                    0.0 if tr is None else tr.robot_speed[i],
                                    tuple(float(a) for a in inst.robot_amounts[i, k:]),
                                    "" if tr is None else tr.sites[tr.home(i)]))
        return TeamSnapshot(self.time, inst.capabilities, tuple(robots), inst.traits)

    def graph_snapshot(self) -> GraphSnapshot:
        inst, tr = self.inst, self.inst.travel
        k = len(inst.capabilities)
        tasks = []
        for j, t in enumerate(inst.tasks):
            started = self.status[j] >= TaskStatus.ASSIGNED
            sites = ("", "") if tr is None else (tr.sites[tr.task_from[j]], tr.sites[tr.task_to[j]])
            tasks.append(TaskInfo(t.id, int(self.status[j]), t.capabilities, t.payload, t.duration, t.after,
                                  tuple(inst.robots[r].id for r in self.team[j]),
                                  float(self.start[j]) if started else None,
                                  float(self.start[j] + self.actual[j]) if self.status[j] == TaskStatus.DONE
                                  else None, *sites, tuple(float(a) for a in inst.task_needs[j, k:]),
                                  roles_code(t.roles)))
        where = ((), ()) if tr is None else graph_sites(tr)
        return GraphSnapshot(self.time, inst.capabilities, tuple(tasks), *where, inst.traits, inst.roles,
                             inst.objective, inst.departure)


def run_noisy(inst: Instance, make: Callable[[], Policy], noise: float, seed: int) -> NoisyRun:
    """``make()`` planned in the executor and run online in the noisy world (a fresh policy
    each); the factors seeded by ``seed``."""
    noise = check_noise(noise)
    planned = simulate(inst, make()).schedule
    world = InstanceWorld(inst, noise, seed)
    online = OnlineScheduler(make())
    decisions = 0
    while not world.done:
        online.offer_team(world.team_snapshot())
        online.offer_graph(world.graph_snapshot())
        d = online.decide()
        online.notices.clear()
        online.changes.clear()
        if d is not None:
            decisions += 1
            for task, robots in d.assignments:
                world.assign(task, robots)
        world.step()
    took = world.executed_instance()
    out = [Assignment(t.id, tuple(inst.robots[r].id for r in world.team[j]), float(world.start[j]),
                      float(world.start[j] + world.actual[j])) for j, t in enumerate(inst.tasks)]
    executed = Schedule.from_assignments(took, planned.policy, out, decisions)
    return NoisyRun(planned, executed, took, decisions)
