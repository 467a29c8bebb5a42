"""Imitation learning of the GATN with the loss of Eq. 12 and Adam; DAgger on top.

Pipeline (``lvws train``): the training splits of the chosen datasets, instances of
the training family mixture (:mod:`lvws_ros.core.families`, ``mixed`` only: the held-out
families are never trained or tuned on) and a user's own instances; the last
instances of each source are held out for model selection (never a test split);
expert demonstrations on the rest; training (from scratch, or fine-tuning a
checkpoint with ``init``); then DAgger rounds: roll the current policy out on training
instances, label the states it reaches with the expert solving from each of them, add
them to the data and train on.
"""

from __future__ import annotations

import copy
import hashlib
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import torch

from lvws_ros.core.datasets import DATASETS, dataset_instance
from lvws_ros.core.executor import Policy, simulate
from lvws_ros.core.families import FAMILIES, TEST_OFFSET, TRAINING_FAMILIES, family_instance
from lvws_ros.core.formats import instance_key
from lvws_ros.core.problem import Instance
from lvws_ros.errors import ConfigError, ModelError
from lvws_ros.learning.checkpoint import load_checkpoint, read_checkpoint, save_checkpoint
from lvws_ros.learning.demonstrations import DEMOS_FORMAT, Demo, dagger_demos, label_instances, load_demos, save_demos
from lvws_ros.learning.features import PAIR_FEATURES
from lvws_ros.learning.gatn import GATN, MODEL_FORMAT, GATNConfig
from lvws_ros.learning.loss import batch_tensors, imitation_loss, wait_targets
from lvws_ros.learning.policies import NO_VOLUNTARY_WAIT, DBGMPolicy, LVWSPolicy


@dataclass
class TrainConfig:
    epochs: int = 20
    batch_size: int = 64
    lr: float = 1e-3
    lam: float = 0.1  # lambda of Eq. 12
    choice_weight: float = 1.0  # per-robot choice term (beyond the paper); 0: Eq. 12 alone
    seed: int = 0
    dbgm: bool = False  # GAT only, no idle column in the loss
    wait_weight: float = 1.0  # the wait head's term (models with a wait head only)
    wait_pos_weight: float | None = None  # weight of the expert's waits; None: class balance (non-waits / waits)
    model: GATNConfig = field(default_factory=GATNConfig)
    device: str = "cpu"  # where training runs: cpu, cuda, cuda:N, or auto (cuda when present)


def training_device(name: str) -> torch.device:
    """The torch device a training run asks for: ``auto`` is CUDA when torch sees a GPU,
    else the CPU; a CUDA device that is not there is a ConfigError, not a crash."""
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except (RuntimeError, ValueError) as exc:
        raise ConfigError(f"--device: {name!r} is not a torch device ({exc})") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise ConfigError(f"--device: {name!r} asked for, but torch sees no CUDA device here "
                          f"(torch {torch.__version__}; use cpu or auto)")
    if device.type not in ("cpu", "cuda"):
        raise ConfigError(f"--device: {name!r}: training runs on cpu or cuda")
    return device


def wait_balance(demos: Sequence[Demo]) -> float:
    """Rows the expert puts to work / rows where it waits voluntarily (:func:`wait_targets`):
    the class-balancing weight of the waits."""
    waits = rows = 0
    for d in demos:
        wait, valid = wait_targets(d)
        waits, rows = waits + int(wait.sum()), rows + int(valid.sum())
    return (rows - waits) / waits if waits else 1.0


def _loss(model: GATN, demos: Sequence[Demo], cfg: TrainConfig, pos_weight: float) -> torch.Tensor:
    batch, targets = batch_tensors(demos, use_idle=not cfg.dbgm)
    device = next(model.parameters()).device
    if device.type != "cpu":
        batch, targets = batch.to(device), targets.to(device)
    r, wait = model.forward_with_wait(batch)
    return imitation_loss(r, targets, batch.entry_row, cfg.lam, cfg.choice_weight, wait_logits=wait,
                          wait_weight=cfg.wait_weight, wait_pos_weight=pos_weight)


