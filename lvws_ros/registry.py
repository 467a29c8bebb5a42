"""Policies by name: the one place that knows every policy (above all of them).

The CLI, the scheduler node's ``policy`` parameter and the result tables use these
names. Heavy modules (OR-Tools, torch) are imported only when their policy is made.
"""

from __future__ import annotations

from typing import Any

from lvws_ros.core.executor import Policy
from lvws_ros.errors import PolicyError

__all__ = ["LEARNED_POLICIES", "POLICY_NAMES", "make_policy"]

POLICY_NAMES = ("auto", "lvws", "lvws_sample", "lvws_rollout", "lvws_beam", "dbgm", "grp", "rand", "rand_subteam", "exact")
LEARNED_POLICIES = ("auto", "lvws", "lvws_sample", "lvws_rollout", "lvws_beam", "dbgm")  # take a model_path


def make_policy(name: str, seed: int = 0, **options: Any) -> Policy:
    """A policy by its name. ``options``: ``time_limit``/``workers`` for ``exact``,
    ``model_path`` for the learned ones (empty or None: the shipped checkpoint),
    ``budget_ms`` for ``auto``, ``lvws_rollout`` and ``lvws_sample`` (per decision step) and
    ``lvws_beam`` (per search; None: no budget), ``width`` for ``lvws_beam`` (None: its
    default), ``matching`` for ``lvws`` (greedy | exact; None: greedy), ``samples`` and
    ``temperature`` for ``lvws_sample`` (None: its defaults; its
    noise is seeded by ``seed``); the learned ones ignore the options of the others.
    ``auto`` without ``budget_ms`` but with ``time_limit`` (seconds of planning in all),
    ``iterations`` or ``background`` (its planner in a process of its own, for a node) is
    the planner (:mod:`lvws_ros.planning.auto`); with ``budget_ms`` (or neither), the search
    within each decision's budget (:mod:`lvws_ros.planning.budgeted`)."""
    if name == "grp":
        from lvws_ros.policies.baselines import GreedyPayloadPolicy

        return GreedyPayloadPolicy()
    if name in ("rand", "rand_subteam"):
        from lvws_ros.policies.baselines import RandomPolicy, RandomSubteamPolicy

        return RandomPolicy(seed) if name == "rand" else RandomSubteamPolicy(seed)
    if name == "exact":
        from lvws_ros.policies.exact import ExactPolicy

        return ExactPolicy(seed=seed, **options)
    if name in LEARNED_POLICIES:
        from lvws_ros.learning.policies import DBGMPolicy, LVWSPolicy, LVWSRolloutPolicy

        model_path = options.get("model_path") or None
        kinds: dict[str, type[LVWSPolicy | DBGMPolicy | LVWSRolloutPolicy]] = {
            "lvws": LVWSPolicy, "dbgm": DBGMPolicy, "lvws_rollout": LVWSRolloutPolicy}
        if name == "lvws_rollout":
            return LVWSRolloutPolicy(model_path=model_path, budget_ms=options.get("budget_ms"))
        if name == "auto" and options.get("budget_ms") is None \
                and (options.get("time_limit") is not None or options.get("iterations") is not None
                     or options.get("background")):
            from lvws_ros.planning.auto import DEFAULT_TIME_LIMIT, PlannedAutoPolicy

            limit = options.get("time_limit")
            return PlannedAutoPolicy(model_path=model_path, seed=seed, background=bool(options.get("background")),
                                     time_limit=DEFAULT_TIME_LIMIT if limit is None else float(limit),
                                     workers=options.get("workers") or 8, iterations=options.get("iterations"))
        if name == "auto":
            from lvws_ros.learning.sampling import DEFAULT_SAMPLES, DEFAULT_TEMPERATURE
            from lvws_ros.planning.budgeted import DEFAULT_BUDGET_MS, AutoPolicy

            budget, samples, temperature = options.get("budget_ms"), options.get("samples"), options.get("temperature")
            return AutoPolicy(model_path=model_path, seed=seed, budget_ms=DEFAULT_BUDGET_MS if budget is None else budget,
                              samples=DEFAULT_SAMPLES if samples is None else samples,
                              temperature=DEFAULT_TEMPERATURE if temperature is None else temperature)
        if name == "lvws_sample":
            from lvws_ros.learning.sampling import DEFAULT_SAMPLES, DEFAULT_TEMPERATURE, LVWSSamplePolicy

            samples, temperature = options.get("samples"), options.get("temperature")
            return LVWSSamplePolicy(model_path=model_path, budget_ms=options.get("budget_ms"), seed=seed,
                                    samples=DEFAULT_SAMPLES if samples is None else samples,
                                    temperature=DEFAULT_TEMPERATURE if temperature is None else temperature)
        if name == "lvws_beam":
            from lvws_ros.learning.search import DEFAULT_WIDTH, LVWSBeamPolicy

            return LVWSBeamPolicy(model_path=model_path, budget_ms=options.get("budget_ms"),
                                  width=DEFAULT_WIDTH if options.get("width") is None else options["width"])
        if name == "lvws":
            return LVWSPolicy(model_path=model_path, matching=options.get("matching") or "greedy")
        return kinds[name](model_path=model_path)
    raise PolicyError(f"unknown policy {name!r}; choose one of {', '.join(POLICY_NAMES)}")
