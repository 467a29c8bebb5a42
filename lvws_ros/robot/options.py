"""The arguments of ``lvws fake-robots`` / ``fake_robots`` and what they are checked
into (no ROS here, so that building the ``lvws`` parser stays light): the cell, the robots
to serve, the clock rate, the duration noise and the scripted faults."""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass
from pathlib import Path

from lvws_ros.core.formats import load_instance
from lvws_ros.core.problem import Instance
from lvws_ros.errors import ConfigError
from lvws_ros.sim.instance_world import check_noise

__all__ = ["FakeCell", "FakeOptions", "add_arguments", "fake_cell"]


@dataclass(frozen=True)
class FakeOptions:
    """How the fake robots behave: ``rate`` (their time runs ``rate`` times faster than
    the node's clock), the duration noise (each task's work takes its planned duration x
    a factor in [1 - noise, 1 + noise] drawn from the seed and the task's id) and the
    scripted faults, (robot, task, phase) triples: an abort, a crash of the process, halfway
    through the work (phase ``working``) or through the way to the task's site
    (``travelling``)."""

    rate: float = 1.0
    noise: float = 0.0
    noise_seed: int = 0
    aborts: frozenset[tuple[str, str, str]] = frozenset()
    crashes: frozenset[tuple[str, str, str]] = frozenset()


@dataclass(frozen=True)
class FakeCell:
    """A checked ``fake-robots`` command line."""

    path: Path
    instance: Instance
    robots: tuple[str, ...]  # the robots this process serves
    options: FakeOptions
    namespace: str
    use_sim_time: bool


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("cell", help="the cell: an lvws-instance/1 file (docs/formats.md); its robots, sites and speeds")
    p.add_argument("--robots", default="", metavar="ID,ID",
                   help="serve only these robots (comma-separated; default: every robot of the cell)")
    p.add_argument("--namespace", default="", help="the cell's ROS namespace, the dispatcher's (e.g. /cellA)")
    p.add_argument("--rate", type=float, default=1.0,
                   help="the robots' time runs RATE times faster than the clock (tests, demos; default 1)")
    p.add_argument("--noise", type=float, default=0.0,
                   help="each task's work takes its planned duration x a factor in [1-NOISE, 1+NOISE] (default 0)")
    p.add_argument("--noise-seed", type=int, default=0, help="the noise's seed (the factor also depends on the task)")
    p.add_argument("--abort", action="append", default=[], metavar="ROBOT:TASK[:travelling]",
                   help="ROBOT aborts its first goal of TASK halfway through the work (or, with :travelling, "
                        "halfway to the task's site), with a message (repeatable)")
    p.add_argument("--crash", action="append", default=[], metavar="ROBOT:TASK[:travelling]",
                   help="the whole process exits at once when ROBOT is halfway through TASK's work (or, with "
                        ":travelling, halfway to its site), as if killed (repeatable)")
    p.add_argument("--use-sim-time", action="store_true", help="follow the simulated clock (/clock) instead of wall time")
    p.add_argument("--ros-args", nargs=argparse.REMAINDER, default=[], dest="ros_args", metavar="ARG",
                   help="ROS arguments to the end of the line (e.g. -r __ns:=/cellA)")


def fake_cell(args: argparse.Namespace) -> FakeCell:
    """Check the arguments against the cell; ConfigError (or InstanceError for the file)
    names the file and the item."""
    path = Path(args.cell)
    inst = load_instance(path)
    known = inst.robot_index
    robots = tuple(r for r in (s.strip() for s in args.robots.split(",")) if r) if args.robots else \
        tuple(r.id for r in inst.robots)
    for r in robots:
        if r not in known:
            raise ConfigError(f"{path}: --robots: unknown robot {r!r} (the cell's robots: {_few(known)})")
    if not robots:
        raise ConfigError(f"{path}: --robots: name at least one robot")
    if not (math.isfinite(args.rate) and args.rate > 0):
        raise ConfigError(f"--rate must be a finite number > 0, got {args.rate!r}")
    try:
        noise = check_noise(args.noise)
    except ConfigError as exc:
        raise ConfigError(f"--noise: {exc}") from None
    options = FakeOptions(rate=float(args.rate), noise=noise, noise_seed=int(args.noise_seed),
                          aborts=_faults(path, inst, "--abort", args.abort),
                          crashes=_faults(path, inst, "--crash", args.crash))
    return FakeCell(path, inst, robots, options, args.namespace, bool(args.use_sim_time))


FAULT_PHASES = ("working", "travelling")  # where a scripted fault strikes: halfway through which


def _faults(path: Path, inst: Instance, option: str, given: list[str]) -> frozenset[tuple[str, str, str]]:
    triples = set()
    for item in given:
        robot, sep, task = item.partition(":")
        head, colon, phase = task.rpartition(":")
        if colon and phase not in FAULT_PHASES and head in {t.id for t in inst.tasks}:
            raise ConfigError(f"{path}: {option} {item!r}: unknown phase {phase!r} (one of {', '.join(FAULT_PHASES)})")
        task, phase = (head, phase) if colon and phase in FAULT_PHASES else (task, FAULT_PHASES[0])
        if not sep or not robot or not task:
            raise ConfigError(f"{option} {item!r}: expected ROBOT:TASK or ROBOT:TASK:travelling")
        if robot not in inst.robot_index:
            raise ConfigError(f"{path}: {option} {item!r}: unknown robot {robot!r} "
                              f"(the cell's robots: {_few(inst.robot_index)})")
        triples.add((robot, task, phase))  # a task the file lacks may still be submitted at run time
    return frozenset(triples)


def _few(names: dict[str, int] | list[str], most: int = 10) -> str:
    names = list(names)
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")
