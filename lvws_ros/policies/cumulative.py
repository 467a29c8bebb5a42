"""A plain cumulative CP-SAT model of resource-constrained project scheduling: the
reference the exact expert's pool model is measured against on PSPLIB.

It is the model a project scheduling library builds for a single-mode RCPSP (as
PyJobShop does with OR-Tools): per activity a start and a fixed-size interval, per
renewable resource one cumulative over the intervals with the demands as constants and
the capacity, precedence, and the makespan minimised; no hint and no bounds beyond the
horizon (the sum of the durations). It reads an instance in the form ``lvws import
psplib`` writes: no travel, no payload, no capabilities, no roles, each robot holding one
trait at amount 1 (a unit of that resource).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from ortools.sat.python import cp_model

from lvws_ros.core.problem import Instance
from lvws_ros.errors import ExpertError

__all__ = ["CumulativeResult", "solve_cumulative"]


@dataclass
class CumulativeResult:
    status: str  # optimal | feasible | unknown
    makespan: float | None
    bound: float
    seconds: float

    @property
    def proven(self) -> bool:
        return self.status == "optimal"


def _resources(inst: Instance) -> tuple[list[int], np.ndarray]:
    """Capacity per trait (the robots holding it) and the integer demands (M, L); an
    ExpertError when ``inst`` is not a plain RCPSP."""
    amounts = inst.robot_amounts[:, len(inst.capabilities):]
    if inst.travel is not None or inst.capabilities or inst.task_roles.any() or np.any(inst.task_payload > 0):
        raise ExpertError(f"{inst.name}: the plain cumulative model takes a project without travel, "
                          "capabilities, roles or payload")
    if not np.all(np.isin(amounts, (0.0, 1.0))) or not np.all(amounts.sum(axis=1) == 1):
        raise ExpertError(f"{inst.name}: the plain cumulative model needs each robot to hold one trait at 1")
    needs = inst.task_needs[:, len(inst.capabilities):]
    if not np.all(needs == np.round(needs)) or not np.all(inst.durations == np.round(inst.durations)):
        raise ExpertError(f"{inst.name}: the plain cumulative model needs whole demands and durations")
    return [int(c) for c in amounts.sum(axis=0)], np.round(needs).astype(np.int64)


def solve_cumulative(inst: Instance, *, time_limit: float = 60.0, workers: int = 8, seed: int = 0) -> CumulativeResult:
    """Minimise the makespan of the project ``inst`` with the plain cumulative model."""
    t0 = time.perf_counter()
    capacity, demand = _resources(inst)
    dur = [int(d) for d in np.round(inst.durations)]
    horizon = sum(dur)
    model = cp_model.CpModel()
    start = [model.new_int_var(0, horizon - d, f"S_{j}") for j, d in enumerate(dur)]
    interval = [model.new_fixed_size_interval_var(s, d, f"I_{j}") for j, (s, d) in enumerate(zip(start, dur, strict=True))]
    for k, cap in enumerate(capacity):
        users = [j for j in range(inst.num_tasks) if demand[j, k] > 0]
        if users:
            model.add_cumulative([interval[j] for j in users], [int(demand[j, k]) for j in users], cap)
    for j, pre in enumerate(inst.prerequisites):
        for p in pre:
            model.add(start[j] >= start[p] + dur[p])
    makespan = model.new_int_var(0, horizon, "C")
    model.add_max_equality(makespan, [s + d for s, d in zip(start, dur, strict=True)])
    model.minimize(makespan)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = time_limit
    solver.parameters.num_workers = workers
    solver.parameters.random_seed = seed
    code = solver.solve(model)
    seconds = time.perf_counter() - t0
    if code not in (cp_model.OPTIMAL, cp_model.FEASIBLE):
        return CumulativeResult("unknown", None, float(solver.best_objective_bound), seconds)
    status = "optimal" if code == cp_model.OPTIMAL else "feasible"
    return CumulativeResult(status, float(solver.objective_value), float(solver.best_objective_bound), seconds)
