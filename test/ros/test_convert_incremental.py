"""The incremental message readers (GraphReader, TeamReader) and the incremental checks:
after any change a message can carry, the reader's snapshot (of the message, or of its
serialized bytes) equals the whole conversion's,
tasks and robots that did not change keep their objects, and a snapshot checked against the
one before is refused exactly when a whole check refuses it."""

from __future__ import annotations

import dataclasses

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lvws_msgs.msg import TaskGraph, TeamState
from rclpy.serialization import serialize_message

from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot, check_graph, check_team
from lvws_ros.errors import InstanceError
from lvws_ros.ros.convert import GraphReader, TeamReader, graph_from_msg, graph_to_msg, team_from_msg, team_to_msg

CAPS = ("arm", "gripper")
SITES = (("a", 0.0, 0.0), ("b", 3.0, 4.0), ("c", 6.0, 0.0))


def task(j: int, status: int = 1, after: tuple[str, ...] = (), site: str = "a") -> TaskInfo:
    return TaskInfo(f"t{j}", status, (1, j % 2), 1.0 + j % 3, 2.0 + j, after, site_from=site)


def graph(n: int = 6, stamp: float = 0.0, sites: tuple = SITES) -> GraphSnapshot:
    return GraphSnapshot(stamp, CAPS, tuple(task(j, after=(f"t{j - 1}",) if j % 3 else ()) for j in range(n)), sites)


def robot(i: int, **kw: object) -> RobotInfo:
    return RobotInfo(f"r{i}", "jackal", True, (1, 1), 5.0, site="a", speed=1.0, **kw)  # type: ignore[arg-type]


def team(n: int = 4, stamp: float = 0.0) -> TeamSnapshot:
    return TeamSnapshot(stamp, CAPS, tuple(robot(i) for i in range(n)))


def set_task(g: GraphSnapshot, j: int, **kw: object) -> GraphSnapshot:
    tasks = list(g.tasks)
    j %= len(tasks)
    tasks[j] = dataclasses.replace(tasks[j], **kw)  # type: ignore[arg-type]
    return dataclasses.replace(g, tasks=tuple(tasks))


def _next(items: tuple[TaskInfo, ...] | tuple[RobotInfo, ...]) -> int:
    """A number no id of ``items`` has yet."""
    return 1 + max(int(x.id[1:]) for x in items)


# Each kind of change a world's next TaskGraph can carry.
GRAPH_CHANGES = {
    "status": lambda g: set_task(g, 1, status=2, assigned_robots=("r0",), start=1.5),
    "done": lambda g: set_task(g, 0, status=3, assigned_robots=("r1", "r2"), start=0.5, end=2.5),
    "added": lambda g: dataclasses.replace(g, tasks=(*g.tasks, task(_next(g.tasks), after=("t0",), site="b"))),
    "cancelled": lambda g: dataclasses.replace(g, tasks=g.tasks[:-1] if len(g.tasks) > 1 else g.tasks),
    "reordered": lambda g: dataclasses.replace(g, tasks=g.tasks[::-1]),
    "duration": lambda g: set_task(g, 2, duration=9.0),
    "prerequisites": lambda g: set_task(g, 4, prerequisites=("t0", "t1")),
    "sites": lambda g: dataclasses.replace(g, sites=(*g.sites, ("d", 1.0, 1.0))),
    "site_of_task": lambda g: set_task(g, 3, site_from="c", site_to="b"),
    "nothing": lambda g: g,
}
TEAM_CHANGES = {
    "busy": lambda t: dataclasses.replace(t, robots=(dataclasses.replace(t.robots[0], available=False, busy_for=2.5,
                                                                         current_task="t1"), *t.robots[1:])),
    "lost": lambda t: dataclasses.replace(t, robots=t.robots[1:] if len(t.robots) > 1 else t.robots),
    "joined": lambda t: dataclasses.replace(t, robots=(*t.robots, robot(_next(t.robots)))),
    "moved": lambda t: dataclasses.replace(t, robots=(*t.robots[:-1], dataclasses.replace(t.robots[-1], site="",
                                                                                          pose=(1.0, 2.0, 0.0)))),
    "nothing": lambda t: t,
}


