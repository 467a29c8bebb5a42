"""The exact solver's makespans for evaluation tables, cached between runs."""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

from lvws_ros.core.metrics import ExpertRecord
from lvws_ros.core.problem import Instance
from lvws_ros.policies.exact import solve_exact

__all__ = ["expert_records"]


def expert_records(instances: Sequence[Instance], cache: Path | None, time_limit: float,
                   workers: int, progress: bool = True) -> dict[str, ExpertRecord]:
    """Exact makespans, reusing ``cache`` (a JSON file) for instances already solved."""
    from tqdm import tqdm

    known: dict[str, ExpertRecord] = {}
    if cache is not None and cache.is_file():
        known = {k: ExpertRecord(**v) for k, v in json.loads(cache.read_text()).items()}
    todo = [inst for inst in instances if inst.name not in known]
    for inst in tqdm(todo, desc="exact expert", disable=not progress or not todo, unit="inst"):
        res = solve_exact(inst, time_limit=time_limit, workers=workers)
        assert res.makespan is not None
        known[inst.name] = ExpertRecord(inst.name, res.status, float(res.makespan), float(res.bound), float(res.seconds))
        if cache is not None:
            cache.parent.mkdir(parents=True, exist_ok=True)
            cache.write_text(json.dumps({k: asdict(v) for k, v in sorted(known.items())}, indent=1))
    return known
