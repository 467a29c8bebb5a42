"""The planner: one whole plan from the current state, made at once (quick plans, the
cheapest on the cell first) and improved in rounds while there is time (CP-SAT, neighbourhoods,
sampling); the plan never gets longer unless the world does. The story, step by step:
``docs/architecture.md``, "The planner"."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.core.bounds import gap, lower_bounds
from lvws_ros.core.executor import (
    Decision,
    Policy,
    SimulationResult,
    State,
    TaskStatus,
    advance,
    schedule_from_state,
    simulate,
)
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.core.subteams import TOLERANCE
from lvws_ros.errors import ExpertError, PolicyError
from lvws_ros.learning.policies import LVWSPolicy, OutOfTime, Until
from lvws_ros.learning.sampling import DEFAULT_SAMPLES, DEFAULT_TEMPERATURE, RoundCost, sample_schedules
from lvws_ros.planning.follow import repair
from lvws_ros.planning.justify import justify, reversed_rest
from lvws_ros.policies.baselines import GreedyPayloadPolicy

EXACT_TASKS = 60  # CP-SAT on the whole rest while at most this many tasks are left to do
POOL_EXACT_TASKS = 400  # the same where the whole model is the pool model (PSPLIB's RG300: 300 activities)
SLICE = 2.0  # seconds of one improvement round (the planner looks for news between rounds)
EXACT_FIRST = 0.25  # seconds of the first CP-SAT solve of an open-ended planner (then doubled, up to SLICE)
WORK = 1.0  # CP-SAT's deterministic time of one solve when rounds are counted, not timed
LNS_WINDOWS = 4  # neighbourhoods of one LNS round when rounds are counted
SAMPLE_EVERY = 3  # every this many improvement rounds, one of LVWS sampling
PATIENCE = 8  # improvement rounds in a row without a shorter plan (a small rest): the planner stops
PATIENCE_LARGE = 40  # the same for a rest too large for CP-SAT's whole model
TEMPERATURE_TASKS = 20  # sampling_temperature: the default temperature up to this many tasks to do
AHEAD_NOISE = 0.5  # "departure": "each": noise on the list schedules' keys, in mean task durations (not tuned)
AHEAD_SAMPLES = 20  # list schedules of one such round when rounds are counted
# the justification walk (a rest too large for CP-SAT's whole model, two rounds of every
# SAMPLE_EVERY): noise on both passes' keys, in mean task durations, one drawn per pass; the walk
# goes on from a pass at most JUSTIFY_SLACK longer than the plan, else from the plan (chosen on
# warehouse instances 10 and 11, 200 x 1000, never on those the results are measured on)
JUSTIFY_NOISES = (0.5, 1.0, 2.0)
JUSTIFY_SLACK = 0.05
JUSTIFY_PASSES = 2  # passes of one walk round when rounds are counted
GRP_ROUND = 3  # offline, a round of GRP runs has time for this many where one takes longer than a slice
PROBE_DECISIONS = 3  # decision steps of a quick plan timed to estimate what it costs on the cell
PROBE_SECONDS = 0.5  # a probe stops after this long even with fewer decision steps
# a cell's first plan: once a probed quick plan projects a whole plan within this many seconds,
# the others are probed with the next quick plans, not before it (an LVWS probe at 1000 x 5000
# is one network pass over the cell, 7-8 s, which held the first plan beside a node)
FIRST_PROBE_ENOUGH = 1.0
PROJECT_AFTER = 1.0  # seconds into a quick plan before its finish is projected from its progress
PROJECT_MARGIN = 3.0  # a quick plan is given up once it projects this many times the time it had

__all__ = ["EXACT_TASKS", "Clock", "ExactState", "Plan", "PlanReport", "Planner", "sampling_temperature"]


class Clock(Enum):
    """How a planner's time is kept."""

    DEADLINE = "deadline"  # offline: it plans up to a deadline (Planner.run with a time limit)
    OPEN_ENDED = "open-ended"  # beside a node: it improves until told otherwise, a slice at a time
    COUNTED = "counted"  # rounds counted, not timed: the same seed gives the same plan


