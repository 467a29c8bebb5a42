"""The dynamic protocol with a world the project did not write: a plain rclpy world (not
cell_sim, not lvws_ros' conversions) adds three tasks, cancels a queued one and fails a
busy robot mid-run, while the scheduler node (its own process, real DDS) schedules it.
The run completes, no assignment names a task or robot absent from the world's latest
snapshots, the changes are reported on diagnostics, and the schedule is valid for the
final task set."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pytest
from lvws_msgs.msg import RobotState, Task, TaskGraph, TeamState

from lvws_ros.core.problem import Instance
from lvws_ros.core.problem import Robot as CoreRobot
from lvws_ros.core.problem import Task as CoreTask
from lvws_ros.core.schedule import Assignment, Schedule, check_schedule
from lvws_ros.core.subteams import covers
from scheduler_probe import Probe, scheduler_probe

pytestmark = pytest.mark.ros

CAPS = ["lift", "weld"]
STATUS = {"queued": Task.STATUS_QUEUED, "ready": Task.STATUS_READY, "assigned": Task.STATUS_ASSIGNED,
          "done": Task.STATUS_DONE}


@dataclass
class WorldTask:
    caps: list[int]
    payload: float
    duration: float
    after: list[str]
    status: str = "queued"
    robots: tuple[str, ...] = ()
    start: float = 0.0
    end: float = 0.0


@dataclass
class World:
    """Robots with capabilities and payloads; tasks with a DAG; time jumps to the next end."""

    robots: dict[str, tuple[list[int], float]]
    tasks: dict[str, WorldTask]
    time: float = 0.0
    failed: set[str] = field(default_factory=set)
    busy: dict[str, str] = field(default_factory=dict)  # robot -> task
    rejected: list[str] = field(default_factory=list)

    def refresh(self) -> None:
        for t in self.tasks.values():
            if t.status == "queued" and all(self.tasks[a].status == "done" for a in t.after):
                t.status = "ready"

    def messages(self) -> tuple[TeamState, TaskGraph]:
        sec, nsec = int(self.time), round((self.time - int(self.time)) * 1e9)
        team = TeamState(capability_names=CAPS)
        team.header.stamp.sec, team.header.stamp.nanosec = sec, nsec
        for rid, (caps, payload) in self.robots.items():
            if rid in self.failed:
                continue  # a failed robot vanishes from TeamState
            task = self.busy.get(rid, "")
            team.robots.append(RobotState(id=rid, kind="cobot", available=not task, capabilities=caps,
                                          payload=payload, current_task=task,
                                          busy_for=max(0.0, self.tasks[task].end - self.time) if task else 0.0))
        graph = TaskGraph(capability_names=CAPS)
        graph.header.stamp.sec, graph.header.stamp.nanosec = sec, nsec
        for tid, t in self.tasks.items():
            graph.tasks.append(Task(id=tid, status=STATUS[t.status], capabilities=t.caps, payload=t.payload,
                                    duration=t.duration, prerequisites=t.after, assigned_robots=list(t.robots)))
        return team, graph

    def assign(self, tid: str, robots: tuple[str, ...]) -> None:
        t = self.tasks.get(tid)
        caps = np.array([self.robots[r][0] for r in robots if r in self.robots], dtype=bool).reshape(-1, len(CAPS))
        pay = np.array([self.robots[r][1] for r in robots if r in self.robots])
        if t is None or t.status != "ready" or any(r in self.failed or r in self.busy or r not in self.robots
                                                   for r in robots) \
                or not covers(caps, pay, np.array(t.caps, dtype=bool), t.payload):
            self.rejected.append(f"t={self.time:g}: {tid} <- {robots}")
            return
        t.status, t.robots, t.start, t.end = "assigned", robots, self.time, self.time + t.duration
        for r in robots:
            self.busy[r] = tid

    def fail(self, rid: str) -> str:
        """The robot stops; its task returns READY with no subteam (the others are released)."""
        tid = self.busy.pop(rid)
        t = self.tasks[tid]
        for r in t.robots:
            self.busy.pop(r, None)
        t.status, t.robots = "ready", ()
        self.failed.add(rid)
        return tid

    def advance(self, until: float | None) -> None:
        ends = [t.end for t in self.tasks.values() if t.status == "assigned"]
        nxt = min([*ends, *([until] if until is not None else [])])
        self.time = nxt
        for t in self.tasks.values():
            if t.status == "assigned" and t.end <= self.time + 1e-9:
                t.status = "done"
                for r in t.robots:
                    self.busy.pop(r, None)
        self.refresh()


def answer(probe: Probe, world: World, seconds: float = 4.0) -> None:
    """Publish the world and take the scheduler's answer to it, if it gives one."""
    before = len(probe.got)
    team, graph = world.messages()
    probe.graph_pub.publish(graph)
    probe.team_pub.publish(team)
    due = any(t.status == "ready" for t in world.tasks.values()) and \
        any(r not in world.busy and r not in world.failed for r in world.robots)
    if not due:
        probe.spin(0.2)
        return
    probe.spin(seconds, lambda: any(abs(m.team_stamp.sec + m.team_stamp.nanosec * 1e-9 - world.time) < 1e-6
                                    for m in probe.got[before:]))
    for m in probe.got[before:]:
        if abs(m.team_stamp.sec + m.team_stamp.nanosec * 1e-9 - world.time) < 1e-6:
            for a in m.assignments:
                world.assign(a.task_id, tuple(a.robot_ids))


