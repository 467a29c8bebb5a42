"""Travel between sites (the optional travel extension of ``lvws-instance/1``, formats.md).

An instance with travel has named sites with coordinates (distances Euclidean, unless a
``distances`` entry gives one for a pair); every robot a site (where it starts, or where it
is fixed) and a speed (absent: fixed, it never leaves its site); every task a site (or a
``from`` where its subteam meets and a ``to`` where the subteam is when it is done, for
transports). Robot r needs ``distance(a, b) / speed_r`` seconds from a to b; a subteam
starts when its slowest member can be there. An instance without travel means zero
travel, exactly as before the extension.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import numpy.typing as npt

from lvws_ros.core.subteams import FloatArray
from lvws_ros.errors import InstanceError

__all__ = ["Travel", "build_travel"]


@dataclass(frozen=True, eq=False)
class Travel:
    sites: tuple[str, ...]
    coordinates: tuple[tuple[float, float], ...]  # per site
    distance: FloatArray  # (S, S)
    overrides: tuple[tuple[str, str, float], ...]  # the file's `distances` entries (kept for writing)
    robot_site: tuple[int, ...]  # (N,) start or fixed site
    robot_speed: tuple[float, ...]  # (N,) > 0, or 0: fixed
    task_from: tuple[int, ...]  # (M,) where the subteam meets
    task_to: tuple[int, ...]  # (M,) where the subteam is when the task is done
    robot_home: tuple[int, ...] = ()  # (N,) where each robot returns (objective "return"); (): its start site

    def home(self, robot: int) -> int:
        """The site robot ``robot`` goes back to: its ``home``, or where it starts."""
        return self.robot_home[robot] if self.robot_home else self.robot_site[robot]

    def time(self, robot: int, a: int, b: int) -> float:
        """Seconds robot ``robot`` needs from site a to site b (inf: a fixed robot elsewhere)."""
        if a == b:
            return 0.0
        speed = self.robot_speed[robot]
        return float(self.distance[a, b]) / speed if speed > 0 else math.inf

    def can_do(self, robot: int, task: int) -> bool:
        """A fixed robot cannot take a task that ends elsewhere (a transport moves its team)."""
        return self.robot_speed[robot] > 0 or self.task_from[task] == self.task_to[task]

    def arrival(self, team: Sequence[int], at: Sequence[int], task: int) -> float:
        """Seconds until the last member of ``team`` (now at sites ``at``) reaches ``task``
        (inf when a member can never do it: a fixed robot elsewhere or on a transport)."""
        return float(self.arrivals(team, at, [task]).max(initial=0.0))

    def arrivals(self, robots: npt.ArrayLike, at: npt.ArrayLike, tasks: npt.ArrayLike) -> FloatArray:
        """(len(robots), len(tasks)): seconds robot ``robots[i]`` (now at site ``at[i]``)
        needs to reach task ``tasks[j]`` alone; inf when it can never do it (:meth:`time`,
        :meth:`can_do`)."""
        r, a, t = (np.asarray(x, dtype=np.int64).reshape(-1) for x in (robots, at, tasks))
        speeds, meets, ends = self.arrays
        speed = speeds[r][:, None]
        meet = meets[t]
        moves = meet != ends[t]
        out = np.where(speed > 0, self.distance[np.ix_(a, meet)] / np.where(speed > 0, speed, 1.0), np.inf)
        out[a[:, None] == meet[None, :]] = 0.0  # already there
        out[(speed <= 0) & moves[None, :]] = np.inf  # a fixed robot never takes a task that moves its team
        return np.asarray(out, dtype=np.float64)

    @cached_property
    def arrays(self) -> tuple[FloatArray, npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        """robot_speed, task_from and task_to as (read-only) arrays, made once."""
        out = (np.array(self.robot_speed, dtype=np.float64), np.array(self.task_from, dtype=np.int64),
               np.array(self.task_to, dtype=np.int64))
        for x in out:
            x.setflags(write=False)
        return out

    def ways_home(self) -> FloatArray:
        """(N, M): seconds robot i needs from where task j ends to its :meth:`home` (inf:
        never, a fixed robot elsewhere)."""
        homes = np.array([self.home(i) for i in range(len(self.robot_site))], dtype=np.int64)
        ends = np.asarray(self.task_to, dtype=np.int64)
        speed = np.asarray(self.robot_speed, dtype=np.float64)[:, None]
        out = np.where(speed > 0, self.distance[np.ix_(ends, homes)].T / np.where(speed > 0, speed, 1.0), np.inf)
        out[homes[:, None] == ends[None, :]] = 0.0
        return np.asarray(out, dtype=np.float64)

    def key(self) -> tuple[object, ...]:
        return (self.sites, self.coordinates, self.overrides, self.robot_site, self.robot_speed, self.task_from,
                self.task_to, self.robot_home)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Travel) and self.key() == other.key()

    def __hash__(self) -> int:
        return hash(self.key())


def _finite(value: float, where: str, positive: bool) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or (value <= 0 if positive else value < 0):
        raise InstanceError(f"{where}: expected a finite number {'> 0' if positive else '>= 0'}, got {value!r}")
    return float(value)


def _coordinate(value: float, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InstanceError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def build_travel(sites: Mapping[str, Sequence[float]], distances: Mapping[str, Mapping[str, float]],
                 robots: Sequence[tuple[str, str, float | None]],
                 tasks: Sequence[tuple[str, str, str]], homes: Sequence[str | None] = ()) -> Travel:
    """A checked :class:`Travel`. ``robots``: (id, site, speed or None for fixed);
    ``tasks``: (id, from site, to site); ``homes``: per robot its home site or None (its
    start). InstanceError names the item."""
    names = tuple(sites)
    if not names:
        raise InstanceError("sites: at least one site is needed")
    index = {s: k for k, s in enumerate(names)}
    coords = []
    for s in names:
        xy = sites[s]
        if not isinstance(xy, (list, tuple)) or len(xy) != 2:
            raise InstanceError(f"sites.{s}: expected [x, y], got {xy!r}")
        coords.append((_coordinate(xy[0], f"sites.{s}[0]"), _coordinate(xy[1], f"sites.{s}[1]")))
    xy_arr = np.array(coords, dtype=np.float64).reshape(len(names), 2)
    dist = np.sqrt(((xy_arr[:, None, :] - xy_arr[None, :, :]) ** 2).sum(axis=-1))
    overrides = []
    for a, row in distances.items():
        for b, d in row.items():
            if a not in index or b not in index:
                raise InstanceError(f"distances.{a}.{b}: unknown site {a if a not in index else b!r}")
            dist[index[a], index[b]] = _finite(d, f"distances.{a}.{b}", False)
            overrides.append((a, b, float(d)))

    def site(name: str, where: str) -> int:
        if name not in index:
            raise InstanceError(f"{where}: unknown site {name!r} (sites: {', '.join(names[:10])})")
        return index[name]

    robot_site, robot_speed = [], []
    for rid, s, speed in robots:
        robot_site.append(site(s, f"robot {rid!r} site"))
        robot_speed.append(0.0 if speed is None else _finite(speed, f"robot {rid!r} speed", True))
    task_from = [site(a, f"task {tid!r} site") for tid, a, _ in tasks]
    task_to = [site(b, f"task {tid!r} site") for tid, _, b in tasks]
    home = [robot_site[k] if h is None else site(h, f"robot {robots[k][0]!r} home") for k, h in enumerate(homes)]
    for k, h in enumerate(home):
        if h != robot_site[k] and robot_speed[k] <= 0:
            raise InstanceError(f"robot {robots[k][0]!r} home: a fixed robot (no speed) stays at its site "
                                f"{names[robot_site[k]]!r}, it cannot go home to {names[h]!r}")
    keep = tuple(home) if home != robot_site else ()  # () when every robot's home is its start
    return Travel(names, tuple(coords), dist, tuple(overrides), tuple(robot_site), tuple(robot_speed),
                  tuple(task_from), tuple(task_to), keep)
