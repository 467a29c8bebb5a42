"""Sampling over LVWS (ours, beyond the paper): the ``lvws_sample`` policy.

LVWS decides each step with one greedy matching (Eqs. 7-11) on the rewards R of Eq. 6.
Sampling perturbs R and keeps the best whole schedule, as Sadcher takes the best of
noisy reward matrices and POMO the best of many starts:

* ``samples`` (K) schedules are advanced in lockstep from the current state: at each
  lockstep step the states that need a decision are encoded, the distinct ones go through
  one batched forward pass (:func:`~lvws_ros.learning.gatn.batch_decision_outputs`), and
  each schedule's matching runs on R plus Gumbel noise scaled by ``temperature``;
* a step without a plan to follow first takes LVWS's own schedule from its state
  (noise-free, alone), so the result is never longer than LVWS's (on the executor's
  model) and a plan exists early under a budget;
* the policy follows the shortest schedule found (as ``lvws_beam`` does, with
  :data:`~lvws_ros.core.executor.PLAN_DRIFT`), and at every decision step samples again
  from the state it is in, replacing the plan only by a shorter schedule: each decision
  improves on the last. When the world departs from the plan, the plan is dropped and the
  samples start afresh from the world's state.

Seeded: the same seed, state and model give the same schedules (without a budget).
``budget_ms`` (anytime): sampling rounds run until the budget of the decision step is
spent, each of at most K schedules, as many as the time left is likely to fit
(:class:`RoundCost`: schedules advanced in lockstep share each step's forward pass, so a
round of c schedules costs less than c rounds of one); a round still running then is
abandoned (its unfinished schedules are dropped), and the plan so far is followed; with
none yet, the step is LVWS's own decision. None: ``rounds`` rounds of K schedules per
decision step.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from lvws_ros.core.executor import Decision, State, advance, decision_deadline, final_makespan
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import TOLERANCE
from lvws_ros.errors import PolicyError
from lvws_ros.learning.checkpoint import DEFAULT_MODELS, load_checkpoint
from lvws_ros.learning.gatn import GATN, batch_decision_outputs
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, LVWSPolicy
from lvws_ros.learning.search import FollowedPlan, PlannedStep, StateKey, _key, _step

DEFAULT_SAMPLES = 16
DEFAULT_TEMPERATURE = 0.1  # Gumbel noise scale on R (whose expert targets lie in [0, 1])

BATCH_SHARE = 0.7  # until fitted: the share of one schedule's time its batch would share (measured, 2 cores)
SAFETY = 0.8  # rounds are sized to this share of the time left (a cut round drops its unfinished schedules)

__all__ = ["DEFAULT_SAMPLES", "DEFAULT_TEMPERATURE", "LVWSSamplePolicy", "RoundCost", "Sampled", "decision_reward",
           "sample_schedules"]


class RoundCost:
    """Seconds a sampling round is likely to take, to size rounds to a budget's time left.

    A round of ``count`` schedules from a state with ``todo`` tasks to do costs about
    ``todo * (a + b * count)``: ``a`` what each lockstep step costs once for the batch
    (the forward pass), ``b`` what it costs each schedule (its matching and encoding).
    ``a`` and ``b`` are fitted by least squares on the rounds timed so far (those that
    ended by the deadline); until two different counts have been timed, or when the
    fit is not positive, the rounds timed give ``a + b x count`` and a batch is taken to
    share :data:`BATCH_SHARE` of one schedule's time (so the first rounds grow, and the
    fit follows). Nothing timed: unknown (:meth:`count` gives the most)."""

    def __init__(self) -> None:
        self.sums = np.zeros(5)  # n, sum x, sum y, sum x^2, sum xy over rounds: x = count, y = seconds / todo

    def add(self, todo: int, count: int, seconds: float) -> None:
        x, y = float(count), seconds / max(1, todo)
        self.sums += (1.0, x, y, x * x, x * y)

    def coefficients(self) -> tuple[float, float]:
        """(a, b) in seconds per task to do: per lockstep step and batch, per schedule."""
        n, sx, sy, sxx, sxy = self.sums
        spread = n * sxx - sx * sx
        if spread > 1e-9 * max(1.0, n * sxx):
            b = (n * sxy - sx * sy) / spread
            a = (sy - b * sx) / n
            if a >= 0 and b > 0:
                return float(a), float(b)
        x0, y0 = sx / n, sy / n  # one count timed (or no usable fit): split y0 = a + b x0 by the share
        u = y0 / (BATCH_SHARE + (1 - BATCH_SHARE) * x0)
        return BATCH_SHARE * u, (1 - BATCH_SHARE) * u

    @property
    def known(self) -> bool:
        """Whether a round has been timed."""
        return bool(self.sums[0])

    def count(self, todo: int, seconds_left: float, most: int) -> int:
        """The most schedules (at most ``most``) a round from a state with ``todo`` tasks
        to do is likely to finish within :data:`SAFETY` of ``seconds_left``; 0 when not
        even one would."""
        if not self.known:
            return most
        a, b = self.coefficients()
        fits = (SAFETY * seconds_left / max(1, todo) - a) / max(b, 1e-12)
        return int(max(0.0, min(float(most), fits)))


class Sampled:
    """One sampled schedule from a state: its makespan, its decision steps (with the
    states they were taken in, when recorded), its final state, and the noise-free
    rewards R of its decisions summed over its steps (how much the policy itself likes
    it: on equally short schedules, the higher is the one closer to the policy's own)."""

    __slots__ = ("final", "makespan", "reward", "states", "steps")

    def __init__(self, makespan: float, steps: list[PlannedStep], states: list[State] | None, final: State,
                 reward: float) -> None:
        self.makespan, self.steps, self.states, self.final, self.reward = makespan, steps, states, final, reward


def decision_reward(state: State, r: np.ndarray, decision: Decision) -> float:
    """Sum of R (rows: the free robots, columns: the ready tasks) over the decision's
    robot-task entries."""
    row = {i: k for k, i in enumerate(state.free_robots())}
    col = {j: k for k, j in enumerate(state.ready_tasks())}
    return float(sum(r[row[i], col[task]] for task, team in decision.assignments for i in team))


def sample_schedules(policy: LVWSPolicy, state: State, samples: int, temperature: float,
                     rng: np.random.Generator, *, deadline: float | None = None,
                     record_states: bool = False) -> list[Sampled]:
    """``samples`` schedules from ``state``, advanced in lockstep with one batched forward
    pass per lockstep step over the distinct states that need a decision; each schedule's
    matching reads R + ``temperature`` x Gumbel noise (temperature 0: LVWS's own
    decisions). The finished ones, in the order sampled (a schedule that would stall is
    dropped, and so is every one unfinished at ``deadline``, a perf_counter value: no
    lockstep step starts that would end past it, by the slowest step so far)."""
    cache = policy.features(state.instance)
    states: dict[int, State] = {k: state.copy() for k in range(samples)}
    steps: dict[int, list[PlannedStep]] = {k: [] for k in range(samples)}
    seen: dict[int, list[State]] = {k: [] for k in range(samples)}
    liked = dict.fromkeys(range(samples), 0.0)
    done: dict[int, Sampled] = {}
    slowest = 0.0  # seconds of the slowest lockstep step so far
    while states:
        t0 = time.perf_counter()
        if deadline is not None and t0 + slowest > deadline:
            break
        need = {k: _key(s) for k, s in states.items() if s.free_robots() and s.ready_tasks()}
        distinct: dict[StateKey, int] = {}  # the distinct states, each encoded once, by first sample
        for k, key in need.items():
            distinct.setdefault(key, k)
        row = {key: n for n, key in enumerate(distinct)}
        feats = [cache.encode(states[k]) for k in distinct.values()]
        outs = batch_decision_outputs(policy.model, feats)
        for k in list(states):
            s = states[k]
            if k in need:
                r, wait = outs[row[need[k]]]
                if not np.isfinite(r).all() or (wait is not None and not np.isfinite(wait).all()):
                    raise PolicyError(f"{policy.name}: the model gave non-finite rewards at t={s.time:g}")
                noisy = r + temperature * rng.gumbel(size=r.shape) if temperature > 0 else r
                d = policy.match(s, noisy, wait=wait)
                liked[k] += decision_reward(s, r, d)
            else:
                d = Decision((), tuple(s.free_robots()))
            steps[k].append(_step(s, d))
            if record_states:
                seen[k].append(s)
            nxt = advance(s, d)
            if nxt is None:  # the decision would stall the schedule
                del states[k]
            elif nxt.done():
                done[k] = Sampled(final_makespan(nxt), steps[k], seen[k] if record_states else None, nxt,
                                  liked[k])
                del states[k]
            else:
                states[k] = nxt
        slowest = max(slowest, time.perf_counter() - t0)
    return [done[k] for k in sorted(done)]


class LVWSSamplePolicy:
    """Best of sampled LVWS schedules, sampled again at every decision step (module docstring)."""

    name = "lvws_sample"

    def __init__(self, model: GATN | None = None, model_path: str | Path | None = None,
                 samples: int = DEFAULT_SAMPLES, temperature: float = DEFAULT_TEMPERATURE, seed: int = 0,
                 budget_ms: float | None = None, rounds: int = 1, idle_bias: float | None = None) -> None:
        if samples < 1:
            raise PolicyError(f"lvws_sample: the number of samples must be at least 1, got {samples}")
        if not math.isfinite(temperature) or temperature < 0:
            raise PolicyError(f"lvws_sample: the temperature must be a finite number >= 0, got {temperature}")
        if rounds < 1:
            raise PolicyError(f"lvws_sample: the rounds per decision must be at least 1, got {rounds}")
        if model is None:
            model, meta = load_checkpoint(Path(model_path) if model_path else DEFAULT_MODELS["lvws"])
            self.base = LVWSPolicy(model=model, idle_bias=float(meta.get("idle_bias", 0.0)),
                                   wait_threshold=meta.get("wait_threshold"))
        else:  # a model without its checkpoint: no voluntary waiting unless told (as lvws_rollout)
            self.base = LVWSPolicy(model=model, idle_bias=NO_VOLUNTARY_WAIT if idle_bias is None else idle_bias)
        self.samples, self.temperature, self.seed = samples, temperature, seed
        self.budget_ms, self.rounds = budget_ms, rounds
        self.clock: float | None = None  # when the next decision's budget starts (core.executor.Budgeted)
        self.plan = FollowedPlan()
        self.rng = np.random.default_rng(seed)
        self.searches = 0  # decision steps that sampled (since reset)
        self.fallbacks = 0  # steps decided by LVWS alone: the budget was spent before any schedule was found
        # What sampling rounds cost on this machine, per task to do (sizes rounds under a
        # budget): kept across instances, whose rounds it measures alike.
        self.cost = RoundCost()

    def reset(self, instance: Instance) -> None:
        self.base.reset(instance)
        self.plan.clear()
        self.rng = np.random.default_rng(self.seed)
        self.searches = self.fallbacks = 0

    @property
    def planned_makespan(self) -> float:
        return self.plan.makespan

    def decide(self, state: State) -> Decision:
        free = state.free_robots()
        if not free or not state.ready_tasks():
            if self.plan.follows(state, self.name):
                return self.plan.pop()
            return Decision((), tuple(free))
        deadline = decision_deadline(self)
        if not self.plan.follows(state, self.name):
            self.plan.clear()
        best = self.plan.makespan if self.plan.steps else math.inf
        self.searches += 1
        rounds = [] if self.plan.steps else [(1, 0.0)]  # without a plan, LVWS's own schedule from here first
        if self.temperature > 0:
            rounds += [(self.samples, self.temperature)] * self.rounds
        k, todo = 0, len(state.tasks_to_do())
        while k < len(rounds) or (deadline is not None and self.temperature > 0):
            count, temperature = rounds[k] if k < len(rounds) else (self.samples, self.temperature)
            k += 1
            t0 = time.perf_counter()
            if deadline is not None:  # as many as the budget left is likely to fit
                count = max(1, self.cost.count(todo, deadline - t0, count))
            found = sample_schedules(self.base, state, count, temperature, self.rng, deadline=deadline)
            spent = time.perf_counter()
            if deadline is None or spent <= deadline:  # a round that ended in time: what it cost
                self.cost.add(todo, count, spent - t0)
            for s in found:
                if s.makespan < best - TOLERANCE:
                    best = s.makespan
                    self.plan.replace(state.instance, s.steps, s.makespan)
            if deadline is not None and time.perf_counter() > deadline:
                break
        if not self.plan.steps:
            self.fallbacks += 1
            return self.base.decide(state)
        return self.plan.pop()
