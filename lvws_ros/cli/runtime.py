"""``lvws`` commands of the case study and of recorded runs: sim, launch, submit, cancel,
fault, report, verify, replay (``lvws scheduler`` is the node itself, see
:mod:`lvws_ros.cli.main`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from lvws_ros.errors import LaunchError, WorldStuck
from lvws_ros.registry import LEARNED_POLICIES, POLICY_NAMES
from lvws_ros.ros.dashboard import DEFAULT_PORT
from lvws_ros.ros.dashboard import add_arguments as dashboard_arguments

T = TypeVar("T")


def cmd_sim(args: argparse.Namespace) -> int:
    from lvws_ros.core.formats import save_schedule
    from lvws_ros.core.schedule import check_schedule
    from lvws_ros.registry import make_policy
    from lvws_ros.ros.resources import case_study_config
    from lvws_ros.sim.config import load_cell_config
    from lvws_ros.sim.events import load_events
    from lvws_ros.sim.runner import run_offline
    from lvws_ros.sim.world import CellSim

    cfg = load_cell_config(args.config or case_study_config())
    if args.compare:
        return _compare_travel(cfg, args)
    sim = CellSim(cfg, noise=args.noise, noise_seed=args.seed)
    if args.noise:
        print(f"duration noise: each task takes its duration x a factor in [{1 - args.noise:g}, {1 + args.noise:g}] "
              f"(seed {args.seed})", file=sys.stderr)
    events = load_events(args.events) if args.events else None
    options = _options(args, args.policy)
    try:
        sched, decisions = run_offline(sim, make_policy(args.policy, seed=args.seed, **options),
                                       frame_every=args.frame_every if args.gif or args.frames else None,
                                       events=events)
    except WorldStuck as exc:
        print(f"lvws sim: the run ended: {exc}", file=sys.stderr)
        return 1
    problems = check_schedule(sim.executed_instance(), sched)
    print(f"{args.policy}: makespan {sched.makespan:.2f} s, {len(decisions)} decisions, "
          f"valid: {'yes' if not problems else problems}")
    if not events:  # the policy's own plan of the cell, for comparison
        from lvws_ros.core.executor import simulate

        plan = simulate(sim.inst, make_policy(args.policy, seed=args.seed, **options)).schedule.makespan
        print(f"  plan (the executor on the cell's instance{', travel included' if sim.inst.travel else ''}): "
              f"{plan:.2f} s; executed - plan: {sched.makespan - plan:+.2f} s "
              f"({100 * (sched.makespan - plan) / plan:+.2f} %)")
    if args.out:  # --out is where the schedule goes: stdout then carries no decision steps
        save_schedule(sched, args.out)
        print(f"written: {args.out}", file=sys.stderr)
    for d in [] if args.out else decisions:
        made = ", ".join(f"{t}<-{'+'.join(r)}" for t, r in d.assignments) or "-"
        print(f"  step {d.step} t={d.team_stamp:.2f}: {made}; waiting {', '.join(d.waiting) or '-'}")
    if args.gif:
        from lvws_ros.sim.render import render_gif

        print(render_gif(sim.cfg, sim.trace, sim.inst.num_tasks, args.gif))
    if args.frames:
        from lvws_ros.sim.render import render_frames

        paths = render_frames(sim.cfg, sim.trace, sim.inst.num_tasks, args.frames)
        print(f"{len(paths)} PNG frames in {args.frames}")
    return 0 if not problems else 1


def _options(args: argparse.Namespace, name: str) -> dict[str, Any]:
    """make_policy's options for ``name`` from ``lvws sim``'s arguments."""
    return {"model_path": args.model, "width": args.beam_width} if name in LEARNED_POLICIES else {}


def _compare_travel(cfg: Any, args: argparse.Namespace) -> int:
    """``lvws sim --compare``: each policy planned with travel, executed told the travel
    and not (lvws_ros.sim.runner.compare_travel), as a table."""
    from functools import partial

    from tqdm import tqdm

    from lvws_ros.errors import PolicyError
    from lvws_ros.registry import make_policy
    from lvws_ros.sim.runner import compare_travel

    names = [n for n in args.compare.split(",") if n]
    unknown = [n for n in names if n not in POLICY_NAMES]
    if unknown or not names:
        raise PolicyError(f"--compare: unknown policy {unknown[0]!r}; choose from {', '.join(POLICY_NAMES)}"
                          if unknown else "--compare: name at least one policy")

    def maker(name: str) -> Any:
        options = _options(args, name)
        return lambda: make_policy(name, seed=args.seed, **options)

    def one(name: str) -> list[Any]:  # a policy's plan and its two runs in the simulator
        return list(compare_travel(cfg, [(name, maker(name))], noise=args.noise, noise_seed=args.seed))

    rows = []
    with tqdm(total=len(names), desc="compare: plan, run told the travel, run told none", unit="policy",
              file=sys.stderr) as bar:
        for n in names:
            bar.set_postfix_str(n)
            rows += _ticking(bar, partial(one, n))
            bar.update()
    noisy = f", durations x U[{1 - args.noise:g}, {1 + args.noise:g}]" if args.noise else ""
    print(f"{cfg.name}: makespans in seconds of sim time (seed {args.seed}{noisy})")
    print("| policy | plan with travel | executed | executed - plan | executed, scheduler told no travel |")
    print("|---|---|---|---|---|")
    for r in rows:
        print(f"| {r.policy} | {r.plan:.2f} | {r.executed:.2f} | {100 * r.plan_error:+.2f} % | {r.blind:.2f} |")
    return 0


TICK_SECONDS = 1.0  # a progress bar's elapsed time is redrawn this often while a step runs


def _ticking(bar: Any, work: Callable[[], T]) -> T:
    """``work()`` on a thread of its own while ``bar`` (tqdm) redraws its elapsed time every
    TICK_SECONDS, so that a long step never leaves the terminal silent; its result (or its
    exception)."""
    from concurrent.futures import ThreadPoolExecutor
    from concurrent.futures import TimeoutError as Pending

    with ThreadPoolExecutor(max_workers=1) as pool:
        future = pool.submit(work)
        while True:
            try:
                return future.result(timeout=TICK_SECONDS)
            except Pending:
                bar.refresh()


def cmd_launch(args: argparse.Namespace) -> int:
    from lvws_ros.cli.report import report
    from lvws_ros.ros.launcher import launch

    if args.retire_after >= 0 and args.protocol != "changes":
        print("lvws launch: --retire-after needs --protocol changes (a snapshot world sends every task)",
              file=sys.stderr)
        return 2

    try:
        res = launch(policy=args.policy, seed=args.seed, model_path=args.model or "", rate=args.rate,
                     config=args.config or "", bag_dir=args.bag_dir, out_dir=args.out_dir, name=args.name,
                     params_file=args.params_file, gif=not args.no_gif, timeout=args.timeout,
                     sync=not args.no_sync, namespace=args.namespace, domain_id=args.domain_id,
                     events=args.events, dashboard=args.dashboard, robots=args.robots, instance=args.instance or "",
                     protocol=args.protocol, retire_after=args.retire_after)
    except LaunchError as exc:
        print(f"lvws launch: failed: {exc}", file=sys.stderr)
        return 1
    gantt = res.out_dir / "gantt.png"
    s = res.summary
    print("reading the bag back and drawing the Gantt chart ...", flush=True)
    print(report(res.bag, gantt).text())
    print()
    clock = "sim time" if args.robots == "sim" else f"the cell's time; the robots ran at --rate {args.rate:g}"
    print(f"makespan:  {float(s.get('makespan') or 0.0):.2f} s ({clock}), {s.get('tasks_done')}/{s.get('tasks')} tasks")
    print(f"decisions: {s.get('decisions_received')}" if args.robots == "sim" else
          f"goals:     {s.get('goals')} sent, {s.get('failures')} failed")
    print(f"wall time: {s.get('wall_seconds_total', 0):.1f} s")
    print(f"bag:       {res.bag}")
    print(f"gantt:     {gantt}")
    print(f"gif:       {res.gif}")
    print(f"logs:      {res.out_dir}")
    return 0


def cmd_world(args: argparse.Namespace) -> int:
    """lvws submit / cancel / fault: one service call to a running cell_sim."""
    from lvws_ros.ros.world_client import call_world, tasks_from_file

    ok, message = call_world(
        args.command, namespace=args.namespace, domain_id=args.domain_id,
        tasks=tasks_from_file(args.tasks) if args.command == "submit" else (),
        target=getattr(args, "task", "") or getattr(args, "robot", ""), failed=not getattr(args, "repair", False),
        timeout=args.timeout)
    print(f"lvws {args.command}: {'done' if ok else 'refused'}: {message}", file=sys.stdout if ok else sys.stderr)
    return 0 if ok else 1


def cmd_report(args: argparse.Namespace) -> int:
    from lvws_ros.cli.report import report

    out = args.gantt or str(Path(args.bag).with_name(Path(args.bag).name + "-gantt.png"))
    rep = report(args.bag, out)
    print(rep.text())
    print(f"gantt: {out}")
    return 0 if rep.complete and not rep.problems else 1


def cmd_verify(args: argparse.Namespace) -> int:
    from lvws_ros.cli.report import verify

    n, bad = verify(args.bag, policy=args.policy, seed=args.seed, model_path=args.model, beam_width=args.beam_width)
    for m in bad:
        print(f"step {m.step}: recorded {m.recorded}, offline {m.replayed}")
    print(f"{n - len(bad)}/{n} decisions reproduced" + (" (deterministic replay: ok)" if not bad else ""))
    return 0 if not bad else 1


def cmd_dashboard(args: argparse.Namespace) -> int:
    from lvws_ros.ros.dashboard import run

    return run(args)


def cmd_reindex(args: argparse.Namespace) -> int:
    from lvws_ros.ros.bag import reindex

    kept, conns = reindex(args.bag)
    print(f"{args.bag}: rebuilt with {kept} messages on {conns} connections (original kept as *.mcap.orig)")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from lvws_ros.ros.replay import replay

    replay(args.bag, args.rate, args.wait_for_subscribers, args.topics)
    return 0


Adder = Any  # (name, function, help) -> argparse.ArgumentParser


def add_parsers(add: Adder) -> None:
    _add_sim(add)
    _add_launch(add)
    _add_world_calls(add)
    _add_scheduler_and_bags(add)


def _add_sim(add: Adder) -> None:
    p = add("sim", cmd_sim, "run the assembly-cell case study in-process with a policy (no ROS)")
    p.add_argument("--policy", choices=POLICY_NAMES, default="lvws")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None, help="lvws/dbgm checkpoint (default: the shipped one)")
    p.add_argument("--beam-width", type=int, default=None,
                   help="lvws_beam: partial schedules kept at each depth (default: its DEFAULT_WIDTH)")
    p.add_argument("--config", default=None, help="assembly-cell YAML (default: config/assembly_cell.yaml)")
    p.add_argument("--noise", type=float, default=0.0,
                   help="duration noise: each task takes its duration x a factor drawn in [1 - NOISE, 1 + NOISE] "
                        "from --seed and its id (0, default: exact durations; below 1)")
    p.add_argument("--out", help="write the executed schedule (lvws-schedule/1) here instead of its decision steps "
                                  "on stdout")
    p.add_argument("--gif", help="write an animated GIF of the run here")
    p.add_argument("--frames", help="write a PNG per frame into this folder")
    p.add_argument("--frame-every", type=float, default=2.0, help="sim seconds between frames")
    p.add_argument("--events", default=None, help="scripted world events (YAML); see lvws_ros/sim/events.py")
    p.add_argument("--compare", default=None, metavar="POLICIES",
                   help="comma-separated policies: each one's plan with travel, its executed makespan, and the "
                        "makespan when the scheduler is told no travel (a cell with plan_travel)")


def _add_launch(add: Adder) -> None:
    p = add("launch", cmd_launch, "the case study on ROS 2: cell_sim + scheduler + recorder, then a summary")
    p.add_argument("--policy", choices=POLICY_NAMES, default=None,
                   help="scheduling policy (default: the --params-file's, else auto)")
    p.add_argument("--seed", type=int, default=None, help="policy seed (default: the --params-file's, else 0)")
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
    p.add_argument("--namespace", default="",
                   help="run the cell in this ROS namespace (topics /NAME/lvws/..., its own clock), so several "
                        "cells share one domain")
    p.add_argument("--domain-id", type=int, default=None,
                   help="ROS_DOMAIN_ID of the run (default: a random one, isolating it)")

    p.add_argument("--robots", choices=("sim", "actions"), default="sim",
                   help="sim: the simulator is the world; actions: the dispatcher and fake robots (one ExecuteTask "
                        "server each, --rate times faster than wall time), the bag holding the goal events")
    p.add_argument("--instance", default=None,
                   help="the cell (lvws-instance/1): the simulator runs it (its robots, sites, travel, traits, the way "
                        "home; each member sets out on its own with \"departure\": \"each\"), or with --robots "
                        "actions the dispatcher and fake robots (default: the --config cell written as one)")
    p.add_argument("--protocol", choices=("snapshots", "changes"), default="snapshots",
                   help="how the simulator sends the cell's state: its whole team and task graph at every step, or "
                        "numbered changes after the first snapshots (docs/ros.md)")
    p.add_argument("--retire-after", type=float, default=-1.0, metavar="SECONDS",
                   help="with --protocol changes: done work retires from the live cell this many sim seconds after "
                        "it ended, once its dependents have started (default -1: never); the bag keeps it")
    p.add_argument("--events", default=None, help="scripted world events (YAML: at t, submit / cancel / fail / "
                                                   "repair); see lvws_ros/sim/events.py")
    p.add_argument("--dashboard", type=int, nargs="?", const=DEFAULT_PORT, default=None, metavar="PORT",
                   help=f"serve the run's web dashboard on 127.0.0.1:PORT while it lasts (default port {DEFAULT_PORT}; "
                        "the printed URL carries its token)")


def _add_world_calls(add: Adder) -> None:
    """submit, cancel and fault: calls to a running cell's services."""
    for name, help_text in (
            ("submit", "add tasks to a running cell (cell_sim's submit_tasks service)"),
            ("cancel", "cancel a task of a running cell (cell_sim's cancel_task service)"),
            ("fault", "fail (or --repair) a robot of a running cell (cell_sim's set_robot_fault service)")):
        p = add(name, cmd_world, help_text)
        if name == "submit":
            p.add_argument("tasks", help="YAML list of task entries, like config/assembly_cell.yaml's tasks")
        elif name == "cancel":
            p.add_argument("task")
        else:
            p.add_argument("robot")
            p.add_argument("--repair", action="store_true", help="bring a failed robot back")
        p.add_argument("--namespace", default="", help="the cell's namespace (lvws launch --namespace)")
        p.add_argument("--domain-id", type=int, default=None, help="the cell's ROS_DOMAIN_ID (lvws launch prints it)")
        p.add_argument("--timeout", type=float, default=20.0, help="wall seconds to wait for the simulator")