class ExactState(Enum):
    """What CP-SAT's whole model has done from the plan's state."""

    OPEN = "open"  # worth a round when its turn comes
    SHORTENING = "shortening"  # its last slice shortened the plan: the next round is its too (a longer slice)
    CLOSED = "closed"  # it proved its model's optimum: solving it again gives nothing new
    OVERRAN = "overran"  # it took far longer than its slice and shortened nothing (too large): LNS instead


def sampling_temperature(todo: int, base: float = DEFAULT_TEMPERATURE) -> float:
    """The temperature of LVWS sampling from a state with ``todo`` tasks to do: ``base``
    (chosen on the small cells of training) up to TEMPERATURE_TASKS tasks, then shrinking
    as 1 / tasks (the noise of one decision adds up over the decisions of a whole schedule:
    at fleet scale the default temperature samples only schedules worse than LVWS's own)."""
    return base * min(1.0, TEMPERATURE_TASKS / max(1, todo))


class Projected(Until):
    """``policy`` within ``deadline`` (:class:`~lvws_ros.learning.policies.Until`) that also
    gives up (OutOfTime) once, PROJECT_AFTER seconds in, the time its progress projects
    (seconds so far over the share of the tasks started) is over PROJECT_MARGIN times the
    time it had: a quick plan far too slow for the time left does not take all of it. The
    margin allows for runs whose first steps start few tasks (a deep graph), where the
    projection errs late."""

    def __init__(self, policy: Policy, deadline: float, state: State) -> None:
        super().__init__(policy, deadline)
        self.began = time.perf_counter()
        self.todo = max(1, int((state.task_status == TaskStatus.QUEUED).sum()))

    def decide(self, state: State) -> Decision:
        spent = time.perf_counter() - self.began
        if spent > PROJECT_AFTER:
            started = self.todo - int((state.task_status == TaskStatus.QUEUED).sum())
            if spent * self.todo > PROJECT_MARGIN * (self.deadline - self.began) * max(started, 0):
                raise OutOfTime
        return super().decide(state)


@dataclass
class Plan:
    """A whole schedule from ``state`` on, as the executor carries it out."""

    state: State
    schedule: Schedule
    makespan: float
    source: str  # the quick plan or improver that made it


@dataclass
class PlanReport:
    makespan: float
    bound: float
    gap: float
    source: str
    proven: bool
    seconds: float  # since the planner started from this cell
    rounds: int  # improvement rounds so far
    improved: dict[str, int] = field(default_factory=dict)  # times each improver shortened the plan
    overrun: float = 0.0  # seconds past the deadline taken to finish the first quick plan (none had finished)
    fallback: str = ""  # that quick plan's name, when it overran


