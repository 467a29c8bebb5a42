"""Policies by name: the one place that knows every policy (above all of them).

The CLI, the scheduler node's ``policy`` parameter and the result tables use these
names. Each name has a factory in one table, registered with :func:`_policy`; heavy
modules (OR-Tools, torch) are imported only when their policy is made.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from lvws_ros.core.executor import Policy
from lvws_ros.errors import PolicyError

__all__ = ["LEARNED_POLICIES", "POLICY_NAMES", "make_policy"]

Factory = Callable[[int, dict[str, Any]], Policy]  # (seed, options) -> the policy
_FACTORIES: dict[str, Factory] = {}


def _policy(*names: str) -> Callable[[Factory], Factory]:
    """Register the decorated factory under ``names``."""
    def register(factory: Factory) -> Factory:
        for name in names:
            _FACTORIES[name] = factory
        return factory
    return register


def _model_path(options: dict[str, Any]) -> Any:
    """A learned policy's checkpoint: empty or None is the shipped one."""
    return options.get("model_path") or None


def _or(value: Any, default: Any) -> Any:
    return default if value is None else value


@_policy("auto")
def _auto(seed: int, options: dict[str, Any]) -> Policy:
    """The planner with ``time_limit``, ``iterations`` or ``background`` and no ``budget_ms``;
    else the search within each decision's budget."""
    if options.get("budget_ms") is None and (options.get("time_limit") is not None
                                             or options.get("iterations") is not None or options.get("background")):
        from lvws_ros.planning.auto import DEFAULT_TIME_LIMIT, FIRST_WAIT, PLANNER_NICENESS, PlannedAutoPolicy

        limit = options.get("time_limit")
        return PlannedAutoPolicy(model_path=_model_path(options), seed=seed, background=bool(options.get("background")),
                                 time_limit=DEFAULT_TIME_LIMIT if limit is None else float(limit),
                                 workers=options.get("workers") or 8, iterations=options.get("iterations"),
                                 first_wait=float(options.get("first_wait", FIRST_WAIT)),
                                 niceness=int(options.get("niceness", PLANNER_NICENESS)))
    from lvws_ros.learning.sampling import DEFAULT_SAMPLES, DEFAULT_TEMPERATURE
    from lvws_ros.planning.budgeted import DEFAULT_BUDGET_MS, AutoPolicy

    return AutoPolicy(model_path=_model_path(options), seed=seed,
                      budget_ms=_or(options.get("budget_ms"), DEFAULT_BUDGET_MS),
                      samples=_or(options.get("samples"), DEFAULT_SAMPLES),
                      temperature=_or(options.get("temperature"), DEFAULT_TEMPERATURE))


@_policy("lvws")
def _lvws(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.learning.policies import LVWSPolicy

    return LVWSPolicy(model_path=_model_path(options), matching=options.get("matching") or "greedy")


@_policy("lvws_sample")
def _lvws_sample(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.learning.sampling import DEFAULT_SAMPLES, DEFAULT_TEMPERATURE, LVWSSamplePolicy

    return LVWSSamplePolicy(model_path=_model_path(options), budget_ms=options.get("budget_ms"), seed=seed,
                            samples=_or(options.get("samples"), DEFAULT_SAMPLES),
                            temperature=_or(options.get("temperature"), DEFAULT_TEMPERATURE))


@_policy("lvws_rollout")
def _lvws_rollout(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.learning.policies import LVWSRolloutPolicy

    return LVWSRolloutPolicy(model_path=_model_path(options), budget_ms=options.get("budget_ms"))


@_policy("lvws_beam")
def _lvws_beam(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.learning.search import DEFAULT_WIDTH, LVWSBeamPolicy

    return LVWSBeamPolicy(model_path=_model_path(options), budget_ms=options.get("budget_ms"),
                          width=_or(options.get("width"), DEFAULT_WIDTH))


@_policy("dbgm")
def _dbgm(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.learning.policies import DBGMPolicy

    return DBGMPolicy(model_path=_model_path(options))


@_policy("grp")
def _grp(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.policies.baselines import GreedyPayloadPolicy

    return GreedyPayloadPolicy()


@_policy("rand")
def _rand(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.policies.baselines import RandomPolicy

    return RandomPolicy(seed)


@_policy("rand_subteam")
def _rand_subteam(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.policies.baselines import RandomSubteamPolicy

    return RandomSubteamPolicy(seed)


@_policy("exact")
def _exact(seed: int, options: dict[str, Any]) -> Policy:
    from lvws_ros.policies.exact import ExactPolicy

    return ExactPolicy(seed=seed, **options)


POLICY_NAMES = tuple(_FACTORIES)  # in the order they are registered
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
    factory = _FACTORIES.get(name)
    if factory is None:
        raise PolicyError(f"unknown policy {name!r}; choose one of {', '.join(POLICY_NAMES)}")
    return factory(seed, options)
