"""Pools: the robots that are interchangeable for a plan.

Two robots are the same for the plan when swapping them in any schedule gives a schedule
that is just as valid and just as long: they bring the same amount of every capability
and trait, the same payload, and, with travel (formats.md, "Travel extension"), the same
speed, the same site (where they start, or where a state has them) and the same home. A
fixed robot (no speed) is in a pool only with fixed robots at its site. The robots that
are the same form a *pool*; a model may then decide how many of a pool a task takes
(a count bounded by the pool's size) instead of which ones, and give the individual
robots afterwards.

Pools are computed per instance, and per :class:`~lvws_ros.core.executor.State`: a robot
still busy is in the pool of the robots it is the same as, and is free to take a task only
from its release time on (``state.robot_free_at``); with travel, where it is (or will be,
when its task is done) is its site. An instance without identical robots has one pool per
robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import FloatArray, IntArray

if TYPE_CHECKING:
    from lvws_ros.core.executor import State

__all__ = ["Pool", "assign_units", "pool_index", "pools", "trivial"]


@dataclass(frozen=True)
class Pool:
    """Robots that are the same for the plan (indices into ``Instance.robots``)."""

    robots: tuple[int, ...]
    amounts: tuple[float, ...]  # each member's row of ``Instance.robot_amounts``
    payload: float  # each member's payload

    @property
    def size(self) -> int:
        return len(self.robots)


def _key(inst: Instance, r: int, site: Sequence[int] | None) -> tuple[object, ...]:
    key: tuple[object, ...] = (inst.robot_amounts[r].tobytes(), float(inst.robot_payload[r]))
    tr = inst.travel
    if tr is not None and site is not None:
        speed = float(tr.robot_speed[r])
        key += (speed, int(site[r]), int(tr.home(r)))
    return key


def pools(inst: Instance, state: State | None = None) -> tuple[Pool, ...]:
    """The pools of ``inst`` (of ``state``, when given: with travel, robots are where the
    state has them), in the order of their first robot; each pool's robots in index order."""
    site: Sequence[int] | None = None
    if inst.travel is not None:
        site = [int(s) for s in (state.robot_site if state is not None and state.robot_site is not None
                                 else inst.travel.robot_site)]
    groups: dict[tuple[object, ...], list[int]] = {}
    for r in range(inst.num_robots):
        groups.setdefault(_key(inst, r, site), []).append(r)
    amounts: FloatArray = inst.robot_amounts
    return tuple(Pool(tuple(members), tuple(float(a) for a in amounts[members[0]]), float(inst.robot_payload[members[0]]))
                 for members in groups.values())


def pool_index(inst: Instance, found: Sequence[Pool]) -> IntArray:
    """(N,): the pool of each robot, as an index into ``found``."""
    out = np.full(inst.num_robots, -1, dtype=np.int64)
    for p, pool in enumerate(found):
        out[list(pool.robots)] = p
    return out


def trivial(found: Sequence[Pool]) -> bool:
    """Whether every pool holds one robot (no two robots are the same for the plan)."""
    return all(pool.size == 1 for pool in found)


def assign_units(robots: Sequence[int], free_at: Sequence[float], uses: Sequence[tuple[float, float, int]],
                 tol: float = 1e-6) -> list[tuple[int, ...]]:
    """Individual robots of one pool for counts on intervals: ``uses`` holds per task its
    (start, end, count); ``free_at`` when each of ``robots`` is free. Tasks are taken by
    start time, each given the free robots (free at its start) in index order. For
    identical robots on intervals this always succeeds when the counts fit the pool at
    every time (the cumulative of the pool model), a busy robot counting from now until
    it is free: the robots busy at a start are exactly the uses and releases running
    then. ValueError when they do not fit."""
    free = dict(zip(robots, free_at, strict=True))
    out: list[tuple[int, ...]] = [() for _ in uses]
    for k in sorted(range(len(uses)), key=lambda k: (uses[k][0], k)):
        start, end, count = uses[k]
        ready = [r for r in robots if free[r] <= start + tol]
        if len(ready) < count:
            raise ValueError(f"{count} robots wanted at {start:g}, {len(ready)} free")
        out[k] = tuple(ready[:count])
        for r in out[k]:
            free[r] = end
    return out
