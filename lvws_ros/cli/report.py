"""Report and verify recorded runs (``lvws report BAG``, ``lvws verify BAG``), ROS-free.

The schedule comes from the bag alone: the last TaskGraph gives each task's subteam and
start/end times (sim time); the executed instance takes the team's capabilities and
payloads and each task's executed duration (end - start), so the rules of formats.md
check subteam coverage (2), precedence (4), robot overlap (5) and makespan (6) of what
really happened.
"""

from __future__ import annotations

import statistics
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lvws_ros.core.executor import Decision, State, TaskStatus, voluntary_waits
from lvws_ros.core.online import (
    GraphSnapshot,
    OnlineDecision,
    OnlineScheduler,
    TeamSnapshot,
    build_instance,
    build_state,
    roles_of,
    scheduling_view,
    sent_at,
    still_pending,
    trait_pairs,
)
from lvws_ros.core.problem import Instance, Robot, Task
from lvws_ros.core.schedule import Assignment, Schedule, Violation, check_schedule
from lvws_ros.errors import BagError
from lvws_ros.registry import LEARNED_POLICIES, make_policy
from lvws_ros.ros.bag import Run, read_run

WALL_CLOCK = 1e8  # stamps beyond this are seconds since 1970, not a simulation's


@dataclass
class RunReport:
    bag: Path
    instance: Instance
    schedule: Schedule
    complete: bool
    problems: list[Violation]
    decisions: int
    policy: str
    latency_ms_p50: float
    latency_ms_p99: float
    waits: list[tuple[int, float, tuple[str, ...]]]  # (step, sim time, robots told to wait)
    subteams: list[tuple[str, tuple[str, ...]]]
    topics: dict[str, int] = field(default_factory=dict)
    # (step, sim time, robot -> ready tasks it could have started); None: inputs not in the bag
    voluntary: list[tuple[int, float, dict[str, tuple[str, ...]]]] | None = None
    # a dispatcher's run: robot -> {"sent", "succeeded", "failed", "canceled"} goal counts
    goals: dict[str, dict[str, int]] = field(default_factory=dict)

    def text(self) -> str:
        lines = [f"bag: {self.bag}", f"policy: {self.policy}; decisions: {self.decisions}; decision latency "
                 f"p50 {self.latency_ms_p50:.2f} ms, p99 {self.latency_ms_p99:.2f} ms",
                 f"tasks done: {len(self.schedule.assignments)}/{self.instance.num_tasks}"
                 + ("" if self.complete else " (incomplete run)"),
                 f"makespan: {self.schedule.makespan:.2f} s"
                 + (" (from the first state recorded)" if self.goals else " (sim time)"),
                 "valid by formats.md: " + ("yes" if not self.problems else
                                            "NO: " + "; ".join(str(p) for p in self.problems)),
                 "", "| task | robots | start | end |", "|---|---|---|---|"]
        lines += [f"| {a.task} | {'+'.join(a.robots)} | {a.start:.2f} | {a.end:.2f} |" for a in self.schedule.assignments]
        lines += ["", "subteams: " + (", ".join(f"{t} <- {'+'.join(r)}" for t, r in self.subteams) or "none")]
        waits = [f"step {s} (t={t:.2f}): {', '.join(r)}" for s, t, r in self.waits]
        lines += ["robots told to wait: " + ("; ".join(waits) if waits else "none")]
        if self.goals:
            lines += ["goals per robot (sent, succeeded, failed, canceled): " + "; ".join(
                f"{r} {g['sent']}/{g['succeeded']}/{g['failed']}/{g['canceled']}" for r, g in sorted(self.goals.items()))]
        if self.voluntary is None:
            lines += ["voluntary waits: unknown (the decisions' inputs are not all in the bag)"]
        else:
            vol = [f"step {s} (t={t:.2f}): " + ", ".join(f"{r} (could start {'/'.join(ts)})" for r, ts in w.items())
                   for s, t, w in self.voluntary]
            lines += ["voluntary waits (free, and a ready task they could start now): "
                      + ("; ".join(vol) if vol else "none")]
        return "\n".join(lines)


