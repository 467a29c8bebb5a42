"""Instance families beyond the paper's recipe: a training mixture and held-out families.

The paper's datasets (:mod:`lvws_ros.core.datasets`) are one generator. A model trained
and measured only there says little about a user's cell, so we draw from families:

* ``mixed`` — the training mixture (domain randomization). Per instance: K = 1..8
  capabilities with skewed holders (each capability held with its own probability,
  Beta(0.6, 0.8)), 3..20 robots, 5..40 tasks (small sizes more likely), a DAG shape among
  :data:`DAG_SHAPES`, a payload regime (solo-feasible, mixed, or tasks needing 2-5 robots), integer or
  float durations, and random units (payloads and durations multiplied by a random
  power of ten, which the scale-free features must not notice).
* ``assembly`` — held out (never used in training or model selection): product
  assembly in-trees (parts -> sub-assemblies -> product, several products), 4..6
  capabilities of which each robot holds one or two (specialists), payloads in kg
  (robots 5..50, parts log-normal), log-normal float durations around 30 s.
* ``mspsp`` — held out: multi-skill project scheduling style. Every robot is one
  worker (payload 1) with 1..3 of K = 4..8 skills; a task needs 1..2 skills and 1..3
  workers (payload = workers); project networks with 1..3 successors per activity and
  skip edges; integer durations 1..20.
* ``depot`` — held out, with travel (the travel extension of formats.md): a shop floor
  of 4..7 stations at float coordinates in 20 m x 8 m, distances the straight line
  rounded up to 0.5 m, given as a matrix (Dataset IV: 3..5 sites on an integer grid,
  Manhattan); 4..7 robots with 1..2 of K = 3..5 skills (IV: 2..3 capabilities, any
  subset), payloads 5..30 float; 40 % fixed at a station (IV: a third), the others at
  0.4, 0.5, 0.8, 1 or 1.25 m/s (IV: 0.5 or 1; travel times then fall on 1 ms, so the
  expert still proves optima); 6..12
  tasks, 35 % transports (IV: 25 %), in-trees, chains or layers, log-normal float
  durations around 10 s, payloads log-normal around 12. Each task is drawn again until
  the robots that can reach it cover it.
* ``traits`` — additive traits (formats.md, "Traits"), written in traits alone: L = 1..16
  traits; 3..8 robots, each with 1..3 traits in whole amounts 1..5 (small ones likelier);
  6..18 tasks needing 1..3 traits in amounts 1..5 (about one in five needs 3 or more of
  one), 30 % of them with roles; integer durations 1..20; a DAG shape among
  :data:`DAG_SHAPES`.
* ``traits-return`` — traits with travel and ``"objective": "return"`` (formats.md,
  "Return to base"): a ``traits`` instance of 6..14 tasks on a floor of 4..7 stations at
  float coordinates in 10 m x 5 m (straight-line distances rounded up to 0.5 m), every
  robot mobile at one of the depot speeds, starting at a random station; half the robots
  have their home at the first station (a dock), the others where they start; 20 % of the
  tasks are transports.
* ``warehouse`` — held out, traits with travel and ``"objective": "return"``: orders are
  chains pick -> carry -> kit -> inspect on a grid of stations 6 m apart (aisles: Manhattan
  distances). Picks and kitting need an ``arm`` (arms are fixed, one to three at each pick
  and kit station); a carry takes a tote from its pick station to a kit station and needs a
  summed ``lift`` of 1-4 (AMRs lift 1 or 2, so heavy totes take two or three); inspection,
  at one of the inspection stations, needs a ``scanner`` (scanners lift 0.5 too). AMRs
  (0.8-1.6 m/s) and scanners (0.5-1 m/s) start at and return to a dock. 15 % of the orders
  kit only after an earlier order's kit. 30 % arms, 50 % AMRs, 20 % scanners by default;
  a pick or kit station per three arms, an inspection station per four kit stations.
* ``traits-roles`` — held out, traits: roles on every task (the instance's ``roles``),
  specialists (each robot 1..2 of L = 3..8 traits), a summed ``payload`` trait in float
  kilograms beside them, in-trees or layers, log-normal float durations around 20 s.

Each trait instance's tasks are drawn again until the whole team covers them (with roles
where they have them).

Instance ``k`` of family ``f`` comes from ``numpy.random.default_rng([seed, code(f), k])``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.subteams import covers
from lvws_ros.core.travel import build_travel

DAG_SHAPES = ("random", "layered", "chains", "in_tree", "out_tree", "wide", "deep")
PAYLOAD_REGIMES = ("solo", "mixed", "heavy")
REGIME_PROBS = (0.2, 0.4, 0.4)
DEPOT_SPEEDS = (0.4, 0.5, 0.8, 1.0, 1.25)  # m/s: 0.5 m / speed is a whole number of ms


@dataclass(frozen=True)
class Family:
    key: str
    code: int
    held_out: bool
    description: str
    travel: bool = False  # its instances have sites, speeds and task sites
    traits: bool = False  # its instances are written in additive traits (not in the paper's tables)


FAMILIES = {
    "mixed": Family("mixed", 11, False, "training mixture: K 1-8, 3-20 robots, 5-40 tasks, 7 DAG shapes"),
    "assembly": Family("assembly", 12, True, "held out: assembly in-trees, specialists, kg payloads, float durations"),
    "mspsp": Family("mspsp", 13, True, "held out: multi-skill project scheduling (unit workers, K 4-8)"),
    "depot": Family("depot", 14, True, "held out, travel: 4-7 stations at float points, straight-line "
                    "distances, K 3-5 specialists, 5 speeds 0.4-1.25, 40 % fixed, 35 % transports", travel=True),
    "traits": Family("traits", 15, False, "additive traits: L 1-16, amounts 1-5, 30 % of tasks with roles",
                     traits=True),
    "traits-return": Family("traits-return", 17, False, "additive traits with travel, homes and the objective "
                            "'return': 4-7 stations in 10 m x 5 m, half the robots docked at one station",
                            travel=True, traits=True),
    "warehouse": Family("warehouse", 18, True, "held out, traits with travel and the objective 'return': orders "
                        "pick -> carry -> kit -> inspect on a station grid, fixed arms, AMRs lifting together, "
                        "scanners", travel=True, traits=True),
    "traits-roles": Family("traits-roles", 16, True, "held out, traits: roles everywhere, specialists, a float "
                           "payload trait, in-trees or layers, float durations", traits=True),
}


def _dag(rng: np.random.Generator, m: int, shape: str) -> list[list[int]]:
    """Prerequisites of each task (indices < j, so the graph is acyclic)."""
    pre: list[list[int]] = [[] for _ in range(m)]
    if shape == "random":  # the paper's datasets: 0-2 prerequisites among earlier tasks
        for j in range(1, m):
            k = min(j, int(rng.choice(3, p=(0.35, 0.40, 0.25))))
            pre[j] = sorted(int(p) for p in rng.choice(j, size=k, replace=False))
    elif shape in ("layered", "wide", "deep"):
        layers = {"layered": max(2, round(m ** 0.5)), "wide": 2, "deep": max(2, m // 2)}[shape]
        cuts = [int(c) for c in np.sort(rng.choice(np.arange(1, m), size=min(layers, m) - 1, replace=False))] \
            if m > 1 else []
        bounds = [0, *cuts, m]
        for a, b, c in zip(bounds, bounds[1:], bounds[2:], strict=False):
            for j in range(b, c):
                k = int(rng.integers(1, min(3, b - a) + 1))
                pre[j] = sorted(int(p) for p in rng.choice(np.arange(a, b), size=k, replace=False))
    elif shape == "chains":
        chains = int(rng.integers(1, max(2, m // 3) + 1))
        owner = rng.integers(chains, size=m)
        for j in range(m):
            earlier = [p for p in range(j) if owner[p] == owner[j]]
            if earlier:
                pre[j] = [earlier[-1]]
    elif shape == "in_tree":  # many roots join into few sinks: task j waits on its children
        for j in range(m - 1):
            parent = int(rng.integers(j + 1, min(m, j + 4)))
            pre[parent].append(j)
        pre = [sorted(p) for p in pre]
    elif shape == "out_tree":
        for j in range(1, m):
            pre[j] = [int(rng.integers(max(0, j - 4), j))]
    else:
        raise ValueError(f"unknown DAG shape {shape!r}")
    return pre


def _holders(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """(n, k) capability vectors, each capability held with its own probability; every
    robot holds one and every capability is held."""
    p = rng.beta(0.6, 0.8, size=k).clip(0.1, 0.95)
    caps = rng.random((n, k)) < p
    for i in np.flatnonzero(~caps.any(axis=1)):
        caps[i, rng.integers(k)] = True
    for c in np.flatnonzero(~caps.any(axis=0)):
        caps[rng.integers(n), c] = True
    return caps


def _instance(name: str, k: int, robot_caps: np.ndarray, robot_payload: np.ndarray, task_caps: np.ndarray,
              task_payload: np.ndarray, durations: np.ndarray, pre: list[list[int]]) -> Instance:
    total = float(robot_payload.sum())
    robots = tuple(Robot(f"r{i}", tuple(int(c) for c in robot_caps[i]), float(robot_payload[i]))
                   for i in range(len(robot_payload)))
    tasks = tuple(Task(f"t{j}", tuple(int(c) for c in task_caps[j]), float(min(task_payload[j], total)),
                       float(durations[j]), tuple(f"t{p}" for p in pre[j])) for j in range(len(durations)))
    return Instance(name, tuple(f"c{c}" for c in range(k)), robots, tasks)


def _specialists(rng: np.random.Generator, n: int, k: int, most: int) -> np.ndarray:
    """(n, k) capability vectors: each robot holds 1..``most`` of the k capabilities."""
    caps = np.zeros((n, k), dtype=bool)
    for i in range(n):
        caps[i, rng.choice(k, size=int(rng.integers(1, most + 1)), replace=False)] = True
    return caps


def _task_caps(rng: np.random.Generator, m: int, k: int, most: int) -> np.ndarray:
    caps = np.zeros((m, k), dtype=bool)
    for j in range(m):
        caps[j, rng.choice(k, size=int(rng.integers(1, min(most, k) + 1)), replace=False)] = True
    return caps


def mixed_instance(rng: np.random.Generator, name: str, num_robots: int | None = None,
                   num_tasks: int | None = None) -> Instance:
    """One instance of the training mixture (module docstring)."""
    k = int(rng.integers(1, 9))
    n = num_robots or int(min(20, 2 + rng.geometric(0.15)))
    m = num_tasks or int(min(40, 4 + rng.geometric(0.08)))
    robot_caps = _holders(rng, n, k)
    hi = int(rng.integers(2, 31))
    robot_payload = rng.integers(1, hi + 1, size=n).astype(float)
    regime = PAYLOAD_REGIMES[int(rng.choice(len(PAYLOAD_REGIMES), p=REGIME_PROBS))]
    team = int(rng.integers(2, 6)) if regime == "heavy" else 1
    mean = {"solo": 0.5, "mixed": 1.0, "heavy": float(team)}[regime] * float(np.median(robot_payload))
    task_payload = np.maximum(rng.gamma(4.0, mean / 4.0, size=m).round(), 0.0)
    if rng.random() < 0.5:
        durations = rng.integers(1, int(rng.integers(3, 21)) + 1, size=m).astype(float)
    else:
        durations = rng.lognormal(1.5, 0.6, size=m).round(2).clip(0.1)
    unit_p, unit_t = 10.0 ** rng.integers(-1, 3), 10.0 ** rng.integers(-1, 3)
    shape = DAG_SHAPES[int(rng.integers(len(DAG_SHAPES)))]
    return _instance(name, k, robot_caps, robot_payload * unit_p, _task_caps(rng, m, k, 3), task_payload * unit_p,
                     durations * unit_t, _dag(rng, m, shape))


def assembly_instance(rng: np.random.Generator, name: str, num_robots: int = 6, num_tasks: int = 18) -> Instance:
    """One instance of the held-out assembly family (module docstring)."""
    k = int(rng.integers(4, 7))
    n, m = num_robots, num_tasks
    robot_caps = _specialists(rng, n, k, 2)
    robot_caps[rng.permutation(n)[:k] if n >= k else rng.integers(n, size=k), np.arange(k)] = True
    robot_payload = rng.uniform(5, 50, size=n).round(1)
    task_payload = rng.lognormal(np.log(25), 0.8, size=m).round(1)
    durations = rng.lognormal(np.log(30), 0.5, size=m).round(1)
    products = int(rng.integers(1, 4))
    owner = np.sort(rng.integers(products, size=m))
    pre: list[list[int]] = [[] for _ in range(m)]
    for prod in range(products):
        members = [int(j) for j in np.flatnonzero(owner == prod)]
        for a, j in enumerate(members[:-1]):  # each part feeds a later (sub-)assembly of its product
            pre[members[int(rng.integers(a + 1, min(len(members), a + 4)))]].append(j)
    return _instance(name, k, robot_caps, robot_payload, _task_caps(rng, m, k, 2), task_payload, durations,
                     [sorted(p) for p in pre])


def mspsp_instance(rng: np.random.Generator, name: str, num_robots: int = 6, num_tasks: int = 18) -> Instance:
    """One instance of the held-out multi-skill project scheduling family (module docstring)."""
    k = int(rng.integers(4, 9))
    n, m = num_robots, num_tasks
    robot_caps = _specialists(rng, n, k, 3)
    for c in np.flatnonzero(~robot_caps.any(axis=0)):
        robot_caps[rng.integers(n), c] = True
    task_caps = _task_caps(rng, m, k, 2)
    workers = rng.integers(1, 4, size=m).astype(float)
    durations = rng.integers(1, 21, size=m).astype(float)
    pre: list[list[int]] = [[] for _ in range(m)]
    for j in range(m - 1):
        for s in rng.choice(np.arange(j + 1, m), size=min(m - j - 1, int(rng.integers(1, 4))), replace=False):
            if rng.random() < 0.5 or s == j + 1:
                pre[int(s)].append(j)
    return _instance(name, k, robot_caps, np.ones(n), task_caps, workers, durations, [sorted(p) for p in pre])


def depot_instance(rng: np.random.Generator, name: str, num_robots: int | None = None,
                   num_tasks: int | None = None) -> Instance:
    """One instance of the held-out depot family, with travel (module docstring)."""
    n = num_robots or int(rng.integers(4, 8))
    m = num_tasks or int(rng.integers(6, 13))
    if n < 3:  # the mobile robots (at least two, 1-2 skills each) must hold all K <= 5 skills
        raise ValueError(f"depot instances have at least 3 robots, not {n}")
    k = int(rng.integers(3, 6))
    stations = [f"st{i}" for i in range(int(rng.integers(4, 8)))]
    xy = rng.uniform((0.0, 0.0), (20.0, 8.0), size=(len(stations), 2)).round(1)
    while True:
        caps = _specialists(rng, n, k, 2)
        fixed = rng.random(n) < 0.4
        fixed[: min(2, n)] = False  # at least two mobile robots
        if caps[~fixed].any(axis=0).all():
            break
    payload = rng.uniform(5.0, 30.0, size=n).round(1)
    robot_site = rng.integers(len(stations), size=n)
    speed = rng.choice(DEPOT_SPEEDS, size=n)
    durations = rng.lognormal(np.log(10.0), 0.5, size=m).round(1).clip(0.5)
    pre = _dag(rng, m, str(rng.choice(("in_tree", "chains", "layered"))))
    task_caps = np.zeros((m, k), dtype=bool)
    task_payload = np.zeros(m)
    sites = []
    for j in range(m):
        while True:
            a, b = (int(x) for x in rng.choice(len(stations), size=2, replace=False))
            if rng.random() >= 0.35:
                b = a
            able = ~fixed | ((robot_site == a) & (a == b))  # who can reach it
            task_caps[j] = _task_caps(rng, 1, k, 2)[0]
            task_payload[j] = round(float(rng.lognormal(np.log(12.0), 0.6)), 1)
            if covers(caps[able], payload[able], task_caps[j], task_payload[j]):
                break
        sites.append((f"t{j}", stations[a], stations[b]))
    inst = _instance(name, k, caps, payload, task_caps, task_payload, durations, pre)
    travel = build_travel({s: [float(x), float(y)] for s, (x, y) in zip(stations, xy, strict=True)},
                          _straight_line(stations, xy),
                          [(f"r{i}", stations[int(robot_site[i])], None if fixed[i] else float(speed[i]))
                           for i in range(n)], sites)
    return Instance(name, inst.capabilities, inst.robots, inst.tasks, travel=travel)


def _draw_amounts(rng: np.random.Generator, count: int, high: int) -> np.ndarray:
    """``count`` whole amounts in 1..``high``, small ones likelier."""
    p = 1.0 / np.arange(1, high + 1)
    return rng.choice(np.arange(1, high + 1), size=count, p=p / p.sum()).astype(float)


def trait_instance(rng: np.random.Generator, name: str, num_robots: int | None = None,
                   num_tasks: int | None = None, held_out: bool = False) -> Instance:
    """One instance of the ``traits`` family, or (``held_out``) of ``traits-roles``
    (module docstring): no capabilities, no paper payload; every task coverable."""
    n = num_robots or int(rng.integers(3, 9))
    m = num_tasks or int(rng.integers(6, 19))
    names = [f"trait{c}" for c in range(int(rng.integers(3, 9) if held_out else rng.integers(1, 17)))]
    per_robot = 2 if held_out else 3
    amounts = np.zeros((n, len(names)))
    for i in range(n):
        cols = rng.choice(len(names), size=min(len(names), int(rng.integers(1, per_robot + 1))), replace=False)
        amounts[i, cols] = _draw_amounts(rng, len(cols), 5)
    for c in np.flatnonzero(~(amounts > 0).any(axis=0)):  # every trait held by someone
        amounts[rng.integers(n), c] = _draw_amounts(rng, 1, 5)[0]
    if held_out:
        names.append("payload")
        amounts = np.hstack([amounts, rng.uniform(0.5, 5.0, size=(n, 1)).round(1)])
    zero = np.zeros(n)
    shape = str(rng.choice(("in_tree", "layered"))) if held_out else str(rng.choice(DAG_SHAPES))
    pre = _dag(rng, m, shape)
    tasks = []
    for j in range(m):
        roles = held_out or bool(rng.random() < 0.3)
        while True:
            need = np.zeros(len(names))
            skills = len(names) - 1 if held_out else len(names)
            cols = rng.choice(skills, size=min(skills, int(rng.integers(1, 4))), replace=False)
            need[cols] = _draw_amounts(rng, len(cols), 5)
            if held_out and rng.random() < 0.5:
                need[-1] = round(float(rng.lognormal(np.log(3.0), 0.6)), 1)
            if covers(amounts, zero, need, 0.0, roles):
                break
        duration = max(0.5, round(float(rng.lognormal(np.log(20.0), 0.5)), 1)) if held_out else \
            float(rng.integers(1, 21))
        tasks.append(Task(f"t{j}", (), 0.0, duration, tuple(f"t{p}" for p in pre[j]),
                          requires=tuple((names[c], float(need[c])) for c in np.flatnonzero(need)),
                          roles=None if held_out else roles))
    robots = tuple(Robot(f"r{i}", (), 0.0, traits=tuple((names[c], float(amounts[i, c]))
                                                       for c in np.flatnonzero(amounts[i])))
                   for i in range(n))
    return Instance(name, (), robots, tuple(tasks), traits=tuple(names), roles=held_out)


def trait_return_instance(rng: np.random.Generator, name: str, num_robots: int | None = None,
                          num_tasks: int | None = None) -> Instance:
    """One instance of the ``traits-return`` family (module docstring): every robot is
    mobile, so every task stays coverable."""
    inst = trait_instance(rng, name, num_robots, num_tasks or int(rng.integers(6, 15)))
    n, m = inst.num_robots, inst.num_tasks
    stations = [f"st{i}" for i in range(int(rng.integers(4, 8)))]
    xy = rng.uniform((0.0, 0.0), (10.0, 5.0), size=(len(stations), 2)).round(1)
    start = rng.integers(len(stations), size=n)
    speed = rng.choice(DEPOT_SPEEDS, size=n)
    docked = rng.random(n) < 0.5
    sites = []
    for j in range(m):
        a, b = (int(x) for x in rng.choice(len(stations), size=2, replace=False))
        sites.append((f"t{j}", stations[a], stations[b] if rng.random() < 0.2 else stations[a]))
    travel = build_travel({s: [float(x), float(y)] for s, (x, y) in zip(stations, xy, strict=True)},
                          _straight_line(stations, xy),
                          [(f"r{i}", stations[int(start[i])], float(speed[i])) for i in range(n)], sites,
                          [stations[0] if docked[i] else None for i in range(n)])
    return replace(inst, travel=travel, objective="return")


WAREHOUSE_SPACING = 6.0  # m between neighbouring stations of the warehouse grid
WAREHOUSE_STAGES = ("pick", "carry", "kit", "inspect")


def _warehouse_fleet(rng: np.random.Generator, n: int) -> tuple[int, int, np.ndarray]:
    """How many arms, AMRs and scanners (at least 2, 1, 1), and each arm's station among
    the arm stations (every station with at least one arm)."""
    arms = max(2, round(0.3 * n))
    scanners = max(1, round(0.2 * n))
    amrs = n - arms - scanners
    if amrs < 1:
        raise ValueError(f"warehouse instances have at least 4 robots, not {n}")
    stations = max(2, arms // 3)
    at = np.concatenate([np.arange(stations), rng.integers(stations, size=arms - stations)])
    return arms, amrs, at


def warehouse_instance(rng: np.random.Generator, name: str, num_robots: int | None = None,
                       num_tasks: int | None = None) -> Instance:
    """One instance of the held-out warehouse family (module docstring): ``num_tasks``
    rounded up to whole orders of four tasks."""
    n = num_robots or int(rng.integers(8, 25))
    orders = -(-(num_tasks or int(rng.integers(12, 41))) // 4)
    arms, amrs, arm_at = _warehouse_fleet(rng, n)
    arm_stations = int(arm_at.max()) + 1
    kits = max(1, arm_stations // 3)  # the last ``kits`` arm stations kit, the others pick
    picks = arm_stations - kits
    inspections = max(1, kits // 4)
    stations = [f"pick{i}" for i in range(picks)] + [f"kit{i}" for i in range(kits)] + \
        [f"inspect{i}" for i in range(inspections)] + ["dock"]
    cols = int(np.ceil(np.sqrt(len(stations))))
    cells = rng.permutation(cols * cols)[: len(stations)]
    xy = np.stack([cells % cols, cells // cols], axis=1).astype(float) * WAREHOUSE_SPACING
    manhattan = np.abs(xy[:, None, :] - xy[None, :, :]).sum(axis=-1)
    distances = {a: {b: float(manhattan[i, j]) for j, b in enumerate(stations) if j != i}
                 for i, a in enumerate(stations)}
    robots: list[Robot] = []
    robot_sites: list[tuple[str, str, float | None]] = []
    for i in range(n):
        if i < arms:
            robots.append(Robot(f"arm{i}", (), 0.0, traits=(("arm", 1.0),)))
            robot_sites.append((f"arm{i}", stations[int(arm_at[i])], None))
        elif i < arms + amrs:
            lift = float(rng.choice((1.0, 2.0), p=(0.7, 0.3)))
            robots.append(Robot(f"amr{i}", (), 0.0, traits=(("lift", lift),)))
            robot_sites.append((f"amr{i}", "dock", float(rng.choice((0.8, 1.0, 1.25, 1.6)))))
        else:
            robots.append(Robot(f"scan{i}", (), 0.0, traits=(("scanner", 1.0), ("lift", 0.5))))
            robot_sites.append((f"scan{i}", "dock", float(rng.choice((0.5, 0.8, 1.0)))))
    tasks, sites = _warehouse_orders(rng, orders, stations, (picks, kits, inspections), manhattan)
    travel = build_travel({s: [float(x), float(y)] for s, (x, y) in zip(stations, xy, strict=True)}, distances,
                          robot_sites, sites)
    return Instance(name, (), tuple(robots), tuple(tasks), travel=travel, traits=("arm", "lift", "scanner"),
                    objective="return")


def _warehouse_orders(rng: np.random.Generator, orders: int, stations: list[str], counts: tuple[int, int, int],
                      manhattan: np.ndarray) -> tuple[list[Task], list[tuple[str, str, str]]]:
    """The orders' tasks (pick -> carry -> kit -> inspect, some kits after an earlier
    order's) and their sites; ``counts``: the pick, kit and inspection stations, listed in
    that order in ``stations``."""
    picks, kits, inspections = counts
    tasks: list[Task] = []
    sites: list[tuple[str, str, str]] = []
    for o in range(orders):
        pick, kit = int(rng.integers(picks)), picks + int(rng.integers(kits))
        inspect = picks + kits + int(rng.integers(inspections))
        lift = float(rng.choice((1.0, 1.5, 2.0, 3.0, 4.0), p=(0.45, 0.15, 0.2, 0.12, 0.08)))
        carry = float(manhattan[pick, kit]) + round(float(rng.uniform(2.0, 6.0)), 1)
        stage = [("pick", stations[pick], stations[pick], "arm", 1.0, round(float(rng.uniform(5.0, 15.0)), 1)),
                 ("carry", stations[pick], stations[kit], "lift", lift, carry),
                 ("kit", stations[kit], stations[kit], "arm", 1.0, round(float(rng.uniform(8.0, 20.0)), 1)),
                 ("inspect", stations[inspect], stations[inspect], "scanner", 1.0,
                  round(float(rng.uniform(3.0, 8.0)), 1))]
        earlier = f"o{int(rng.integers(max(0, o - 10), o))}-kit" if o and rng.random() < 0.15 else None
        for s, (kind, a, b, trait, amount, duration) in enumerate(stage):
            after: tuple[str, ...] = (f"o{o}-{stage[s - 1][0]}",) if s else ()
            if kind == "kit" and earlier is not None:
                after += (earlier,)
            tasks.append(Task(f"o{o}-{kind}", (), 0.0, duration, after, requires=((trait, amount),)))
            sites.append((f"o{o}-{kind}", a, b))
    return tasks, sites


def _straight_line(stations: list[str], xy: np.ndarray) -> dict[str, dict[str, float]]:
    """Distances between stations: the straight line rounded up to 0.5 m."""
    line = np.ceil(2 * np.sqrt(((xy[:, None, :] - xy[None, :, :]) ** 2).sum(axis=-1))) / 2
    return {a: {b: float(line[i, j]) for j, b in enumerate(stations) if j != i} for i, a in enumerate(stations)}


def family_instance(key: str, index: int, seed: int, num_robots: int | None = None,
                    num_tasks: int | None = None) -> Instance:
    """Instance ``index`` of family ``key`` (``mixed`` draws its own sizes unless given)."""
    fam = FAMILIES[key]
    rng = np.random.default_rng([seed, fam.code, index])
    if key == "mixed":
        inst = mixed_instance(rng, "tmp", num_robots, num_tasks)
    elif key == "assembly":
        inst = assembly_instance(rng, "tmp", num_robots or 6, num_tasks or 18)
    elif key == "depot":
        inst = depot_instance(rng, "tmp", num_robots, num_tasks)
    elif key == "warehouse":
        inst = warehouse_instance(rng, "tmp", num_robots, num_tasks)
    elif key == "traits-return":
        inst = trait_return_instance(rng, "tmp", num_robots, num_tasks)
    elif fam.traits:
        inst = trait_instance(rng, "tmp", num_robots, num_tasks, held_out=fam.held_out)
    else:
        inst = mspsp_instance(rng, "tmp", num_robots or 6, num_tasks or 18)
    return replace(inst, name=f"{inst.num_robots}r-{inst.num_tasks}t-{key}-{index:05d}")


TRAINING_FAMILIES = tuple(k for k, f in FAMILIES.items() if not f.held_out)
TABLE_TRAINING_FAMILIES = tuple(k for k in TRAINING_FAMILIES if not FAMILIES[k].traits)  # Table I: the paper's model
HELD_OUT_FAMILIES = tuple(k for k, f in FAMILIES.items() if f.held_out and not f.travel and not f.traits)  # Table I
TRAIT_FAMILIES = tuple(k for k, f in FAMILIES.items() if f.traits)
TRAVEL_FAMILIES = tuple(k for k, f in FAMILIES.items() if f.held_out and f.travel and not f.traits)  # Table III
TEST_OFFSET = 1_000_000  # test instances of a family: indices from here (training uses 0, 1, ...)
TEST_COUNT = 100


def family_test_split(key: str, seed: int, count: int = TEST_COUNT) -> list[Instance]:
    """The evaluation instances of family ``key``: indices TEST_OFFSET.., never trained on."""
    return [family_instance(key, TEST_OFFSET + k, seed) for k in range(count)]
