"""The scheduler's reuse of its instance between snapshots of the same cell: kept while
only what the run changes changed, rebuilt (and the policies reset) on any other change."""

from __future__ import annotations

import dataclasses

import pytest

from lvws_ros.core.online import (
    GraphSnapshot,
    OnlineScheduler,
    RobotInfo,
    TaskInfo,
    TeamSnapshot,
    build_instance,
    same_cell,
    schedulable,
)
from lvws_ros.registry import make_policy

CAPS = ("arm", "gripper")


def team(stamp: float = 0.0) -> TeamSnapshot:
    return TeamSnapshot(stamp, CAPS, tuple(RobotInfo(f"r{i}", "x", True, (1, 1), 5.0) for i in range(3)))


def graph(stamp: float = 0.0) -> GraphSnapshot:
    return GraphSnapshot(stamp, CAPS, tuple(TaskInfo(f"t{j}", 1 if j < 2 else 0, (1, 0), 1.0, 2.0 + j,
                                                     ("t0",) if j == 2 else ()) for j in range(4)))


def set_task(g: GraphSnapshot, j: int, **kw: object) -> GraphSnapshot:
    return dataclasses.replace(g, tasks=(*g.tasks[:j], dataclasses.replace(g.tasks[j], **kw),  # type: ignore[arg-type]
                                         *g.tasks[j + 1:]))


def set_robot(t: TeamSnapshot, i: int, **kw: object) -> TeamSnapshot:
    return dataclasses.replace(t, robots=(*t.robots[:i], dataclasses.replace(t.robots[i], **kw),  # type: ignore[arg-type]
                                          *t.robots[i + 1:]))


RUN_CHANGES = {  # what changes as the world runs: the same cell
    "stamps": lambda t, g: (dataclasses.replace(t, stamp=3.0), dataclasses.replace(g, stamp=3.0)),
    "status": lambda t, g: (t, set_task(g, 0, status=2, assigned_robots=("r0",), start=0.0)),
    "busy": lambda t, g: (set_robot(t, 1, available=False, busy_for=1.5, current_task="t1"), g),
    "pose": lambda t, g: (set_robot(t, 2, pose=(1.0, 1.0, 0.0)), g),
}
CELL_CHANGES = {  # anything else: another cell
    "duration": lambda t, g: (t, set_task(g, 1, duration=7.0)),
    "capabilities": lambda t, g: (t, set_task(g, 1, capabilities=(1, 1))),
    "prerequisites": lambda t, g: (t, set_task(g, 3, prerequisites=("t1",))),
    "payload": lambda t, g: (set_robot(t, 0, payload=2.0), g),
    "task added": lambda t, g: (t, dataclasses.replace(g, tasks=(*g.tasks, TaskInfo("t9", 1, (0, 1), 1.0, 1.0)))),
    "task cancelled": lambda t, g: (t, dataclasses.replace(g, tasks=g.tasks[:-1])),
    "robot lost": lambda t, g: (dataclasses.replace(t, robots=t.robots[1:]), g),
    "robot renamed": lambda t, g: (set_robot(t, 0, id="r7"), g),
    "sites": lambda t, g: (dataclasses.replace(t, robots=tuple(dataclasses.replace(r, site="a", speed=1.0)
                                                                for r in t.robots)),
                           dataclasses.replace(g, sites=(("a", 0.0, 0.0),),
                                               tasks=tuple(dataclasses.replace(x, site_from="a") for x in g.tasks))),
    "objective": lambda t, g: (t, dataclasses.replace(g, objective="return")),
}


@pytest.mark.parametrize("change", sorted(RUN_CHANGES))
def test_what_the_run_changes_keeps_the_cell(change: str) -> None:
    before = (team(), graph())
    now = RUN_CHANGES[change](*before)
    assert same_cell(before, now)
    assert build_instance(*now) == build_instance(*before)
    assert schedulable(*now)[1] == {}


@pytest.mark.parametrize("change", sorted(CELL_CHANGES))
def test_any_other_change_is_another_cell(change: str) -> None:
    before = (team(), graph())
    assert not same_cell(before, CELL_CHANGES[change](*before))


@pytest.mark.parametrize("change", sorted(CELL_CHANGES))
def test_the_scheduler_rebuilds_its_instance_on_a_cell_change_and_keeps_it_otherwise(change: str) -> None:
    core = OnlineScheduler(make_policy("grp"))
    core.offer_team(team())
    core.offer_graph(graph())
    first = core.instance()
    core.offer_graph(set_task(graph(1.0), 0, status=2, assigned_robots=("r0",), start=0.0))
    assert core.instance() is first
    t, g = CELL_CHANGES[change](team(2.0), graph(2.0))
    core.offer_team(t)
    core.offer_graph(g)
    rebuilt = core.instance()
    assert rebuilt is not first
    assert rebuilt == build_instance(t, schedulable(t, g)[0])
