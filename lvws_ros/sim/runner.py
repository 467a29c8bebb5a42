"""Run the case study in-process with a policy (no ROS): ``lvws sim``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

from lvws_ros.core.executor import Policy, simulate
from lvws_ros.core.online import OnlineDecision, OnlineScheduler
from lvws_ros.core.schedule import Schedule
from lvws_ros.errors import PolicyError, WorldStuck
from lvws_ros.sim.config import CellConfig
from lvws_ros.sim.events import WorldEvent, apply_event, stuck_reason
from lvws_ros.sim.world import CellSim

__all__ = ["TravelComparison", "compare_travel", "run_offline"]


def run_offline(sim: CellSim, policy: Policy, *, max_time: float = 3600.0,
                frame_every: float | None = None,
                events: list[WorldEvent] | None = None) -> tuple[Schedule, list[OnlineDecision]]:
    """Run the case study with ``policy`` in-process (no ROS), through the same
    :class:`~lvws_ros.core.online.OnlineScheduler` the scheduler node uses; ``events``
    (time order) change the world on the way. WorldStuck when the world can never finish."""
    online = OnlineScheduler(policy)
    decisions: list[OnlineDecision] = []
    later = list(events or [])
    next_frame = 0.0
    changed = True
    while not sim.done:
        if sim.time > max_time:
            raise PolicyError(f"case study not finished after {max_time:g} s of sim time "
                               f"(status {sim.status})")
        while later and later[0].at <= sim.time + 1e-9:
            apply_event(sim, later.pop(0))
            changed = True
        if changed and (reason := stuck_reason(sim, later)):
            raise WorldStuck(f"t={sim.time:.2f}: {reason}")
        if changed:
            online.offer_team(sim.team_snapshot())
            online.offer_graph(sim.graph_snapshot())
            d = online.decide()
            online.notices.clear()  # nobody reads them here (the node reports them)
            online.changes.clear()
            if d is not None:
                decisions.append(d)
                for task, robots in d.assignments:
                    sim.assign(task, robots)
        if frame_every is not None and sim.time >= next_frame - 1e-9:
            sim.record_frame()
            next_frame += frame_every
        changed = bool(sim.step())
    if frame_every is not None:
        sim.record_frame()
    latency = sum(d.latency for d in decisions)
    return sim.schedule(policy.name, len(decisions), latency), decisions


@dataclass(frozen=True)
class TravelComparison:
    """One policy on a cell with ``plan_travel``: its plan, what the world executed of it,
    and what a scheduler told nothing of the travel executes in the same world."""

    policy: str
    plan: float  # makespan of the policy in the executor on the cell's instance (travel in the plan)
    executed: float  # in the simulator, the scheduler given the travel
    blind: float  # in the simulator, the scheduler given no travel (the paper's instance)

    @property
    def plan_error(self) -> float:
        """(executed - plan) / plan: how closely the world follows the plan."""
        return (self.executed - self.plan) / self.plan if self.plan > 0 else 0.0


def compare_travel(cfg: CellConfig, policies: Sequence[tuple[str, Callable[[], Policy]]], noise: float = 0.0,
                   noise_seed: int = 0) -> list[TravelComparison]:
    """Each (name, policy maker) planned in the executor and run twice in the simulator,
    told the travel and not (``CellSim.share_travel``); the cell must plan with travel.
    With ``noise``, the world's durations depart from the plan's (``CellSim``)."""
    rows = []
    for name, make in policies:
        aware = CellSim(cfg, noise=noise, noise_seed=noise_seed)
        if aware.inst.travel is None:
            raise PolicyError(f"{cfg.name}: the cell does not plan with travel (plan_travel: false)")
        plan = simulate(aware.inst, make()).schedule.makespan
        executed = run_offline(aware, make())[0].makespan
        blind = run_offline(CellSim(cfg, share_travel=False, noise=noise, noise_seed=noise_seed), make())[0].makespan
        rows.append(TravelComparison(name, plan, executed, blind))
    return rows