def evaluate_loss(model: GATN, demos: Sequence[Demo], cfg: TrainConfig) -> float:
    model.eval()
    total, count = 0.0, 0
    pos_weight = wait_balance(demos) if cfg.wait_pos_weight is None else cfg.wait_pos_weight
    with torch.inference_mode():
        for k in range(0, len(demos), 256):
            chunk = demos[k:k + 256]
            total += _loss(model, chunk, cfg, pos_weight).item() * len(chunk)
            count += len(chunk)
    return total / max(count, 1)


def _with_config(meta: dict[str, Any], cfg: TrainConfig, model: GATN) -> dict[str, Any]:
    """Checkpoint meta with the training config that produced the weights."""
    return {**meta, "train_config": {**asdict(cfg), "model": model.cfg.to_dict()}}


def _resume(path: str | Path, model: GATN, opt: torch.optim.Optimizer, log: Callable[[str], None]) -> int:
    """Weights and optimizer state of a training checkpoint; the epoch to go on from."""
    data = read_checkpoint(path)
    model.load_state_dict(data["state_dict"])
    if "optimizer" in data:
        opt.load_state_dict(data["optimizer"])
    epoch = int(data.get("epoch", 0))
    log(f"resumed from {path} at epoch {epoch}")
    return epoch


def train(
    demos: Sequence[Demo],
    cfg: TrainConfig,
    *,
    model: GATN | None = None,
    validate: Callable[[GATN], float] | None = None,
    checkpoint: str | Path | None = None,
    resume: str | Path | None = None,
    meta: dict[str, Any] | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> tuple[GATN, list[dict[str, float]]]:
    """Train on ``demos``; keep the weights with the best ``validate`` score (lower is
    better, e.g. mean makespan on held-out training instances) or the last ones."""
    from tqdm import tqdm

    torch.manual_seed(cfg.seed)
    rng = np.random.default_rng(cfg.seed)
    device = training_device(cfg.device)
    if model is None:
        model = GATN(cfg.model)
    model = model.to(device)
    if device.type != "cpu":
        log(f"training on {device} ({torch.cuda.get_device_name(device)})")
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr)
    start_epoch = 0 if resume is None else _resume(resume, model, opt, log)
    # Batches of similar team sizes pad less (robots are padded per batch): sort, shuffle the batches.
    order = sorted(range(len(demos)), key=lambda k: (demos[k].features.robots.shape[0], demos[k].expert.shape, k))
    batches = [order[k:k + cfg.batch_size] for k in range(0, len(order), cfg.batch_size)]
    pos_weight = 1.0
    if model.wait is not None:
        pos_weight = wait_balance(demos) if cfg.wait_pos_weight is None else cfg.wait_pos_weight
        log(f"wait head: expert waits weighted {pos_weight:.3g}")
    history: list[dict[str, float]] = []
    best_score, best_state = math.inf, None
    for epoch in range(start_epoch, cfg.epochs):
        model.train()
        t0 = time.perf_counter()
        losses = []
        for idx in tqdm(rng.permutation(len(batches)), desc=f"epoch {epoch + 1}/{cfg.epochs}",
                        disable=not progress, unit="batch", leave=False):
            opt.zero_grad()
            loss = _loss(model, [demos[k] for k in batches[idx]], cfg, pos_weight)
            loss.backward()
            opt.step()
            losses.append(loss.item())
        row = {"epoch": epoch + 1, "loss": statistics.fmean(losses), "seconds": time.perf_counter() - t0}
        if validate is not None:
            model.eval()
            row["validation"] = validate(model if device.type == "cpu" else copy.deepcopy(model).cpu())
            if row["validation"] < best_score:
                best_score = row["validation"]
                best_state = {k: v.detach().clone() for k, v in model.state_dict().items()}
        history.append(row)
        log("  ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))
        if checkpoint is not None:
            save_checkpoint(checkpoint, model, _with_config({**(meta or {}), "history": history}, cfg, model), opt,
                            epoch + 1)
    if best_state is not None:
        model.load_state_dict(best_state)
    model = model.cpu()  # policies, validation and checkpoints run on the CPU
    model.eval()
    return model, history


# ------------------------------------------------------------------ the whole pipeline

VALIDATION_TIME_LIMIT = 10.0
IDLE_BIASES = (0.0, -0.05, -0.1, -0.2, NO_VOLUNTARY_WAIT)
WAIT_THRESHOLDS = (None, 0.95, 0.9, 0.8, 0.7, 0.6, 0.5)  # the wait head's; None: off


@dataclass
class PipelineConfig:
    datasets: tuple[str, ...] = ("I", "II")
    data_seed: int = 0
    count: int | None = None  # training instances per dataset (None: the whole split)
    families: tuple[tuple[str, int], ...] = (("mixed", 4000),)  # (training family, instances)
    validation_per_dataset: int = 100
    dagger_rounds: int = 2
    dagger_instances: int = 1500
    dagger_epochs: int = 6
    dagger_states: int = 8  # labelled states per rollout, spread over the run
    label_time_limit: float = 5.0
    targets: str = "eq12"  # expert targets: eq12 | dense (lvws_ros.learning.demonstrations.TARGETS)
    processes: int = 2
    ray_address: str | None = None
    train: TrainConfig = field(default_factory=TrainConfig)


def split_training_instances(cfg: PipelineConfig, own: Sequence[Instance] = ()) -> tuple[list[Instance],
                                                                                            list[Instance]]:
    """(training, validation) from the training splits of the datasets, the training
    families and ``own`` instances; validation is the last ``validation_per_dataset``
    instances of each source (at most a fifth of it)."""
    sources: list[list[Instance]] = []
    for key in cfg.datasets:
        spec = DATASETS[key]
        n = spec.train if cfg.count is None else min(cfg.count, spec.train)
        sources.append([dataset_instance(spec, k, cfg.data_seed) for k in range(n)])
    for key, count in cfg.families:
        if count > TEST_OFFSET:
            raise ConfigError(f"family {key!r}: at most {TEST_OFFSET} training instances (test indices start there)")
        if FAMILIES[key].held_out:
            raise ConfigError(f"family {key!r} is held out for evaluation; train on {TRAINING_FAMILIES}")
        sources.append([family_instance(key, k, cfg.data_seed) for k in range(count)])
    if own:
        sources.append(list(own))
    train_set: list[Instance] = []
    val_set: list[Instance] = []
    for insts in sources:
        cut = max(1, min(cfg.validation_per_dataset, len(insts) // 5)) if len(insts) > 1 else 0
        train_set += insts[:len(insts) - cut]
        val_set += insts[len(insts) - cut:]
    return train_set, val_set


def _cache_groups(cfg: PipelineConfig, train_set: Sequence[Instance]) -> list[tuple[str, list[Instance]]]:
    """The training instances in two cached groups: without travel and with it (Dataset
    IV), each named by its sources, so adding travel instances keeps the other group's
    demonstrations."""
    groups = []
    for travel in (False, True):
        names = [k for k in cfg.datasets if DATASETS[k].travel == travel]
        names += [f"{k}{n}" for k, n in cfg.families if FAMILIES[k].travel == travel]
        part = [inst for inst in train_set if (inst.travel is not None) == travel]
        if part:
            groups.append(("-".join(names), part))
    return groups


def _cache_path(cache_dir: str | Path, cfg: PipelineConfig, train_set: Sequence[Instance], sources: str) -> Path:
    """Demonstrations are cached by what they are: the format, the sources, the content of
    every training instance and the expert's time limit."""
    digest = _digest(train_set)
    version = DEMOS_FORMAT.split("/")[-1]
    kind = "" if cfg.targets == "eq12" else f"-{cfg.targets}"
    return Path(cache_dir) / (f"demos{version}-{sources}-s{cfg.data_seed}-n{len(train_set)}"
                              f"-t{cfg.label_time_limit:g}{kind}-{digest}.npz")


def _cached_demos(cache: Path, log: Callable[[str], None]) -> list[Demo] | None:
    if not cache.is_file():
        return None
    try:
        demos, _ = load_demos(cache)
    except ModelError as exc:
        log(f"{exc}: labelling again")
        return None
    log(f"expert demonstrations from {cache}: {len(demos)} states")
    return demos


def _digest(instances: Sequence[Instance]) -> str:
    """What a set of instances is, for cache file names: their content, not their names."""
    return hashlib.sha256("".join(instance_key(i) for i in instances).encode()).hexdigest()[:12]


def validation_makespans(instances: Sequence[Instance], time_limit: float, workers: int, cache_dir: str | Path | None,
                         log: Callable[[str], None]) -> dict[str, tuple[float, bool]]:
    """CP-SAT's best makespan of each validation instance within ``time_limit`` on
    ``workers`` workers and whether it is a proven optimum, by instance key; kept in
    ``cache_dir`` (:func:`~lvws_ros.policies.expert_cache.expert_records`, a file named
    by the instances' content, the limit and the workers), so a resumed run does not
    solve them again."""
    from lvws_ros.policies.expert_cache import expert_records

    name = f"optima-t{time_limit:g}-w{workers}-{_digest(instances)}.json"
    cache = Path(cache_dir) / name if cache_dir else None
    t0 = time.perf_counter()
    records = expert_records(instances, cache, time_limit, workers, progress=False)  # the file holds these alone
    out = {k: (r.makespan, r.status == "optimal") for k, r in records.items()}
    log(f"validation: {sum(p for _, p in out.values())} of {len(out)} optima proven ({time.perf_counter() - t0:.0f} s"
        f"{f'; kept in {cache}' if cache else ''})")
    return out


def _policy(model: GATN, dbgm: bool, idle_bias: float, wait_threshold: float | None = None) -> Policy:
    return DBGMPolicy(model=model) if dbgm else LVWSPolicy(model=model, idle_bias=idle_bias,
                                                          wait_threshold=wait_threshold)


def _dagger_job(args: tuple[Instance, dict[str, Any], dict[str, Any], bool, float, float | None, float, int, str]
                ) -> list[Demo]:
    inst, state_dict, model_cfg, dbgm, idle_bias, threshold, time_limit, max_states, targets = args
    torch.set_num_threads(1)  # one process per core
    model = GATN(GATNConfig.from_dict(model_cfg))
    model.load_state_dict(state_dict)
    return dagger_demos(inst, _policy(model.eval(), dbgm, idle_bias, threshold), time_limit=time_limit, workers=1,
                        max_states=max_states, targets=targets)


@dataclass(frozen=True)
class Calibration:
    idle_bias: float
    wait_threshold: float | None  # None: the wait head is off (or absent)
    score: float  # mean validation suboptimality, %


def _validation_score(model: GATN, val: Sequence[Instance], optimal: dict[str, float], dbgm: bool, bias: float,
                      threshold: float | None) -> float:
    policy = _policy(model, dbgm, bias, threshold)
    return statistics.fmean(
        100 * (simulate(inst, policy).schedule.makespan - optimal[instance_key(inst)]) / optimal[instance_key(inst)]
        for inst in val)


def calibrate(model: GATN, val: Sequence[Instance], optimal: dict[str, float], dbgm: bool,
              log: Callable[[str], None]) -> Calibration:
    """The idle bias of IDLE_BIASES with the best mean validation suboptimality, then
    (with a wait head) the best of WAIT_THRESHOLDS at that bias."""
    best = Calibration(0.0, None, math.inf)
    for bias in (IDLE_BIASES if not dbgm else (0.0,)):
        score = _validation_score(model, val, optimal, dbgm, bias, None)
        log(f"  validation: idle bias {bias:g} -> suboptimality {score:.2f} %")
        if score < best.score:
            best = Calibration(bias, None, score)
    if model.wait is not None and not dbgm:
        for threshold in WAIT_THRESHOLDS[1:]:
            score = _validation_score(model, val, optimal, dbgm, best.idle_bias, threshold)
            log(f"  validation: idle bias {best.idle_bias:g}, wait threshold {threshold:g} -> suboptimality "
                f"{score:.2f} %")
            if score < best.score:
                best = Calibration(best.idle_bias, threshold, score)
    return best


def run_pipeline(cfg: PipelineConfig, out: str | Path, *, cache_dir: str | Path | None = None,
                 resume: str | Path | None = None, init: str | Path | None = None,
                 own: Sequence[Instance] = (), progress: bool = True,
                 log: Callable[[str], None] = print) -> tuple[GATN, dict[str, Any]]:
    """Label, train (from ``init``'s weights when given: fine-tuning), calibrate, DAgger;
    write the final checkpoint (no optimizer state) to ``out``."""
    tcfg = cfg.train
    torch.manual_seed(tcfg.seed)
    train_set, val_set = split_training_instances(cfg, own)
    log(f"{len(train_set)} training and {len(val_set)} validation instances: training splits of datasets "
        f"{cfg.datasets}, families {cfg.families}, {len(own)} own instances (data seed {cfg.data_seed}, "
        f"training seed {tcfg.seed})")
    start: GATN | None = None
    if init is not None:
        start, tcfg = _initial_model(init, tcfg, log)
    demos = _expert_demos(cfg, train_set, bool(own), cache_dir, progress, log)
    optimal = {k: makespan for k, (makespan, _) in  # best known within the limit: only for model selection
               validation_makespans(val_set, VALIDATION_TIME_LIMIT, 2, cache_dir, log).items()}
    stages: list[dict[str, Any]] = []
    model, history = train(demos, tcfg, model=start, checkpoint=Path(out).with_suffix(".train.pt"), resume=resume,
                           progress=progress, log=log)
    best = calibrate(model, val_set, optimal, tcfg.dbgm, log)
    stages.append(_stage("imitation", len(demos), history, best))
    rng = np.random.default_rng(tcfg.seed)
    for rnd in range(cfg.dagger_rounds):
        picks = rng.choice(len(train_set), size=min(cfg.dagger_instances, len(train_set)), replace=False)
        demos = _dagger_demos(cfg, tcfg, [train_set[k] for k in picks], model, best, demos, rnd, progress, log)
        round_cfg = TrainConfig(**{**asdict(tcfg), "model": tcfg.model, "epochs": cfg.dagger_epochs,
                                   "lr": tcfg.lr / 2, "seed": tcfg.seed + rnd + 1})
        candidate, history = train(demos, round_cfg, model=copy.deepcopy(model), progress=progress, log=log)
        cand = calibrate(candidate, val_set, optimal, tcfg.dbgm, log)
        stages.append(_stage(f"dagger-{rnd + 1}", len(demos), history, cand))
        if cand.score < best.score:  # keep a round only when it helps on validation
            model, best = candidate, cand
    meta = {"kind": "dbgm" if tcfg.dbgm else "lvws", "idle_bias": best.idle_bias,
            "wait_threshold": best.wait_threshold, "validation_suboptimality": best.score,
            "datasets": list(cfg.datasets), "families": [list(f) for f in cfg.families], "own_instances": len(own),
            "init": str(init) if init else None, "data_seed": cfg.data_seed, "training_seed": tcfg.seed,
            "pipeline": {k: v for k, v in asdict(cfg).items() if k != "train"}, "stages": stages}
    save_checkpoint(out, model, _with_config(meta, tcfg, model))
    log(f"model written to {out}: idle bias {best.idle_bias:g}, wait threshold {best.wait_threshold}, "
        f"validation suboptimality {best.score:.2f} %")
    return model, meta


def _stage(name: str, states: int, history: Any, calibration: Calibration) -> dict[str, Any]:
    """One stage of the pipeline as the checkpoint's metadata lists it."""
    return {"stage": name, "states": states, "history": history, "idle_bias": calibration.idle_bias,
            "wait_threshold": calibration.wait_threshold, "validation_suboptimality": calibration.score}


def _initial_model(init: str | Path, tcfg: TrainConfig, log: Callable[[str], None]) -> tuple[GATN, TrainConfig]:
    """``init``'s model to fine-tune (a wait head added when ``tcfg`` asks for one, the pair
    features it lacks added at zero weight) and the training configuration of its model."""
    start, init_meta = load_checkpoint(init)
    if tcfg.model.wait_head and start.wait is None and init_meta.get("kind") != "dbgm":
        grown = GATN(replace(start.cfg, wait_head=True))  # a fresh wait head on the initial weights
        grown.load_state_dict(start.state_dict(), strict=False)
        start = grown
        log(f"{init}: a wait head added")
    if start.cfg.pair_features < PAIR_FEATURES:  # an older model: learn to read the features it lacks
        wider = GATN(replace(start.cfg, pair_features=PAIR_FEATURES))
        state = start.state_dict()
        old_w = state["psi_p.weight"]
        state["psi_p.weight"] = torch.cat([old_w, old_w.new_zeros(old_w.shape[0], PAIR_FEATURES - old_w.shape[1])],
                                          dim=1)  # the new columns start at zero: the same outputs at first
        wider.load_state_dict(state)
        start = wider
        log(f"{init}: reads {PAIR_FEATURES - old_w.shape[1]} more pair features from now on "
            f"({MODEL_FORMAT})")
    tcfg = TrainConfig(**{**asdict(tcfg), "model": start.cfg, "dbgm": init_meta.get("kind") == "dbgm"})
    log(f"fine-tuning {init} ({init_meta.get('kind', 'lvws')})")
    return start, tcfg


def _expert_demos(cfg: PipelineConfig, train_set: Sequence[Instance], own: bool, cache_dir: str | Path | None,
                  progress: bool, log: Callable[[str], None]) -> list[Demo]:
    """The expert's demonstrations on the training set (with ``own`` instances: one group),
    from the cache under ``cache_dir`` when it holds them, else labelled and cached."""
    demos: list[Demo] = []
    own_group = [("-".join([*cfg.datasets, *(f"{k}{n}" for k, n in cfg.families), "own"]), list(train_set))]
    for sources, part in own_group if own else _cache_groups(cfg, train_set):
        cache = _cache_path(cache_dir, cfg, part, sources) if cache_dir else None
        got = _cached_demos(cache, log) if cache is not None else None
        if got is None:
            t0 = time.perf_counter()
            got = label_instances(part, processes=cfg.processes, time_limit=cfg.label_time_limit,
                                  ray_address=cfg.ray_address, progress=progress, targets=cfg.targets)
            log(f"expert demonstrations ({sources}): {len(got)} states in {time.perf_counter() - t0:.0f} s")
            if cache is not None:
                save_demos(got, cache, {"datasets": cfg.datasets, "data_seed": cfg.data_seed})
        demos += got
    return demos


def _dagger_demos(cfg: PipelineConfig, tcfg: TrainConfig, instances: list[Instance], model: GATN, best: Calibration,
                  demos: list[Demo], rnd: int, progress: bool, log: Callable[[str], None]) -> list[Demo]:
    """DAgger round ``rnd``: ``demos`` and the expert's labels of the states ``model`` (at
    its calibration ``best``) reaches on ``instances``."""
    state_dict = {k: v.detach().clone() for k, v in model.state_dict().items()}
    jobs = [(inst, state_dict, model.cfg.to_dict(), tcfg.dbgm, best.idle_bias, best.wait_threshold,
             cfg.label_time_limit, cfg.dagger_states, cfg.targets) for inst in instances]
    t0 = time.perf_counter()
    new = label_instances([], processes=cfg.processes, ray_address=cfg.ray_address, progress=progress,
                          jobs=jobs, job=_dagger_job)
    demos = [*demos, *new]
    log(f"DAgger round {rnd + 1}: {len(new)} states labelled in {time.perf_counter() - t0:.0f} s, "
        f"{len(demos)} in all")
    return demos