def _add_scheduler_and_bags(add: Adder) -> None:
    """The scheduler node's --help, the dashboard (live or a bag) and the commands on
    recorded runs: report, verify, reindex, replay."""
    # main() hands `lvws scheduler ...` to the node; this parser only serves --help
    p = add("scheduler", None, "the scheduler node (same as `ros2 run lvws_ros scheduler`)")
    p.add_argument("ros_args", nargs=argparse.REMAINDER, help="--ros-args ... for rclpy")

    p = add("report", cmd_report, "makespan, assignments and a Gantt chart of a recorded run, from the bag alone")
    p.add_argument("bag")
    p.add_argument("--gantt", default=None, help="PNG path (default: next to the bag)")

    p = add("dashboard", cmd_dashboard, "the operator's web page of a cell: live over DDS, or a bag (--bag)")
    dashboard_arguments(p)

    p = add("verify", cmd_verify, "re-run the scheduler offline on a bag's inputs; exit 0 when it decides the same")
    p.add_argument("bag")
    p.add_argument("--policy", choices=POLICY_NAMES, default=None, help="default: the recorded one")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", default=None)
    p.add_argument("--beam-width", type=int, default=None, help="lvws_beam: the run's beam_width (default: the search's)")

    p = add("reindex", cmd_reindex, "rebuild the index and metadata.yaml of a bag whose recorder was killed "
            "(like `ros2 bag reindex`)")
    p.add_argument("bag")

    p = add("replay", cmd_replay, "republish a bag's messages with the recorded timing and QoS")
    p.add_argument("bag")
    p.add_argument("--rate", type=float, default=1.0)
    p.add_argument("--wait-for-subscribers", type=float, default=2.0)
    p.add_argument("--topics", nargs="*", default=None)
