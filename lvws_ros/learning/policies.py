"""Learned policies: LVWS (GATN rewards + subteam matching with waiting) and DBGM-style.

* ``lvws``: one GATN forward pass per decision step gives R (N x (M+1)); the rows of
  free robots and the columns of ready tasks plus the idle task go to
  :func:`~lvws_ros.core.matching.greedy_match` (Eqs. 7-11). Robots matched to the idle task
  wait. The idle column gets the checkpoint's ``idle_bias``, calibrated on held-out
  training instances (NO_VOLUNTARY_WAIT: robots wait only when no ready task needs
  them). With a wait head (ours), free robots whose probability of waiting exceeds the
  checkpoint's ``wait_threshold`` (calibrated likewise; None: off) wait and the others
  are matched. Safety net: if every free robot chose to wait while nothing is running
  (which would stall the schedule), the matching is redone with all of them and without
  the idle task.
* ``matching="exact"`` (ours): Eqs. 7-11 on R solved exactly (the maximum of Eq. 7, by
  CP-SAT, :func:`~lvws_ros.policies.exact.exact_match`) instead of the paper's greedy.
* ``dbgm``: a GAT-only network (no transformer, no global context), no idle task, and
  subteams only when no single free robot can do a task: one-to-one matching by reward
  first, then subteams for the tasks left that need them.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.core.executor import (
    Decision,
    Policy,
    State,
    TaskStatus,
    advance,
    decision_deadline,
    final_makespan,
    simulate,
)
from lvws_ros.core.matching import Match, greedy_match
from lvws_ros.core.problem import Instance
from lvws_ros.errors import PolicyError
from lvws_ros.learning.checkpoint import DEFAULT_MODELS, load_checkpoint
from lvws_ros.learning.features import InstanceFeatures
from lvws_ros.learning.gatn import GATN, decision_outputs, reward_matrix
from lvws_ros.policies.baselines import GreedyPayloadPolicy

NO_VOLUNTARY_WAIT = -1e6  # idle bias that leaves waiting only to robots with nothing to do
MATCHINGS = ("greedy", "exact")  # how LVWS solves Eqs. 7-11 on R at a decision step
EXACT_MATCH_SECONDS = 1.0  # CP-SAT's limit for one decision step's exact matching


def reachable(state: State, robots: Sequence[int], tasks: Sequence[int]) -> np.ndarray | None:
    """(robots, tasks): the pairs the matching may use, with travel the robots that can
    reach a task at all (a fixed robot only at its site); None without travel (all)."""
    return None if state.instance.travel is None else state.reachable(robots, tasks)


def _idle_last(sub: np.ndarray) -> None:
    """Put the idle column below every task reward, whatever their scale: a robot then
    waits only when no ready task needs it (NO_VOLUNTARY_WAIT)."""
    sub[:, -1] = float(sub[:, :-1].min(initial=0.0)) - 1.0


class LVWSPolicy:
    name = "lvws"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 idle_bias: float | None = None, wait_threshold: float | str | None = "checkpoint",
                 matching: str = "greedy") -> None:
        if matching not in MATCHINGS:
            raise PolicyError(f"lvws: unknown matching {matching!r}; one of {', '.join(MATCHINGS)}")
        self.matching = matching
        meta: dict[str, Any] = {}
        if model is None:
            model, meta = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["lvws"])
            idle_bias = float(meta.get("idle_bias", 0.0)) if idle_bias is None else idle_bias
        self.model = model.eval()
        self.idle_bias = 0.0 if idle_bias is None else idle_bias
        if wait_threshold == "checkpoint":
            wait_threshold = meta.get("wait_threshold")
        self.wait_threshold = None if wait_threshold is None else float(wait_threshold)
        self._cache: InstanceFeatures | None = None

    def reset(self, instance: Instance) -> None:
        if self._cache is None or self._cache.instance is not instance:  # rollouts reset once per simulation
            self._cache = InstanceFeatures(instance, self.model.cfg.pair_features)

    def features(self, instance: Instance) -> InstanceFeatures:
        """What the model reads of ``instance`` alone (computed once per instance)."""
        self.reset(instance)
        assert self._cache is not None
        return self._cache

    def outputs(self, state: State) -> tuple[np.ndarray, np.ndarray | None]:
        """R of Eq. 6 for this decision step, (free robots, ready tasks + idle task), and
        the free robots' wait probabilities (None without a wait head): one forward pass,
        the reward MLP only on the entries the matching reads."""
        self.reset(state.instance)
        assert self._cache is not None
        r, wait = decision_outputs(self.model, self._cache.encode(state))
        if not np.isfinite(r).all() or (wait is not None and not np.isfinite(wait).all()):
            raise PolicyError(f"{self.name}: the model gave non-finite rewards at t={state.time:g}")
        return r, wait

    def rewards(self, state: State) -> np.ndarray:
        """R of :meth:`outputs` alone."""
        return self.outputs(state)[0]

    def match(self, state: State, r: np.ndarray, subset: list[int] | None = None,
              idle_bias: float | None = None, wait: np.ndarray | None = None,
              wait_threshold: float | None = None, only: int | None = None) -> Decision:
        """Eqs. 7-11 on ``r`` (rows: the free robots, columns: the ready tasks, then the
        idle task), for the free robots in ``subset`` (default: all of them). With ``wait``
        (the free robots' wait probabilities) and a threshold (``wait_threshold``, else the
        policy's), the robots above it wait and the others are matched. With ``only`` (a
        ready task), that task alone is matched, without voluntary waiting, and the other
        robots wait."""
        inst = state.instance
        ready, free = state.ready_tasks(), state.free_robots()
        robots = free if subset is None else subset
        if not robots or not ready:
            return Decision((), tuple(robots))
        row_of = {i: k for k, i in enumerate(free)}
        threshold = self.wait_threshold if wait_threshold is None else wait_threshold
        if wait is not None and threshold is not None:
            keep = [i for i in robots if wait[row_of[i]] <= threshold]
            if len(keep) < len(robots):
                d = self.match(state, r, keep, idle_bias) if keep else Decision((), ())
                if d.assignments or (state.task_status == TaskStatus.ASSIGNED).any():
                    return Decision(d.assignments, tuple(sorted(set(robots) - {i for _, t in d.assignments
                                                                               for i in t})))
                # waiting now would stall: match them all as without the head
        sub = r[[row_of[i] for i in robots]].copy()
        bias = self.idle_bias if idle_bias is None else idle_bias
        if bias <= NO_VOLUNTARY_WAIT or only is not None:
            _idle_last(sub)
        else:
            sub[:, -1] += bias
        allowed = reachable(state, robots, ready)
        if only is not None:
            alone = np.zeros((len(robots), len(ready)), dtype=bool)
            alone[:, ready.index(only)] = True
            allowed = alone if allowed is None else allowed & alone
        args = (inst.robot_amounts[robots], inst.robot_payload[robots], inst.task_needs[ready], inst.task_payload[ready],
                allowed, inst.task_roles[ready])
        match = self._match(sub, *args)
        if not match.teams and not (state.task_status == TaskStatus.ASSIGNED).any():
            _idle_last(sub)  # waiting now would stall: take the best task instead
            match = self._match(sub, *args)
        assignments = tuple((ready[j], tuple(robots[i] for i in team)) for j, team in sorted(match.teams.items()))
        return Decision(assignments, tuple(robots[i] for i in match.waiting))

    def _match(self, r: np.ndarray, robot_caps: np.ndarray, robot_payload: np.ndarray, task_caps: np.ndarray,
               task_payload: np.ndarray, allowed: np.ndarray | None, roles: np.ndarray) -> Match:
        """Eqs. 7-11 on ``r``: the paper's sequential greedy, or (``matching="exact"``) the
        maximum of Eq. 7 by CP-SAT (within EXACT_MATCH_SECONDS; its best when not proven)."""
        if self.matching == "greedy":
            return greedy_match(r, robot_caps, robot_payload, task_caps, task_payload, allowed, roles)
        from lvws_ros.policies.exact import exact_match

        return exact_match(r, robot_caps, robot_payload, task_caps, task_payload, allowed=allowed, roles=roles,
                           time_limit=EXACT_MATCH_SECONDS, workers=1)

    def decide(self, state: State) -> Decision:
        free = state.free_robots()
        if not free or not state.ready_tasks():
            return Decision((), tuple(free))
        r, wait = self.outputs(state)
        return self.match(state, r, wait=wait)


class DBGMPolicy:
    name = "dbgm"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None) -> None:
        if model is None:
            model = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["dbgm"])[0]
        self.model = model.eval()
        self._cache: InstanceFeatures | None = None

    def reset(self, instance: Instance) -> None:
        self._cache = InstanceFeatures(instance, self.model.cfg.pair_features)

    def decide(self, state: State) -> Decision:
        inst = state.instance
        free, ready = state.free_robots(), state.ready_tasks()
        if not free or not ready:
            return Decision((), tuple(free))
        if self._cache is None or self._cache.instance is not inst:
            self.reset(inst)
        assert self._cache is not None
        r = reward_matrix(self.model, self._cache.encode(state))  # rows free, columns ready (+ idle, unused)
        out: list[tuple[int, tuple[int, ...]]] = []
        allowed = reachable(state, free, ready)
        alone = self._cache.alone[np.ix_(free, ready)]  # robot covers the task alone (Eqs. 10-11)
        if allowed is not None:
            alone = alone & allowed
        pairs = [(r[a, b], int(a), int(b)) for a, b in zip(*np.nonzero(alone), strict=True)]
        used_r: set[int] = set()
        used_t: set[int] = set()
        for _, a, b in sorted(pairs, key=lambda p: -p[0]):  # one-to-one bipartite matching, best first
            if a not in used_r and b not in used_t:
                out.append((ready[b], (free[a],)))
                used_r.add(a)
                used_t.add(b)
        rest_r = [a for a in range(len(free)) if a not in used_r]
        single = {b for _, _, b in pairs}
        rest_t = [b for b in range(len(ready)) if b not in used_t and b not in single]  # need a subteam
        if rest_r and rest_t:
            sub = r[np.ix_(rest_r, rest_t)]
            sub = np.concatenate([sub, np.zeros((len(rest_r), 1))], axis=1)
            _idle_last(sub)  # no idle task
            rr, tt = [free[a] for a in rest_r], [ready[b] for b in rest_t]
            match = greedy_match(sub, inst.robot_amounts[rr], inst.robot_payload[rr], inst.task_needs[tt],
                                 inst.task_payload[tt], None if allowed is None else allowed[np.ix_(rest_r, rest_t)],
                                 inst.task_roles[tt])
            out += [(tt[j], tuple(rr[i] for i in team)) for j, team in match.teams.items()]
            used_r |= {rest_r[i] for team in match.teams.values() for i in team}
        return Decision(tuple(out), tuple(free[a] for a in range(len(free)) if a not in used_r))


class OutOfTime(Exception):
    """A continuation passed its deadline (the rollout's budget)."""


class Until:
    """``policy`` that raises OutOfTime at its first decision that would end past
    ``deadline`` (perf_counter): when the time left is less than its slowest decision so far."""

    def __init__(self, policy: Policy, deadline: float) -> None:
        self.policy, self.deadline = policy, deadline
        self.name = getattr(policy, "name", "policy")
        self.slowest = 0.0  # seconds of its slowest decision so far

    def reset(self, instance: Instance) -> None:
        self.policy.reset(instance)

    def decide(self, state: State) -> Decision:
        t0 = time.perf_counter()
        if t0 + self.slowest > self.deadline:
            raise OutOfTime
        decision = self.policy.decide(state)
        self.slowest = max(self.slowest, time.perf_counter() - t0)
        return decision


def continue_after(state: State, decision: Decision, policy: Policy, deadline: float | None = None) -> float:
    """Makespan when ``decision`` is taken in ``state`` and ``policy`` runs the rest
    (inf if the decision would stall the schedule). OutOfTime when the continuation is
    still running at ``deadline`` (a time.perf_counter() value)."""
    s = advance(state, decision)
    if s is None:
        return math.inf
    if s.done():
        return final_makespan(s)
    runner = policy if deadline is None else Until(policy, deadline)
    return float(simulate(state.instance, runner, state=s).schedule.makespan)


class LVWSRolloutPolicy:
    """LVWS with one-step rollout (beyond the paper).

    At each decision step the candidates are LVWS's matching; the matchings with the
    learned idle column at ``wait_biases`` (voluntary waiting as the network proposes
    it); with a wait head, the matchings with its waits at ``wait_thresholds``; GRP's
    matching; with ``hold_back``, LVWS's matching with one of its subteams
    told to wait; with ``exclude``, LVWS's matching redone without one free robot (who
    waits); with ``single_tasks``, each ready task started alone, by the subteam LVWS's
    rewards match to it, every other free robot waiting. Each candidate is scored by the
    makespan reached when LVWS finishes the schedule from there (and GRP, with
    ``finish_with_grp``: the better of the two), and the shortest wins, LVWS's own on
    ties. Never worse than LVWS alone on the executor's model, at the price of one or
    two simulated schedules per distinct candidate and step.

    ``budget_ms`` (anytime): candidates are scored in the order above until the budget
    of the decision step is spent, and a continuation still running when it is spent is
    abandoned (its candidate unscored); the best fully scored candidate wins, LVWS's own
    when none was. The decision step then takes the budget plus at most one decision of
    LVWS or GRP. None: no budget.
    """

    name = "lvws_rollout"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 wait_biases: tuple[float, ...] = (-0.2, -0.1, 0.0), hold_back: bool = True,
                 exclude: bool = True, finish_with_grp: bool = True, budget_ms: float | None = None,
                 wait_thresholds: tuple[float, ...] = (0.8, 0.5), single_tasks: bool = False) -> None:
        if model is None:
            model, meta = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["lvws"])
            base_bias = float(meta.get("idle_bias", NO_VOLUNTARY_WAIT))
            threshold = meta.get("wait_threshold")
        else:
            base_bias, threshold = NO_VOLUNTARY_WAIT, None
        self.base = LVWSPolicy(model=model, idle_bias=base_bias, wait_threshold=threshold)
        self.wait_biases, self.wait_thresholds = wait_biases, wait_thresholds
        self.hold_back, self.exclude, self.finish_with_grp = hold_back, exclude, finish_with_grp
        self.single_tasks = single_tasks
        self.grp = GreedyPayloadPolicy()
        self.budget_ms = budget_ms
        self.clock: float | None = None  # when the next decision's budget starts (core.executor.Budgeted)

    def reset(self, instance: Instance) -> None:
        self.base.reset(instance)
        self.grp.reset(instance)

    def candidates(self, state: State, deadline: float | None = None) -> list[Decision]:
        """Distinct candidate decisions, LVWS's own first; past ``deadline`` (perf_counter)
        no further one is made (the left-out ones: one per free robot, at fleet scale)."""
        free = state.free_robots()
        if not free or not state.ready_tasks():
            return [Decision((), tuple(free))]
        r, wait = self.base.outputs(state)
        first = self.base.match(state, r, wait=wait)
        proposals = [self.base.match(state, r, idle_bias=b) for b in self.wait_biases]
        if wait is not None:  # the wait head's proposals, from strict to lenient
            proposals += [self.base.match(state, r, wait=wait, wait_threshold=t) for t in self.wait_thresholds]
        proposals.append(self.grp.decide(state))
        if self.hold_back:
            proposals += [Decision(tuple(a for a in first.assignments if a != held),
                                   tuple(sorted({*first.waiting, *held[1]}))) for held in first.assignments]
        if self.exclude and len(free) > 1:
            for x in free:
                if deadline is not None and time.perf_counter() > deadline:
                    break
                d = self.base.match(state, r, [i for i in free if i != x])  # x waits
                proposals.append(Decision(d.assignments, tuple(sorted({x, *d.waiting}))))
        if self.single_tasks:
            proposals += [d for task in state.ready_tasks() if (d := self.base.match(state, r, only=task)).assignments]
        out = [first]
        seen = {frozenset(first.assignments)}
        for d in proposals:
            if frozenset(d.assignments) not in seen:
                seen.add(frozenset(d.assignments))
                out.append(d)
        return out

    def score(self, state: State, decision: Decision, deadline: float | None = None) -> float:
        makespan = continue_after(state, decision, self.base, deadline)
        if self.finish_with_grp:
            makespan = min(makespan, continue_after(state, decision, self.grp, deadline))
        return makespan

    def decide(self, state: State) -> Decision:
        deadline = decision_deadline(self)
        candidates = self.candidates(state, deadline)
        if len(candidates) == 1:
            return candidates[0]
        best, best_score = candidates[0], math.inf
        for d in candidates:
            if deadline is not None and time.perf_counter() > deadline:
                break
            try:
                score = self.score(state, d, deadline)
            except OutOfTime:
                break
            if score < best_score:
                best, best_score = d, score
        return best
