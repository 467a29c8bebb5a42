"""Metrics of the LVWS paper (section IV): makespan and suboptimality against the
exact solver, plus validity rate and decision time; evaluation tables as markdown/CSV."""

from __future__ import annotations

import csv
import io
import math
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from lvws_ros.core.executor import Policy, simulate, voluntary_waits
from lvws_ros.core.formats import instance_key
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import check_schedule
from lvws_ros.errors import PolicyError


def suboptimality(makespan: float, optimal: float) -> float:
    """Percent increase of ``makespan`` over the proven optimal makespan."""
    if optimal <= 0:
        raise ValueError(f"optimal makespan must be > 0, got {optimal!r}")
    return 100.0 * (makespan - optimal) / optimal


@dataclass(frozen=True)
class ExpertRecord:
    """The exact solver's answer for one instance (cached between evaluations)."""

    instance: str
    status: str
    makespan: float
    bound: float
    seconds: float


@dataclass(frozen=True)
class RunRecord:
    instance: str
    policy: str
    valid: bool
    makespan: float
    decisions: int
    compute_seconds: float
    error: str = ""
    voluntary_steps: int = 0  # decision steps where a free robot waits though it could start a ready task
    key: str = ""  # content hash of the instance (formats.instance_key): what expert records are keyed by


@dataclass(frozen=True)
class PolicySummary:
    policy: str
    instances: int
    valid_rate: float
    mean_makespan: float
    mean_suboptimality: float  # over instances with a proven optimum
    proven: int
    mean_decision_ms: float


def run_policy(inst: Instance, policy: Policy) -> RunRecord:
    """One run, checked against the rules of formats.md; a policy error is an invalid run.
    The policy object is reused across instances (``reset`` restores its seed)."""
    try:
        res = simulate(inst, policy, record_states=True)
    except PolicyError as exc:
        return RunRecord(inst.name, policy.name, False, math.nan, 0, 0.0, str(exc), key=instance_key(inst))
    problems = check_schedule(inst, res.schedule)
    voluntary = sum(bool(voluntary_waits(s.state, s.decision)) for s in res.steps if s.state is not None)
    return RunRecord(inst.name, policy.name, not problems, res.schedule.makespan, res.schedule.decisions,
                     res.schedule.compute_seconds, "; ".join(map(str, problems)), voluntary, instance_key(inst))


def summarize(runs: Iterable[RunRecord], experts: dict[str, ExpertRecord]) -> list[PolicySummary]:
    """Per policy; ``experts`` is keyed by :func:`~lvws_ros.core.formats.instance_key`."""
    by_policy: dict[str, list[RunRecord]] = {}
    for r in runs:
        by_policy.setdefault(r.policy, []).append(r)
    out = []
    for policy, rows in by_policy.items():
        valid = [r for r in rows if r.valid]
        proven = [r for r in valid if r.key in experts and experts[r.key].status == "optimal"]
        subs = [suboptimality(r.makespan, experts[r.key].makespan) for r in proven]
        decisions = sum(r.decisions for r in valid)
        out.append(PolicySummary(
            policy=policy,
            instances=len(rows),
            valid_rate=len(valid) / len(rows) if rows else 0.0,
            mean_makespan=statistics.fmean(r.makespan for r in valid) if valid else math.nan,
            mean_suboptimality=statistics.fmean(subs) if subs else math.nan,
            proven=len(proven),
            mean_decision_ms=1000 * sum(r.compute_seconds for r in valid) / decisions if decisions else math.nan,
        ))
    return out


HEADERS = ["policy", "instances", "valid %", "mean makespan", "suboptimality %", "proven optima", "decision ms"]


def _cells(s: PolicySummary) -> list[str]:
    return [s.policy, str(s.instances), f"{100 * s.valid_rate:.1f}", f"{s.mean_makespan:.2f}",
            f"{s.mean_suboptimality:.2f}", str(s.proven), f"{s.mean_decision_ms:.3f}"]


def to_markdown(rows: Sequence[PolicySummary]) -> str:
    lines = ["| " + " | ".join(HEADERS) + " |", "|" + "---|" * len(HEADERS)]
    lines += ["| " + " | ".join(_cells(s)) + " |" for s in rows]
    return "\n".join(lines) + "\n"


def to_csv(rows: Sequence[PolicySummary]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(HEADERS)
    writer.writerows(_cells(s) for s in rows)
    return buf.getvalue()