def test_an_outside_world_adds_cancels_and_fails_and_the_schedule_completes_valid(ros_context):
    world = World(
        robots={"r0": ([1, 0], 3.0), "r1": ([0, 1], 3.0), "r2": ([1, 1], 2.0), "r3": ([1, 0], 4.0)},
        tasks={"t0": WorldTask([1, 0], 5.0, 4.0, []), "t1": WorldTask([0, 1], 1.0, 3.0, []),
               "t2": WorldTask([1, 1], 2.0, 5.0, ["t0"]), "t3": WorldTask([1, 0], 1.0, 2.0, ["t1"]),
               "t4": WorldTask([0, 1], 1.0, 6.0, ["t2", "t3"]), "t5": WorldTask([1, 0], 1.0, 2.0, ["t4"])})
    world.refresh()
    script = [2.0, 3.0]  # at 2: add three tasks and cancel t5 (queued); at 3: fail a busy robot
    failed_robot = interrupted = ""
    with scheduler_probe(ros_context, "lvws_outside_world", ["-p", "policy:=grp"]) as probe:
        probe.wait_for_scheduler()
        for _ in range(200):
            if all(t.status == "done" for t in world.tasks.values()):
                break
            answer(probe, world)
            world.advance(script[0] if script else None)
            if script and world.time >= script[0] - 1e-9:
                at = script.pop(0)
                if at == 2.0:
                    assert world.tasks["t5"].status == "queued"
                    del world.tasks["t5"]
                    world.tasks.update({"t6": WorldTask([0, 1], 2.0, 3.0, []), "t7": WorldTask([1, 0], 6.0, 2.0, []),
                                        "t8": WorldTask([1, 1], 1.0, 2.0, ["t6"])})
                    world.refresh()
                else:
                    failed_robot = next(r for r in sorted(world.busy))
                    interrupted = world.fail(failed_robot)
        probe.spin(1.5)  # the last diagnostics
    assert all(t.status == "done" for t in world.tasks.values()), {k: t.status for k, t in world.tasks.items()}
    assert world.rejected == [], world.rejected
    assert failed_robot and interrupted
    assert failed_robot not in world.tasks[interrupted].robots  # replanned without it
    for m in probe.got:  # nothing assigned that the latest snapshots did not hold
        assert all(a.task_id != "t5" for a in m.assignments if m.team_stamp.sec >= 2)
        assert all(failed_robot not in a.robot_ids for a in m.assignments if m.team_stamp.sec >= 3)
    inst = Instance("outside", tuple(CAPS),
                    tuple(CoreRobot(r, tuple(c), p) for r, (c, p) in world.robots.items()),
                    tuple(CoreTask(k, tuple(t.caps), t.payload, t.duration, tuple(t.after)) for k, t in world.tasks.items()))
    sched = Schedule.from_assignments("outside", "grp",
                                      [Assignment(k, t.robots, t.start, t.end) for k, t in world.tasks.items()])
    assert check_schedule(inst, sched) == []
    text = " ".join(probe.diags)
    assert "t6, t7, t8 added" in text and "t5 removed" in text
    assert f"{failed_robot} left the team" in text and f"{interrupted} interrupted" in text
