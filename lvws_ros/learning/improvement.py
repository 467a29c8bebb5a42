"""Self-improvement training (ours, after SLIM's self-labelling and Gumbeldore): ``lvws train --improve``.

Imitation learns one demonstrated decision per state from an expert whose many optimal
schedules clash with each other, and which the matching cannot always express. Each
round of self-improvement instead labels the policy's own best schedules:

* for every training instance, candidates: LVWS's own schedule, ``samples`` schedules
  sampled from the current policy (:func:`~lvws_ros.learning.sampling.sample_schedules`,
  Gumbel noise on R), optionally the beam search's schedule (``beam_width``) and the
  expert's (CP-SAT within ``expert_time_limit``);
* the shortest is kept; on a tie the policy's own is preferred (a label it can reach):
  LVWS's own schedule first, then the sample whose decisions the noise-free R rewards
  most, then the search's, then the expert's;
* the states along it are labelled with E and X of Eq. 12, the decisions as taken
  (:func:`~lvws_ros.learning.demonstrations.label_state`), and the model is fine-tuned on
  them;
* the round is kept only if LVWS's mean suboptimality (one pass, greedy) on the
  validation instances with proven optima improves; otherwise the next round starts
  again from the best model with other samples.

Self-labelling needs no proof, so the training instances may be larger than the expert
can prove (``large``: the training mixture at 20-60 robots x 50-200 tasks). With
``per_round``, each round samples on that many training instances drawn afresh. Every round
is written to ``<out>.improve.pt`` (weights, round, history): a run stopped anywhere
resumes from the last finished round (each round's model, kept or not, is
``<out>.roundN.pt``). With ``replay`` every round trains on all labels so far; at most
``states_per_instance`` states are labelled per instance, spread over its schedule, so
a large instance weighs as a few small ones. With ``improved_only``, an instance whose
best candidate is LVWS's own schedule is not labelled (it would teach what LVWS does).
"""

from __future__ import annotations

import copy
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lvws_ros.core.executor import Decision, State, advance, final_makespan, schedule_from_state, simulate
from lvws_ros.core.families import TEST_OFFSET, family_instance
from lvws_ros.core.formats import instance_key
from lvws_ros.core.problem import Instance
from lvws_ros.errors import ConfigError
from lvws_ros.learning.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from lvws_ros.learning.demonstrations import Demo, demo, run_jobs
from lvws_ros.learning.features import InstanceFeatures
from lvws_ros.learning.gatn import GATN, GATNConfig
from lvws_ros.learning.policies import LVWSPolicy
from lvws_ros.learning.sampling import DEFAULT_TEMPERATURE, sample_schedules
from lvws_ros.learning.training import TrainConfig, train, validation_makespans

LARGE_ROBOTS = (20, 60)
LARGE_TASKS = (50, 200)
LARGE_OFFSET = 500_000  # indices of the large training instances (below the families' test indices)
KINDS = ("lvws", "sample", "beam", "expert")  # candidate kinds, in the order preferred on ties


@dataclass
class ImproveConfig:
    rounds: int = 3
    samples: int = 16  # K
    temperature: float = DEFAULT_TEMPERATURE
    beam_width: int = 0  # the search's schedule as a candidate (0: none)
    expert_time_limit: float = 0.0  # the expert's schedule as a candidate (0: none) [s]
    large: int = 0  # training instances of the mixture at LARGE_ROBOTS x LARGE_TASKS
    per_round: int = 0  # training instances drawn afresh for each round (0: all of them every round)
    states_per_instance: int = 24  # labelled states per instance, spread over its schedule (0: all)
    replay: bool = True  # train on the labels of every round so far, not only this round's
    improved_only: bool = False  # label only instances whose best candidate is shorter than LVWS's own schedule
    epochs: int = 4  # fine-tuning epochs per round
    lr: float = 5e-4
    seed: int = 0
    processes: int = 2
    ray_address: str | None = None
    validation_time_limit: float = 10.0  # CP-SAT per validation instance, to prove its optimum
    targets: str = "eq12"  # the labels' targets: eq12 | dense (lvws_ros.learning.demonstrations.TARGETS)
    train: TrainConfig = field(default_factory=TrainConfig)