def executed(teams: Sequence[TeamSnapshot], graph: GraphSnapshot, name: str = "run",
             origin: float = 0.0) -> tuple[Instance, Schedule]:
    """The executed instance and schedule of the tasks the final graph holds: every robot
    any of ``teams`` had (a robot that failed for good still did its earlier work); times
    less ``origin``."""
    latest = {r.id: r for team in teams for r in team.robots}
    traits = tuple(graph.trait_names)
    robots = tuple(Robot(r.id, tuple(r.capabilities), r.payload, traits=trait_pairs(traits, r.traits))
                   for r in latest.values())
    tasks, out = [], []
    for t in graph.tasks:
        duration = t.duration
        if t.status == TaskStatus.DONE and t.start is not None and t.end is not None:
            duration = t.end - t.start
            out.append(Assignment(t.id, tuple(t.assigned_robots), t.start - origin, t.end - origin))
        tasks.append(Task(t.id, tuple(t.capabilities), t.payload, max(duration, 1e-9), tuple(t.prerequisites),
                          requires=trait_pairs(traits, t.requires), roles=roles_of(t.roles)))
    inst = Instance(name, tuple(graph.capability_names), robots, tuple(tasks), traits=traits,
                    roles=bool(graph.roles))
    return inst, Schedule.from_assignments(name, "", out)


def report_run(run: Run) -> RunReport:
    if not run.teams or not run.graphs:
        raise BagError(f"{run.path}: no team state or task graph recorded")
    graph = run.whole_graph()  # done work that retired included
    # a world on wall time (a dispatcher's: seconds since 1970) counts from its first state,
    # or from the first start when a recorder that joined late missed that state
    starts = [t.start for t in graph.tasks if t.start is not None]
    origin = min([run.teams[0].stamp, *starts]) if run.teams[0].stamp > WALL_CLOCK else 0.0
    inst, sched = executed(run.teams, graph, run.path.name, origin)
    policy = run.decisions[0].policy if run.decisions else "?"
    sched.policy = policy
    sched.decisions = len(run.decisions)
    complete = all(t.status == TaskStatus.DONE for t in graph.tasks)
    problems = check_schedule(inst, sched) if complete else []
    lat = [1000 * d.latency for d in run.decisions] or [float("nan")]
    waits = [(d.step, max(d.team_stamp, d.graph_stamp), d.waiting) for d in run.decisions if d.waiting]
    subteams = [(t, r) for d in run.decisions for t, r in d.assignments if len(r) > 1]
    return RunReport(run.path, inst, sched, complete, problems, len(run.decisions), policy,
                     statistics.median(lat), float(np.percentile(lat, 99)), waits, subteams, run.topics,
                     recorded_voluntary_waits(run), goal_counts(run.goal_events))


_GOAL_COUNTS = {0: "sent", 4: "succeeded", 2: "failed", 5: "failed", 7: "failed", 6: "canceled"}  # GoalEvent kinds


def goal_counts(events: Sequence[tuple[int, str, str]]) -> dict[str, dict[str, int]]:
    """Per robot, its goals sent, succeeded, failed (rejected, aborted, lost) and canceled."""
    out: dict[str, dict[str, int]] = {}
    for kind, _task, robot in events:
        counts = out.setdefault(robot, dict.fromkeys(("sent", "succeeded", "failed", "canceled"), 0))
        if kind in _GOAL_COUNTS:
            counts[_GOAL_COUNTS[kind]] += 1
    return out


def recorded_voluntary_waits(run: Run) -> list[tuple[int, float, dict[str, tuple[str, ...]]]] | None:
    """The voluntary waits of each recorded decision, judged in the state it was made in."""
    out = []
    try:
        for d, _, _, state in decision_inputs(run):
            inst = state.instance
            known = [(inst.task_index[t], tuple(inst.robot_index[r] for r in rs)) for t, rs in d.assignments
                     if t in inst.task_index and all(r in inst.robot_index for r in rs)]
            vol = voluntary_waits(state, Decision(tuple(known)))
            if vol:
                out.append((d.step, state.time, {inst.robots[r].id: tuple(inst.tasks[j].id for j in ts)
                                                 for r, ts in vol.items()}))
    except BagError:
        return None
    return out


