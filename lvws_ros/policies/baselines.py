"""Baseline scheduling policies of the LVWS paper, section IV.

* ``rand``: for each ready task (random order) a random capable single free robot; a
  random minimal subteam only when no single robot can do the task.
* ``rand_subteam``: a random choice among all minimal covering robots and subteams.
* ``grp``: the robot or subteam with the smallest total payload that meets the task's
  requirements (ties: fewer robots, then lower robot indices).

All are work-conserving: they start every ready task for which free robots suffice.
Subteams are inclusion-minimal (a superset only ties up more robots, the duration
being the same); with more than 16 free robots the candidates come from
:func:`lvws_ros.core.subteams.shortlist`.
"""

from __future__ import annotations

import numpy as np

from lvws_ros.core.executor import Decision, State
from lvws_ros.core.problem import Instance
from lvws_ros.core.subteams import team_candidates


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
