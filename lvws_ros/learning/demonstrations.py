"""Expert demonstrations for imitation learning (LVWS paper, section III-C).

A demonstration is one decision step: the graph features of the state, the expert
reward matrix E and the feasibility mask X over the entries a decision reads (the free
robots x the ready tasks, last column the idle task).

Expert rewards. Let k = 1, 2, ... count the decision steps after the current one in
the expert's schedule from this state (a decision step is every distinct task end).
The immediate expert reward e_k is 1 for each task finished at step k, so the
accumulated discounted reward of an assignment, S = sum_k gamma^k e_k, is gamma^{k_j}
for the task j it finishes:

* robot i that the expert assigns to task j now:   E_ij      = gamma^{k_j};
* free robot i that the expert makes wait:         E_i,idle  = gamma^{k_i}, k_i the step
  at which the robot's next task ends (the end of the schedule if it has none);
* every other entry:                                0.

gamma = GAMMA (0.9). Earlier-finishing expert assignments thus get larger rewards, and
the greedy matching takes them first. X_ij = 1 for a free robot and a ready task the
robot can help (a needed capability, or payload), and for a free robot's idle column.

States come from the expert's own run (:func:`expert_demos`) or, for DAgger, from any
policy's run, labelled by the expert solving from each visited state
(:func:`dagger_demos`). :func:`label_instances` runs either over many instances in
parallel processes, or on a Ray cluster when given its address.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from lvws_ros.core.executor import Decision, Policy, State, simulate
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.core.subteams import TOLERANCE
from lvws_ros.errors import ConfigError, ModelError
from lvws_ros.learning.features import (
    BUSY_PAIR_FEATURES,
    LEGACY_PAIR_FEATURES,
    PAIR_FEATURES,
    TRAVEL_PAIR_FEATURES,
    GraphFeatures,
    InstanceFeatures,
)
from lvws_ros.learning.loss import Demo, feasibility_mask
from lvws_ros.policies.exact import ExactPolicy, departures, solve_exact

GAMMA = 0.9
TARGETS = ("eq12", "dense")
"""Expert targets. ``eq12``: the paper's (module docstring). ``dense`` (after Sadcher):
E_ij = gamma^((end_j - t) / d) for every task j in robot i's schedule from this state on,
the one it takes now and the later ones, d the mean task duration; a free robot the
schedule leaves idle gets gamma^((s - t) / d) on the idle column, s when its next task
sets out (the end of the schedule if none): above that task's own target, so waiting
for it is learnt where the schedule waits (Eq. 7's idle task, learned voluntary waiting)."""


def label_state(state: State, schedule: Schedule, gamma: float = GAMMA,
                started: Decision | None = None, targets: str = "eq12") -> tuple[np.ndarray, np.ndarray]:
    """E and X of one state, from a schedule that continues from it. The tasks the
    schedule assigns at this state are those whose subteam sets out now (the expert's
    left-shifted schedule), or, with ``started``, the decision taken in this state (a
    policy's own schedule, whose departures are its decisions).

    ``targets``: "eq12" (the paper's, module docstring) or "dense" (:data:`TARGETS`)."""
    if targets not in TARGETS:
        raise ValueError(f"unknown targets {targets!r}; one of {', '.join(TARGETS)}")
    inst = state.instance
    n, m = inst.num_robots, inst.num_tasks
    t = state.time
    ends = sorted({round(a.end, 9) for a in schedule.assignments if a.end > t + TOLERANCE})

    def steps_until(time: float) -> int:
        return 1 + int(np.searchsorted(ends, round(time, 9) - 1e-9))

    e = np.zeros((n, m + 1), dtype=np.float32)
    free = state.robot_available()
    assigned: set[int] = set()
    next_end = np.full(n, np.inf)
    next_leave = np.full(n, np.inf)  # dense targets: when the robot's next task sets out
    unit = float(inst.durations.mean()) if m else 1.0  # dense targets discount per mean task duration
    # the expert assigns a task at its departure: its start, or (travel) when its subteam sets out
    leave = departures(inst, schedule, state) if inst.travel is not None and started is None else {}
    now = None if started is None else {task for task, _ in started.assignments}
    for a in schedule.assignments:
        j = inst.task_index[a.task]
        robots = [inst.robot_index[r] for r in a.robots]
        assign_at = t if now is not None and j in now else leave.get(a.task, a.start)
        if abs(assign_at - t) <= TOLERANCE and np.isnan(state.task_start[j]):
            for r in robots:
                e[r, j] = gamma ** (steps_until(a.end) if targets == "eq12" else (a.end - t) / unit)
                assigned.add(r)
        elif assign_at > t + TOLERANCE:
            for r in robots:
                next_end[r] = min(next_end[r], a.end)
                if targets == "dense":  # every task later in the robot's schedule, discounted by its end
                    e[r, j] = gamma ** ((a.end - t) / unit)
                    next_leave[r] = min(next_leave[r], assign_at)
    makespan = max(ends) if ends else t
    for w in np.flatnonzero(free):
        if w not in assigned:
            if targets == "eq12":
                e[w, m] = gamma ** steps_until(next_end[w] if np.isfinite(next_end[w]) else makespan)
            else:  # left idle until its next task sets out: above that task's own target
                e[w, m] = gamma ** (((next_leave[w] if np.isfinite(next_leave[w]) else makespan) - t) / unit)
    ready = np.zeros(m, dtype=bool)
    ready[state.ready_tasks()] = True
    x = feasibility_mask(inst.robot_amounts, inst.task_needs, inst.robot_payload, inst.task_payload)
    x[:, :m] &= ready[None, :]
    if inst.travel is not None:  # with travel, only robots that can reach the task at all
        x[:, :m] &= state.reachable(range(n), range(m))
    x &= free[:, None]
    return e, x


def demo(state: State, schedule: Schedule, cache: InstanceFeatures, started: Decision | None = None,
         targets: str = "eq12") -> Demo:
    """The demonstration of ``state``: its features and E, X on the entries it reads
    (``started``, ``targets``: as :func:`label_state`)."""
    feats = cache.encode(state)
    e, x = label_state(state, schedule, started=started, targets=targets)
    cols = [*feats.task_ids[feats.cols[:-1]], state.instance.num_tasks]
    pick = np.ix_(feats.rows, cols)
    return Demo(feats, e[pick], x[pick])


def expert_demos(inst: Instance, time_limit: float = 30.0, workers: int = 2, targets: str = "eq12") -> list[Demo]:
    """Demonstrations along the expert's own schedule."""
    policy = ExactPolicy(time_limit=time_limit, workers=workers)
    run = simulate(inst, policy, record_states=True)
    cache = InstanceFeatures(inst)
    return [demo(step.state, run.schedule, cache, targets=targets) for step in run.steps if step.state is not None]


def dagger_demos(inst: Instance, policy: Policy, time_limit: float = 30.0, workers: int = 2,
                 max_states: int | None = None, targets: str = "eq12") -> list[Demo]:
    """States visited by ``policy``, each labelled by the expert solving from that state."""
    run = simulate(inst, policy, record_states=True)
    states = [s.state for s in run.steps if s.state is not None]
    if max_states is not None and len(states) > max_states:
        keep = np.linspace(0, len(states) - 1, max_states).round().astype(int)
        states = [states[k] for k in keep]
    cache = InstanceFeatures(inst)
    out = []
    for state in states:
        res = solve_exact(inst, state=state, time_limit=time_limit, workers=workers)
        assert res.schedule is not None
        out.append(demo(state, res.schedule, cache, targets=targets))
    return out


def _expert_job(args: tuple[Instance, float, int, str]) -> list[Demo]:
    return expert_demos(*args)


def run_jobs(jobs: Sequence[Any], job: Callable[[Any], Any], *, processes: int = 2, ray_address: str | None = None,
             progress: bool = True, desc: str = "labelling") -> list[Any]:
    """``job`` on every item of ``jobs``, in order: in local processes, or as Ray tasks
    when ``ray_address`` is given ("local" starts a local Ray instance)."""
    from tqdm import tqdm

    if ray_address is not None:
        try:
            import ray
        except ImportError as exc:  # optional: requirements-dev.txt has it, requirements.txt not
            raise ConfigError("--ray-address needs Ray, which is not installed: make env-dev installs it "
                              "(pinned in requirements-dev.txt), or pip install ray") from exc

        ray.init(address=None if ray_address == "local" else ray_address,
                 num_cpus=processes if ray_address == "local" else None,
                 include_dashboard=False, log_to_driver=False, ignore_reinit_error=True)
        try:
            remote = ray.remote(job)
            pending = [remote.remote(j) for j in jobs]
            with tqdm(total=len(pending), desc=f"{desc} (ray)", disable=not progress, unit="inst") as bar:
                order = {ref: k for k, ref in enumerate(pending)}
                done: dict[int, Any] = {}
                while pending:
                    ready, pending = ray.wait(pending, num_returns=1)
                    done[order[ready[0]]] = ray.get(ready[0])
                    bar.update(1)
            return [done[k] for k in range(len(jobs))]
        finally:
            ray.shutdown()
    if processes <= 1:
        return [job(j) for j in tqdm(jobs, desc=desc, disable=not progress, unit="inst")]
    with ProcessPoolExecutor(max_workers=processes) as pool:
        return list(tqdm(pool.map(job, jobs, chunksize=4), total=len(jobs), desc=desc, disable=not progress,
                         unit="inst"))


def label_instances(
    instances: Sequence[Instance],
    *,
    processes: int = 2,
    time_limit: float = 30.0,
    workers: int = 1,
    ray_address: str | None = None,
    jobs: Sequence[Any] | None = None,
    job: Callable[[Any], list[Demo]] = _expert_job,
    progress: bool = True,
    targets: str = "eq12",
) -> list[Demo]:
    """Label many instances in parallel (:func:`run_jobs`). By default each job is the
    expert's own run on one instance (``targets``: as :func:`label_state`); ``jobs``/``job``
    run other labelling (DAgger) the same way."""
    if jobs is None:
        jobs = [(inst, time_limit, workers, targets) for inst in instances]
    results = run_jobs(jobs, job, processes=processes, ray_address=ray_address, progress=progress)
    return [d for demos in results for d in demos]


DEMOS_FORMAT = "lvws-demos/3"
_ARRAYS = ("robots", "tasks", "edges", "rows", "cols", "pairs", "task_ids", "expert", "mask")


def _parts(d: Demo) -> tuple[np.ndarray, ...]:
    f = d.features
    return f.robots, f.tasks, f.edges, f.rows, f.cols, f.pairs, f.task_ids, d.expert, d.mask


def save_demos(demos: Sequence[Demo], path: str | Path, meta: dict[str, Any] | None = None) -> None:
    """Write demonstrations as a data-only ``.npz`` (no pickle): each array kind is
    flattened and concatenated over the demonstrations, with each one's shape."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {}
    for k, name in enumerate(_ARRAYS):
        parts = [_parts(d)[k] for d in demos]
        ndim = parts[0].ndim if parts else 1
        arrays[name] = np.concatenate([x.reshape(-1) for x in parts]) if parts else np.zeros(0, np.float32)
        arrays[f"{name}_shape"] = np.array([x.shape for x in parts], dtype=np.int64).reshape(len(parts), ndim)
    header = json.dumps({"format": DEMOS_FORMAT, "meta": meta or {}, "count": len(demos)})
    tmp = p.with_name(p.name + ".tmp.npz")
    np.savez_compressed(tmp, header=np.array(header), **arrays)
    tmp.replace(p)


def load_demos(path: str | Path) -> tuple[list[Demo], dict[str, Any]]:
    """Read :func:`save_demos` files with ``allow_pickle=False``: a file never runs code."""
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as data:
            header = json.loads(str(data["header"]))
            if not isinstance(header, dict) or header.get("format") != DEMOS_FORMAT:
                raise ModelError(f"{p}: not an {DEMOS_FORMAT} file")
            count, meta = int(header["count"]), dict(header["meta"])
            split: dict[str, list[np.ndarray]] = {}
            for name in _ARRAYS:
                flat, shapes = data[name], data[f"{name}_shape"]
                if len(shapes) != count:
                    raise ModelError(f"{p}: {name}: {len(shapes)} shapes for {count} demonstrations")
                sizes = [int(np.prod(shape)) for shape in shapes]
                ends = np.cumsum(sizes, dtype=np.int64)
                split[name] = [flat[e - n:e].reshape(tuple(shape)) for e, n, shape in zip(ends, sizes, shapes,
                                                                                          strict=True)]
    except (OSError, ValueError, KeyError, TypeError, IndexError, AttributeError) as exc:
        raise ModelError(f"{p}: not a readable {DEMOS_FORMAT} file ({type(exc).__name__}: {exc})") from None
    split["pairs"] = [_travel_columns(pairs, p) for pairs in split["pairs"]]
    demos = [Demo(GraphFeatures(*(split[name][k] for name in _ARRAYS[:7])), split["expert"][k], split["mask"][k])
             for k in range(count)]
    return demos, meta


def _travel_columns(pairs: np.ndarray, path: Path) -> np.ndarray:
    """Pair features as this version has them. A file written before the travel features
    (LEGACY_PAIR_FEATURES columns), before the busy-robot ones (TRAVEL_PAIR_FEATURES) or
    before the way home (BUSY_PAIR_FEATURES) gets the missing columns as zeros, which is
    what they are without travel; a state with travel (a nonzero travel column) cannot be
    completed (its instance may have had the objective "return", which the file does not
    say), and the file must be labelled again (ModelError)."""
    width = pairs.shape[-1] if pairs.ndim == 3 else -1
    if width == PAIR_FEATURES:
        return pairs
    if width == TRAVEL_PAIR_FEATURES and pairs[..., LEGACY_PAIR_FEATURES:].any():
        raise ModelError(f"{path}: travel states without the busy-robot pair features ({width} of {PAIR_FEATURES}): "
                         "written by an older version")
    if width == BUSY_PAIR_FEATURES and pairs[..., LEGACY_PAIR_FEATURES:].any():
        raise ModelError(f"{path}: travel states without the way-home pair feature ({width} of {PAIR_FEATURES}): "
                         "written by an older version")
    if width in (LEGACY_PAIR_FEATURES, TRAVEL_PAIR_FEATURES, BUSY_PAIR_FEATURES):
        pad = np.zeros((*pairs.shape[:-1], PAIR_FEATURES - width), pairs.dtype)
        return np.concatenate([pairs, pad], axis=-1)
    raise ModelError(f"{path}: pairs of shape {pairs.shape}: expected {PAIR_FEATURES} (or {BUSY_PAIR_FEATURES}, "
                     f"{TRAVEL_PAIR_FEATURES}, {LEGACY_PAIR_FEATURES}) pair features")
