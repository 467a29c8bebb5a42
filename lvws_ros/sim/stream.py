"""A cell that never stops: jobs of tasks with precedence arrive as a Poisson stream, robots
work them off, done work retires, and the world says what changed (the change-only
protocol, :class:`~lvws_ros.core.changes.CellChanges`) once per tick of its clock.

Each job has 5-20 tasks; each task after the first waits on one or two earlier tasks of its
job, needs one or two of the cell's capabilities and a payload that takes one to three robots
(Eqs. 10-11 on the team), and lasts 2-8 time units. A DONE task retires ``retire_after`` time
units after it ended once all its dependents have started. The stream benchmark
(``lvws_ros.cli.bench_stream``) and the tests drive it; nothing here knows of ROS.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, replace

import numpy as np

from lvws_ros.core.changes import CellChanges
from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot
from lvws_ros.errors import AssignmentRejected

__all__ = ["StreamCounts", "StreamWorld"]

CAPABILITIES = ("arm", "lift", "scan")
_Q, _R, _A, _D = (int(s) for s in (TaskStatus.QUEUED, TaskStatus.READY, TaskStatus.ASSIGNED, TaskStatus.DONE))


@dataclass
class StreamCounts:
    """Every task accounted for: added = done + live (not done yet) at any time."""

    added: int = 0
    done: int = 0
    retired: int = 0
    rejected: int = 0  # assignments the world refused (a task not ready, a robot busy)


class StreamWorld:
    """The world (module docstring): ``robots`` robots, ``jobs_per_unit`` jobs arriving per
    time unit on average, a tick of ``tick`` time units between two batches."""

    def __init__(self, robots: int, jobs_per_unit: float, seed: int = 0, tick: float = 1.0,
                 retire_after: float = 0.0) -> None:
        self.rng = np.random.default_rng(seed)
        self.rate, self.tick, self.retire_after = jobs_per_unit, tick, retire_after
        self.time = 0.0
        self.counts = StreamCounts()
        self.robots: dict[str, RobotInfo] = {}
        for i in range(robots):
            caps = tuple(int(c) for c in self.rng.integers(0, 2, len(CAPABILITIES)))
            if not any(caps):
                caps = tuple(int(k == i % len(CAPABILITIES)) for k in range(len(CAPABILITIES)))
            self.robots[f"r{i}"] = RobotInfo(f"r{i}", "amr", True, caps, float(self.rng.integers(2, 6)))
        self.until: dict[str, float] = {}  # busy robots: when their task ends
        self.tasks: dict[str, TaskInfo] = {}
        self.dependents: dict[str, list[str]] = {}
        self.ending: list[tuple[float, str]] = []  # (end, task) of running tasks
        self.done_live: set[str] = set()  # DONE, not retired yet
        self.next_job = 0
        self.next_arrival = float(self.rng.exponential(1.0 / jobs_per_unit))
        # changed since the last batch, in the order they changed: a new task goes out in the
        # order the world holds it, so a follower's cell lists tasks as a resync's snapshot does
        self.dirty_tasks: dict[str, None] = {}
        self.dirty_robots: dict[str, None] = {}
        self.gone: list[str] = []  # retired since the last batch
        self._arrive()

    # -- the stream ----------------------------------------------------------------------
    def _arrive(self) -> None:
        while self.next_arrival <= self.time + 1e-12:
            self._job()
            self.next_arrival += float(self.rng.exponential(1.0 / self.rate))

    def _job(self) -> None:
        rng, k = self.rng, len(CAPABILITIES)
        ids = [f"j{self.next_job}_{n}" for n in range(int(rng.integers(5, 21)))]
        self.next_job += 1
        for n, tid in enumerate(ids):
            after = tuple(sorted({ids[int(p)] for p in rng.integers(0, n, int(rng.integers(1, 3)))})) if n else ()
            caps = [0] * k
            for c in rng.choice(k, int(rng.integers(1, 3)), replace=False):
                caps[int(c)] = 1
            t = TaskInfo(tid, _Q if after else _R, tuple(caps), float(rng.integers(1, 12)),
                         float(rng.integers(2, 9)), after)
            self.tasks[tid] = t
            for p in after:
                self.dependents.setdefault(p, []).append(tid)
            self.dirty_tasks[tid] = None
            self.counts.added += 1

    # -- the robots' work ----------------------------------------------------------------
    def assign(self, task: str, robots: tuple[str, ...]) -> None:
        """Start ``task`` with ``robots`` now (AssignmentRejected: not ready, or a member busy)."""
        t = self.tasks.get(task)
        if t is None or t.status != _R or any(r not in self.robots or r in self.until for r in robots):
            self.counts.rejected += 1
            raise AssignmentRejected(f"{task} <- {list(robots)}: not ready, or a member is busy or unknown")
        end = self.time + t.duration
        self.tasks[task] = replace(t, status=_A, assigned_robots=tuple(robots), start=self.time)
        heapq.heappush(self.ending, (end, task))
        for r in robots:
            self.until[r] = end
            self.robots[r] = replace(self.robots[r], available=False, current_task=task)
            self.dirty_robots[r] = None
        self.dirty_tasks[task] = None

    def advance(self) -> None:
        """One tick: tasks that end in it are DONE (their robots free, their dependents
        ready), jobs that arrive in it are added, done work retires."""
        self.time += self.tick
        while self.ending and self.ending[0][0] <= self.time + 1e-12:
            end, tid = heapq.heappop(self.ending)
            t = self.tasks[tid]
            self.tasks[tid] = replace(t, status=_D, end=end)
            self.done_live.add(tid)
            self.counts.done += 1
            self.dirty_tasks[tid] = None
            for r in t.assigned_robots:
                del self.until[r]
                self.robots[r] = replace(self.robots[r], available=True, current_task="")
                self.dirty_robots[r] = None
            for d in self.dependents.get(tid, ()):
                dep = self.tasks[d]
                if dep.status == _Q and all(self.tasks[p].status == _D for p in dep.prerequisites
                                            if p in self.tasks):
                    self.tasks[d] = replace(dep, status=_R)
                    self.dirty_tasks[d] = None
        self._arrive()
        self._retire()

    def _retire(self) -> None:
        """DONE tasks said DONE in an earlier batch, ended ``retire_after`` ago, whose
        dependents have all started, leave."""
        for tid in [k for k in self.done_live if k not in self.dirty_tasks]:
            t = self.tasks[tid]
            if t.end is not None and t.end <= self.time - self.retire_after and \
                    all(self.tasks[d].status >= _A for d in self.dependents.get(tid, ())):
                self._drop(tid)

    def _drop(self, tid: str) -> None:
        t = self.tasks.pop(tid)
        for d in self.dependents.pop(tid, ()):
            dep = self.tasks[d]
            self.tasks[d] = replace(dep, prerequisites=tuple(p for p in dep.prerequisites if p != tid))
        for p in t.prerequisites:
            if p in self.dependents:
                self.dependents[p].remove(tid)
        self.done_live.discard(tid)
        self.gone.append(tid)
        self.counts.retired += 1

    # -- what it says ----------------------------------------------------------------------
    @property
    def live(self) -> int:
        return len(self.tasks)

    def snapshots(self) -> tuple[TeamSnapshot, GraphSnapshot]:
        """The cell now, whole (change 0, or a resync's answer)."""
        robots = tuple(replace(r, busy_for=self.until[r.id] - self.time) if r.id in self.until else r
                       for r in self.robots.values())
        return (TeamSnapshot(self.time, CAPABILITIES, robots),
                GraphSnapshot(self.time, CAPABILITIES, tuple(self.tasks.values())))

    def changes(self, seq: int) -> CellChanges:
        """What changed since the last batch, as batch ``seq``."""
        tasks = tuple(self.tasks[t] for t in self.dirty_tasks if t in self.tasks)
        robots = tuple(replace(self.robots[r], busy_for=self.until[r] - self.time) if r in self.until
                       else self.robots[r] for r in self.dirty_robots)
        batch = CellChanges(seq, self.time, tasks, retired=tuple(self.gone), robots=robots)
        self.dirty_tasks, self.dirty_robots, self.gone = {}, {}, []
        return batch
