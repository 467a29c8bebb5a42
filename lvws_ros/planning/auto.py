"""``auto`` as a planner: one whole plan, improved while there is time; decisions taken from it.

Two ways to run it:

* **offline** (``lvws solve --policy auto --time-limit S``): at the first decision the
  :class:`~lvws_ros.planning.planner.Planner` plans for ``time_limit`` seconds in all (less
  when it proves the plan optimal or the plan reaches the lower bound); every decision is
  then the plan's (:class:`~lvws_ros.planning.follow.PlanFollower`; should the world depart
  from it, the follower repairs it as it goes);
* **beside a node** (``background=True``, the scheduler node's ``auto``): the planner runs in
  a process of its own (:class:`~lvws_ros.planning.worker.PlannerProcess`) and never holds a
  decision up: each decision takes the newest plan that has arrived and dispatches from it at
  once (milliseconds), then hands the state after the decision to the planner, which repairs
  its plan from there and goes on improving it. Before the first plan of a cell has arrived,
  a decision waits for it at most ``first_wait`` seconds, then is GRP's (the process is
started with the policy, a node's configure, so that its imports and the model's loading
are done by then; should they not be, the first decision waits for them at most
READY_WAIT seconds more). If the planner's
  process dies, the decision is GRP's, a notice says so (the node puts it on
  ``diagnostics`` as a WARN) and the process is started again.

The per-decision search of :class:`~lvws_ros.planning.budgeted.AutoPolicy` (a budget of
``budget_ms`` per decision, searched from each decision's state) stays what ``auto`` is
when a budget is given.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

from lvws_ros.core.executor import Decision, State
from lvws_ros.core.problem import Instance
from lvws_ros.errors import PolicyError
from lvws_ros.planning import PLANNER_NICENESS
from lvws_ros.planning.follow import PlanFollower
from lvws_ros.planning.planner import Planner, PlanReport
from lvws_ros.planning.worker import PlannerProcess, PlanUpdate
from lvws_ros.policies.baselines import GreedyPayloadPolicy

DEFAULT_TIME_LIMIT = 60.0  # seconds of planning offline
FIRST_WAIT = 1.0  # seconds a decision waits for the first plan of a cell from the planner's process
READY_WAIT = 3.0  # seconds the first decision waits, at most, for that process to have started (a loaded machine)

__all__ = ["DEFAULT_TIME_LIMIT", "FIRST_WAIT", "PLANNER_NICENESS", "PlannedAutoPolicy"]


class PlannedAutoPolicy:
    """``auto`` with a planner (module docstring)."""

    name = "auto"

    def __init__(self, model_path: str | Path | None = None, seed: int = 0, time_limit: float = DEFAULT_TIME_LIMIT,
                 background: bool = False, workers: int = 8, learned: bool = True,
                 first_wait: float = FIRST_WAIT, iterations: int | None = None,
                 niceness: int = PLANNER_NICENESS) -> None:
        if time_limit < 0 or first_wait < 0:
            raise PolicyError(f"auto: the time limit and the first wait must be >= 0, got {time_limit}, {first_wait}")
        self.options: dict[str, Any] = {"model_path": model_path, "seed": seed, "workers": workers, "learned": learned}
        self.time_limit, self.iterations, self.first_wait = time_limit, iterations, first_wait
        self.niceness = niceness  # the planner's process: this far below the caller's CPU priority
        self.background = background
        self.planner = Planner(**self.options)
        self.process: PlannerProcess | None = None
        self.follower: PlanFollower | None = None
        self.grp = GreedyPayloadPolicy(priority="critical-path")
        self.report: PlanReport | None = None  # the latest plan's
        self.decided_at = 0.0  # the time of the latest decision's state (the cell's clock)
        self.notices: list[str] = []  # for the node's diagnostics
        self.fallbacks = 0  # decisions taken by GRP (no plan yet, or the planner's process gone)
        self.restarts = 0  # the planner's process started again after it died
        self.proven = False
        self.quick_makespan = float("nan")
        self.improved: dict[str, int] = {}
        self._cell: Instance | None = None
        if background:  # started now (a node's configure), so that it is ready when the cell's first state comes
            self.process = PlannerProcess(niceness=self.niceness, prepare=self._prepare, **self.options)
            self.process.start()

    def warm_up(self) -> None:
        """Wait (at most READY_WAIT seconds) until the planner's process has started and
        loaded its model: a node's configure, so that the cell's first decision does not."""
        if self.process is not None:
            self.process.wait_ready(READY_WAIT)

    @property
    def planned_makespan(self) -> float:
        return self.report.makespan if self.report is not None else float("nan")

    def reset(self, instance: Instance) -> None:
        self.grp.reset(instance)
        if not self.background:
            self.follower, self.report = None, None
            self.planner = Planner(**self.options)
        elif self.process is None:
            self.process = PlannerProcess(niceness=self.niceness, prepare=self._prepare, **self.options)
            self.process.start()

    def decide(self, state: State) -> Decision:
        self.decided_at = state.time
        if self.background:
            return self._decide_beside(state)
        if self.follower is None:
            self.report = self.planner.run(state, time_limit=None if self.iterations is not None else self.time_limit,
                                           iterations=self.iterations)
            assert self.planner.plan is not None
            self.follower = PlanFollower(self.planner.plan.schedule)
            self.proven, self.improved = self.report.proven, dict(self.report.improved)
            self.quick_makespan = self.planner.quick_makespan
        return self.follower.decide(state)

    def _prepare(self, update: PlanUpdate) -> PlanFollower:
        """A plan that arrived, made ready to follow on the cell of the latest decision
        (the planner process's receiver thread, between decisions)."""
        follower = PlanFollower(update.schedule)
        cell = self._cell
        if cell is not None:
            follower.reset(cell)
        return follower

    def _take(self, update: PlanUpdate | None) -> None:
        """Follow ``update`` when it was made from the newest state handed to the planner
        (or when there is no plan yet): a plan made from an older state has not seen the
        decisions since (the planner repairs it from the newest state and sends it again)."""
        assert self.process is not None
        if update is not None and (update.seq == self.process.sent or self.follower is None):
            ready = update.prepared if isinstance(update.prepared, PlanFollower) else None
            self.follower, self.report = ready or PlanFollower(update.schedule), update.report
            self.proven, self.improved = update.report.proven, dict(update.report.improved)

    def _decide_beside(self, state: State) -> Decision:
        if self.process is None or not self.process.alive():
            if self.process is not None:
                why = f" ({self.process.failure})" if self.process.failure else ""
                self.notices.append(f"the planner's process is gone{why}: this decision is GRP's; starting it again")
                self.process.stop()  # what is left of it: its threads and pipes
                self.restarts += 1
            self.process = PlannerProcess(niceness=self.niceness, prepare=self._prepare, **self.options)
            self.process.start()
            self._cell = None  # the new process gets the cell; the plan followed so far stays until it sends one
        self._take(self.process.latest())
        new_cell = self._cell is not state.instance
        if new_cell:
            self._cell = state.instance
            self.process.send(state)
        if self.follower is None and new_cell:  # the cell's first plan: the best within first_wait
            self.process.wait_ready(READY_WAIT)  # started with the policy: normally long ready by now
            end = time.perf_counter() + self.first_wait
            while (left := end - time.perf_counter()) > 0 and (update := self.process.latest(left)) is not None:
                self._take(update)
                if update.report.proven:
                    break
        if self.follower is None:
            self.fallbacks += 1
            decision = self.grp.decide(state)
        else:
            decision = self.follower.decide(state)
        after = state.copy()
        for task, team in decision.assignments:
            after.start(task, team)
        self.process.send(after)
        return decision

    def status_values(self) -> list[tuple[str, str]]:
        """The plan as of the latest decision, for a node's diagnostics."""
        r = self.report
        if r is None:
            return [("plan", "none yet"), ("planner_restarts", str(self.restarts))]
        return [("plan_makespan", f"{r.makespan:.3f}"), ("plan_left", f"{r.makespan - self.decided_at:.3f}"),
                ("plan_bound", f"{r.bound:.3f}"), ("plan_gap", f"{r.gap:.4f}"),
                ("plan_source", r.source), ("plan_proven", str(r.proven).lower()),
                ("planner_restarts", str(self.restarts))]

    def close(self) -> None:
        """Stop the planner's process (the node's cleanup and shutdown)."""
        if self.process is not None:
            self.process.stop()
            self.process = None
