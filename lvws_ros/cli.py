"""The user-facing ``lvws`` command: generate, solve, check, evaluate, gantt."""

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
    from lvws_ros.policies import make_policy
    from lvws_ros.schedule import save_schedule, schedule_to_dict

    inst = load_instance(args.instance)
    options = {"time_limit": args.time_limit, "workers": args.workers} if args.policy == "exact" else {}
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

    instances = _instances(args.instances)
    policies = [p.strip() for p in args.policies.split(",") if p.strip()]
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{len(instances)} instances, policies {policies}, seed {args.seed}", file=sys.stderr)
    experts = expert_records(instances, out / "expert_cache.json", args.time_limit, args.workers,
                             progress=not args.quiet)
    runs = [run_policy(inst, p, args.seed)
            for p in policies
            for inst in tqdm(instances, desc=p, disable=args.quiet, unit="inst")]
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
    p.add_argument("--out", help="also write the schedule to this file")

    p = add("check", cmd_check, "check a schedule against an instance (exit 0 only when valid)")
    p.add_argument("instance")
    p.add_argument("schedule")

    p = add("evaluate", cmd_evaluate,
            "policies x instances: mean makespan, suboptimality vs the exact solver, validity, decision time")
    p.add_argument("instances", nargs="+", help="instance files or folders")
    p.add_argument("--policies", default="rand,rand_subteam,grp")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--time-limit", type=float, default=60.0, help="CP-SAT time limit per instance [s]")
    p.add_argument("--workers", type=int, default=8, help="CP-SAT workers")
    p.add_argument("--out-dir", default="results", help="results.md, results.csv and the expert cache go here")
    p.add_argument("--quiet", action="store_true", help="no progress bars")

    p = add("gantt", cmd_gantt, "draw a schedule as a Gantt chart (PNG)")
    p.add_argument("schedule")
    p.add_argument("--instance", help="the instance, to show robots that never work")
    p.add_argument("--out", required=True)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    try:
        return int(args.func(args))
    except (InstanceError, ValueError, RuntimeError, OSError) as exc:
        print(f"lvws {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
