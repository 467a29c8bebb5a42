"""Pools: robots the same for the plan (traits, payload, speed, site, home) are one pool;
anything that differs splits them."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import State
from lvws_ros.core.formats import load_instance
from lvws_ros.core.pools import pool_index, pools, trivial
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.travel import build_travel

ROOT = Path(__file__).resolve().parents[2]


def _team(robots: list[Robot], travel: list[tuple[str, float | None, str | None]] | None = None) -> Instance:
    """Four tasks, each coverable by any robot below; ``travel``: per robot (site, speed, home)."""
    tasks = tuple(Task(f"t{j}", (), 0.0, 2.0, requires=(("weld", 1.0),)) for j in range(4))
    tr = None
    if travel is not None:
        sites = {"a": [0.0, 0.0], "b": [3.0, 4.0]}
        tr = build_travel(sites, {}, [(r.id, s, v) for r, (s, v, _) in zip(robots, travel, strict=True)],
                          [(t.id, "a", "a") for t in tasks], [h for _, _, h in travel])
    return Instance("pools", (), tuple(robots), tasks, travel=tr, traits=("weld", "lift"))


def _robot(rid: str, weld: float = 1.0, lift: float = 0.0, payload: float = 5.0) -> Robot:
    return Robot(rid, (), payload, traits=tuple((k, v) for k, v in (("weld", weld), ("lift", lift)) if v))


def _groups(inst: Instance, state: State | None = None) -> list[tuple[str, ...]]:
    return [tuple(inst.robots[r].id for r in p.robots) for p in pools(inst, state)]


def test_identical_robots_form_one_pool() -> None:
    inst = _team([_robot("r0"), _robot("r1"), _robot("r2", lift=2.0), _robot("r3"), _robot("r4", lift=2.0)])
    found = pools(inst)
    assert _groups(inst) == [("r0", "r1", "r3"), ("r2", "r4")]
    assert [p.size for p in found] == [3, 2]
    assert found[1].amounts == (1.0, 2.0) and found[1].payload == 5.0
    assert pool_index(inst, found).tolist() == [0, 0, 1, 0, 1]
    assert not trivial(found)


@pytest.mark.parametrize("other", [
    _robot("r1", weld=2.0),  # a trait's amount
    _robot("r1", lift=1.0),  # a trait the other lacks
    _robot("r1", payload=6.0),  # payload
])
def test_robots_differing_in_a_trait_or_payload_are_apart(other: Robot) -> None:
    inst = _team([_robot("r0"), other])
    assert _groups(inst) == [("r0",), ("r1",)]
    assert trivial(pools(inst))


def test_capabilities_split_pools() -> None:
    inst = Instance("caps", ("weld", "lift"), (Robot("r0", (1, 0), 5.0), Robot("r1", (1, 1), 5.0),
                                                Robot("r2", (1, 0), 5.0)),
                    (Task("t", (1, 0), 1.0, 1.0),))
    assert _groups(inst) == [("r0", "r2"), ("r1",)]


@pytest.mark.parametrize(("travel", "expected"), [
    ([("a", 1.0, None), ("a", 1.0, None)], [("r0", "r1")]),
    ([("a", 1.0, None), ("a", 2.0, None)], [("r0",), ("r1",)]),  # speed
    ([("a", 1.0, None), ("b", 1.0, "a")], [("r0",), ("r1",)]),  # start site, same home
    ([("a", 1.0, None), ("a", 1.0, "b")], [("r0",), ("r1",)]),  # home
    ([("a", None, None), ("a", None, None)], [("r0", "r1")]),  # fixed at one site
    ([("a", None, None), ("b", None, None)], [("r0",), ("r1",)]),  # fixed at two sites
    ([("a", None, None), ("a", 1.0, None)], [("r0",), ("r1",)]),  # fixed and mobile
])
def test_travel_splits_pools_by_speed_site_and_home(travel: list[tuple[str, float | None, str | None]],
                                                    expected: list[tuple[str, ...]]) -> None:
    inst = _team([_robot("r0"), _robot("r1")], travel)
    assert _groups(inst) == expected


def test_a_state_puts_robots_where_they_are_and_keeps_busy_ones_in_their_pool() -> None:
    inst = _team([_robot("r0"), _robot("r1"), _robot("r2")], [("a", 1.0, "a"), ("a", 1.0, "a"), ("a", 1.0, "a")])
    state = State.initial(inst)
    state.start(0, [0])  # r0 busy at site a: still in the pool
    assert _groups(inst, state) == [("r0", "r1", "r2")]
    assert state.robot_site is not None
    state.robot_site[2] = 1  # r2 now at site b
    assert _groups(inst, state) == [("r0", "r1"), ("r2",)]


def test_files_without_identical_robots_give_singleton_pools() -> None:
    for name in ("weld_cell.json", "weld_cell_traits.json"):
        cell = load_instance(ROOT / "examples" / name)
        found = pools(cell)
        assert trivial(found) and len(found) == cell.num_robots
        assert sorted(r for p in found for r in p.robots) == list(range(cell.num_robots))
    inst = dataset_instance(DATASETS["I"], 0, 0)
    assert trivial(pools(inst))
    twin = replace(inst.robots[0], id="twin")
    doubled = replace(inst, robots=(*inst.robots, twin))
    assert (0, inst.num_robots) in [p.robots for p in pools(doubled)]


def test_assign_units_gives_free_robots_by_start_time() -> None:
    from lvws_ros.core.pools import assign_units

    # three robots, robot 12 busy until 4; counts that fit the pool at every time
    uses = [(0.0, 5.0, 2), (5.0, 7.0, 3), (4.0, 5.0, 1), (0.0, 3.0, 0)]
    got = assign_units([10, 11, 12], [0.0, 0.0, 4.0], uses)
    assert got == [(10, 11), (10, 11, 12), (12,), ()]
    for (s, e, _), team in zip(uses, got, strict=True):  # no robot in two tasks at once
        for (s2, e2, _), team2 in zip(uses, got, strict=True):
            if (s, e) != (s2, e2) and s < e2 and s2 < e:
                assert not set(team) & set(team2)
    with pytest.raises(ValueError, match="2 robots wanted at 1, 1 free"):
        assign_units([10, 11, 12], [0.0, 0.0, 4.0], [(0.0, 5.0, 1), (1.0, 2.0, 2)])
