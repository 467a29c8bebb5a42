"""The exact solver's makespans (evaluation tables, training validation), cached between runs."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from lvws_ros.core.formats import instance_key
from lvws_ros.core.metrics import ExpertRecord
from lvws_ros.core.problem import Instance
from lvws_ros.errors import InstanceError
from lvws_ros.policies.exact import solve_exact

__all__ = ["expert_records"]


def expert_records(instances: Sequence[Instance], cache: Path | None, time_limit: float,
                   workers: int, progress: bool = True) -> dict[str, ExpertRecord]:
    """Exact makespans keyed by :func:`~lvws_ros.core.formats.instance_key` (the content,
    not the name), reusing ``cache`` (a JSON file) for instances already solved. The file
    is written after each solve, whole and atomically (a stopped run leaves the last
    complete file, and a resumed one goes on from it)."""
    from tqdm import tqdm

    known: dict[str, ExpertRecord] = {}
    if cache is not None and cache.is_file():
        try:
            known = {k: ExpertRecord(**v) for k, v in json.loads(cache.read_text()).items()}
        except (ValueError, TypeError, AttributeError) as exc:
            raise InstanceError(f"{cache}: not an expert cache ({exc}); delete it to recompute") from None
    keys = {instance_key(inst): inst for inst in instances}
    todo = [(k, inst) for k, inst in keys.items() if k not in known]
    for key, inst in tqdm(todo, desc="exact expert", disable=not progress or not todo, unit="inst"):
        res = solve_exact(inst, time_limit=time_limit, workers=workers)
        assert res.makespan is not None
        known[key] = ExpertRecord(inst.name, res.status, float(res.makespan), float(res.bound), float(res.seconds))
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            part = cache.with_name(cache.name + ".part")
            part.write_text(json.dumps({k: asdict(v) for k, v in sorted(known.items())}, indent=1))
            part.replace(cache)
    return known
