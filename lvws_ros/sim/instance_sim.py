"""The cell simulator's world for any instance file (``cell_sim`` with ``instance:=FILE``,
``lvws launch --instance FILE``): the instance's robots, sites, travel, traits, roles and
way home, run in steps of ``dt`` sim seconds by the rules of
:class:`~lvws_ros.sim.instance_world.InstanceWorld` (with ``"departure": "each"`` each
member sets out on its own; duration noise as the assembly cell's). No physics: a robot
stands at the site its last task given leaves it (the markers show it there). The world
does not change while it runs: submitting, cancelling and faults are served by the
assembly-cell world only, and are refused here with that reason.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import GraphSnapshot, TeamSnapshot
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Assignment, Schedule
from lvws_ros.errors import AssignmentRejected, ConfigError, PolicyError, WorldEventRejected
from lvws_ros.sim.instance_world import InstanceWorld, check_noise
from lvws_ros.sim.world import Event

__all__ = ["InstanceSim", "check_alone"]


def check_alone(instance: str, config: str = "", events: str = "") -> None:
    """An instance file is the whole world: ConfigError when an assembly-cell config or
    scripted events are given beside it."""
    if instance and (config or events):
        raise ConfigError(f"instance {instance}: runs alone; {'config' if config else 'events'} is for an "
                          "assembly-cell configuration")

UNCHANGING = "the simulator runs an instance file, which does not change while it runs (submit, cancel and " \
             "faults are served by an assembly-cell config)"


@dataclass(frozen=True)
class InstanceSimConfig:
    dt: float = 0.05  # sim seconds per step
    frame_id: str = "map"


class InstanceSim:
    """``assign`` gives tasks (to busy robots too, with departure each), ``step`` advances
    sim time by ``cfg.dt`` and says which tasks finished."""

    def __init__(self, inst: Instance, noise: float = 0.0, noise_seed: int = 0, dt: float = 0.05) -> None:
        self.inst = inst
        self.world = InstanceWorld(inst, check_noise(noise), int(noise_seed))
        self.cfg = InstanceSimConfig(dt)
        self.failed: set[str] = set()  # robots never fail here (the assembly cell's faults)
        self.trace: list[Any] = []  # no GIF frames (the assembly cell draws them)
        self.jobs: list[str] = []

    @property
    def time(self) -> float:
        return self.world.time

    @property
    def done(self) -> bool:
        return self.world.done

    @property
    def status(self) -> dict[str, TaskStatus]:
        return {t.id: TaskStatus(int(s)) for t, s in zip(self.inst.tasks, self.world.status, strict=True)}

    @property
    def robot_task(self) -> dict[str, str | None]:
        """The task each robot is on or heading to (None: free)."""
        return {r.id: (self.inst.tasks[q[0]].id if q else None) for r, q in zip(self.inst.robots, self.world.queue,
                                                                                strict=True)}

    def schedule(self, policy: str = "", decisions: int = 0) -> Schedule:
        """What ran (the durations the world took), once done."""
        w, inst = self.world, self.inst
        out = [Assignment(t.id, tuple(inst.robots[r].id for r in w.team[j]), float(w.start[j]),
                          float(w.start[j] + w.actual[j])) for j, t in enumerate(inst.tasks) if w.team[j]]
        return Schedule.from_assignments(w.executed_instance(), policy, out, decisions)

    @property
    def makespan(self) -> float | None:
        """By the instance's objective (with ``"return"``: the last robot home), once done."""
        return self.schedule().makespan if self.done else None

    def assign(self, task_id: str, robot_ids: Sequence[str]) -> None:
        if task_id not in self.inst.task_index or any(r not in self.inst.robot_index for r in robot_ids):
            raise AssignmentRejected(f"{task_id} <- {list(robot_ids)}: an unknown task or robot")
        try:
            self.world.assign(task_id, tuple(robot_ids))
        except PolicyError as exc:
            raise AssignmentRejected(str(exc)) from None

    def step(self) -> list[Event]:
        """``cfg.dt`` sim seconds on, or to the end of the next task within them."""
        w = self.world
        end = w.next_end()
        if end is None or end > w.time + self.cfg.dt:
            w.time += self.cfg.dt
            return []
        return [Event(w.time, "finished", self.inst.tasks[j].id, tuple(self.inst.robots[r].id for r in w.team[j]))
                for j in w.step()]

    def team_snapshot(self) -> TeamSnapshot:
        return self.world.team_snapshot()

    def graph_snapshot(self) -> GraphSnapshot:
        return self.world.graph_snapshot()

    def position(self, robot_id: str) -> tuple[float, float]:
        """Where the robot stands (its site's coordinates; 0, 0 without travel)."""
        tr = self.inst.travel
        if tr is None:
            return (0.0, 0.0)
        x, y = tr.coordinates[self.world.site[self.inst.robot_index[robot_id]]]
        return (float(x), float(y))

    def impossible(self) -> dict[str, str]:
        return {}  # the robots never change: a file that loads can be finished

    def record_frame(self) -> None:
        return None

    def submit(self, _items: Any) -> list[Event]:
        raise WorldEventRejected(UNCHANGING)

    def cancel(self, _task: str) -> list[Event]:
        raise WorldEventRejected(UNCHANGING)

    def fail(self, _robot: str) -> list[Event]:
        raise WorldEventRejected(UNCHANGING)

    def repair(self, _robot: str) -> list[Event]:
        raise WorldEventRejected(UNCHANGING)
