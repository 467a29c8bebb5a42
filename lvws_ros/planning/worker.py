"""The planner in a process of its own, beside whoever dispatches from its plan.

:class:`PlannerProcess` starts a child process (``spawn``: no thread or DDS state of the
parent is copied into it) that runs a :class:`~lvws_ros.planning.planner.Planner`. The
parent sends the cell when it changes and the state after each of its decisions; the
child plans from the newest state it has (older ones are skipped), sends the plan at once
(the old plan carried out from the new state, :meth:`~lvws_ros.planning.planner.Planner.rebase`),
then the quick plans when the world departed from the plan, then every improvement, and
improves while nothing new arrives. The parent never waits for it: :meth:`PlannerProcess.latest`
reads what has arrived. The child ends when told, when the pipe closes, or when its parent
is gone.

Messages (pickled over a :func:`multiprocessing.Pipe`): to the child ``("cell", Instance)``,
``("state", StatePayload)``, ``("stop",)``; to the parent ``("ready",)`` once, then
``("plan", PlanUpdate)``. As with every ``spawn`` start, a script that starts the planner
must guard its own work with ``if __name__ == "__main__":`` (the child imports the parent's
main module); the package's entry points do.
"""

from __future__ import annotations

import multiprocessing
import os
import time
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

import numpy as np

from lvws_ros.core.executor import State
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.planning.planner import Planner, PlanReport

QUICK_SECONDS = 60.0  # the child's quick plans from one state: at most this long in all
PARENT_CHECK = 1.0  # seconds between the child's looks at whether its parent is still there

__all__ = ["PlanUpdate", "PlannerProcess"]

StatePayload = tuple[float, np.ndarray, np.ndarray, np.ndarray, list[tuple[int, ...]], int, np.ndarray | None]


@dataclass(frozen=True)
class PlanUpdate:
    """A plan from the child: the whole schedule from the state of decision ``step``."""

    step: int
    schedule: Schedule
    report: PlanReport


def _payload(state: State) -> StatePayload:
    return (state.time, state.robot_free_at, state.task_status, state.task_start, list(state.task_team), state.step,
            state.robot_site)


def _state(inst: Instance, p: StatePayload) -> State:
    return State(inst, p[0], p[1], p[2], p[3], list(p[4]), p[5], p[6])


def _serve(conn: Connection, options: dict[str, Any], parent: int) -> None:
    """The child's loop (module docstring)."""
    planner = Planner(**options)
    planner.open_ended = True
    if planner.learned:
        planner.lvws()  # the model loaded before the first state comes
    conn.send(("ready",))
    inst: Instance | None = None
    state: State | None = None

    def send() -> None:
        assert planner.plan is not None
        conn.send(("plan", PlanUpdate(planner.plan.state.step, planner.plan.schedule, planner.report())))

    while True:
        if os.getppid() != parent:
            return
        while True:  # everything that has arrived; when there is nothing to do, wait for news
            busy = state is not None or (planner.plan is not None and not planner.exhausted)
            if not conn.poll(0 if busy else PARENT_CHECK):
                if busy or os.getppid() != parent:
                    break
                continue
            try:
                msg = conn.recv()
            except EOFError:
                return
            if msg[0] == "stop":
                return
            if msg[0] == "cell":
                inst = msg[1]
            elif msg[0] == "state" and inst is not None:
                state = _state(inst, msg[1])
        if state is not None:
            if planner.rebase(state, quick=False):
                send()  # the old plan re-timed (or GRP's): at once
                assert planner.plan is not None
                planner.quick_plans(planner.plan.state, time.perf_counter() + QUICK_SECONDS)
            send()
            state = None
        elif planner.improve(time.perf_counter() + planner.slice):
            send()


class PlannerProcess:
    """The parent's handle on the planner's child process (module docstring)."""

    def __init__(self, **options: Any) -> None:
        self.options = options
        self.process: BaseProcess | None = None
        self.conn: Connection | None = None
        self.cell: Instance | None = None  # the cell the child has
        self.ready = False  # the child has started and said so
        self.starts = 0

    def start(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        ours, theirs = ctx.Pipe()
        self.process = ctx.Process(target=_serve, args=(theirs, self.options, os.getpid()), daemon=True,
                                   name="lvws-planner")
        self.process.start()
        theirs.close()
        self.conn, self.cell, self.ready = ours, None, False
        self.starts += 1

    def wait_ready(self, timeout: float) -> bool:
        """Wait at most ``timeout`` seconds for the child to have started (its imports and
        model loaded); True when it has."""
        if self.ready:
            return True
        if self.conn is None:
            return False
        try:
            if self.conn.poll(timeout):
                msg = self.conn.recv()
                self.ready = msg[0] == "ready"
        except (EOFError, OSError):
            return False
        return self.ready

    def alive(self) -> bool:
        return self.process is not None and self.process.is_alive()

    def send(self, state: State) -> bool:
        """Hand ``state`` to the child (the cell first when it changed); False when the
        child is gone."""
        if self.conn is None or not self.alive():
            return False
        try:
            if self.cell is not state.instance:
                self.conn.send(("cell", state.instance))
                self.cell = state.instance
            self.conn.send(("state", _payload(state)))
        except (BrokenPipeError, ConnectionResetError, EOFError, OSError):
            return False
        return True

    def latest(self, wait: float = 0.0) -> PlanUpdate | None:
        """The newest plan the child sent since the last call (None: none), waiting at most
        ``wait`` seconds for one."""
        out: PlanUpdate | None = None
        if self.conn is None:
            return None
        try:
            end = time.perf_counter() + wait
            while self.conn.poll(max(0.0, end - time.perf_counter()) if out is None else 0):
                msg = self.conn.recv()
                if msg[0] == "plan":
                    out = msg[1]
        except (EOFError, OSError):
            pass
        return out

    def stop(self) -> None:
        """End the child (politely, then by force)."""
        if self.conn is not None:
            try:
                self.conn.send(("stop",))
            except (BrokenPipeError, OSError):
                pass
        if self.process is not None:
            self.process.join(2.0)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(2.0)
        if self.conn is not None:
            self.conn.close()
        self.process = self.conn = None