def large_instances(count: int, seed: int) -> list[Instance]:
    """``count`` instances of the training mixture at 20-60 robots x 50-200 tasks."""
    rng = np.random.default_rng([seed, LARGE_OFFSET])
    out = []
    for k in range(count):
        n = int(rng.integers(LARGE_ROBOTS[0], LARGE_ROBOTS[1] + 1))
        m = int(rng.integers(LARGE_TASKS[0], LARGE_TASKS[1] + 1))
        out.append(family_instance("mixed", LARGE_OFFSET + k, seed, num_robots=n, num_tasks=m))
    assert LARGE_OFFSET + count < TEST_OFFSET
    return out


@dataclass(frozen=True)
class Candidate:
    kind: str  # one of KINDS
    makespan: float
    liked: float  # noise-free R summed over the decisions (policy's own kinds; 0 otherwise)
    states: list[State]
    decisions: list[Decision]
    final: State


def _replay(state: State, decisions: Sequence[Decision]) -> tuple[list[State], State]:
    """The states in which ``decisions`` are taken from ``state`` on, and the last one."""
    states, s = [], state
    for d in decisions:
        states.append(s)
        nxt = advance(s, d)
        if nxt is None:
            raise ValueError("a planned decision stalls")
        s = nxt
    return states, s


def choose(candidates: Sequence[Candidate]) -> Candidate:
    """The shortest; on ties (makespans within 1e-9, relative) the policy's own first
    (KINDS order), then the one whose decisions R rewards most."""
    best = min(c.makespan for c in candidates)
    tied = [c for c in candidates if c.makespan <= best + 1e-9 * max(1.0, abs(best))]
    return min(tied, key=lambda c: (KINDS.index(c.kind), -c.liked))


def candidates(inst: Instance, policy: LVWSPolicy, cfg: ImproveConfig, rng: np.random.Generator) -> list[Candidate]:
    """Every candidate schedule of one instance (module docstring)."""
    start = State.initial(inst)
    out: list[Candidate] = []
    for kind, count, temperature in (("lvws", 1, 0.0), ("sample", cfg.samples, cfg.temperature)):
        for s in sample_schedules(policy, start, count, temperature, rng, record_states=True):
            assert s.states is not None
            out.append(Candidate(kind, s.makespan, s.reward, s.states, [p.decision for p in s.steps], s.final))
    if cfg.beam_width > 0:
        from lvws_ros.learning.search import LVWSBeamPolicy

        beam = LVWSBeamPolicy(model=policy.model, width=cfg.beam_width)
        beam.reset(inst)
        plan = [p.decision for p in beam.search(start)]
        if plan:
            states, final = _replay(start, plan)
            out.append(Candidate("beam", final_makespan(final), 0.0, states, plan, final))
    if cfg.expert_time_limit > 0:
        from lvws_ros.policies.exact import ExactPolicy

        run = simulate(inst, ExactPolicy(time_limit=cfg.expert_time_limit, workers=1), record_states=True)
        states = [r.state for r in run.steps if r.state is not None]
        final = _replay(start, [r.decision for r in run.steps])[1]
        out.append(Candidate("expert", run.schedule.makespan, 0.0, states, [r.decision for r in run.steps], final))
    return out


def label(inst: Instance, chosen: Candidate, targets: str = "eq12", max_states: int = 0) -> list[Demo]:
    """Demonstrations along ``chosen``: each state with a decision to make, labelled by
    the schedule with the decision taken there (``targets``: eq12 | dense); at most
    ``max_states`` of them, spread over the schedule (0: all)."""
    cache = InstanceFeatures(inst)
    schedule = schedule_from_state(chosen.final, chosen.kind)
    steps = [(s, d) for s, d in zip(chosen.states, chosen.decisions, strict=True) if s.free_robots() and s.ready_tasks()]
    if 0 < max_states < len(steps):  # spread over the schedule: a large instance weighs as a few small ones
        steps = [steps[k] for k in np.linspace(0, len(steps) - 1, max_states).round().astype(int)]
    return [demo(s, schedule, cache, started=d, targets=targets) for s, d in steps]


