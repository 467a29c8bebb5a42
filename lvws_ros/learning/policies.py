"""Learned policies: LVWS (GATN rewards + subteam matching with waiting) and DBGM-style.

* ``lvws``: one GATN forward pass per decision step gives R (N x (M+1)); the rows of
  free robots and the columns of ready tasks plus the idle task go to
  :func:`~lvws_ros.core.matching.greedy_match` (Eqs. 7-11). Robots matched to the idle task
  wait. The idle column gets the checkpoint's ``idle_bias``, calibrated on held-out
  training instances (NO_VOLUNTARY_WAIT: robots wait only when no ready task needs
  them). Safety net: if every free robot chose to wait while nothing is running (which
  would stall the schedule), the matching is redone without the idle task.
* ``dbgm``: a GAT-only network (no transformer, no global context), no idle task, and
  subteams only when no single free robot can do a task: one-to-one matching by reward
  first, then subteams for the tasks left that need them.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lvws_ros.core.executor import Decision, Policy, State, TaskStatus, simulate
from lvws_ros.core.matching import greedy_match
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import covers
from lvws_ros.learning.checkpoint import DEFAULT_MODELS, load_checkpoint
from lvws_ros.learning.features import check_size, encode_state, pair_features
from lvws_ros.learning.gatn import GATN, reward_matrix
from lvws_ros.policies.baselines import GreedyPayloadPolicy

NO_VOLUNTARY_WAIT = -1e6  # idle bias that leaves waiting only to robots with nothing to do


def _idle_last(sub: np.ndarray) -> None:
    """Put the idle column below every task reward, whatever their scale: a robot then
    waits only when no ready task needs it (NO_VOLUNTARY_WAIT)."""
    sub[:, -1] = float(sub[:, :-1].min(initial=0.0)) - 1.0


class LVWSPolicy:
    name = "lvws"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 idle_bias: float | None = None) -> None:
        if model is None:
            model, meta = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["lvws"])
            idle_bias = float(meta.get("idle_bias", 0.0)) if idle_bias is None else idle_bias
        self.model = model.eval()
        self.idle_bias = 0.0 if idle_bias is None else idle_bias
        self._pairs: tuple[Instance, np.ndarray] | None = None

    def reset(self, instance: Instance) -> None:
        if self._pairs is None or self._pairs[0] is not instance:  # rollouts reset once per simulation
            check_size(instance)
            self._pairs = (instance, pair_features(instance))

    def rewards(self, state: State) -> np.ndarray:
        """R (N x (M+1)) of Eq. 6 for this decision step: one GATN forward pass, the
        reward MLP only on the free robots x the ready tasks and the idle task (the
        entries the matching reads; the others are NaN)."""
        self.reset(state.instance)
        assert self._pairs is not None
        return reward_matrix(self.model, encode_state(state, self._pairs[1]), state.free_robots(),
                             [*state.ready_tasks(), state.instance.num_tasks])

    def match(self, state: State, r: np.ndarray, free: list[int], idle_bias: float | None = None) -> Decision:
        """Eqs. 7-11 on the rows of ``free`` and the ready tasks plus the idle column."""
        inst = state.instance
        ready = state.ready_tasks()
        if not free or not ready:
            return Decision((), tuple(free))
        sub = r[np.ix_(free, [*ready, inst.num_tasks])]
        bias = self.idle_bias if idle_bias is None else idle_bias
        if bias <= NO_VOLUNTARY_WAIT:
            _idle_last(sub)
        else:
            sub[:, -1] += bias
        args = (inst.robot_caps[free], inst.robot_payload[free], inst.task_caps[ready], inst.task_payload[ready])
        match = greedy_match(sub, *args)
        if not match.teams and not (state.task_status == TaskStatus.ASSIGNED).any():
            _idle_last(sub)  # waiting now would stall: take the best task instead
            match = greedy_match(sub, *args)
        assignments = tuple((ready[j], tuple(free[i] for i in team)) for j, team in sorted(match.teams.items()))
        return Decision(assignments, tuple(free[i] for i in match.waiting))

    def decide(self, state: State) -> Decision:
        free = state.free_robots()
        if not free or not state.ready_tasks():
            return Decision((), tuple(free))
        return self.match(state, self.rewards(state), free)


class DBGMPolicy:
    name = "dbgm"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None) -> None:
        if model is None:
            model = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["dbgm"])[0]
        self.model = model.eval()

    def reset(self, instance: Instance) -> None:
        check_size(instance)

    def decide(self, state: State) -> Decision:
        inst = state.instance
        free, ready = state.free_robots(), state.ready_tasks()
        if not free or not ready:
            return Decision((), tuple(free))
        r = reward_matrix(self.model, encode_state(state), free, ready)
        out: list[tuple[int, tuple[int, ...]]] = []
        pairs = [(r[i, j], i, j) for i in free for j in ready
                 if covers(inst.robot_caps[[i]], inst.robot_payload[[i]], inst.task_caps[j], inst.tasks[j].payload)]
        used_r: set[int] = set()
        used_t: set[int] = set()
        for _, i, j in sorted(pairs, key=lambda p: -p[0]):  # one-to-one bipartite matching, best first
            if i not in used_r and j not in used_t:
                out.append((j, (i,)))
                used_r.add(i)
                used_t.add(j)
        rest_r = [i for i in free if i not in used_r]
        single = {j for _, _, j in pairs}
        rest_t = [j for j in ready if j not in used_t and j not in single]  # need a subteam
        if rest_r and rest_t:
            sub = r[np.ix_(rest_r, rest_t)]
            sub = np.concatenate([sub, np.zeros((len(rest_r), 1))], axis=1)
            _idle_last(sub)  # no idle task
            match = greedy_match(sub, inst.robot_caps[rest_r], inst.robot_payload[rest_r],
                                 inst.task_caps[rest_t], inst.task_payload[rest_t])
            out += [(rest_t[j], tuple(rest_r[i] for i in team)) for j, team in match.teams.items()]
            used_r |= {rest_r[i] for team in match.teams.values() for i in team}
        return Decision(tuple(out), tuple(i for i in free if i not in used_r))


def continue_after(state: State, decision: Decision, policy: Policy) -> float:
    """Makespan when ``decision`` is taken in ``state`` and ``policy`` runs the rest
    (inf if the decision would stall the schedule)."""
    s = state.copy()
    for task, team in decision.assignments:
        s.start(task, team)
    nxt = s.next_event_time()
    if nxt is None:
        return math.inf
    s.time, s.step = nxt, s.step + 1
    s.refresh()
    if s.done():
        return float(np.nanmax(s.task_end))
    return float(simulate(state.instance, policy, state=s).schedule.makespan)


class LVWSRolloutPolicy:
    """LVWS with one-step rollout (beyond the paper).

    At each decision step the candidates are LVWS's matching; the matchings with the
    learned idle column at ``wait_biases`` (voluntary waiting as the network proposes
    it); GRP's matching; with ``hold_back``, LVWS's matching with one of its subteams
    told to wait; with ``exclude``, LVWS's matching redone without one free robot (who
    waits). Each candidate is scored by the makespan reached when LVWS finishes the
    schedule from there (and GRP, with ``finish_with_grp``: the better of the two), and
    the shortest wins, LVWS's own on ties. Never worse than LVWS alone on the executor's
    model, at the price of one or two simulated schedules per distinct candidate and step.
    """

    name = "lvws_rollout"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 wait_biases: tuple[float, ...] = (-0.2, -0.1, 0.0), hold_back: bool = True,
                 exclude: bool = True, finish_with_grp: bool = True) -> None:
        if model is None:
            model, meta = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["lvws"])
            base_bias = float(meta.get("idle_bias", NO_VOLUNTARY_WAIT))
        else:
            base_bias = NO_VOLUNTARY_WAIT
        self.base = LVWSPolicy(model=model, idle_bias=base_bias)
        self.wait_biases = wait_biases
        self.hold_back, self.exclude, self.finish_with_grp = hold_back, exclude, finish_with_grp
        self.grp = GreedyPayloadPolicy()

    def reset(self, instance: Instance) -> None:
        self.base.reset(instance)
        self.grp.reset(instance)

    def candidates(self, state: State) -> list[Decision]:
        """Distinct candidate decisions, LVWS's own first."""
        free = state.free_robots()
        if not free or not state.ready_tasks():
            return [Decision((), tuple(free))]
        r = self.base.rewards(state)
        first = self.base.match(state, r, free)
        proposals = [self.base.match(state, r, free, b) for b in self.wait_biases]
        proposals.append(self.grp.decide(state))
        if self.hold_back:
            proposals += [Decision(tuple(a for a in first.assignments if a != held),
                                   tuple(sorted({*first.waiting, *held[1]}))) for held in first.assignments]
        if self.exclude and len(free) > 1:
            for x in free:
                d = self.base.match(state, r, [i for i in free if i != x])
                proposals.append(Decision(d.assignments, tuple(sorted({x, *d.waiting}))))
        out = [first]
        seen = {frozenset(first.assignments)}
        for d in proposals:
            if frozenset(d.assignments) not in seen:
                seen.add(frozenset(d.assignments))
                out.append(d)
        return out

    def score(self, state: State, decision: Decision) -> float:
        makespan = continue_after(state, decision, self.base)
        if self.finish_with_grp:
            makespan = min(makespan, continue_after(state, decision, self.grp))
        return makespan

    def decide(self, state: State) -> Decision:
        candidates = self.candidates(state)
        if len(candidates) == 1:
            return candidates[0]
        scores = [self.score(state, d) for d in candidates]
        return candidates[int(np.argmin(scores))]