def report(bag: str | Path, gantt_png: str | Path | None = None) -> RunReport:
    """Read a bag, rebuild and check its schedule, and draw its Gantt chart if asked."""
    rep = report_run(read_run(bag))
    if gantt_png is not None and rep.schedule.assignments:
        from lvws_ros.cli.gantt import plot_gantt

        plot_gantt(rep.schedule, gantt_png, rep.instance,
                   title=f"{rep.policy}: makespan {rep.schedule.makespan:.2f} s ({Path(bag).name})")
    return rep


@dataclass
class Mismatch:
    step: int
    recorded: tuple[tuple[tuple[str, tuple[str, ...]], ...], tuple[str, ...]]
    replayed: tuple[tuple[tuple[str, tuple[str, ...]], ...], tuple[str, ...]]


def decision_inputs(run: Run, ack_timeout: float = 5.0) -> Iterator[tuple[OnlineDecision, TeamSnapshot, GraphSnapshot, State]]:
    """Each recorded decision with the TeamState and TaskGraph it names and the executor
    state the scheduler built from them (tasks assigned but not yet acknowledged by the
    simulator count as running, as in the node)."""
    # A stamp names the first snapshot taken at that instant: a paused (sync) simulator
    # republishes at the same sim time once it has executed the decision.
    teams: dict[float, TeamSnapshot] = {}
    graphs: dict[float, GraphSnapshot] = {}
    for t in run.teams:
        teams.setdefault(round(t.stamp, 6), t)
    for g in run.graphs:
        graphs.setdefault(round(g.stamp, 6), g)
    pending: dict[str, tuple[tuple[str, ...], float]] = {}
    inst: Instance | None = None
    key: object = None
    for d in sorted(run.decisions, key=lambda d: d.step):
        team, graph = teams.get(round(d.team_stamp, 6)), graphs.get(round(d.graph_stamp, 6))
        if team is None or graph is None:
            raise BagError(f"{run.path}: decision {d.step} names inputs the bag does not hold "
                           f"(team {d.team_stamp}, graph {d.graph_stamp})")
        view, view_key, _ = scheduling_view(team, graph)  # as the scheduler saw it (robots may have failed)
        if inst is None or view_key != key:  # tasks or robots came or went
            inst, key = build_instance(team, view), view_key
        now = max(team.stamp, graph.stamp)
        pending = still_pending(pending, graph, now, ack_timeout, team)
        yield d, team, graph, build_state(inst, team, view, {k: v[0] for k, v in pending.items()})
        for task, robots in d.assignments:
            pending[task] = (tuple(robots), sent_at(d, now))


def verify(bag: str | Path, *, policy: str | None = None, seed: int = 0, model_path: str | None = None,
           ack_timeout: float = 5.0, beam_width: int | None = None) -> tuple[int, list[Mismatch]]:
    """Feed each recorded decision's inputs (the TeamState and TaskGraph it names) to the
    scheduler core offline; return (decisions checked, those that differ)."""
    run = read_run(bag)
    if not run.decisions:
        raise BagError(f"{run.path}: no decisions recorded on /lvws/assignments")
    name = policy or run.decisions[0].policy
    options = {"model_path": model_path, "width": beam_width} if name in LEARNED_POLICIES else {}
    online = OnlineScheduler(make_policy(name, seed=seed, **options), ack_timeout)
    bad: list[Mismatch] = []
    for k, (d, team, graph, state) in enumerate(decision_inputs(run, ack_timeout)):
        if k == 0:
            online.policy.reset(state.instance)
        online.team, online.graph = team, graph
        got = online.decide_state(state)
        rec = (tuple(sorted((t, tuple(r)) for t, r in d.assignments)), tuple(sorted(d.waiting)))
        new = (tuple(sorted(got.assignments)), tuple(sorted(got.waiting)))
        if rec != new:
            bad.append(Mismatch(d.step, rec, new))
    return len(run.decisions), bad