class Planner:
    """Holds one plan and improves it (module docstring). ``learned``: LVWS among the quick
    plans and the sampler (False: GRP's alone, no torch at all)."""

    def __init__(self, model_path: str | Path | None = None, seed: int = 0, workers: int = 8,
                 exact_tasks: int = EXACT_TASKS, learned: bool = True, samples: int = DEFAULT_SAMPLES,
                 slice_seconds: float = SLICE, work: float = WORK) -> None:
        self.model_path, self.seed, self.workers = model_path, seed, workers
        self.exact_tasks, self.learned, self.samples, self.slice = exact_tasks, learned, samples, slice_seconds
        self.work = work  # CP-SAT's deterministic time of one solve when rounds are counted
        self._lvws: LVWSPolicy | None = None
        self.plan: Plan | None = None
        self.proven = False
        self.exact = ExactState.OPEN  # CP-SAT's whole model from the plan's state
        self.exact_rounds = 0  # CP-SAT solves from the plan's state
        self.lns_rounds = 0  # LNS rounds from the plan's state
        self.unimproved = 0  # improvement rounds in a row that did not shorten the plan
        self.lns_window: int | None = None  # the neighbourhood size LNS adapted to last (None: its default)
        self.justified: Plan | None = None  # the plan justification last started from (one pass each)
        self.walk: tuple[State, Schedule] | None = None  # where the justification walk stands, from which state
        self._reversed: tuple[State, list[int], Instance] | None = None  # the rest turned around, of which state
        self._pooled: bool | None = None  # the cell's whole model is the pool model (None: not asked yet)
        self.clock = Clock.DEADLINE
        self.bound = self.base_bound = 0.0  # the plan's lower bound; the cell's (lower_bounds)
        self.rounds = 0
        self.improved: dict[str, int] = {}
        self.rng = np.random.default_rng(seed)
        self.round_cost = RoundCost()
        self.lvws_seconds = math.inf  # what LVWS's quick plan took last (sampling costs as much per schedule)
        self.quick_makespan = math.nan  # the best quick plan's, from the latest state they were made from
        self.quick: dict[str, tuple[float, float]] = {}  # each quick plan's (makespan, seconds), latest made
        self.quick_at: dict[str, float] = {}  # when each was made, in seconds since the planner started
        self.quick_cost: dict[str, float] = {}  # each quick plan's probed seconds per decision step, on this cell
        self.quick_rate: dict[str, float] = {}  # and the tasks it started per step
        self.overrun, self.fallback = 0.0, ""  # the first quick plan finished past the deadline (by, which)
        self.started = time.perf_counter()
        self._instance: Instance | None = None
        self._quick: list[tuple[str, Callable[[], Policy]]] = [
            ("grp-critical-path", lambda: GreedyPayloadPolicy(priority="critical-path")),
            ("grp", GreedyPayloadPolicy)]
        if learned:
            self._quick.append(("lvws", self.lvws))

    @property
    def counted(self) -> bool:
        """Rounds counted, not timed (deterministic)."""
        return self.clock is Clock.COUNTED

    def lvws(self) -> LVWSPolicy:
        """The LVWS policy (loaded once, on first use)."""
        if self._lvws is None:
            self._lvws = LVWSPolicy(model_path=self.model_path)
        return self._lvws

    # -- the incumbent -------------------------------------------------------------------

    def offer(self, result: SimulationResult, state: State, source: str) -> bool:
        """Make ``result`` (a run from ``state``) the plan when it is shorter (True then)."""
        makespan = float(result.schedule.makespan)
        if self.plan is not None and self.plan.state is state and makespan >= self.plan.makespan - TOLERANCE:
            return False
        self.plan = Plan(state, result.schedule, makespan, source)
        return True

    def offer_schedule(self, schedule: Schedule, source: str) -> bool:
        """A schedule from an improver, carried out by the executor from the plan's state;
        kept when shorter."""
        assert self.plan is not None
        try:
            res = repair(self.plan.state, schedule)
        except PolicyError:
            return False
        if self.offer(res, self.plan.state, source):
            self.improved[source] = self.improved.get(source, 0) + 1
            return True
        return False

    def report(self) -> PlanReport:
        makespan = self.plan.makespan if self.plan is not None else math.nan
        bound = makespan if self.proven else self.bound
        return PlanReport(makespan, bound, gap(makespan, bound) if self.plan is not None else math.nan,
                          self.plan.source if self.plan is not None else "", self.proven,
                          time.perf_counter() - self.started, self.rounds, dict(self.improved),
                          self.overrun, self.fallback)

    # -- from a state ----------------------------------------------------------------------

    def rebase(self, state: State, deadline: float | None = None, quick: bool = True) -> bool:
        """Plan from ``state`` on: the incumbent carried out from there (its orders and
        subteams that still hold, re-timed; what is new or broken planned by GRP). On a new
        cell, or when that made the plan longer (the world departed from it), the quick
        plans are due: made here when ``quick`` (the shortest wins). Returns whether they
        were due."""
        state = state.copy()
        old = self.plan
        new_cell = self._instance is not state.instance
        if new_cell:
            self._instance = state.instance
            self.base_bound = lower_bounds(state.instance).best
            self.lns_window = None
            self._pooled = None
            self.quick_cost, self.quick_rate = {}, {}
        self.plan = None
        if old is not None:
            try:
                self.offer(repair(state, old.schedule), state, old.source)
            except PolicyError:
                pass
        due = self.plan is None or old is None or new_cell or self.plan.makespan > old.makespan + TOLERANCE
        if due:  # the world departed from the plan: CP-SAT's bound and proofs no longer hold, the search starts over
            self.proven, self.bound = False, self.base_bound
            self.exact, self.exact_rounds, self.lns_rounds, self.unimproved = ExactState.OPEN, 0, 0, 0
        if due and quick:
            self.quick_plans(state, deadline)
        if self.plan is None:  # nothing yet: the cheapest quick plan, however long it takes
            self.quick_plans(state, -math.inf)
        return due

    def quick_order(self, state: State, first: bool = False) -> list[tuple[str, Callable[[], Policy]]]:
        """The quick plans, the cheapest on this cell first: each one's cost per decision step,
        probed once per cell (:meth:`_probe`: its first decision steps from ``state``, timed)
        and kept in :attr:`quick_cost`. Ties keep the listed order. ``first`` (the cell has no
        plan yet): once one projects a whole plan within FIRST_PROBE_ENOUGH seconds, the rest
        are left unprobed (last in the order) until the next call."""
        for name, make in self._quick:
            if name in self.quick_cost:
                continue
            if first and any(self._projected(n, state) <= FIRST_PROBE_ENOUGH for n in self.quick_cost):
                continue
            self.quick_cost[name], self.quick_rate[name] = self._probe(state, make)
        return sorted(self._quick, key=lambda q: self.quick_cost.get(q[0], math.inf))

    def _projected(self, name: str, state: State) -> float:
        """Seconds a whole quick plan ``name`` from ``state`` would take by its probe."""
        return self.quick_cost[name] * len(state.tasks_to_do()) / max(self.quick_rate.get(name, 1.0), 1.0)

    def _probe(self, state: State, make: Callable[[], Policy]) -> tuple[float, float]:
        """Seconds per decision step of ``make()``'s run from ``state``: the median of its
        first PROBE_DECISIONS decision steps (at most PROBE_SECONDS), timed, taken as the
        cost of each of the steps to come (a run's first steps start the most tasks, so
        seconds per task started would flatter a policy whose every step costs the same,
        like a network's pass over the whole cell); and the tasks it started per step."""
        policy = make()
        policy.reset(state.instance)
        probe: State | None = state.copy()
        steps: list[float] = []
        started = 0
        end = time.perf_counter() + PROBE_SECONDS
        while probe is not None and len(steps) < PROBE_DECISIONS and probe.tasks_to_do() \
                and time.perf_counter() < end:
            t0 = time.perf_counter()
            try:
                decision = policy.decide(probe)
            except PolicyError:
                return math.inf, 1.0
            steps.append(time.perf_counter() - t0)
            started += len(decision.assignments)
            probe = advance(probe, decision)
        return (float(np.median(steps)), started / len(steps)) if steps else (0.0, 1.0)

    def quick_plans(self, state: State, deadline: float | None) -> None:
        """The quick plans from ``state``, cheapest first (:meth:`quick_order`), each within
        ``deadline`` (a perf_counter time; None: all of them, in the listed order), given up
        once its progress projects a finish past it (:class:`Projected`). Until one has
        finished from ``state``, the cheapest runs whatever the deadline: the time it takes
        past it is :attr:`overrun`. Made, they are offered in the listed order (ties: the
        first listed)."""
        order = self._quick if deadline is None or self.counted else self.quick_order(state, first=self.plan is None)
        made: dict[str, SimulationResult] = {}
        for name, make in order:
            planned = self.plan is not None and self.plan.state is state
            if planned and self.plan is not None and self.plan.source == name:
                continue  # made already
            have = planned or bool(made)
            if have and deadline is not None and deadline <= time.perf_counter():
                break
            res = self._quick_plan(state, name, make, deadline if have else None)
            if res is not None:
                made[name] = res
                if not have and deadline is not None:
                    self.overrun = max(0.0, time.perf_counter() - deadline)
                    self.fallback = name if self.overrun > 0 else ""
        for name, _ in self._quick:
            if name in made:
                self.offer(made[name], state, name)
        if state.instance.departure == "each":
            self._ahead_plans(state, deadline)
        if self.plan is not None:
            self.quick_makespan = self.plan.makespan

    def _quick_plan(self, state: State, name: str, make: Callable[[], Policy],
                    deadline: float | None) -> SimulationResult | None:
        """One quick plan from ``state`` (None: it would not finish by ``deadline``)."""
        t0 = time.perf_counter()
        policy = make()
        try:
            res = simulate(state.instance, policy if deadline is None else Projected(policy, deadline, state),
                           state=state)
        except (OutOfTime, PolicyError):
            return None
        if name == "lvws":
            self.lvws_seconds = time.perf_counter() - t0
            self.round_cost.add(len(state.tasks_to_do()), 1, self.lvws_seconds)
        res = self._ahead(state, res)
        self.quick[name] = (float(res.schedule.makespan), time.perf_counter() - t0)
        self.quick_at[name] = time.perf_counter() - self.started
        return res

    def _ahead_plans(self, state: State, deadline: float | None) -> None:
        """With ``"departure": "each"``, the list schedules of robots that set out on their
        own (:func:`~lvws_ros.planning.ahead.earliest_start_plan`, soonest start and soonest
        end first), each carried out by the executor from ``state``."""
        from lvws_ros.planning.ahead import earliest_start_plan

        for name, finish in (("earliest-start", False), ("earliest-finish", True)):
            if deadline is not None and time.perf_counter() >= deadline:
                return
            t0 = time.perf_counter()
            plan = earliest_start_plan(state, finish=finish, deadline=deadline)
            if plan is None:
                continue
            try:
                res = repair(state, plan)
            except PolicyError:
                continue
            self.quick[name] = (float(res.schedule.makespan), time.perf_counter() - t0)
            self.offer(res, state, name)

    @staticmethod
    def _ahead(state: State, res: SimulationResult) -> SimulationResult:
        """With ``"departure": "each"``: ``res``'s subteams and orders carried out with each
        member setting out once it is free (the quick plans give tasks to free robots only),
        when that is shorter; ``res`` otherwise."""
        if state.instance.departure != "each":
            return res
        try:
            ahead = repair(state, res.schedule)
        except PolicyError:
            return res
        return ahead if ahead.schedule.makespan < res.schedule.makespan - TOLERANCE else res

    # -- improvement -------------------------------------------------------------------------

    def improve(self, deadline: float | None = None) -> bool:
        """One improvement round within ``deadline`` (None: counted, not timed); True when
        it shortened the plan."""
        if self.plan is None or self.exhausted:
            return False
        self.rounds += 1
        state = self.plan.state
        todo = len(state.tasks_to_do())
        if not todo:
            self.proven = True
            return False
        end = time.perf_counter() + self.slice if deadline is None else min(deadline, time.perf_counter() + self.slice)
        if state.instance.departure == "each" and self.rounds % SAMPLE_EVERY == 1:
            shorter = self._sample_ahead(state, end)
        elif self.justified is not self.plan and not self._whole(todo):
            shorter = self._justify(state, self._grp_round_end(end, deadline))
        elif self.learned and self.rounds % SAMPLE_EVERY == 0 and (self.counted or self.lvws_seconds < self.slice):
            shorter = self._sample(state, todo, end)
        elif self.rounds % SAMPLE_EVERY != SAMPLE_EVERY - 1 and not self._whole(todo):
            shorter = self._walk(state, self._grp_round_end(end, deadline))
        elif self._whole(todo) and self.exact in (ExactState.OPEN, ExactState.SHORTENING) \
                and (self.exact_rounds <= self.lns_rounds or self.exact is ExactState.SHORTENING):
            shorter = self._exact(state, end, deadline)
        else:  # a larger rest, or every other round on a small one (CP-SAT's whole model may find nothing there)
            self.lns_rounds += 1
            shorter = self._lns(state, end)
        self.unimproved = 0 if shorter else self.unimproved + 1
        return shorter

    @property
    def exhausted(self) -> bool:
        """Nothing left worth trying from the plan's state (until the world departs from
        the plan): proven optimal, or PATIENCE rounds in a row shortened nothing (a rest
        small enough for CP-SAT's whole model, once CP-SAT closed it: its proofs hold only
        for its own model with travel), PATIENCE_LARGE otherwise (a larger rest, one whose
        whole model CP-SAT has not closed, or one too large to build in its slice)."""
        if self.proven or self.plan is None:
            return self.proven
        small = self._whole(len(self.plan.state.tasks_to_do())) and self.exact is ExactState.CLOSED
        return self.unimproved >= (PATIENCE if small else PATIENCE_LARGE)

    def _whole(self, todo: int) -> bool:
        """Whether CP-SAT's whole model takes rounds for a rest of ``todo`` tasks: at most
        ``exact_tasks``, or POOL_EXACT_TASKS where it is the pool model (interchangeable
        robots, no travel: a count per pool, not a robot per task, e.g. PSPLIB's J120
        proven in 16 s where neighbourhoods stayed 5.5 % above)."""
        if todo <= self.exact_tasks:
            return True
        if todo > POOL_EXACT_TASKS or self._instance is None:
            return False
        if self._pooled is None:
            from lvws_ros.core.subteams import MAX_ENUMERATED
            from lvws_ros.policies.exact import pools_apply

            self._pooled = self._instance.num_robots > MAX_ENUMERATED and pools_apply(self._instance)
        return self._pooled

    def _exact(self, state: State, end: float, deadline: float | None) -> bool:
        from lvws_ros.policies.exact import proves_executor_bound, solve_exact

        assert self.plan is not None
        # the whole rest, in slices that double from EXACT_FIRST (rounds of LNS between them), each
        # warm-started from the plan: up to the deadline, or (a planner without one) up to a round's end
        if self.counted:  # CP-SAT's deterministic time alone decides
            left = math.inf
        elif deadline is not None and self.clock is Clock.DEADLINE:
            left = min(deadline - time.perf_counter(), EXACT_FIRST * 2 ** self.exact_rounds)
        else:
            left = min(end - time.perf_counter(), EXACT_FIRST * 2 ** self.exact_rounds)
        self.exact_rounds += 1
        began = time.perf_counter()
        try:
            res = solve_exact(state.instance, state=state, time_limit=max(0.05, left) if left < math.inf else 1e9,
                              hint=self.plan.schedule,
                              workers=1 if self.counted else self.workers, seed=self.seed + self.rounds,
                              work=self.work if self.counted else None)
        except ExpertError:
            return False
        if res.schedule is None:
            return False
        shorter = self.offer_schedule(res.schedule, "exact")
        # a model that took far longer than its slice to build and shortened nothing (e.g. 20
        # robots x 50 tasks with travel: seconds to build): its rounds go to LNS from here on
        overran = left < math.inf and time.perf_counter() - began > 2 * left + EXACT_FIRST and not shorter
        self.exact = ExactState.OVERRAN if overran else ExactState.CLOSED if res.proven else \
            ExactState.SHORTENING if shorter else ExactState.OPEN
        if res.proven and proves_executor_bound(state.instance, res) \
                and abs(float(res.schedule.makespan) - self.plan.makespan) <= TOLERANCE:
            self.proven = True
        elif proves_executor_bound(state.instance, res):
            self.bound = max(self.bound, float(res.bound))
        return shorter

    def _lns(self, state: State, end: float) -> bool:
        from lvws_ros.policies.lns import ROUND_LIMIT, improve

        assert self.plan is not None
        try:
            found = improve(state.instance, self.plan.schedule, state=state, workers=1,
                            time_limit=math.inf if self.counted else max(0.0, end - time.perf_counter()),
                            max_rounds=LNS_WINDOWS if self.counted else None,
                            round_limit=self.work / LNS_WINDOWS if self.counted else ROUND_LIMIT,
                            seed=self.seed + self.rounds, bound=self.bound, window=self.lns_window)
        except ExpertError:
            return False
        self.lns_window = found.window
        return bool(found.improved) and self.offer_schedule(found.schedule, "lns")

    def _sample_ahead(self, state: State, end: float) -> bool:
        """A round of randomized list schedules of robots that set out on their own
        (:func:`~lvws_ros.planning.ahead.earliest_start_plan` with noise on its keys, soonest
        start or end first at random) until ``end`` (AHEAD_SAMPLES of them when counted);
        the shortest, carried out by the executor, offered."""
        from lvws_ros.planning.ahead import earliest_start_plan

        assert self.plan is not None
        best: Schedule | None = None
        made = 0
        while (time.perf_counter() < end) if not self.counted else made < AHEAD_SAMPLES:
            plan = earliest_start_plan(state, finish=bool(self.rng.random() < 0.5), rng=self.rng,
                                       noise=AHEAD_NOISE, deadline=None if self.counted else end)
            made += 1
            if plan is not None and (best is None or plan.makespan < best.makespan):
                best = plan
        if best is None or best.makespan >= self.plan.makespan - TOLERANCE:
            return False
        return self.offer_schedule(best, "sample")

    def _grp_round_end(self, end: float, deadline: float | None) -> float:
        """When a round of randomized GRP ends: with a deadline (offline, nothing else to
        hear), long enough for GRP_ROUND of them where one takes longer than a slice (a
        fleet cell); otherwise at the round's ``end``."""
        if deadline is None or self.clock is Clock.OPEN_ENDED:
            return end
        one = self.quick.get("grp-critical-path", (0.0, 0.0))[1]
        return max(end, min(deadline, time.perf_counter() + GRP_ROUND * one))

    def _justify(self, state: State, end: float) -> bool:
        """Justification (:mod:`~lvws_ros.planning.justify`) from the plan, pass after pass
        while each shortens it, until ``end``: once per plan, the first round after a plan
        too large for CP-SAT's whole model changed (a pass is two GRP runs)."""
        assert self.plan is not None
        self.justified = self.plan
        if not self._pass_fits(end):
            return False
        todo, backward = self._reversed_rest(state)
        shorter = False
        while True:
            try:
                res = justify(state, self.plan.schedule, backward, todo, math.inf if self.counted else end,
                              seed=int(self.rng.integers(2**31)))
            except (OutOfTime, PolicyError):
                return shorter
            if not self.offer(self._ahead(state, res), state, "justify"):
                return shorter
            self.improved["justify"] = self.improved.get("justify", 0) + 1
            self.justified, shorter = self.plan, True

    def _reversed_rest(self, state: State) -> tuple[list[int], Instance]:
        """The tasks to do from ``state`` and their :func:`reversed_rest`, made once per state."""
        if self._reversed is None or self._reversed[0] is not state:
            todo = state.tasks_to_do()
            self._reversed = (state, todo, reversed_rest(state.instance, todo))
        return self._reversed[1], self._reversed[2]

    def _pass_fits(self, end: float) -> bool:
        """Whether a justification pass (two GRP runs, as long as GRP's quick plan each)
        fits before ``end``; always when rounds are counted."""
        return self.counted or 2 * self.quick.get("grp-critical-path", (0.0, 0.0))[1] <= end - time.perf_counter()

    def _walk(self, state: State, end: float) -> bool:
        """A round of the justification walk: passes with noise (JUSTIFY_NOISES) from where
        the walk stands, until ``end`` (JUSTIFY_PASSES when counted); the walk goes on from a
        pass at most JUSTIFY_SLACK longer than the plan, else from the plan; a pass shorter
        than the plan is offered. The improver of a rest too large for CP-SAT's whole model
        (an iterated local search: a worse schedule may lead to a better one)."""
        assert self.plan is not None
        if not self._pass_fits(end):
            return False
        if self.walk is None or self.walk[0] is not state:
            self.walk = (state, self.plan.schedule)
        todo, backward = self._reversed_rest(state)
        shorter, made = False, 0
        while (time.perf_counter() < end) if not self.counted else made < JUSTIFY_PASSES:
            made += 1
            at = self.walk[1]
            try:
                res = self._ahead(state, justify(state, at, backward, todo, math.inf if self.counted else end,
                                                 float(self.rng.choice(JUSTIFY_NOISES)),
                                                 int(self.rng.integers(2**31))))
            except (OutOfTime, PolicyError):
                break
            if self.offer(res, state, "justify"):
                self.improved["justify"] = self.improved.get("justify", 0) + 1
                shorter = True
            near = res.schedule.makespan <= self.plan.makespan * (1 + JUSTIFY_SLACK)
            self.walk = (state, res.schedule if near else self.plan.schedule)
        return shorter

    def _sample(self, state: State, todo: int, end: float) -> bool:
        assert self.plan is not None
        count = self.samples if self.counted else self.round_cost.count(todo, end - time.perf_counter(), self.samples)
        if not count:
            return False
        t0 = time.perf_counter()
        try:
            found = sample_schedules(self.lvws(), state, count, sampling_temperature(todo), self.rng,
                                     deadline=None if self.counted else end)
        except PolicyError:
            return False
        if not self.counted and time.perf_counter() <= end:
            self.round_cost.add(todo, count, time.perf_counter() - t0)
        best = min(found, key=lambda s: s.makespan, default=None)
        if best is None or best.makespan >= self.plan.makespan - TOLERANCE:
            return False
        return self.offer_schedule(schedule_from_state(best.final, "lvws-sample"), "sample")

    # -- a whole run -------------------------------------------------------------------------

    def run(self, state: State, time_limit: float | None = None, iterations: int | None = None,
            on_report: Callable[[PlanReport], Any] | None = None) -> PlanReport:
        """Plan from ``state`` for ``time_limit`` seconds in all (quick plans included) or
        ``iterations`` improvement rounds (deterministic), whichever ends first; earlier
        when the plan is proven optimal or reaches the bound. ``on_report`` hears every
        improvement."""
        if time_limit is None and iterations is None:
            raise PolicyError("planner: give a time limit or a number of iterations")
        self.started = time.perf_counter()
        if iterations is not None and time_limit is None:
            self.clock = Clock.COUNTED
        elif self.clock is Clock.COUNTED:
            self.clock = Clock.DEADLINE
        deadline = None if time_limit is None else self.started + time_limit
        self.rebase(state, deadline)
        if on_report is not None:
            on_report(self.report())
        while not self.exhausted and (iterations is None or self.rounds < iterations):
            if deadline is not None and time.perf_counter() >= deadline - 0.05:
                break
            assert self.plan is not None
            if self.plan.makespan <= self.bound + TOLERANCE:
                self.proven = True  # at the lower bound: optimal
                break
            if self.improve(deadline) and on_report is not None:
                on_report(self.report())
        return self.report()
