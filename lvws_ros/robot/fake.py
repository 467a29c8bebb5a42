"""Fake robots: every robot of a cell file (or some of them) as a :class:`FakeRobot`, one
``<robot id>/execute_task`` server each, all in one process: ``lvws fake-robots CELL.json``
or ``ros2 run lvws_ros fake_robots CELL.json``.

A fake robot does its part of a goal as the cell file says a robot would: it travels from
the site it is at to ``goal.site`` (the distance over its speed; a fixed robot, with no
speed, never leaves its site, and aborts a goal elsewhere), then works for
``planned_duration`` (times the ``--noise`` factor of the task, the cell simulator's rule:
:func:`~lvws_ros.sim.instance_world.duration_factor`), and ends at ``goal.site_to`` (or
``goal.site``). Arrived before ``goal.planned_start`` (seconds of ROS time; 0: none, or
the later start the dispatcher published since on ``lvws/planned_starts``), it waits there,
reporting ``waiting``, and starts work at the planned start: the dispatcher plans
the start for when the last member of the subteam can be there (each member sets out once it
is free). A member that sets out late moves the start (the others wait for the new one);
one that is slow on its way holds nobody back: each starts at the planned start or on
arrival, whichever is later (the dispatcher counts the task from its last member's
start). Feedback comes every 0.1 s of wall time: the phase, the progress over travel and
work together, the site (empty while travelling) and the pose (interpolated between
the sites' coordinates). A transport's work (``site_to`` elsewhere) moves the robot from
``site`` to ``site_to``, reported between sites. A goal stopped on the way (cancelled or
aborted) leaves the robot between sites, at the pose it last reported (its next travel is
the straight line from there); one stopped while working, at the task's site. With
``--rate R`` travel and work take R times less time on the node's clock; the result's
duration is in the robot's own, faster, seconds (the cell's).

Scripted faults: ``--abort ROBOT:TASK`` aborts that robot's first goal of that task
halfway through the work with a message (a later goal of the same task succeeds);
``--crash ROBOT:TASK`` ends the whole process there and then (``os._exit``, as a SIGKILL
would: no result, no goodbye). With ``ROBOT:TASK:travelling`` either strikes halfway
along the way to the task's site instead (never when the robot is there already): the
rest of its subteam may be waiting at the site.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from lvws_msgs.action import ExecuteTask
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from lvws_ros.core.problem import Instance
from lvws_ros.errors import LvwsError
from lvws_ros.robot.options import FakeCell, FakeOptions, add_arguments, fake_cell
from lvws_ros.robot.server import TaskFailed, TaskFeedback, TaskServer, action_name, serve
from lvws_ros.sim.instance_world import duration_factor

__all__ = ["CRASH_EXIT", "FakeRobot", "main", "run"]

FEEDBACK_SECONDS = 0.1  # wall seconds between two feedback messages
FAULT_AT = 0.5  # --abort and --crash strike at this share of the work (or of the way)
MAX_WAIT = 86_400.0  # robot seconds: a planned start further ahead is on another clock, and not waited for
CRASH_EXIT = 137  # the exit status of --crash: what a shell reports for a SIGKILLed process

TRAVELLING = ExecuteTask.Feedback.PHASE_TRAVELLING
WAITING = ExecuteTask.Feedback.PHASE_WAITING
WORKING = ExecuteTask.Feedback.PHASE_WORKING

Where = Callable[[float], tuple[str, tuple[float, float, float] | None]]  # share done -> site, pose


class FakeRobot(TaskServer):
    """One robot of ``instance`` simulated: travel, work, faults (the module's doc)."""

    def __init__(self, instance: Instance, robot_id: str, options: FakeOptions | None = None, **server_args: Any):
        super().__init__(robot_id, **server_args)
        self.instance = instance
        self.options = options or FakeOptions()
        self.aborted: set[tuple[str, str]] = set()  # the (task, phase) whose scripted abort happened (once each)
        k = instance.robot_index[robot_id]
        travel = instance.travel
        self.speed = travel.robot_speed[k] if travel is not None else 0.0
        # the site the robot is at (an index into travel.sites); None: between sites, at xy (or a cell without sites)
        self.site: int | None = travel.robot_site[k] if travel is not None else None
        self.xy = travel.coordinates[travel.robot_site[k]] if travel is not None else (0.0, 0.0)
        self.theta = 0.0

    def now(self) -> float:
        """The robot's seconds: the node's clock, ``rate`` times faster."""
        return super().now() * self.options.rate

    @property
    def site_name(self) -> str:
        travel = self.instance.travel
        return travel.sites[self.site] if travel is not None and self.site is not None else ""

    def execute(self, goal: Any, feedback: TaskFeedback) -> Any:
        target, end = self._site(goal.site), self._site(goal.site_to or goal.site)
        way = self._travel_seconds(goal, target, end)
        work = max(float(goal.planned_duration), 0.0) * duration_factor(
            self.options.noise, self.options.noise_seed, goal.task_id)
        share = way / (way + work) if way + work > 0 else 0.0
        if way > 0:
            way_there = self._way(target, goal.site)
            self._phase(feedback, TRAVELLING, way, (0.0, share), lambda f: ("", way_there(f)[1]),  # no site until working
                        task=goal.task_id)
        travel = self.instance.travel
        if travel is not None and target is not None:
            self.site, self.xy = target, travel.coordinates[target]
        self._wait(feedback, share, self._way(target, goal.site))
        # a transport (site_to elsewhere) moves its subteam while it works
        self._phase(feedback, WORKING, work, (share, 1.0), self._way(end, goal.site_to or goal.site),
                    task=goal.task_id)
        return ExecuteTask.Result(success=True, duration=work,
                                  message=f"{self.robot_id} did its part of {goal.task_id!r} in {work:.2f} s"
                                          f"{' after ' + format(way, '.2f') + ' s of travel' if way else ''}")

    def _wait(self, feedback: TaskFeedback, share: float, here: Where) -> None:
        """At the site before the planned start: report ``waiting`` until it (the start
        may move later meanwhile: :attr:`TaskFeedback.planned_start`)."""
        while (left := feedback.planned_start - super().now()) > 0:  # seconds of the node's clock
            if left * self.options.rate > MAX_WAIT:  # a planned start on another clock than this robot's
                self.get_logger().warning(f"{self.robot_id}: task {feedback.goal.task_id!r} planned to start "
                                          f"{left * self.options.rate:.0f} s from now: the dispatcher's clock is not "
                                          "this robot's (--rate, --use-sim-time); starting at once")
                return
            site, pose = here(1.0)
            feedback.send(WAITING, share, site, pose)
            feedback.sleep(min(FEEDBACK_SECONDS, left))

    def _site(self, name: str) -> int | None:
        """The index of site ``name`` ('' or a cell without sites: where the robot is)."""
        travel = self.instance.travel
        if not name or travel is None:
            return self.site
        if name not in travel.sites:
            raise TaskFailed(f"{self.robot_id}: unknown site {name!r} (the cell's sites: {', '.join(travel.sites)})")
        return travel.sites.index(name)

    def _travel_seconds(self, goal: Any, target: int | None, end: int | None) -> float:
        travel = self.instance.travel
        if travel is None or target is None or (target == self.site and end == target):
            return 0.0
        if self.speed <= 0:
            raise TaskFailed(f"{self.robot_id} is fixed at site {self.site_name!r}: it cannot do task "
                             f"{goal.task_id!r} at {goal.site!r}" + (f" to {goal.site_to!r}" if end != target else ""))
        if self.site is None:  # stopped between sites: the straight line from where it stands
            (xa, ya), (xb, yb) = self.xy, travel.coordinates[target]
            return math.hypot(xb - xa, yb - ya) / self.speed
        return float(travel.distance[self.site, target]) / self.speed

    def _way(self, dest: int | None, label: str) -> Where:
        """Where the robot is at each share of a phase that ends at site ``dest``: still at
        its site, or on the straight line to ``dest``, between sites (site "") until it is
        there. The robot's own site and pose follow, so a goal stopped on the way leaves it
        between sites, at the pose it last reported."""
        travel = self.instance.travel
        if travel is None or dest is None:
            return lambda share: (label, None)
        (xa, ya), (xb, yb), name = self.xy, travel.coordinates[dest], travel.sites[dest]
        if dest == self.site:
            return lambda share: (name, (xb, yb, self.theta))
        if (xa, ya) != (xb, yb):
            self.theta = math.atan2(yb - ya, xb - xa)

        def where(share: float) -> tuple[str, tuple[float, float, float]]:
            self.xy = (xa + (xb - xa) * share, ya + (yb - ya) * share)
            self.site = dest if share >= 1.0 else None
            return (name if share >= 1.0 else "", (*self.xy, self.theta))
        return where

    def _phase(self, feedback: TaskFeedback, phase: str, seconds: float, progress: tuple[float, float],
               where: Where, task: str | None = None) -> None:
        """Report ``phase`` every FEEDBACK_SECONDS until ``seconds`` of robot time went by;
        with ``task`` given, strike the scripted fault of this phase halfway."""
        start, rate = self.now(), self.options.rate
        while True:
            done = min((self.now() - start) / seconds, 1.0) if seconds > 0 else 1.0
            site, pose = where(done)
            feedback.send(phase, progress[0] + (progress[1] - progress[0]) * done, site, pose)
            if task is not None and done >= FAULT_AT:
                self._fault(task, phase, done)
            if done >= 1.0:
                return
            feedback.sleep(min(FEEDBACK_SECONDS, (1.0 - done) * seconds / rate))

    def _fault(self, task: str, phase: str, done: float) -> None:
        if (self.robot_id, task, phase) in self.options.crashes:
            sys.stderr.write(f"fake robot {self.robot_id}: crashing during task {task!r}, {phase} (--crash): "
                             "the process exits now\n")
            sys.stderr.flush()
            os._exit(CRASH_EXIT)
        if (self.robot_id, task, phase) in self.options.aborts and (task, phase) not in self.aborted:
            self.aborted.add((task, phase))
            part = "its work" if phase == WORKING else "its way to the site"
            raise TaskFailed(f"{self.robot_id} aborts task {task!r} at {100 * done:.0f} % of {part} "
                             "(a scripted fault: --abort)")


def run(args: argparse.Namespace, ros_args: Sequence[str] | None = None) -> int:
    """Serve the robots of ``args`` (:func:`~lvws_ros.robot.options.add_arguments`) until
    Ctrl-C or SIGTERM; ``ros_args``: rclpy's command line (default: ``args.ros_args``).
    LvwsError (bad input, naming the file and the item) before any server starts."""
    cell = fake_cell(args)
    for r in cell.robots:
        try:
            action_name(r)
        except LvwsError as exc:
            raise type(exc)(f"{cell.path}: {exc}") from None
    rclpy.init(args=list(ros_args) if ros_args is not None else ["fake_robots", "--ros-args", *args.ros_args])
    try:
        robots = _make_robots(cell)
    except BaseException:
        rclpy.try_shutdown()
        raise
    sys.stderr.write(f"fake robots of {cell.path}: serving {', '.join(cell.robots)} on "
                     f"{robots[0].get_namespace()} at rate {cell.options.rate:g}\n")
    sys.stderr.flush()
    return serve(robots)


def _make_robots(cell: FakeCell) -> list[FakeRobot]:
    overrides = [Parameter("use_sim_time", value=True)] if cell.use_sim_time else []
    robots: list[FakeRobot] = []
    try:
        for r in cell.robots:
            robots.append(FakeRobot(cell.instance, r, cell.options, namespace=cell.namespace,
                                    parameter_overrides=overrides))
    except BaseException:
        for robot in robots:
            robot.destroy_node()
        raise
    return robots


def main(argv: Sequence[str] | None = None) -> int:
    """The ``fake_robots`` executable (``ros2 run lvws_ros fake_robots CELL.json``; it
    takes ``--ros-args`` too)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(prog="fake_robots", description="Fake robots of a cell: one ExecuteTask "
                                     "action server per robot, travelling and working as the cell file says.")
    add_arguments(parser)
    args = parser.parse_args(remove_ros_args([parser.prog, *argv])[1:])
    try:
        return run(args, [parser.prog, *argv])
    except (LvwsError, OSError) as exc:
        sys.stderr.write(f"fake_robots: error: {exc}\n")
        return 2


if __name__ == "__main__":
    sys.exit(main())
