"""``lvws`` commands on files: generate, solve, check, evaluate, gantt, train."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lvws_ros.core.datasets import DATASETS
from lvws_ros.core.families import TRAINING_FAMILIES
from lvws_ros.core.formats import dumps, load_instance, save_instance
from lvws_ros.core.problem import Instance
from lvws_ros.errors import ConfigError, InstanceError
from lvws_ros.registry import LEARNED_POLICIES, POLICY_NAMES

# Heavy modules (ortools, matplotlib, torch) are imported inside the commands so that
# `lvws --help` stays instant.



def _print_auto(policy: Any, args: argparse.Namespace) -> None:
    """What ``auto`` did: the planner's report (its quick plans, improvers, proof and any
    overrun), or the per-decision search's counts (with ``--budget-ms``)."""
    report = getattr(policy, "report", None)
    if report is None:
        improved = getattr(policy, "improved", {})
        print(f"auto: quick plan {getattr(policy, 'quick_makespan', float('nan')):g}, improved by a quick plan "
              f"made later {improved.get('quick', 0)}, by CP-SAT {improved.get('exact', 0)}, "
              f"by large-neighbourhood search {improved.get('lns', 0)} and by sampling "
              f"{improved.get('sample', 0)} times; "
              f"{'proven optimal' if getattr(policy, 'proven', False) else 'not proven optimal'}; seed {args.seed}",
              file=sys.stderr)
        return
    improved, quick = report.improved, getattr(policy, "quick_makespan", float("nan"))
    print(f"auto: planned {report.seconds:.1f} s ({report.rounds} improvement rounds): quick plan "
          f"{quick:g}, final plan {report.makespan:g} by {report.source}, improved by CP-SAT "
          f"{improved.get('exact', 0)}, by large-neighbourhood search {improved.get('lns', 0)}, by "
          f"justification {improved.get('justify', 0)} and by sampling {improved.get('sample', 0)} times; "
          f"{'proven optimal' if report.proven else 'not proven optimal'}; seed {args.seed}", file=sys.stderr)
    _print_quick_plans(policy, report, args.time_limit)


def _print_quick_plans(policy: Any, report: Any, limit: float) -> None:
    """``auto``'s quick plans as they finished (cheapest first on the cell), and by how much
    the limit was overrun when none had finished by it (the cheapest is finished anyway)."""
    quick = getattr(getattr(policy, "planner", None), "quick", {})
    if quick:
        print("auto: quick plans that finished: " + ", ".join(f"{name} {makespan:g} in {seconds:.2f} s"
                                                              for name, (makespan, seconds) in quick.items()),
              file=sys.stderr)
    if report.overrun > 0:
        print(f"auto: no quick plan had finished by the limit, so {report.fallback}'s (the cheapest on this cell) "
              f"was finished: overran the time limit of {limit:g} s by {report.overrun:.2f} s", file=sys.stderr)

def _instances(paths: Sequence[str]) -> list[Instance]:
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(f for f in p.rglob("*.json") if f.name != "manifest.json" and not f.name.startswith("."))
        else:
            files.append(p)
    if not files:
        raise InstanceError(f"no instance files found in {list(paths)}")
    return [load_instance(f) for f in files]


def cmd_generate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from lvws_ros.core.datasets import write_dataset

    print(f"dataset {args.dataset}, seed {args.seed} -> {args.out}", file=sys.stderr)

    def bar(items: Any, total: int) -> Any:
        return tqdm(items, total=total, desc=f"dataset {args.dataset}", unit="inst")

    counts = write_dataset(args.dataset, args.out, args.seed, args.count, progress=None if args.quiet else bar)
    print(f"wrote {counts['train']} training and {counts['test']} test instances to {args.out}")
    return 0