def _round_job(args: tuple[Instance, dict[str, Any], dict[str, Any], float, dict[str, Any], int]
               ) -> tuple[list[Demo], dict[str, float]]:
    inst, state_dict, model_cfg, idle_bias, cfg_dict, seed = args
    torch.set_num_threads(1)  # one process per core
    model = GATN(GATNConfig.from_dict(model_cfg))
    model.load_state_dict(state_dict)
    cfg = ImproveConfig(**{k: v for k, v in cfg_dict.items() if k != "train"})
    policy = LVWSPolicy(model=model.eval(), idle_bias=idle_bias, wait_threshold=None)
    found = candidates(inst, policy, cfg, np.random.default_rng(seed))
    chosen = choose(found)
    best = {k: min((c.makespan for c in found if c.kind == k), default=math.nan) for k in KINDS}
    demos = [] if cfg.improved_only and chosen.kind == "lvws" else label(inst, chosen, cfg.targets,
                                                                          cfg.states_per_instance)
    return demos, {**best, "chosen": float(KINDS.index(chosen.kind))}


def validation_optima(instances: Sequence[Instance], time_limit: float, cache_dir: str | Path | None,
                      log: Callable[[str], None]) -> dict[str, float]:
    """Proven optima of the validation instances (those CP-SAT proves within
    ``time_limit``; the others are left out of the score), kept in ``cache_dir``."""
    return {k: makespan for k, (makespan, proven) in
            validation_makespans(instances, time_limit, 8, cache_dir, log).items() if proven}


def validation_score(model: GATN, instances: Sequence[Instance], optima: dict[str, float], idle_bias: float) -> float:
    """LVWS's mean suboptimality (%) over the validation instances with proven optima."""
    policy = LVWSPolicy(model=model, idle_bias=idle_bias, wait_threshold=None)
    subs = [100 * (simulate(inst, policy).schedule.makespan - optima[k]) / optima[k]
            for inst in instances if (k := instance_key(inst)) in optima]
    return statistics.fmean(subs) if subs else math.inf


