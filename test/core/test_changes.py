"""The change-only protocol's core: a cell kept from numbered batches is the cell the world's
snapshots describe, whatever the batches (tasks added, run, done, cancelled and retired,
robots failing, coming back, joining); gaps and bad batches are refused whole."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lvws_ros.core.changes import (
    CellChanges,
    ChangeFollower,
    ChangeGap,
    ChangeRefused,
    LiveCell,
    changes_between,
    without_retired,
)
from lvws_ros.core.executor import State, TaskStatus
from lvws_ros.core.online import (
    BUSY_EPS,
    GraphSnapshot,
    OnlineScheduler,
    RobotInfo,
    TaskColumns,
    TaskInfo,
    TeamSnapshot,
    build_state,
)
from lvws_ros.errors import InstanceError
from lvws_ros.policies.baselines import GreedyPayloadPolicy

Q, R, A, D = (int(s) for s in (TaskStatus.QUEUED, TaskStatus.READY, TaskStatus.ASSIGNED, TaskStatus.DONE))
CAPS = ("arm", "lift")


class ToyWorld:
    """A world that keeps whole snapshots: tasks added, started, finished, cancelled and
    retired, robots failing, repaired and joining, time going by."""

    def __init__(self, robots: int = 4) -> None:
        self.time = 0.0
        self.tasks: dict[str, TaskInfo] = {}
        self.robots: dict[str, RobotInfo] = {}
        self.until: dict[str, float] = {}
        self.gone: dict[str, RobotInfo] = {}
        self.next_task = self.next_robot = 0
        for _ in range(robots):
            self.join()

    def join(self) -> None:
        rid = f"r{self.next_robot}"
        self.next_robot += 1
        self.robots[rid] = RobotInfo(rid, "x", True, (1, 1), 2.0)

    def add(self, prereqs: list[int], cap: int) -> None:
        tid = f"t{self.next_task}"
        self.next_task += 1
        known = [t for t in self.tasks if self.tasks[t].status != D]
        after = tuple(sorted({known[p % len(known)] for p in prereqs})) if known else ()
        caps = (1, 0) if cap == 0 else (0, 1) if cap == 1 else (1, 1)
        self.tasks[tid] = TaskInfo(tid, Q if after else R, caps, 1.0, 2.0 + cap, after)

    def start(self, k: int) -> None:
        ready = [t for t in self.tasks.values() if t.status == R]
        free = [r for r in self.robots.values() if r.available]
        if not ready or not free:
            return
        t, r = ready[k % len(ready)], free[k % len(free)]
        self.tasks[t.id] = replace(t, status=A, assigned_robots=(r.id,), start=self.time)
        self.robots[r.id] = replace(r, available=False, current_task=t.id)
        self.until[r.id] = self.time + t.duration

    def finish(self, k: int) -> None:
        running = [t for t in self.tasks.values() if t.status == A]
        if not running:
            return
        t = running[k % len(running)]
        self.tasks[t.id] = replace(t, status=D, end=self.time)
        for rid in t.assigned_robots:
            if rid in self.robots:
                self.robots[rid] = replace(self.robots[rid], available=True, current_task="")
            self.until.pop(rid, None)
        self._ready()

    def _ready(self) -> None:
        for tid, t in self.tasks.items():
            if t.status == Q and all(self.tasks[p].status == D for p in t.prerequisites):
                self.tasks[tid] = replace(t, status=R)

    def cancel(self, k: int) -> None:
        open_ = [t for t in self.tasks.values() if t.status in (Q, R)]
        if not open_:
            return
        gone = open_[k % len(open_)].id
        del self.tasks[gone]
        for tid, t in self.tasks.items():
            if gone in t.prerequisites:
                self.tasks[tid] = replace(t, prerequisites=tuple(p for p in t.prerequisites if p != gone))
        self._ready()

    def retire(self) -> None:
        for tid in [t.id for t in self.tasks.values() if t.status == D]:
            deps = [t for t in self.tasks.values() if tid in t.prerequisites]
            if all(d.status >= A for d in deps):
                del self.tasks[tid]
                for d in deps:
                    self.tasks[d.id] = replace(d, prerequisites=tuple(p for p in d.prerequisites if p != tid))

    def fail(self, k: int) -> None:
        if len(self.robots) <= 1:
            return
        rid = sorted(self.robots)[k % len(self.robots)]
        r = self.robots.pop(rid)
        self.until.pop(rid, None)
        self.gone[rid] = replace(r, available=True, current_task="")
        for tid, t in self.tasks.items():
            if t.status == A and rid in t.assigned_robots:  # interrupted: READY again
                self.tasks[tid] = replace(t, status=R, assigned_robots=(), start=None)

    def repair(self) -> None:
        if self.gone:
            rid = sorted(self.gone)[0]
            self.robots[rid] = self.gone.pop(rid)

    def snapshots(self) -> tuple[TeamSnapshot, GraphSnapshot]:
        robots = tuple(replace(r, busy_for=max(0.0, self.until[r.id] - self.time)) if r.id in self.until else r
                       for r in self.robots.values())
        return (TeamSnapshot(self.time, CAPS, robots), GraphSnapshot(self.time, CAPS, tuple(self.tasks.values())))


OPS = st.lists(st.tuples(st.sampled_from(["add", "add", "start", "start", "finish", "cancel", "retire", "fail",
                                          "repair", "join", "tick"]),
                         st.lists(st.integers(0, 20), max_size=3), st.integers(0, 100)), min_size=1, max_size=40)


def run_ops(world: ToyWorld, op: str, args: list[int], k: int) -> None:
    if op == "add":
        world.add(args, k % 3)
    elif op in ("start", "finish", "cancel", "fail"):
        getattr(world, op)(k)
    elif op in ("retire", "repair", "join"):
        getattr(world, op)()
    else:
        world.time += 0.5 + k / 10


def as_dicts(team: TeamSnapshot, graph: GraphSnapshot) -> tuple[dict[str, RobotInfo], dict[str, TaskInfo]]:
    return ({r.id: replace(r, busy_for=round(r.busy_for, 6)) for r in team.robots}, {t.id: t for t in graph.tasks})


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(OPS)
def test_changes_applied_one_by_one_give_the_snapshot_after_them(ops: list[tuple[str, list[int], int]]) -> None:
    world = ToyWorld()
    before = world.snapshots()
    cell = LiveCell(*before)
    direct, followed, viewed = (OnlineScheduler(GreedyPayloadPolicy(), ack_timeout=1e9) for _ in range(3))
    columns = TaskColumns()
    for seq, (op, args, k) in enumerate(ops, start=1):
        run_ops(world, op, args, k)
        world.time += 0.01  # every batch at its own time
        after = world.snapshots()
        cell.apply(changes_between(before, after, seq))
        assert as_dicts(*cell.snapshots()) == as_dicts(*after)
        assert [t.id for t in cell.snapshots()[1].tasks] == [t.id for t in after[1].tasks]  # the same order
        assert cell.seq == seq
        for core, (team, graph) in ((direct, after), (followed, cell.snapshots())):
            core.offer_team(team)
            core.offer_graph(graph)
        team, graph, delta = cell.view()  # in time proportional to the batch: the same state
        assert viewed.offer_cell(team, graph, delta)
        assert delta.since is not None or seq == 1
        same_state(build_state(direct.instance(), *after), build_state(viewed.instance(), team, graph, {},
                                                                       delta.until, columns))
        a, b, c = direct.decide(), followed.decide(), viewed.decide()  # the same node state decides the same
        assert (a.assignments, a.waiting) == (b.assignments, b.waiting) if a and b else a is b is None
        assert (a.assignments, a.waiting) == (c.assignments, c.waiting) if a and c else a is c is None
        for core in (direct, followed, viewed):
            core.pending.clear()
        before = after


def same_state(a: State, b: State) -> None:
    assert a.time == b.time and a.task_team == b.task_team
    assert (a.task_status == b.task_status).all()
    assert np.allclose(a.robot_free_at, b.robot_free_at, rtol=0, atol=1e-9)
    assert np.allclose(a.task_start, b.task_start, rtol=0, atol=1e-9, equal_nan=True)


def small_cell() -> LiveCell:
    team = TeamSnapshot(0.0, CAPS, (RobotInfo("r0", "x", True, (1, 1), 2.0), RobotInfo("r1", "x", True, (1, 1), 2.0)))
    graph = GraphSnapshot(0.0, CAPS, (TaskInfo("a", R, (1, 0), 1.0, 2.0), TaskInfo("b", Q, (0, 1), 1.0, 2.0, ("a",))))
    return LiveCell(team, graph)


def test_a_gap_or_a_repeat_is_refused_and_nothing_is_taken() -> None:
    cell = small_cell()
    with pytest.raises(ChangeGap, match="expected 1"):
        cell.apply(CellChanges(2, 1.0, tasks=(TaskInfo("c", R, (1, 0), 1.0, 1.0),)))
    assert "c" not in cell.tasks and cell.seq == 0
    cell.apply(CellChanges(1, 1.0, tasks=(TaskInfo("c", R, (1, 0), 1.0, 1.0),)))
    with pytest.raises(ChangeGap, match="already taken"):
        cell.apply(CellChanges(1, 1.0))


@pytest.mark.parametrize(("batch", "names"), [
    (CellChanges(1, 1.0, cancelled=("nope",)), "tasks_cancelled[0]: unknown task 'nope'"),
    (CellChanges(1, 1.0, retired=("a",)), "task 'a' is not DONE"),
    (CellChanges(1, 1.0, left=("r9",)), "robots_left[0]: unknown robot 'r9'"),
    (CellChanges(1, 1.0, tasks=(TaskInfo("x", A, (1, 0), 1.0, 1.0, (), ("r0",), 0.5),)), "tasks[0] ('x'): unknown"),
    (CellChanges(1, 1.0, tasks=(TaskInfo("x", R, (1, 0, 1), 1.0, 1.0),)), "tasks[0] ('x').capabilities"),
    (CellChanges(1, 1.0, tasks=(TaskInfo("x", Q, (1, 0), 1.0, 1.0, ("zz",)),)), "unknown task id"),
    (CellChanges(1, 1.0, tasks=(TaskInfo("x", Q, (1, 0), 1.0, 1.0, ("y",)), TaskInfo("y", Q, (1, 0), 1.0, 1.0, ("x",)))),
     "cycle"),
    (CellChanges(1, float("nan")), "header.stamp"),
    (CellChanges(1, 1.0, robots=(RobotInfo("r0", "x", True, (1,), 2.0),)), "robots[0] ('r0').capabilities"),
])
def test_a_bad_batch_is_refused_naming_the_item_and_nothing_is_taken(batch: CellChanges, names: str) -> None:
    cell = small_cell()
    snaps = cell.snapshots()
    with pytest.raises(ChangeRefused, match=names.replace("(", r"\(").replace(")", r"\)").replace("[", r"\[")
                       .replace("]", r"\]")):
        cell.apply(batch)
    assert cell.snapshots() == snaps and cell.seq == 0
    cell.apply(CellChanges(1, 1.0))  # and the next good batch is taken


def test_a_retired_task_never_comes_back_and_a_task_waiting_on_it_is_ready() -> None:
    cell = small_cell()
    cell.apply(CellChanges(1, 1.0, tasks=(TaskInfo("a", A, (1, 0), 1.0, 2.0, (), ("r0",), 1.0),)))
    cell.apply(CellChanges(2, 3.0, tasks=(TaskInfo("a", D, (1, 0), 1.0, 2.0, (), ("r0",), 1.0, 3.0),
                                          TaskInfo("b", R, (0, 1), 1.0, 2.0, ("a",)))))
    assert cell.retire(horizon=0.0) == []  # b has not started
    cell.apply(CellChanges(3, 4.0, tasks=(TaskInfo("b", A, (0, 1), 1.0, 2.0, ("a",), ("r1",), 4.0),)))
    assert cell.retire(horizon=5.0) == []  # ended 1 s ago: within the horizon
    cell.apply(CellChanges(4, 9.0))
    assert cell.retire(horizon=5.0) == ["a"]
    assert "a" not in cell.tasks and cell.tasks["b"].prerequisites == ()
    # a world that still sends it (it keeps its own horizon), or a new task naming it
    cell.apply(CellChanges(5, 9.5, tasks=(TaskInfo("a", D, (1, 0), 1.0, 2.0, (), ("r0",), 1.0, 3.0),
                                          TaskInfo("c", Q, (1, 0), 1.0, 1.0, ("a",)))))
    team, graph = cell.snapshots()
    assert [t.id for t in graph.tasks] == ["b", "c"] and graph.tasks[1].prerequisites == ()
    core = OnlineScheduler(GreedyPayloadPolicy(), ack_timeout=1e9)
    core.offer_team(team)
    core.offer_graph(replace(graph, tasks=(graph.tasks[0], replace(graph.tasks[1], status=R))))
    d = core.decide()
    assert d is not None and [t for t, _ in d.assignments] == ["c"]
    # and a snapshot that holds it again (a resync)
    world_graph = replace(graph, tasks=(TaskInfo("a", D, (1, 0), 1.0, 2.0, (), ("r0",), 1.0, 3.0), *graph.tasks))
    cell.reset(team, world_graph, seq=5)
    assert "a" not in cell.tasks


def test_a_batch_costs_what_it_changes_not_the_cell() -> None:
    """Unchanged tasks stay the very same objects (the core's checks skip them), and a
    batch that adds tasks does not look at the others."""
    team = TeamSnapshot(0.0, CAPS, tuple(RobotInfo(f"r{i}", "x", True, (1, 1), 2.0) for i in range(50)))
    graph = GraphSnapshot(0.0, CAPS, tuple(TaskInfo(f"t{j}", R, (1, 0), 1.0, 2.0) for j in range(5000)))
    cell = LiveCell(team, graph)
    cell.apply(CellChanges(1, 1.0, tasks=(TaskInfo("new", Q, (0, 1), 1.0, 1.0, ("t7",)),
                                          replace(graph.tasks[3], status=A, assigned_robots=("r0",), start=1.0)),
                           robots=(replace(team.robots[0], available=False, current_task="t3", busy_for=2.0),)))
    _, g = cell.snapshots()
    assert all(a is b for a, b in zip(g.tasks[4:5000], graph.tasks[4:], strict=True))
    assert g.tasks[-1].id == "new" and cell.dependents["t7"] == {"new"}


def test_without_retired_drops_retired_tasks_and_their_names_and_keeps_the_others_the_same_objects():
    a, b = TaskInfo("a", D, (1, 0), 1.0, 1.0), TaskInfo("b", Q, (0, 1), 1.0, 1.0, ("a", "c"))
    c, d = TaskInfo("c", R, (1, 0), 1.0, 1.0), TaskInfo("d", R, (1, 0), 1.0, 1.0)
    kept = list(without_retired((a, b, c, d), {"a"}))
    assert [t.id for t in kept] == ["b", "c", "d"]
    assert kept[0].prerequisites == ("c",) and kept[1] is c and kept[2] is d
    assert list(without_retired((a, b), set())) == [a, b] and list(without_retired((a, b), set()))[1] is b


def test_the_first_snapshots_start_the_cell_for_batch_one_and_for_no_other() -> None:
    world = ToyWorld()
    world.add([], 0)
    first = world.snapshots()
    world.start(0)
    world.time += 1.0
    batch = changes_between(first, world.snapshots(), 1)
    follower = ChangeFollower()
    assert not follower.start_from(*first, replace(batch, seq=2))  # a batch after a gap: the world's snapshots
    assert not follower.start_from(first[0], replace(first[1], stamp=0.5), batch)  # not one instant
    assert follower.start_from(*first, batch) and follower.take(batch)
    assert not follower.needs_resync and follower.resyncs == 0 and follower.cell is not None
    assert as_dicts(*follower.cell.snapshots()) == as_dicts(*world.snapshots())
    assert not follower.start_from(*first, batch)  # once only


def test_a_live_cell_s_pair_is_taken_whole_or_its_team_with_the_times_it_came_with() -> None:
    busy = RobotInfo("r0", "x", False, (1, 1), 2.0, current_task="a", busy_for=5.0)
    tasks = (TaskInfo("a", A, (1, 0), 1.0, 5.0, assigned_robots=("r0",), start=4.0), TaskInfo("b", R, (1, 0), 1.0, 2.0))
    core = OnlineScheduler(GreedyPayloadPolicy())
    core.offer_team(TeamSnapshot(3.0, CAPS, (busy,)))  # heard on the topics before following
    core.offer_graph(GraphSnapshot(10.0, CAPS, tasks))
    follower = ChangeFollower()
    follower.resync(TeamSnapshot(4.0, CAPS, (busy,)), GraphSnapshot(4.0, CAPS, tasks), 0)  # r0 busy until 9
    follower.take(CellChanges(1, 8.0, tasks=(TaskInfo("c", Q, (1, 0), 1.0, 2.0, ("b",)),)))
    assert follower.cell is not None
    team, graph, delta = follower.cell.view()
    assert not core.offer_cell(team, graph, delta)  # the graph is older than the one held: not taken
    assert core.team is team  # the team is: with its robots' end times
    state = build_state(core.instance(), core.team, core._view, {}, core._until)
    assert state.robot_free_at[0] == pytest.approx(10.0 + BUSY_EPS)  # until 9 as the cell says: overdue at 10


def test_a_batch_that_leaves_no_robot_is_refused_as_an_empty_team_snapshot_is() -> None:
    team = TeamSnapshot(0.0, CAPS, (RobotInfo("r0", "x", True, (1, 1), 2.0),))
    cell = LiveCell(team, GraphSnapshot(0.0, CAPS, (TaskInfo("a", R, (1, 0), 1.0, 2.0),)))
    core = OnlineScheduler(GreedyPayloadPolicy())
    assert core.offer_cell(*cell.view())
    cell.apply(CellChanges(1, 1.0, left=("r0",)))
    with pytest.raises(InstanceError, match="at least one robot"):
        core.offer_cell(*cell.view())
    assert core.team is not None and len(core.team.robots) == 1  # the last good one stays


def test_batch_one_after_later_ones_is_a_world_started_again_and_its_cell_starts_anew() -> None:
    old = ToyWorld()
    before = old.snapshots()
    follower = ChangeFollower()
    follower.resync(*before, 0)
    for seq, step in enumerate(("add", "start", "finish", "retire"), start=1):  # t0 retires from the old world
        run_ops(old, step, [], 0)
        old.time += 1.0
        after = old.snapshots()
        follower.take(changes_between(before, after, seq))
        before = after
    assert follower.cell is not None and follower.cell.seq == 4 and "t0" in follower.cell.retired
    new = ToyWorld(robots=2)
    zero = new.snapshots()
    new.add([], 1)  # its own t0
    one = new.snapshots()
    assert not follower.take(changes_between(zero, one, 1))
    assert follower.needs_resync and follower.restarts == 1 and "started again" in follower.notices[-1]
    new.time += 1.0
    new.add([], 0)
    two = new.snapshots()
    assert not follower.take(changes_between(one, two, 2))  # held until the snapshot says what it covers
    follower.resync(*one, 1)
    assert follower.cell.seq == 2 and as_dicts(*follower.cell.snapshots()) == as_dicts(*two)
    assert follower.repeated == 0