def cmd_solve(args: argparse.Namespace) -> int:
    from lvws_ros.core.executor import simulate
    from lvws_ros.core.formats import save_schedule, schedule_to_dict
    from lvws_ros.registry import make_policy

    inst = load_instance(args.instance)
    if args.noise is not None:
        from lvws_ros.sim.instance_world import check_noise

        check_noise(args.noise)
    options: dict[str, object] = {}
    if args.policy == "exact":
        options = {"time_limit": args.time_limit, "workers": args.workers}
    elif args.policy in LEARNED_POLICIES:
        options = {"model_path": args.model, "budget_ms": args.budget_ms, "width": args.beam_width,
                   "samples": args.samples, "temperature": args.temperature, "matching": args.matching}
        if args.policy == "auto" and args.budget_ms is None:  # the planner: --time-limit seconds in all
            options.update(time_limit=args.time_limit, workers=args.workers)
    from lvws_ros.core.bounds import gap, lower_bounds
    from lvws_ros.core.subteams import TOLERANCE
    from lvws_ros.policies.exact import proves_executor_bound

    policy = make_policy(args.policy, seed=args.seed, **options)
    result = simulate(inst, policy)
    bounds = lower_bounds(inst)
    bound, source = bounds.best, "critical path" if bounds.critical_path >= bounds.workload else "workload"
    expert = getattr(policy, "result", None)
    if expert is not None:
        result.schedule.extra.update({"status": expert.status})
        print(f"exact: {expert.status}, makespan {expert.makespan:g}, bound {expert.bound:g}, "
              f"{expert.seconds:.2f} s", file=sys.stderr)
        if expert.bound > bound and proves_executor_bound(inst, expert):
            bound, source = expert.bound, "CP-SAT"
    makespan = result.schedule.makespan
    if bound > makespan + TOLERANCE:  # a bound above a schedule found would be a bug: say so
        print(f"{policy.name}: warning: lower bound {bound:g} above the makespan {makespan:g} (a bug in the bound)",
              file=sys.stderr)
    result.schedule.extra.update({"bound": bound, "gap": gap(makespan, bound)})
    print(f"{policy.name}: makespan {makespan:g}, lower bound {bound:g} ({source}; critical path with the least "
          f"travel {bounds.critical_path:g}, workload {bounds.workload:g}), gap {100 * gap(makespan, bound):.2f} %",
          file=sys.stderr)
    if fallbacks := getattr(policy, "fallbacks", 0):
        print(f"{policy.name}: {fallbacks} of {len(result.steps)} steps decided by LVWS alone (the search budget "
              "was spent before any schedule was found)", file=sys.stderr)
    if args.policy == "lvws_sample":
        print(f"lvws_sample: seed {args.seed}", file=sys.stderr)
    if args.policy == "auto":
        _print_auto(policy, args)
    if args.noise is not None:
        from lvws_ros.sim.instance_world import run_noisy

        run = run_noisy(inst, lambda: make_policy(args.policy, seed=args.seed, **options), args.noise,
                        args.noise_seed)
        print(f"{policy.name}: with duration noise {args.noise:g} (noise seed {args.noise_seed}): planned "
              f"{run.planned.makespan:g}, executed {run.executed.makespan:g} online in "
              f"{run.decisions} decisions" + (" (each member sets out on its own)" if inst.departure == "each" else ""),
              file=sys.stderr)
        result.schedule.extra.update({"noise": args.noise, "noise_seed": args.noise_seed,
                                      "executed_makespan": run.executed.makespan})
    if args.out:  # --out is where the schedule goes: stdout then carries none
        save_schedule(result.schedule, args.out)
        print(f"written: {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(dumps(schedule_to_dict(result.schedule)))
    return 0


def _yaml_mapping(path: Path) -> dict[str, Any]:
    """A YAML file's top mapping, read with PyYAML's safe loader (plain data, nothing in it
    runs); an error naming the file when it is missing, not YAML, or not a mapping."""
    import yaml

    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InstanceError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    except yaml.YAMLError as exc:
        raise InstanceError(f"{path}: not YAML ({str(exc).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise InstanceError(f"{path}: expected a mapping at the top")
    return data


def _import_dcmrta(folder: Path, name: str | None) -> Instance:
    """One instance of the DCMRTA / CTAS-D test sets: its four YAML files (:func:`_yaml_mapping`)."""
    from lvws_ros.core.importers import dcmrta_instance

    docs = {part: _yaml_mapping(folder / f"{part}.yaml")
            for part in ("graph", "task_param", "vehicle_param", "planner_param")}
    return dcmrta_instance(docs["graph"], docs["task_param"], docs["vehicle_param"], docs["planner_param"],
                           name or folder.name, str(folder))


def _import_ctas_plan(path: Path, inst: Instance, out: str) -> None:
    """The CTAS-D MILP's plan of ``path`` (its routes: :func:`~lvws_ros.core.importers.ctas_plan`)
    carried out by the executor from the start, written to ``out`` as a schedule."""
    from lvws_ros.core.executor import State
    from lvws_ros.core.formats import save_schedule
    from lvws_ros.core.importers import ctas_plan
    from lvws_ros.planning.follow import repair

    executed = repair(State.initial(inst), ctas_plan(_yaml_mapping(path), inst, str(path))).schedule
    executed.policy = "ctas-d"
    save_schedule(executed, out)
    print(f"{out}: the plan of {path}, makespan {executed.makespan:g}")


def cmd_import(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from lvws_ros.core.importers import import_csv, import_mspsp, import_psplib

    wanted = 2 if args.kind == "csv" else 1
    if len(args.files) != wanted:
        usage = {"mspsp": "FILE.dzn", "psplib": "FILE.sm or FILE.rcp", "csv": "ROBOTS.csv TASKS.csv",
                 "dcmrta": "a folder with graph.yaml, task_param.yaml, vehicle_param.yaml, planner_param.yaml"}
        raise ConfigError(f"{args.kind} takes {wanted} file(s): {usage[args.kind]}, got {len(args.files)}")
    if args.plan and args.kind != "dcmrta":
        raise ConfigError("--plan is for dcmrta (a folder with the CTAS-D MILP's results.yaml)")
    if args.kind == "dcmrta":
        if args.sites or args.objective != "makespan":
            raise ConfigError("--sites and --objective are for csv")
        inst = _import_dcmrta(Path(args.files[0]), args.name)
        if args.plan:
            _import_ctas_plan(Path(args.files[0]) / "results.yaml", inst, args.plan)
    elif args.kind != "csv":
        if args.sites or args.objective != "makespan":
            raise ConfigError("--sites and --objective are for csv")
        inst = (import_mspsp if args.kind == "mspsp" else import_psplib)(args.files[0])
        if args.name:
            inst = replace(inst, name=args.name)
    else:
        inst = import_csv(args.files[0], args.files[1], args.sites, name=args.name, objective=args.objective)
    save_instance(inst, args.out)
    print(f"{args.out}: {inst.num_robots} robots, {inst.num_tasks} tasks, traits {list(inst.traits)}"
          + (", roles" if inst.task_roles.any() else "") + (", travel" if inst.travel is not None else ""))
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    from lvws_ros.core.formats import load_schedule
    from lvws_ros.core.schedule import check_schedule

    inst = load_instance(args.instance)
    sched = load_schedule(args.schedule)
    problems = check_schedule(inst, sched)
    if sched.instance != inst.name:
        print(f"note: schedule is for instance {sched.instance!r}, checking against {inst.name!r}", file=sys.stderr)
    if not problems:
        print(f"valid: {len(sched.assignments)} assignments, makespan {sched.makespan:g}")
        return 0
    for p in problems:
        print(p)
    print(f"invalid: {len(problems)} violation(s) of rules {sorted({p.rule for p in problems})}")
    return 1


def _evaluate_paper(args: argparse.Namespace, chosen: list[str]) -> int:
    from lvws_ros.cli.paper import POLICIES, reproduce

    text = reproduce(Path(args.out_md), data_seed=args.data_seed, policy_seed=args.seed,
                     time_limit=args.time_limit, table2_time_limit=args.table2_time_limit,
                     workers=args.workers, limit=args.limit, cache_dir=Path(args.out_dir) / "paper-cache",
                     progress=not args.quiet and args.processes <= 1, policies=chosen or POLICIES,
                     processes=args.processes)
    print(text)
    print(f"written: {args.out_md}", file=sys.stderr)
    return 0


def _evaluate_psplib(args: argparse.Namespace) -> int:
    import time

    from lvws_ros.cli.paper import psplib_rows, psplib_table

    folder = Path(args.psplib)
    if not folder.is_dir():
        raise InstanceError(f"{folder}: not a folder of PSPLIB files (.sm, .rcp)")
    t0 = time.perf_counter()
    rows = psplib_rows(folder, args.time_limit, args.workers, progress=not args.quiet)
    text = "\n".join(psplib_table(rows, args.time_limit, args.workers, time.perf_counter() - t0)) + "\n"
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    (out / "psplib.md").write_text(text)
    print(text)
    print(f"written: {out / 'psplib.md'}", file=sys.stderr)
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from lvws_ros.core.metrics import run_policy, summarize, to_csv, to_markdown
    from lvws_ros.policies.expert_cache import expert_records
    from lvws_ros.registry import make_policy

    chosen = [p.strip() for p in (args.policies or "").split(",") if p.strip()]
    if args.paper:
        return _evaluate_paper(args, chosen)
    if args.psplib:
        return _evaluate_psplib(args)
    if not args.instances:
        raise InstanceError("give instance files or folders, or --paper")
    instances = _instances(args.instances)
    policies = chosen or ["rand", "rand_subteam", "grp", "lvws"]
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{len(instances)} instances, policies {policies}, seed {args.seed}", file=sys.stderr)
    experts = expert_records(instances, out / "expert_cache.json", args.time_limit, args.workers,
                             progress=not args.quiet)
    runs = [run_policy(inst, policy)
            for policy in (make_policy(p, seed=args.seed) for p in policies)
            for inst in tqdm(instances, desc=policy.name, disable=args.quiet, unit="inst")]
    rows = summarize(runs, experts)
    table = to_markdown(rows)
    unproven = [e for e in experts.values() if e.status != "optimal"]
    note = (f"\nExact solver: {len(experts) - len(unproven)}/{len(experts)} optima proven "
            f"(time limit {args.time_limit:g} s, {args.workers} workers)")
    if unproven:
        gaps = [(e.makespan - e.bound) / e.makespan for e in unproven]
        note += f"; {len(unproven)} without proof, mean gap {100 * sum(gaps) / len(gaps):.2f} % (left out of suboptimality)"
    (out / "results.md").write_text(table + note + "\n")
    (out / "results.csv").write_text(to_csv(rows))
    print(table + note)
    print(f"written: {out / 'results.md'}, {out / 'results.csv'}", file=sys.stderr)
    return 0


def cmd_gantt(args: argparse.Namespace) -> int:
    from lvws_ros.cli.gantt import plot_gantt
    from lvws_ros.core.formats import load_schedule

    sched = load_schedule(args.schedule)
    inst = load_instance(args.instance) if args.instance else None
    print(plot_gantt(sched, args.out, inst))
    return 0


# Named training recipes: the stages (train's own flags) that produced a model. "shipped"
# reproduces lvws_ros/learning/models/lvws.pt (its log: lvws.training.txt beside it); a
# stage's "{previous}" is the checkpoint the stage before wrote.
RECIPES: dict[str, tuple[tuple[str, ...], ...]] = {
    "shipped": (
        ("--datasets", "I,II,IV", "--count", "2500", "--families", "mixed:4000,traits:1500,traits-return:1500",
         "--epochs", "15", "--dagger-rounds", "1", "--dagger-instances", "1000", "--dagger-epochs", "5",
         "--label-time-limit", "5"),
    ),
}
RECIPE_PASSED = ("--cache-dir", "--processes", "--ray-address", "--device")  # the run's own, kept per stage


def _run_recipe(args: argparse.Namespace) -> int:
    """``lvws train --recipe NAME --out OUT``: each stage of the recipe with its own
    flags (the stages before the last write OUT's ``.stageN.pt``)."""
    stages = RECIPES[args.recipe]
    out = Path(args.out)
    passed = [x for flag in RECIPE_PASSED if (value := getattr(args, flag[2:].replace("-", "_"))) is not None
              for x in (flag, str(value))] + (["--quiet"] if args.quiet else [])
    previous = ""
    for k, stage in enumerate(stages, start=1):
        target = out if k == len(stages) else out.with_suffix(f".stage{k}.pt")
        argv = ["train", *(a.replace("{previous}", previous) for a in stage), *passed, "--out", str(target)]
        print(f"recipe {args.recipe}, stage {k} of {len(stages)}: lvws {' '.join(argv)}", file=sys.stderr)
        stage_args = _train_parser().parse_args(argv)
        if cmd_train(stage_args) != 0:
            return 1
        previous = str(target)
    return 0


def _train_parser() -> argparse.ArgumentParser:
    """A parser of ``train`` alone (a recipe's stages), as ``lvws`` parses it."""
    parser = argparse.ArgumentParser(prog="lvws")
    sub = parser.add_subparsers(dest="command")

    def add(name: str, func: Any, help_text: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(func=func)
        return p

    _add_train(add)
    return parser


def cmd_train(args: argparse.Namespace) -> int:
    from lvws_ros.learning.checkpoint import DEFAULT_MODELS

    if getattr(args, "recipe", None):
        return _run_recipe(args)
    from lvws_ros.learning.training import training_device

    training_device(args.device)  # a device that is not there is refused now, not after hours of labelling
    from lvws_ros.learning.gatn import GATNConfig
    from lvws_ros.learning.training import PipelineConfig, TrainConfig, run_pipeline

    model_cfg = GATNConfig(hidden=args.hidden, use_transformer=not args.dbgm,
                           wait_head=args.wait_head and not args.dbgm)
    train_cfg = TrainConfig(epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, lam=args.lam,
                            choice_weight=args.choice_weight, seed=args.seed, dbgm=args.dbgm,
                            wait_weight=args.wait_weight, model=model_cfg, device=args.device)
    datasets = tuple(d for d in args.datasets.split(",") if d)
    trainable = [k for k, spec in DATASETS.items() if spec.train]
    unknown = [d for d in datasets if d not in trainable]
    if unknown:
        raise ConfigError(f"--datasets: {unknown} have no training split (choose from {', '.join(trainable)})")
    families = _families(args.families, args.family_count)
    bad = [k for k, _ in families if k not in TRAINING_FAMILIES]
    if bad:
        raise ConfigError(f"--families: {bad} are not training families (choose from {list(TRAINING_FAMILIES)})")
    own = _instances(args.instances) if args.instances else []
    init = None if args.init is None else DEFAULT_MODELS["dbgm" if args.dbgm else "lvws"] if args.init == "shipped" \
        else Path(args.init)
    cfg = PipelineConfig(datasets=datasets, data_seed=args.data_seed, count=args.count, families=families,
                         validation_per_dataset=args.validation, dagger_rounds=args.dagger_rounds,
                         dagger_instances=args.dagger_instances, dagger_epochs=args.dagger_epochs,
                         label_time_limit=args.label_time_limit, targets=args.targets, processes=args.processes,
                         ray_address=args.ray_address, train=train_cfg)
    if args.improve:
        return _improve(args, cfg, own, init or DEFAULT_MODELS["lvws"])
    run_pipeline(cfg, args.out, cache_dir=args.cache_dir, resume=args.resume, init=init, own=own,
                 progress=not args.quiet)
    return 0


def _families(text: str, count: int) -> tuple[tuple[str, int], ...]:
    """``--families``: ``key`` (``--family-count`` instances) or ``key:count``, comma-separated."""
    out = []
    for item in (x.strip() for x in text.split(",")):
        if not item:
            continue
        key, _, n = item.partition(":")
        if n and not (n.isdigit() and int(n) > 0):
            raise ConfigError(f"--families: {item!r}: the count after ':' must be a whole number > 0")
        out.append((key, int(n) if n else count))
    return tuple(out)


def _improve(args: argparse.Namespace, cfg: Any, own: list[Instance], init: Path) -> int:
    """``lvws train --improve ROUNDS``: self-improvement from ``init`` on the training
    split (lvws_ros.learning.improvement), validated on its held-out instances."""
    from lvws_ros.learning.improvement import ImproveConfig, improve, large_instances
    from lvws_ros.learning.sampling import DEFAULT_TEMPERATURE
    from lvws_ros.learning.training import split_training_instances

    if args.dbgm:
        raise ConfigError("--improve trains LVWS; DBGM has no sampling")
    train_set, val_set = split_training_instances(cfg, own)
    train_set += large_instances(args.large, args.data_seed)
    icfg = ImproveConfig(rounds=args.improve, samples=args.samples, beam_width=args.improve_beam,
                         temperature=DEFAULT_TEMPERATURE if args.temperature is None else args.temperature,
                         expert_time_limit=args.improve_expert, large=args.large, per_round=args.per_round,
                         states_per_instance=args.states_per_instance, replay=args.replay,
                         improved_only=args.improved_only,
                         epochs=args.epochs, lr=args.lr,
                         seed=args.seed, processes=args.processes, ray_address=args.ray_address,
                         targets=args.targets, train=cfg.train)
    print(f"self-improvement: seed {args.seed}, data seed {args.data_seed}, {len(train_set)} training and "
          f"{len(val_set)} validation instances", file=sys.stderr)
    improve(init, train_set, val_set, icfg, args.out, cache_dir=args.cache_dir, resume=args.resume,
            progress=not args.quiet)
    return 0


Adder = Any  # (name, function, help) -> argparse.ArgumentParser


def add_parsers(add: Adder) -> None:
    p = add("generate", cmd_generate, "write one of the paper's datasets as lvws-instance/1 files")
    p.add_argument("--dataset", choices=list(DATASETS), required=True)
    p.add_argument("--out", required=True, help="output folder (train/ and test/ inside)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--count", type=int, default=None, help="only the first COUNT instances")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_solve(add)
    _add_import(add)
    p = add("check", cmd_check, "check a schedule against an instance (exit 0 only when valid)")
    p.add_argument("instance")
    p.add_argument("schedule")

    _add_evaluate(add)
    _add_train(add)

    p = add("gantt", cmd_gantt, "draw a schedule as a Gantt chart (PNG)")
    p.add_argument("schedule")
    p.add_argument("--instance", help="the instance, to show robots that never work")
    p.add_argument("--out", required=True)


def _add_solve(add: Adder) -> None:
    p = add("solve", cmd_solve, "schedule an instance with a policy; prints lvws-schedule/1 JSON (to --out instead "
            "when given)")
    p.add_argument("instance")
    p.add_argument("--policy", choices=POLICY_NAMES, default="grp")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--time-limit", type=float, default=60.0,
                   help="exact: CP-SAT time limit; auto: planning time in all, less once proven optimal [s]")
    p.add_argument("--workers", type=int, default=8, help="exact and auto: CP-SAT workers")
    p.add_argument("--model", default=None, help="lvws/dbgm policy: checkpoint (default: the shipped one)")
    p.add_argument("--budget-ms", type=float, default=None,
                   help="auto, lvws_rollout, lvws_sample: time budget per decision step, lvws_beam: per search [ms] "
                        "(default: none; with it auto searches within each decision's budget instead of planning "
                        "for --time-limit)")
    p.add_argument("--beam-width", type=int, default=None,
                   help="lvws_beam: partial schedules kept at each depth (default: its DEFAULT_WIDTH)")
    p.add_argument("--samples", type=int, default=None,
                   help="lvws_sample: schedules sampled in lockstep per round (default: its DEFAULT_SAMPLES)")
    p.add_argument("--temperature", type=float, default=None,
                   help="lvws_sample: scale of the Gumbel noise on R (default: its DEFAULT_TEMPERATURE; 0: LVWS)")
    p.add_argument("--matching", choices=("greedy", "exact"), default=None,
                   help="lvws: Eqs. 7-11 on R by the paper's greedy (default) or exactly by CP-SAT")
    p.add_argument("--noise", type=float, default=None,
                   help="also run the policy online in a world where each task takes its duration x a seeded "
                        "factor in [1-NOISE, 1+NOISE] and print planned against executed makespan")
    p.add_argument("--noise-seed", type=int, default=0, help="the noise's seed (with --noise)")
    p.add_argument("--out", help="write the schedule to this file instead of stdout")


def _add_import(add: Adder) -> None:
    p = add("import", cmd_import, "turn a multi-skill project scheduling file (MiniZinc data, .dzn), a PSPLIB "
                                   "project scheduling file (.sm or Patterson .rcp), CSV files of robots and "
                                   "tasks, or an instance folder of the DCMRTA / CTAS-D coalition benchmarks "
                                   "into an lvws-instance/1 file")
    p.add_argument("kind", choices=("mspsp", "psplib", "csv", "dcmrta"))
    p.add_argument("files", nargs="+", help="mspsp: FILE.dzn; psplib: FILE.sm or FILE.rcp; csv: ROBOTS.csv "
                                            "TASKS.csv; dcmrta: the folder of graph.yaml, task_param.yaml, "
                                            "vehicle_param.yaml, planner_param.yaml")
    p.add_argument("--sites", default=None, help="csv: SITES.csv (name,x,y): the travel extension")
    p.add_argument("--objective", choices=("makespan", "return"), default="makespan",
                   help="csv: the instance's objective")
    p.add_argument("--name", default=None, help="the instance's name (default: the file's)")
    p.add_argument("--out", required=True, help="the lvws-instance/1 file to write")
    p.add_argument("--plan", default=None, help="dcmrta: also the folder's results.yaml (the CTAS-D MILP's plan), "
                                                "carried out by the executor, to this lvws-schedule/1 file")


def _add_evaluate(add: Adder) -> None:
    p = add("evaluate", cmd_evaluate,
            "policies x instances: mean makespan, suboptimality vs the exact solver, validity, decision time")
    p.add_argument("instances", nargs="*", help="instance files or folders")
    p.add_argument("--paper", action="store_true",
                   help="regenerate the paper's Tables I and II and our Table III (travel) on our datasets into --out-md")
    p.add_argument("--psplib", nargs="?", const="examples/psplib", default=None, metavar="DIR",
                   help="the PSPLIB table: each .sm/.rcp file of DIR (default: examples/psplib) solved by GRP, the "
                        "exact expert and a plain cumulative CP-SAT model at --time-limit each, beside the published "
                        "optima of DIR/optima.csv; written to --out-dir/psplib.md")
    p.add_argument("--out-md", default="docs/results.md", help="with --paper: the markdown report")
    p.add_argument("--data-seed", type=int, default=0, help="with --paper: dataset seed")
    p.add_argument("--limit", type=int, default=None, help="with --paper: first LIMIT test instances per dataset")
    p.add_argument("--policies", default=None,
                   help="comma-separated (default: rand,rand_subteam,grp,lvws; with --paper: all of Table I)")
    p.add_argument("--table2-time-limit", type=float, default=30.0,
                   help="with --paper: CP-SAT time limit per Dataset III instance [s]")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--time-limit", type=float, default=60.0, help="CP-SAT time limit per instance [s]")
    p.add_argument("--workers", type=int, default=8, help="CP-SAT workers")
    p.add_argument("--out-dir", default="results", help="results.md, results.csv and the expert cache go here")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--processes", type=int, default=1,
                   help="with --paper: run the tables' columns in this many processes at once (one thread each; "
                        "no progress bars)")


def _add_train(add: Adder) -> None:
    p = add("train", cmd_train, "imitation learning of the GATN (Eq. 12) on expert demonstrations, with DAgger")
    p.add_argument("--out", required=True, help="checkpoint to write (e.g. my_model.pt)")
    p.add_argument("--recipe", choices=sorted(RECIPES), default=None,
                   help="run a named recipe's stages ('shipped': how the shipped model was trained); only --out, "
                        f"--quiet and {', '.join(RECIPE_PASSED)} are taken from the command line")
    p.add_argument("--datasets", default="I,II", help="training splits to use, comma-separated ('' for none)")
    p.add_argument("--families", default="mixed",
                   help=f"training families, comma-separated, each KEY or KEY:COUNT ('' for none; from "
                        f"{list(TRAINING_FAMILIES)})")
    p.add_argument("--family-count", type=int, default=4000, help="instances per training family without a :COUNT")
    p.add_argument("--instances", nargs="*", default=None,
                   help="your own instance files or folders: labelled by the expert and trained on")
    p.add_argument("--init", default=None,
                   help="start from this checkpoint ('shipped': the shipped model): fine-tuning")
    p.add_argument("--label-time-limit", type=float, default=5.0, help="CP-SAT time limit per labelled state [s]")
    p.add_argument("--targets", choices=("eq12", "dense"), default="eq12",
                   help="expert targets: the paper's Eq. 12 labels (default), or dense ones over every task later in "
                        "a robot's schedule with a learned idle")
    p.add_argument("--count", type=int, default=None, help="training instances per dataset (default: all)")
    p.add_argument("--validation", type=int, default=100, help="held-out training instances per dataset")
    p.add_argument("--data-seed", type=int, default=0)
    p.add_argument("--seed", type=int, default=0, help="training seed")
    p.add_argument("--epochs", type=int, default=20)
    p.add_argument("--batch-size", type=int, default=64)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--lam", type=float, default=0.1, help="lambda of Eq. 12")
    p.add_argument("--choice-weight", type=float, default=1.0, help="per-robot choice term; 0: Eq. 12 alone")
    p.add_argument("--hidden", type=int, default=64)
    p.add_argument("--dbgm", action="store_true", help="the DBGM-style baseline: GAT only, no idle task")
    p.add_argument("--wait-head", action=argparse.BooleanOptionalAction, default=False,
                   help="learn voluntary waiting with a wait head (added to an --init model without one); off by "
                        "default: it was break-even in our test (docs/wait_head_experiment.md)")
    p.add_argument("--wait-weight", type=float, default=1.0, help="weight of the wait head's term")
    p.add_argument("--dagger-rounds", type=int, default=2)
    p.add_argument("--dagger-instances", type=int, default=1500)
    p.add_argument("--dagger-epochs", type=int, default=6)
    p.add_argument("--processes", type=int, default=2, help="parallel labelling processes")
    p.add_argument("--ray-address", default=None, help="label on this Ray cluster ('local': a local Ray instance)")
    p.add_argument("--cache-dir", default=None, help="keep expert demonstrations (and validation optima) here")
    p.add_argument("--resume", default=None,
                   help="continue from a training checkpoint (*.train.pt; with --improve: *.improve.pt)")
    p.add_argument("--device", default="cpu", help="where training runs: cpu (default), cuda, cuda:N, or auto")
    _add_improve_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress bars")


def _add_improve_options(p: argparse.ArgumentParser) -> None:
    """``lvws train``'s self-improvement options, in a group of their own."""
    g = p.add_argument_group("self-improvement (--improve): labels from the policy's own best schedules")
    g.add_argument("--improve", type=int, default=0, metavar="ROUNDS",
                   help="rounds of self-improvement from --init (default: the shipped model) instead of imitation; "
                        "--epochs and --lr then apply to each round's fine-tuning")
    g.add_argument("--samples", type=int, default=16, help="schedules sampled per training instance and round")
    g.add_argument("--temperature", type=float, default=None, help="Gumbel noise on R (default: lvws_sample's)")
    g.add_argument("--improve-beam", type=int, default=0, metavar="WIDTH",
                   help="also the beam search's schedule at this width (0: not)")
    g.add_argument("--improve-expert", type=float, default=0.0, metavar="SECONDS",
                   help="also the expert's schedule, CP-SAT within this limit (0: not)")
    g.add_argument("--per-round", type=int, default=0,
                   help="training instances drawn afresh for each round (0: all of them every round)")
    g.add_argument("--states-per-instance", type=int, default=24,
                   help="labelled states per instance, spread over its schedule (0: all)")
    g.add_argument("--replay", action=argparse.BooleanOptionalAction, default=True,
                   help="train each round on the labels of every round so far (default) or on its own only")
    g.add_argument("--improved-only", action="store_true",
                   help="label only instances where a candidate beats LVWS's own schedule")
    g.add_argument("--large", type=int, default=0,
                   help="training instances of the mixture at 20-60 robots x 50-200 tasks (no proof needed)")