def improve(init: str | Path, train_set: Sequence[Instance], val_set: Sequence[Instance], cfg: ImproveConfig,
            out: str | Path, *, cache_dir: str | Path | None = None, resume: str | Path | None = None,
            progress: bool = True, log: Callable[[str], None] = print) -> tuple[GATN, dict[str, Any]]:
    """Rounds of self-improvement from the checkpoint ``init`` (module docstring); the
    best model is written to ``out``, each round's state to ``<out>.improve.pt``."""
    model, meta = load_checkpoint(init)
    if model.wait is not None:
        raise ConfigError(f"{init}: self-improvement labels the matching's decisions; a model with a wait head is "
                          "not supported")
    idle_bias = float(meta.get("idle_bias", 0.0))
    state_path = Path(out).with_suffix(".improve.pt")
    optima = validation_optima(val_set, cfg.validation_time_limit, cache_dir, log)
    if not train_set:
        raise ConfigError("self-improvement: no training instances (give datasets, families, --instances or --large)")
    if not optima:
        raise ConfigError(f"self-improvement: none of the {len(val_set)} validation instances has a proven optimum "
                          f"(CP-SAT, {cfg.validation_time_limit:g} s each): no round could be kept")
    best_score = validation_score(model, val_set, optima, idle_bias)
    history: list[dict[str, Any]] = [{"round": 0, "validation_suboptimality": best_score, "kept": True}]
    first = 1
    if resume is not None:
        data = read_checkpoint(resume)
        model.load_state_dict(data["state_dict"])
        history = list(data["meta"]["improve_history"])
        best_score = float(data["meta"]["validation_suboptimality"])
        first = int(data["epoch"]) + 1
        log(f"resumed from {resume} after round {first - 1} (validation {best_score:.2f} %)")
    log(f"self-improvement from {init}: {len(train_set)} training instances, {len(optima)} validation optima; "
        f"round 0: LVWS {best_score:.2f} % on validation (seed {cfg.seed})")
    replayed: list[Demo] = []  # with replay: every round's labels so far (not kept across a resume)
    for rnd in range(first, cfg.rounds + 1):
        t0 = time.perf_counter()
        state_dict = {k: v.detach().clone() for k, v in model.state_dict().items()}
        settings = {k: v for k, v in asdict(cfg).items() if k != "train"}
        rng = np.random.default_rng([cfg.seed, rnd])
        picked = list(train_set) if not 0 < cfg.per_round < len(train_set) else \
            [train_set[k] for k in sorted(rng.choice(len(train_set), size=cfg.per_round, replace=False))]
        jobs = [(inst, state_dict, model.cfg.to_dict(), idle_bias, settings, int(seed))
                for inst, seed in zip(picked, rng.integers(2**31, size=len(picked)), strict=True)]
        results = run_jobs(jobs, _round_job, processes=cfg.processes, ray_address=cfg.ray_address, progress=progress,
                           desc=f"round {rnd}: sampling")
        new = [d for ds, _ in results for d in ds]
        replayed = [*replayed, *new] if cfg.replay else new
        demos = replayed
        stats = [st for _, st in results]
        gain = statistics.fmean(100 * (st["lvws"] - min(st[k] for k in KINDS if not math.isnan(st[k]))) / st["lvws"]
                                for st in stats)
        chosen = {k: sum(1 for st in stats if int(st["chosen"]) == i) for i, k in enumerate(KINDS)}
        labelled = time.perf_counter() - t0
        if not demos:
            log(f"round {rnd}: no labelled states (no candidate beat LVWS's own schedule); nothing to train")
            history.append({"round": rnd, "states": 0, "validation_suboptimality": best_score, "kept": False})
            save_checkpoint(state_path, model, {**meta, "improve_history": history,
                                                "validation_suboptimality": best_score}, epoch=rnd)
            continue
        tcfg = TrainConfig(**{**asdict(cfg.train), "model": model.cfg, "epochs": cfg.epochs, "lr": cfg.lr,
                              "seed": cfg.seed + rnd})
        candidate, fit = train(demos, tcfg, model=copy.deepcopy(model), progress=progress, log=log)
        score = validation_score(candidate, val_set, optima, idle_bias)
        kept = score < best_score
        save_checkpoint(Path(out).with_suffix(f".round{rnd}.pt"), candidate,
                        {**meta, "round": rnd, "validation_suboptimality": score, "kept": kept})
        row = {"round": rnd, "states": len(new), "trained_on": len(demos), "chosen": chosen, "best_below_lvws_percent": gain,
               "labelling_seconds": labelled, "training": fit, "validation_suboptimality": score, "kept": kept}
        history.append(row)
        log(f"round {rnd}: {len(new)} states in {labelled:.0f} s (trained on {len(demos)}); chosen {chosen}; the best candidate "
            f"{gain:.2f} % shorter than LVWS's own on average; validation {score:.2f} % "
            f"({'kept' if kept else 'not kept'}; best {min(best_score, score):.2f} %)")
        if kept:
            model, best_score = candidate, score
        round_meta = {**meta, "improve_history": history, "validation_suboptimality": best_score}
        save_checkpoint(state_path, model, round_meta, epoch=rnd)
    final_meta = {**meta, "init": str(init), "validation_suboptimality": best_score,
                  "improve": {k: v for k, v in asdict(cfg).items() if k != "train"}, "improve_history": history}
    save_checkpoint(out, model, final_meta)
    log(f"model written to {out}: validation {best_score:.2f} % (round 0: {history[0]['validation_suboptimality']:.2f} %)")
    return model, final_meta