def _read_through(reader, snapshot, to_msg, from_msg, items, changes, steps, serialized):
    """Feed ``reader`` the messages of ``snapshot`` after each of ``steps`` (names of
    ``changes``; ``serialized``: their bytes): each snapshot read equals the whole
    conversion's, and an unchanged item (``items`` of a snapshot) is the very object of the
    message before."""
    read = (lambda msg: reader.read_serialized(serialize_message(msg))) if serialized else reader.read
    before = read(to_msg(snapshot))
    for n, change in enumerate(steps):
        snapshot = dataclasses.replace(changes[change](snapshot), stamp=float(n + 1))
        msg = to_msg(snapshot)
        got = read(msg)
        assert got == from_msg(msg)
        old = {x.id: x for x in items(before)}
        assert all(x is old[x.id] for x in items(got) if x.id in old and x == old[x.id])
        before = got


@pytest.mark.parametrize("serialized", [False, True], ids=["messages", "bytes"])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.sampled_from(sorted(GRAPH_CHANGES)), min_size=1, max_size=6))
def test_the_graph_reader_equals_the_whole_conversion_after_any_changes(serialized: bool, changes: list[str]) -> None:
    _read_through(GraphReader(), graph(), graph_to_msg, graph_from_msg, lambda g: g.tasks, GRAPH_CHANGES, changes,
                  serialized)


@pytest.mark.parametrize("serialized", [False, True], ids=["messages", "bytes"])
@settings(max_examples=40, deadline=None)
@given(st.lists(st.sampled_from(sorted(TEAM_CHANGES)), min_size=1, max_size=5))
def test_the_team_reader_equals_the_whole_conversion_after_any_changes(serialized: bool, changes: list[str]) -> None:
    _read_through(TeamReader(), team(), team_to_msg, team_from_msg, lambda t: t.robots, TEAM_CHANGES, changes,
                  serialized)


def test_a_reused_message_changed_in_place_is_read_again() -> None:
    reader, msg = GraphReader(), graph_to_msg(graph())
    reader.read(msg)
    msg.tasks[2].capabilities[1] = 0
    msg.tasks[3].prerequisites.append("t0")
    assert reader.read(msg) == graph_from_msg(msg)


def test_generated_messages_are_read_through_their_slots_and_other_objects_by_name() -> None:
    """rclpy's generated messages keep each field in its underscored slot: the readers read
    those (no Python call per field) and get what the properties give; an object that only
    has the fields' names (a copy, a bag reader's) is read by name."""
    import types

    from lvws_ros.ros import convert

    task_msg, robot_msg = graph_to_msg(graph()).tasks[1], team_to_msg(team()).robots[1]
    assert convert._fields_of(task_msg, convert._task_fields, convert._task_slots) is convert._task_slots
    assert convert._fields_of(robot_msg, convert._robot_fields, convert._robot_slots) is convert._robot_slots
    assert convert._task_slots(task_msg) == convert._task_fields(task_msg)
    plain = types.SimpleNamespace(**{f: getattr(robot_msg, f) for f in robot_msg.get_fields_and_field_types()})
    assert convert._fields_of(plain, convert._robot_fields, convert._robot_slots) is convert._robot_fields


def test_messages_without_the_newer_fields_are_read_whole() -> None:
    plain = TaskGraph()
    plain.tasks = graph_to_msg(graph()).tasks
    assert GraphReader().read(plain) == graph_from_msg(plain)
    assert TeamReader().read(TeamState()) == team_from_msg(TeamState())


