"""Scripted world events (``--events events.yaml``): at a sim time, add tasks, cancel a
task, fail or repair a robot. The same events reach a running ``cell_sim`` through its
services (``lvws submit / cancel / fault``).

File format (YAML; a list, or a mapping with an ``events`` list)::

    events:
      - {at: 12.0, fail: jackal_1}          # the robot stops; its task returns READY
      - {at: 40.0, repair: jackal_1}
      - {at: 5.0, cancel: t12}              # a task not done; dependents stop waiting for it
      - at: 20.0
        submit:                              # entries like config/assembly_cell.yaml's tasks
          - {id: t15, type: transport, object: obj3, from: cell_3, to: cell_1, after: [t05]}

Every problem is a :class:`~lvws_ros.errors.ConfigError` naming the file and the event.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from lvws_ros.errors import ConfigError
from lvws_ros.sim.config import read_yaml
from lvws_ros.sim.world import CellSim, Event

if TYPE_CHECKING:
    from lvws_ros.sim.instance_sim import InstanceSim

__all__ = ["KINDS", "WorldEvent", "apply_event", "load_events", "may_unblock", "stuck_reason"]

KINDS = ("submit", "cancel", "fail", "repair")


@dataclass(frozen=True)
class WorldEvent:
    at: float  # sim seconds
    kind: str  # one of KINDS
    target: str = ""  # cancel: the task; fail / repair: the robot
    tasks: tuple[dict[str, Any], ...] = ()  # submit: the task entries


def _event(k: int, item: Any) -> WorldEvent:
    what = f"event {k}"
    if not isinstance(item, dict):
        raise ConfigError(f"{what}: expected a mapping like {{at: 10.0, fail: jackal_1}}, got {item!r}")
    at = item.get("at")
    if isinstance(at, bool) or not isinstance(at, (int, float)) or not math.isfinite(at) or at < 0:
        raise ConfigError(f"{what}: 'at' must be a sim time >= 0, got {at!r}")
    kinds = [kind for kind in KINDS if kind in item]
    extra = sorted(set(item) - {"at", *KINDS})
    if len(kinds) != 1 or extra:
        raise ConfigError(f"{what}: expected 'at' and exactly one of {', '.join(KINDS)}, got {sorted(item)}")
    kind = kinds[0]
    value = item[kind]
    if kind == "submit":
        if not isinstance(value, list) or not value or not all(isinstance(t, dict) for t in value):
            raise ConfigError(f"{what}: 'submit' must be a non-empty list of task entries")
        return WorldEvent(float(at), kind, tasks=tuple(value))
    if not isinstance(value, str) or not value:
        raise ConfigError(f"{what}: {kind!r} must name a {'task' if kind == 'cancel' else 'robot'}, got {value!r}")
    return WorldEvent(float(at), kind, target=value)


def load_events(path: str | Path) -> list[WorldEvent]:
    """The events of a file, in time order (stable for equal times)."""
    p = Path(path)
    data = read_yaml(p, "events file")
    items = data.get("events") if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise ConfigError(f"{p}: expected a list of events (or a mapping with an 'events' list)")
    try:
        events = [_event(k, item) for k, item in enumerate(items)]
    except ConfigError as exc:
        raise ConfigError(f"{p}: {exc}") from None
    return sorted(events, key=lambda e: e.at)


def apply_event(sim: CellSim | InstanceSim, event: WorldEvent) -> list[Event]:
    """Apply one event to the world (WorldEventRejected when the world refuses it)."""
    if event.kind == "submit":
        return sim.submit(event.tasks)
    if event.kind == "cancel":
        return sim.cancel(event.target)
    return sim.fail(event.target) if event.kind == "fail" else sim.repair(event.target)


def may_unblock(events: list[WorldEvent]) -> bool:
    """Whether a later event may still make an impossible task possible (a repair) or
    take it away (a cancel)."""
    return any(e.kind in ("repair", "cancel") for e in events)


def stuck_reason(sim: CellSim | InstanceSim, later: list[WorldEvent]) -> str:
    """Why the run can never finish ('' while it can): tasks the robots left can never do,
    with no later event that could change that."""
    impossible = sim.impossible()
    if not impossible or may_unblock(later):
        return ""
    return "can never finish: " + "; ".join(f"{t}: {why}" for t, why in sorted(impossible.items())) + \
        (f" (failed: {', '.join(sorted(sim.failed))})" if sim.failed else "")
