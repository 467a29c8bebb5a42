"""Baseline scheduling policies of the LVWS paper, section IV, and the policy registry.

* ``rand``: for each ready task (random order) a random capable single free robot; a
  random minimal subteam only when no single robot can do the task.
* ``rand_subteam``: a random choice among all minimal covering robots and subteams.
* ``grp``: the robot or subteam with the smallest total payload that meets the task's
  requirements (ties: fewer robots, then lower robot indices).

All are work-conserving: they start every ready task for which free robots suffice.
Subteams are inclusion-minimal (a superset only ties up more robots, the duration
being the same); with more than 16 free robots the candidates come from
:func:`lvws_ros.subteams.shortlist`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from lvws_ros.executor import Decision, Policy, State
from lvws_ros.model import Instance
from lvws_ros.subteams import team_candidates

POLICY_NAMES = ("lvws", "lvws_rollout", "dbgm", "grp", "rand", "rand_subteam", "exact")
LEARNED_POLICIES = ("lvws", "lvws_rollout", "dbgm")  # take a model_path


def candidate_teams(state: State, task: int, free: list[int]) -> list[tuple[int, ...]]:
    """Minimal covering subteams for ``task`` among the ``free`` robots (global indices)."""
    inst = state.instance
    if not free:
        return []
    local = team_candidates(inst.robot_caps[free], inst.robot_payload[free], inst.task_caps[task], inst.tasks[task].payload)
    return [tuple(free[i] for i in team) for team in local]


class _SequentialPolicy:
    """Takes ready tasks one by one and gives each a subteam chosen by ``pick``."""

    name = "sequential"

    def __init__(self, seed: int = 0) -> None:
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    def reset(self, instance: Instance) -> None:
        self.rng = np.random.default_rng(self.seed)

    def order(self, ready: list[int]) -> list[int]:
        return ready

    def pick(self, state: State, teams: list[tuple[int, ...]]) -> tuple[int, ...]:
        raise NotImplementedError

    def decide(self, state: State) -> Decision:
        free = state.free_robots()
        out = []
        for task in self.order(state.ready_tasks()):
            teams = candidate_teams(state, task, free)
            if not teams:
                continue
            team = self.pick(state, teams)
            out.append((task, team))
            free = [r for r in free if r not in team]
        return Decision(tuple(out), tuple(free))


class GreedyPayloadPolicy(_SequentialPolicy):
    name = "grp"

    def pick(self, state: State, teams: list[tuple[int, ...]]) -> tuple[int, ...]:
        pay = state.instance.robot_payload
        return min(teams, key=lambda team: (float(pay[list(team)].sum()), len(team), team))


class RandomPolicy(_SequentialPolicy):
    name = "rand"

    def order(self, ready: list[int]) -> list[int]:
        return [ready[i] for i in self.rng.permutation(len(ready))]

    def pick(self, state: State, teams: list[tuple[int, ...]]) -> tuple[int, ...]:
        singles = [t for t in teams if len(t) == 1]
        pool = singles or teams
        return pool[int(self.rng.integers(len(pool)))]


class RandomSubteamPolicy(RandomPolicy):
    name = "rand_subteam"

    def pick(self, state: State, teams: list[tuple[int, ...]]) -> tuple[int, ...]:
        return teams[int(self.rng.integers(len(teams)))]


def make_policy(name: str, seed: int = 0, **options: Any) -> Policy:
    """A policy by its name (CLI, node parameter and tables use the same names)."""
    factories: dict[str, Callable[[], Policy]] = {
        "grp": GreedyPayloadPolicy,
        "rand": lambda: RandomPolicy(seed),
        "rand_subteam": lambda: RandomSubteamPolicy(seed),
    }
    if name == "exact":
        from lvws_ros.expert import ExactPolicy

        return ExactPolicy(seed=seed, **options)
    if name in ("lvws", "lvws_rollout", "dbgm"):
        from lvws_ros.lvws_policy import DBGMPolicy, LVWSPolicy, LVWSRolloutPolicy

        model_path = options.get("model_path") or None
        if name == "lvws_rollout":
            return LVWSRolloutPolicy(model_path=model_path)
        return LVWSPolicy(model_path=model_path) if name == "lvws" else DBGMPolicy(model_path=model_path)
    if name not in factories:
        raise ValueError(f"unknown policy {name!r}; choose one of {', '.join(POLICY_NAMES)}")
    return factories[name]()
