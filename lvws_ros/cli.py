"""The user-facing ``lvws`` command: offline scheduling (generate, solve, check, evaluate,
gantt, train), the case study (sim, launch, scheduler) and recorded runs (report,
verify, replay)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

from lvws_ros import __version__
from lvws_ros.model import Instance, InstanceError, dumps, load_instance

# Heavy modules (ortools, matplotlib, torch) are imported inside the commands so that
# `lvws --help` stays instant.


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
    from lvws_ros.datasets import write_dataset

    print(f"dataset {args.dataset}, seed {args.seed} -> {args.out}", file=sys.stderr)
    counts = write_dataset(args.dataset, args.out, args.seed, args.count, progress=not args.quiet)
    print(f"wrote {counts['train']} training and {counts['test']} test instances to {args.out}")
    return 0


def cmd_solve(args: argparse.Namespace) -> int:
    from lvws_ros.executor import simulate
    from lvws_ros.policies import LEARNED_POLICIES, make_policy
    from lvws_ros.schedule import save_schedule, schedule_to_dict

    inst = load_instance(args.instance)
    options: dict[str, object] = {}
    if args.policy == "exact":
        options = {"time_limit": args.time_limit, "workers": args.workers}
    elif args.policy in LEARNED_POLICIES:
        options = {"model_path": args.model}
    policy = make_policy(args.policy, seed=args.seed, **options)
    result = simulate(inst, policy)
    expert = getattr(policy, "result", None)
    if expert is not None:
        result.schedule.extra.update(
            {"status": expert.status, "bound": expert.bound, "gap": expert.gap})
        print(f"exact: {expert.status}, makespan {expert.makespan:g}, bound {expert.bound:g}, "
              f"{expert.seconds:.2f} s", file=sys.stderr)
    if args.out:
        save_schedule(result.schedule, args.out)
    sys.stdout.write(dumps(schedule_to_dict(result.schedule)))
    return 0


def cmd_check(args: argparse.Namespace) -> int:
    from lvws_ros.schedule import check_schedule, load_schedule

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


def cmd_evaluate(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from lvws_ros.metrics import expert_records, run_policy, summarize, to_csv, to_markdown
    from lvws_ros.policies import make_policy

    chosen = [p.strip() for p in (args.policies or "").split(",") if p.strip()]
    if args.paper:
        from lvws_ros.paper import POLICIES, reproduce

        text = reproduce(Path(args.out_md), data_seed=args.data_seed, policy_seed=args.seed,
                         time_limit=args.time_limit, table2_time_limit=args.table2_time_limit,
                         workers=args.workers, limit=args.limit, cache_dir=Path(args.out_dir) / "paper-cache",
                         progress=not args.quiet, policies=chosen or POLICIES)
        print(text)
        print(f"written: {args.out_md}", file=sys.stderr)
        return 0
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
    from lvws_ros.gantt import plot_gantt
    from lvws_ros.schedule import load_schedule

    sched = load_schedule(args.schedule)
    inst = load_instance(args.instance) if args.instance else None
    path = plot_gantt(sched, args.out, inst)
    print(path)
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from lvws_ros.gatn import GATNConfig
    from lvws_ros.training import PipelineConfig, TrainConfig, run_pipeline

    model_cfg = GATNConfig(hidden=args.hidden, use_transformer=not args.dbgm)
    train_cfg = TrainConfig(epochs=args.epochs, batch_size=args.batch_size, lr=args.lr, lam=args.lam,
                            choice_weight=args.choice_weight, seed=args.seed, dbgm=args.dbgm, model=model_cfg)
    cfg = PipelineConfig(datasets=tuple(args.datasets.split(",")), data_seed=args.data_seed, count=args.count,
                         validation_per_dataset=args.validation, dagger_rounds=args.dagger_rounds,
                         dagger_instances=args.dagger_instances, dagger_epochs=args.dagger_epochs,
                         processes=args.processes, ray_address=args.ray_address, train=train_cfg)
    run_pipeline(cfg, args.out, cache_dir=args.cache_dir, resume=args.resume, progress=not args.quiet)
    return 0


def cmd_sim(args: argparse.Namespace) -> int:
    from lvws_ros.cell_sim import CellSim, load_cell_config, run_offline
    from lvws_ros.policies import LEARNED_POLICIES, make_policy
    from lvws_ros.schedule import check_schedule, save_schedule

    sim = CellSim(load_cell_config(args.config))
    options = {"model_path": args.model} if args.model and args.policy in LEARNED_POLICIES else {}
    sched, decisions = run_offline(sim, make_policy(args.policy, seed=args.seed, **options),
                                   frame_every=args.frame_every if args.gif or args.frames else None)
    problems = check_schedule(sim.executed_instance(), sched)
    print(f"{args.policy}: makespan {sched.makespan:.2f} s, {len(decisions)} decisions, "
          f"valid: {'yes' if not problems else problems}")
    for d in decisions:
        made = ", ".join(f"{t}<-{'+'.join(r)}" for t, r in d.assignments) or "-"
        print(f"  step {d.step} t={d.team_stamp:.2f}: {made}; waiting {', '.join(d.waiting) or '-'}")
    if args.out:
        save_schedule(sched, args.out)
    if args.gif:
        from lvws_ros.cell_render import render_gif

        print(render_gif(sim.cfg, sim.trace, sim.inst.num_tasks, args.gif))
    if args.frames:
        from lvws_ros.cell_render import render_frames

        paths = render_frames(sim.cfg, sim.trace, sim.inst.num_tasks, args.frames)
        print(f"{len(paths)} PNG frames in {args.frames}")
    return 0 if not problems else 1


def cmd_launch(args: argparse.Namespace) -> int:
    from lvws_ros.launcher import LaunchError, launch

    try:
        res = launch(policy=args.policy, seed=args.seed, model_path=args.model or "", rate=args.rate,
                     config=args.config or "", bag_dir=args.bag_dir, out_dir=args.out_dir, name=args.name,
                     params_file=args.params_file, gif=not args.no_gif, timeout=args.timeout,
                     sync=not args.no_sync)
    except LaunchError as exc:
        print(f"lvws launch: failed: {exc}", file=sys.stderr)
        return 1
    s = res.summary
    print(res.report_text)
    print()
    print(f"makespan:  {s.get('makespan')} s (sim time), {s.get('tasks_done')}/{s.get('tasks')} tasks")
    print(f"decisions: {s.get('decisions_received')}")
    print(f"wall time: {s.get('wall_seconds_total', 0):.1f} s")
    print(f"bag:       {res.bag}")
    print(f"gantt:     {res.gantt}")
    print(f"gif:       {res.gif}")
    print(f"logs:      {res.out_dir}")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from lvws_ros.report import report

    out = args.gantt or str(Path(args.bag).with_name(Path(args.bag).name + "-gantt.png"))
    rep = report(args.bag, out)
    print(rep.text())
    print(f"gantt: {out}")
    return 0 if rep.complete and not rep.problems else 1


def cmd_verify(args: argparse.Namespace) -> int:
    from lvws_ros.report import verify

    n, bad = verify(args.bag, policy=args.policy, seed=args.seed, model_path=args.model)
    for m in bad:
        print(f"step {m.step}: recorded {m.recorded}, offline {m.replayed}")
    print(f"{n - len(bad)}/{n} decisions reproduced" + (" (deterministic replay: ok)" if not bad else ""))
    return 0 if not bad else 1


def cmd_replay(args: argparse.Namespace) -> int:
    from lvws_ros.ros.replay import replay

    replay(args.bag, args.rate, args.wait_for_subscribers, args.topics)
    return 0


def cmd_scheduler(args: argparse.Namespace) -> int:  # reached only for `lvws scheduler --help`-less errors
    from lvws_ros.ros.scheduler_node import main as scheduler_main

    return scheduler_main(list(args.ros_args))


def build_parser() -> argparse.ArgumentParser:
    from lvws_ros.policies import POLICY_NAMES

    parser = argparse.ArgumentParser(
        prog="lvws",
        description="LVWS heterogeneous multi-robot scheduling with subteams and waiting.",
    )
    parser.add_argument("--version", action="version", version=f"lvws_ros {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")

    def add(name: str, func: Callable[[argparse.Namespace], int], help_text: str) -> argparse.ArgumentParser:
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(func=func)
        return p

    p = add("generate", cmd_generate, "write one of the paper's datasets as lvws-instance/1 files")
    p.add_argument("--dataset", choices=["I", "II", "III"], required=True)
    p.add_argument("--out", required=True, help="output folder (train/ and test/ inside)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--count", type=int, default=None, help="only the first COUNT instances")
    p.add_argument("--quiet", action="store_true", help="no progress bar")

    p = add("solve", cmd_solve, "schedule an instance with a policy; prints lvws-schedule/1 JSON")
    p.add_argument("instance")
    p.add_argument("--policy", choices=POLICY_NAMES, default="grp")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--time-limit", type=float, default=60.0, help="exact policy: CP-SAT time limit [s]")
    p.add_argument("--workers", type=int, default=8, help="exact policy: CP-SAT workers")
    p.add_argument("--model", default=None, help="lvws/dbgm policy: checkpoint (default: the shipped one)")
    p.add_argument("--out", help="also write the schedule to this file")

    p = add("check", cmd_check, "check a schedule against an instance (exit 0 only when valid)")
    p.add_argument("instance")
    p.add_argument("schedule")

    p = add("evaluate", cmd_evaluate,
            "policies x instances: mean makespan, suboptimality vs the exact solver, validity, decision time")
    p.add_argument("instances", nargs="*", help="instance files or folders")
    p.add_argument("--paper", action="store_true",
                   help="regenerate the paper's Tables I and II on our datasets into --out-md")
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

    p = add("train", cmd_train, "imitation learning of the GATN (Eq. 12) on expert demonstrations, with DAgger")
    p.add_argument("--out", required=True, help="checkpoint to write (e.g. lvws_ros/models/lvws.pt)")
    p.add_argument("--datasets", default="I,II", help="training splits to use, comma-separated")
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
    p.add_argument("--dagger-rounds", type=int, default=2)
    p.add_argument("--dagger-instances", type=int, default=1500)
    p.add_argument("--dagger-epochs", type=int, default=6)
    p.add_argument("--processes", type=int, default=2, help="parallel labelling processes")
    p.add_argument("--ray-address", default=None, help="label on this Ray cluster ('local': a local Ray instance)")
    p.add_argument("--cache-dir", default=None, help="keep expert demonstrations here between runs")
    p.add_argument("--resume", default=None, help="continue from a training checkpoint (*.train.pt)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")

    p = add("sim", cmd_sim, "run the assembly-cell case study in-process with a policy (no ROS)")
    p.add_argument("--policy", choices=POLICY_NAMES, default="lvws")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None, help="lvws/dbgm checkpoint (default: the shipped one)")
    p.add_argument("--config", default=None, help="assembly-cell YAML (default: config/assembly_cell.yaml)")
    p.add_argument("--out", help="write the executed schedule (lvws-schedule/1) here")
    p.add_argument("--gif", help="write an animated GIF of the run here")
    p.add_argument("--frames", help="write a PNG per frame into this folder")
    p.add_argument("--frame-every", type=float, default=2.0, help="sim seconds between frames")

    p = add("launch", cmd_launch, "the case study on ROS 2: cell_sim + scheduler + recorder, then a summary")
    p.add_argument("--policy", choices=POLICY_NAMES, default="lvws")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None, help="lvws/dbgm checkpoint (default: the shipped one)")
    p.add_argument("--rate", type=float, default=20.0, help="sim time / wall time")
    p.add_argument("--config", default=None, help="assembly-cell YAML (default: config/assembly_cell.yaml)")
    p.add_argument("--params-file", default=None, help="scheduler parameters (e.g. config/scheduler.yaml)")
    p.add_argument("--bag-dir", default="bags")
    p.add_argument("--out-dir", default="out", help="Gantt PNG, GIF, summary and logs go to OUT_DIR/<run>")
    p.add_argument("--name", default=None, help="run name (default: case-study-<policy>-<time>)")
    p.add_argument("--no-gif", action="store_true")
    p.add_argument("--no-sync", action="store_true",
                   help="free-running world: it does not pause at decision steps, so decision latency costs sim time")
    p.add_argument("--timeout", type=float, default=600.0, help="wall seconds before giving up")

    p = add("scheduler", cmd_scheduler, "the scheduler node (same as `ros2 run lvws_ros scheduler`)")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args ... for rclpy")

    p = add("report", cmd_report, "makespan, assignments and a Gantt chart of a recorded run, from the bag alone")
    p.add_argument("bag")
    p.add_argument("--gantt", default=None, help="PNG path (default: next to the bag)")

    p = add("verify", cmd_verify, "re-run the scheduler offline on a bag's inputs; exit 0 when it decides the same")
    p.add_argument("bag")
    p.add_argument("--policy", choices=POLICY_NAMES, default=None, help="default: the recorded one")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None)

    p = add("replay", cmd_replay, "republish a bag's messages with the recorded timing and QoS")
    p.add_argument("bag")
    p.add_argument("--rate", type=float, default=1.0)
    p.add_argument("--wait-for-subscribers", type=float, default=2.0)
    p.add_argument("--topics", nargs="*", default=None)

    p = add("gantt", cmd_gantt, "draw a schedule as a Gantt chart (PNG)")
    p.add_argument("schedule")
    p.add_argument("--instance", help="the instance, to show robots that never work")
    p.add_argument("--out", required=True)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv[:1] == ["scheduler"] and "-h" not in argv and "--help" not in argv:
        from lvws_ros.ros.scheduler_node import main as scheduler_main

        return scheduler_main(argv[1:])  # rclpy parses --ros-args itself
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args))
    except (InstanceError, ValueError, RuntimeError, OSError, KeyError) as exc:
        print(f"lvws {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
