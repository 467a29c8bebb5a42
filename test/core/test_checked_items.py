"""An instance built from snapshots that passed the snapshot checks skips its per-item
checks and its search for cycles (``prechecked``): that is sound only if the snapshot
checks refuse everything those would. Hostile field values, drawn at random, hold it."""

from __future__ import annotations

import math

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot, build_instance, check_graph, check_team
from lvws_ros.core.problem import _check_items
from lvws_ros.errors import InstanceError

CAPS = ("arm", "lift")
GOOD = 12  # in each list below, the first ones are good values, repeated so that most cells pass
NUMBERS = st.sampled_from([0.5, 1.0, 3.0] * GOOD + [0.0, -1.0, 1e9, 1e300, math.inf, math.nan, -0.0])
BITS = st.sampled_from([(1, 0), (0, 1), (1, 1)] * GOOD + [(0, 0), (2, 0), (1,), (1, 0, 1), (-1, 1)])
AMOUNTS = st.sampled_from([(1.0,), (2.5,)] * GOOD + [(), (0.0,), (-1.0,), (math.nan,), (1.0, 1.0), (1e300,)])


@st.composite
def cells(draw: st.DrawFn) -> tuple[TeamSnapshot, GraphSnapshot]:
    traits = draw(st.sampled_from([(), ("load",)]))
    robots = tuple(RobotInfo(f"r{i}", "x", True, draw(BITS), draw(NUMBERS), traits=draw(AMOUNTS) if traits else ())
                   for i in range(draw(st.integers(1, 3))))
    n = draw(st.integers(1, 4))
    ids = [f"t{j}" for j in range(n)] + ["ghost"]
    tasks = tuple(TaskInfo(f"t{j}", draw(st.sampled_from([0, 1, 3] * GOOD + [7])), draw(BITS), draw(NUMBERS), draw(NUMBERS),
                           tuple(draw(st.lists(st.sampled_from(ids * GOOD if draw(st.booleans()) else ids[:j] * GOOD
                                                               + ids[-1:]), max_size=3))),
                           requires=draw(AMOUNTS) if traits else (), roles=draw(st.sampled_from([0, 1, 2] * GOOD + [5])))
                  for j in range(n))
    return TeamSnapshot(0.0, CAPS, robots, traits), GraphSnapshot(0.0, CAPS, tasks, trait_names=traits)


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(cells())
def test_what_passes_the_snapshot_checks_passes_the_item_checks(cell: tuple[TeamSnapshot, GraphSnapshot]) -> None:
    team, graph = cell
    try:
        check_team(team)
        check_graph(graph)
    except InstanceError:
        return
    try:
        inst = build_instance(team, graph, checked=True)
    except InstanceError:
        return  # refused as a whole instance (coverage, ...): never built unchecked
    _check_items(inst)  # would raise InstanceError if a robot or task were bad
    full = build_instance(team, graph)  # the same as built with every check
    assert full == inst
    assert full.topological_order == inst.topological_order


def test_a_prerequisite_given_twice_is_refused_naming_the_field() -> None:
    tasks = (TaskInfo("t0", 1, (1, 0), 1.0, 1.0), TaskInfo("t1", 0, (1, 0), 1.0, 1.0, ("t0", "t0")))
    with pytest.raises(InstanceError, match=r"tasks\[1\] \('t1'\)\.prerequisites: an id given twice"):
        check_graph(GraphSnapshot(0.0, CAPS, tasks))
