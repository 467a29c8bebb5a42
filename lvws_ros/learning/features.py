"""Features of a decision step: the robot graph, the task DAG and robot-task pairs (section III-A).

The paper's vertices are r_i = [a_i, c_i, w_i] and t_j = [s_j, c_j, w_j] with raw
capability vectors and payloads. Ours (model ``lvws-gatn/2``) keep a_i and s_j and
replace the raw c and w by features that are

* **capability-agnostic**: capabilities enter only through counts, shares and the
  coverage test of Eqs. 10-11 (:mod:`lvws_ros.core.subteams`), so one checkpoint serves
  any K >= 1 and permuting the capability columns changes no feature. Counts, shares
  and rarity are over skills; sites ("@cell_1", :data:`lvws_ros.core.problem.SITE_PREFIX`)
  enter through coverage and the pair features, as the matching enforces them;
* **scale-free**: payloads are relative to the team's (mean robot payload, whole team),
  durations to the instance's mean duration and critical path, so multiplying every
  payload or every duration by a constant changes no feature.

Robot vertex (ROBOT_FEATURES): a_i; busy time left / mean duration; payload / mean
robot payload; capabilities held / K; rarity of its rarest capability (share of robots
holding it); share of tasks it can help; share of tasks it covers alone.

Task vertex (TASK_FEATURES), only for tasks not done (a done task changes no decision,
and no task still to do waits on it): s_j = [ready, assigned, incomplete]; payload /
mean robot payload; payload / team payload; capabilities needed / K; share of robots
that hold one of them; rarity of its rarest capability; fewest robots that carry its
payload (/ N, and capped count / 10); duration / mean duration; duration / critical
path; critical-path tail / critical path; share of tasks depending on it; time left
while assigned / mean duration; idle flag; share of tasks done (idle vertex only). The
idle task t_{M+1} is the last vertex, with no edges.

Pair features (PAIR_FEATURES, ours, for the reward MLP of Eq. 6), only for the entries a
decision reads (free robots x ready tasks, and the idle column, all zeros): robot i
alone covers j (Eqs. 10-11); i holds a capability j needs; share of j's capabilities i
holds; min(w_i / w_j, 2) / 2; i is the only free robot holding one of j's capabilities;
and with travel (model ``lvws-gatn/3``; zeros without): i's arrival time at j and how
much later it is than the earliest free robot's, each as x / (1 + x) of x = seconds /
mean duration (1: never); and (model ``lvws-gatn/4``) with busy robots too, a busy one
setting out when its time left is over from where its task ends: how much later i
arrives than the earliest a subteam covering j can be there (Eqs. 10-11), and (the same
for the whole column) how much later that earliest subteam is with free robots only,
both squashed the same way (0: nobody sooner). They tell the network when holding a
task back for busy robots pays. And (model ``lvws-gatn/5``) with ``"objective":
"return"`` (formats.md, "Return to base"): the time i needs from where j ends to its home,
squashed the same way (0 without travel or without that objective): where a robot's last
task is decides when it is home. A robot that is not available but has no time left
(the online scheduler gives it BUSY_EPS, ``core/online.py``) counts as back in a
moment. A ``lvws-gatn/2`` checkpoint reads the first LEGACY_PAIR_FEATURES only, a
``lvws-gatn/3`` one the first TRAVEL_PAIR_FEATURES (the busy-robot ones are then not
computed), a ``lvws-gatn/4`` one the first BUSY_PAIR_FEATURES.

Cost per decision step: O(N K + T + E + R C K), and O(N C (K + log N)) more with travel
for ``lvws-gatn/4``, with T the tasks not done, E their DAG edges, R the free robots and
C the ready tasks; what depends on the instance alone is
computed once (:class:`InstanceFeatures`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from lvws_ros.core.executor import State, TaskStatus
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import TOLERANCE, covers_alone, earliest_cover, fewest_carriers, helps

ROBOT_FEATURES = 7
TASK_FEATURES = 17
PAIR_FEATURES = 10
LEGACY_PAIR_FEATURES = 5  # lvws-gatn/2: no travel features
TRAVEL_PAIR_FEATURES = 7  # lvws-gatn/3: travel features of free robots only
BUSY_PAIR_FEATURES = 9  # lvws-gatn/4: busy robots too, no way home
MODEL_FORMATS = {LEGACY_PAIR_FEATURES: "lvws-gatn/2",  # the network's format by the pair features it reads
                 TRAVEL_PAIR_FEATURES: "lvws-gatn/3", BUSY_PAIR_FEATURES: "lvws-gatn/4",
                 PAIR_FEATURES: "lvws-gatn/5"}
CAP_COUNT = 10.0  # "fewest robots" saturates here

F32 = npt.NDArray[np.float32]
I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class GraphFeatures:
    """One decision step. ``rows`` are the free robots (instance indices); ``cols`` index
    ``tasks`` (the ready tasks, then the idle vertex, always last); ``pairs`` is
    (len(rows), len(cols), PAIR_FEATURES)."""

    robots: F32  # (N, ROBOT_FEATURES)
    tasks: F32  # (T+1, TASK_FEATURES): tasks not done, then the idle task
    edges: I64  # (2, E): P_ij = 1 (i a prerequisite of j), local indices into ``tasks``
    rows: I64  # (R,)
    cols: I64  # (C,)
    pairs: F32  # (R, C, PAIR_FEATURES)
    task_ids: I64  # (T,): instance index of each task vertex


class InstanceFeatures:
    """What depends on the instance alone, computed once per run. ``read``: the pair
    features the model reads (its ``pair_features``); the busy-robot ones (past
    TRAVEL_PAIR_FEATURES) are left zero for a model that does not read them."""

    def __init__(self, inst: Instance, read: int = PAIR_FEATURES) -> None:
        self.read = read
        n, m = inst.num_robots, inst.num_tasks
        rc, tc = inst.robot_amounts > 0, inst.task_needs > 0  # who holds / what needs each trait
        skills = list(inst.skill_columns)  # counts and rarity: skills and traits only, not sites ("@...")
        rs, ts = rc[:, skills], tc[:, skills]
        k = max(len(skills), 1)
        self.instance = inst
        mean_payload = float(inst.robot_payload.mean())
        self.payload_unit = mean_payload if mean_payload > 0 else 1.0
        team = float(inst.robot_payload.sum())
        durations = inst.durations
        self.time_unit = float(durations.mean()) if m else 1.0
        tail = inst.critical_tail
        critical = float(tail.max()) if m else 1.0
        holders = rs.sum(axis=0) / n  # (K,) share of robots holding each skill
        robot_rarity = np.where(rs, holders[None, :], 1.0).min(axis=1, initial=1.0)
        ra, tn = inst.robot_amounts, inst.task_needs
        help_ij = helps(ra, tn, inst.task_payload) if m else np.zeros((n, 0), bool)  # (N, M)
        alone = covers_alone(ra[:, None, :], inst.robot_payload[:, None], tn[None, :, :], inst.task_payload[None, :],
                             inst.task_roles[None, :]) if m else np.zeros((n, 0), bool)
        self.robots = np.zeros((n, ROBOT_FEATURES), np.float32)
        self.robots[:, 2] = inst.robot_payload / self.payload_unit
        self.robots[:, 3] = rs.sum(axis=1) / k
        self.robots[:, 4] = robot_rarity
        self.robots[:, 5] = help_ij.mean(axis=1) if m else 0.0
        self.robots[:, 6] = alone.mean(axis=1) if m else 0.0
        fewest = fewest_carriers(inst.robot_payload, inst.task_payload)  # robots needed for the payload
        self.tasks = np.zeros((m, TASK_FEATURES), np.float32)
        self.tasks[:, 3] = inst.task_payload / self.payload_unit
        self.tasks[:, 4] = inst.task_payload / team if team > 0 else 0.0
        self.tasks[:, 5] = ts.sum(axis=1) / k
        helpers = (rs.astype(np.float32) @ ts.T.astype(np.float32) > 0).mean(axis=0) if m else np.zeros(0)
        self.tasks[:, 6] = np.where(ts.any(axis=1), helpers, 1.0) if m else 0.0
        self.tasks[:, 7] = np.where(ts, holders[None, :], 1.0).min(axis=1, initial=1.0) if m else 0.0
        self.tasks[:, 8] = np.minimum(fewest, n) / n
        self.tasks[:, 9] = np.minimum(fewest, CAP_COUNT) / CAP_COUNT
        self.tasks[:, 10] = durations / self.time_unit
        self.tasks[:, 11] = durations / critical
        self.tasks[:, 12] = tail / critical
        self.tasks[:, 13] = inst.descendant_count / max(m, 1)
        src = [p for j in range(m) for p in inst.prerequisites[j]]
        dst = [j for j in range(m) for _ in inst.prerequisites[j]]
        self.edges = np.array([src, dst], dtype=np.int64).reshape(2, -1)
        self.alone = alone
        self.rc32 = rc.astype(np.float32)
        self.tc32 = tc.astype(np.float32)
        self.need = np.maximum(tc.sum(axis=1), 1).astype(np.float32)
        tr = inst.travel  # the way home (N, M), read by lvws-gatn/5 models, with "return" and travel only
        self.home_after = tr.ways_home() / self.time_unit \
            if read > BUSY_PAIR_FEATURES and inst.objective == "return" and tr is not None else None

    def encode(self, state: State, rows: npt.ArrayLike | None = None) -> GraphFeatures:
        """Features of ``state``; ``rows`` (default: the free robots) choose the pair rows."""
        inst = self.instance
        m = inst.num_tasks
        status = state.task_status
        free = state.robot_available()
        robots = self.robots.copy()
        robots[:, 0] = free
        robots[:, 1] = state.busy_remaining() / self.time_unit
        keep = np.flatnonzero(status != TaskStatus.DONE)
        t = len(keep)
        tasks = np.zeros((t + 1, TASK_FEATURES), np.float32)
        tasks[:t] = self.tasks[keep]
        s = status[keep]
        tasks[:t, 0] = s == TaskStatus.READY
        tasks[:t, 1] = s == TaskStatus.ASSIGNED
        tasks[:t, 2] = 1.0
        left = state.task_end[keep] - state.time
        tasks[:t, 14] = np.where(s == TaskStatus.ASSIGNED, np.nan_to_num(left), 0.0) / self.time_unit
        tasks[t, 15] = 1.0  # the idle task t_{M+1}
        tasks[t, 16] = 1.0 - t / max(m, 1)
        local = np.full(m, -1, dtype=np.int64)
        local[keep] = np.arange(t)
        src, dst = local[self.edges[0]], local[self.edges[1]]
        both = (src >= 0) & (dst >= 0)
        edges = np.stack([src[both], dst[both]])
        rows_ = np.flatnonzero(free) if rows is None else np.asarray(rows, dtype=np.int64)
        ready = np.flatnonzero(status == TaskStatus.READY)
        cols = np.append(local[ready], t).astype(np.int64)
        return GraphFeatures(robots, tasks, edges, rows_.astype(np.int64), cols, self.pairs(state, rows_, ready, free),
                             keep.astype(np.int64))

    def pairs(self, state: State, rows: npt.NDArray[np.int64], ready: npt.NDArray[np.int64],
              free: npt.NDArray[np.bool_]) -> F32:
        """(len(rows), len(ready) + 1, PAIR_FEATURES); the idle column is zeros."""
        inst = self.instance
        out = np.zeros((len(rows), len(ready) + 1, PAIR_FEATURES), np.float32)
        if not len(rows) or not len(ready):
            return out
        rc, tc = self.rc32[rows], self.tc32[ready]
        shared = rc @ tc.T
        out[:, :-1, 0] = self.alone[np.ix_(rows, ready)]
        out[:, :-1, 1] = shared > 0
        out[:, :-1, 2] = shared / self.need[ready][None, :]
        ratio = inst.robot_payload[rows][:, None] / np.maximum(inst.task_payload[ready][None, :], TOLERANCE)
        out[:, :-1, 3] = np.minimum(ratio, 2.0) / 2.0
        sole = (self.rc32[free].sum(axis=0) == 1).astype(np.float32)  # capabilities one free robot holds
        out[:, :-1, 4] = (rc * sole[None, :]) @ tc.T > 0
        if inst.travel is not None:
            arrive = state.arrivals(rows, ready) / self.time_unit  # (R, C), inf: never
            first = state.arrivals(np.flatnonzero(free), ready).min(axis=0, initial=np.inf) / self.time_unit
            out[:, :-1, 5] = _squash(arrive)
            with np.errstate(invalid="ignore"):  # inf - inf where no free robot reaches j: never, 1
                out[:, :-1, 6] = _squash(np.where(np.isfinite(arrive), arrive - first[None, :], np.inf))
            if self.read > TRAVEL_PAIR_FEATURES:
                soon_free = self.soonest(state, ready, np.where(free, 0.0, np.inf))
                soon_any = soon_free if free.all() else \
                    self.soonest(state, ready, np.where(free, 0.0, state.busy_remaining()))
                out[:, :-1, 7] = _squash(_later(arrive, soon_any[None, :]))
                out[:, :-1, 8] = _squash(_later(soon_free, soon_any))[None, :]
        if self.home_after is not None:
            out[:, :-1, 9] = _squash(self.home_after[np.ix_(rows, ready)])
        return out

    def soonest(self, state: State, ready: npt.NDArray[np.int64],
                wait: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        """(len(ready),) in mean durations: the earliest a subteam covering each ready task
        can be there (Eqs. 10-11, :func:`earliest_cover`), robot r setting out after
        ``wait[r]`` seconds (inf: never) from where it is when free."""
        inst = self.instance
        times = wait[:, None] + state.arrivals(np.arange(inst.num_robots), ready)
        start = earliest_cover(times, inst.robot_amounts, inst.robot_payload, inst.task_needs[ready],
                               inst.task_payload[ready])
        return start / self.time_unit


def _later(x: npt.NDArray[np.float64], ref: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """max(x - ref, 0), inf where x is inf, 0 where only ref is (nobody is sooner)."""
    with np.errstate(invalid="ignore"):
        gap = np.maximum(x - ref, 0.0)
    return np.where(np.isinf(x), np.inf, np.where(np.isinf(ref), 0.0, gap))


def _squash(x: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """x / (1 + x) for x >= 0, 1 at inf."""
    finite = np.isfinite(x)
    return np.where(finite, np.divide(x, 1.0 + x, where=finite, out=np.ones_like(x)), 1.0)


def encode_state(state: State, cache: InstanceFeatures | None = None) -> GraphFeatures:
    """Features of ``state``; pass the run's :class:`InstanceFeatures` to reuse them."""
    if cache is None or cache.instance is not state.instance:
        cache = InstanceFeatures(state.instance)
    return cache.encode(state)