BAD_TASKS = {
    "status": {"status": 9},
    "capabilities": {"capabilities": (1,)},
    "duration": {"duration": 0.0},
    "prerequisite": {"prerequisites": ("nope",)},
    "cycle": {"prerequisites": ("t5",)},  # t0 <- t5 <- t4 <- t3 ... t0: a cycle
    "site": {"site_from": "nowhere"},
}


@pytest.mark.parametrize("field", sorted(BAD_TASKS))
def test_a_bad_task_is_refused_when_checked_against_a_good_graph(field: str) -> None:
    good = graph()
    check_graph(good)
    bad = set_task(good, 0, **BAD_TASKS[field])
    if field == "cycle":
        bad = set_task(set_task(bad, 3, prerequisites=("t2",)), 5, prerequisites=("t4",))
    with pytest.raises(InstanceError):
        check_graph(bad)
    with pytest.raises(InstanceError):
        check_graph(bad, good)


def test_a_task_cancelled_while_another_waits_on_it_is_refused() -> None:
    good = graph()
    gone = dataclasses.replace(good, tasks=(*good.tasks[:1], task(50), *good.tasks[2:]))  # t1 replaced, t2 waits on it
    with pytest.raises(InstanceError, match="prerequisites"):
        check_graph(gone, good)


def test_a_removed_site_is_refused_for_an_unchanged_task() -> None:
    good = set_task(graph(), 1, site_from="c")
    with pytest.raises(InstanceError, match="unknown site"):
        check_graph(dataclasses.replace(good, sites=SITES[:2]), good)


def test_a_bad_robot_is_refused_when_checked_against_a_good_team() -> None:
    good = team()
    check_team(good)
    for bad in (dataclasses.replace(good.robots[1], payload=float("nan")),
                dataclasses.replace(good.robots[1], capabilities=(1, 2)), dataclasses.replace(good.robots[1], id="")):
        with pytest.raises(InstanceError):
            check_team(dataclasses.replace(good, robots=(good.robots[0], bad, *good.robots[2:])), good)
    with pytest.raises(InstanceError, match="capabilities"):  # the same robots under other capability names
        check_team(dataclasses.replace(good, capability_names=("arm",)), good)


def _verdict(g: GraphSnapshot, checked: GraphSnapshot | None = None) -> str:
    try:
        check_graph(g, checked)
    except InstanceError as exc:
        return str(exc).split(":")[0]
    return "ok"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, 9), st.integers(0, 9), st.integers(0, 3)), min_size=1, max_size=8),
       st.permutations(range(6)))
def test_checked_against_a_good_graph_the_verdict_is_the_full_checks(edits: list[tuple[int, int, int]],
                                                                     order: list[int]) -> None:
    """Against a graph that passed, only new and changed tasks are checked and a cycle is
    looked for among the new ones unless a known task waits on more: the same verdict as
    checking everything, whatever tasks come, go, move or wait on each other (a task
    cancelled and added again under its id, cycles through known tasks included)."""
    good = graph()
    check_graph(good)
    tasks = {t.id: t for t in good.tasks}
    for a, b, kind in edits:
        ta, tb = f"t{a}", f"t{b}"
        if kind == 0:  # a task (new, or a known one again) waiting on another
            base = tasks.get(ta, task(a))
            tasks[ta] = dataclasses.replace(base, prerequisites=(*base.prerequisites, tb))
        elif kind == 1:  # a task cancelled
            tasks.pop(ta, None)
        elif kind == 2:  # a known task waiting on less
            if ta in tasks:
                tasks[ta] = dataclasses.replace(tasks[ta], prerequisites=tasks[ta].prerequisites[1:])
        else:  # a new task, waiting on nothing
            tasks.setdefault(ta, task(a))
    kept = [tasks[f"t{j}"] for j in order if f"t{j}" in tasks]  # the known ones moved about
    now = dataclasses.replace(good, tasks=(*kept, *(t for k, t in tasks.items() if t not in kept)))
    assert _verdict(now, good) == _verdict(now)
