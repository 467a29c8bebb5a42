"""The planner in a process of its own, beside whoever dispatches from its plan.

:class:`PlannerProcess` starts a child process (``spawn``: no thread or DDS state of the
parent is copied into it) that runs a :class:`~lvws_ros.planning.planner.Planner`. The
parent sends the cell when it changes and the state after each of its decisions; the
child plans from the newest state it has (older ones are skipped), sends the plan at once
(the old plan carried out from the new state, :meth:`~lvws_ros.planning.planner.Planner.rebase`),
then the quick plans when the world departed from the plan, then every improvement, and
improves while nothing new arrives. The parent never waits for it: a receiver thread reads
what arrives, unpickles only the newest plan and prepares it for use (``prepare``: the
follower of ``auto``, mapped onto its cell), off the decision's path; :meth:`PlannerProcess.latest`
hands over the newest. The child ends when told, when the pipe closes, or when its parent
is gone.

Messages (pickled over a one-way :func:`multiprocessing.Pipe` each way): to the child
``("cell", Instance)``, ``("state", seq, StatePayload)``, ``("stop",)``; to the parent
``("ready",)`` once, then ``("plan", seq, bytes)``: a :class:`PlanUpdate` pickled by the child
(``seq``: the number of the state the plan is made from), which the receiver thread unpickles
only when it is the newest that arrived and, once a plan was handed over, made from the newest
state sent (a plan from an older one has not seen the decisions since: the child sends it
again from the newest). As with every ``spawn`` start, a script
that starts the planner must guard its own work with ``if __name__ == "__main__":`` (the
child imports the parent's main module); the package's entry points do.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import Any

import numpy as np

from lvws_ros.core.executor import State
from lvws_ros.core.problem import Instance
from lvws_ros.core.schedule import Schedule
from lvws_ros.planning import PLANNER_NICENESS
from lvws_ros.planning.planner import Clock, Planner, PlanReport

QUICK_SECONDS = 60.0  # the child's quick plans from one state: at most this long in all
PARENT_CHECK = 1.0  # seconds between the child's looks at whether its parent is still there

__all__ = ["PlanUpdate", "PlannerProcess"]

StatePayload = tuple[float, np.ndarray, np.ndarray, np.ndarray, list[tuple[int, ...]], int, np.ndarray | None]


@dataclass(frozen=True)
class PlanUpdate:
    """A plan from the child: the whole schedule from the ``seq``-th state it was sent."""

    seq: int
    schedule: Schedule
    report: PlanReport
    prepared: Any = field(default=None, compare=False)  # what the parent's ``prepare`` made of it


def _payload(state: State) -> StatePayload:
    return (state.time, state.robot_free_at, state.task_status, state.task_start, list(state.task_team), state.step,
            state.robot_site)


def _state(inst: Instance, p: StatePayload) -> State:
    return State(inst, p[0], p[1], p[2], p[3], list(p[4]), p[5], p[6])


def lower_priority(niceness: int) -> None:
    """This process, every thread of it (on Linux ``os.nice`` moves the calling thread only,
    and numpy's thread pool started at import), ``niceness`` below where it runs; threads
    started later inherit it. Raising one's own niceness needs no privilege."""
    own = os.nice(0)
    target = min(19, own + niceness)
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:  # not Linux: the process as one
        os.nice(target - own)
        return
    for tid in threads:
        try:
            os.setpriority(os.PRIO_PROCESS, tid, max(target, os.getpriority(os.PRIO_PROCESS, tid)))
        except OSError:  # a thread that ended meanwhile
            pass


def _serve(inbox: Connection, outbox: Connection, options: dict[str, Any], parent: int, niceness: int = 0) -> None:
    """The child's loop (module docstring)."""
    if niceness > 0:
        lower_priority(niceness)
    planner = Planner(**options)
    planner.clock = Clock.OPEN_ENDED
    if planner.learned:
        planner.lvws()  # the model loaded before the first state comes
    outbox.send(("ready",))
    inst: Instance | None = None
    state: State | None = None
    seq = 0  # of the state the plan is made from

    def send() -> None:
        assert planner.plan is not None
        # pickled here, unpickled by the parent only when it is the newest that arrived
        outbox.send(("plan", seq, pickle.dumps(PlanUpdate(seq, planner.plan.schedule, planner.report()),
                                          protocol=pickle.HIGHEST_PROTOCOL)))

    while True:
        if os.getppid() != parent:
            return
        while True:  # everything that has arrived; when there is nothing to do, wait for news
            busy = state is not None or (planner.plan is not None and not planner.exhausted)
            if not inbox.poll(0 if busy else PARENT_CHECK):
                if busy or os.getppid() != parent:
                    break
                continue
            try:
                msg = inbox.recv()
            except EOFError:
                return
            if msg[0] == "stop":
                return
            if msg[0] == "cell":
                inst = msg[1]
            elif msg[0] == "state" and inst is not None:
                state, seq = _state(inst, msg[2]), msg[1]
        if state is not None:
            if planner.rebase(state, quick=False):
                send()  # the old plan re-timed (or GRP's): at once
                assert planner.plan is not None
                planner.quick_plans(planner.plan.state, time.perf_counter() + QUICK_SECONDS)
            send()
            state = None
        elif planner.improve(time.perf_counter() + planner.slice):
            send()


RECEIVE_POLL = 0.1  # seconds the receiver thread waits on the pipe between looks at whether it should stop
RECEIVE_BURST = 1000  # messages read in a row before the newest plan among them is prepared
PICKLE_TRIES = 100  # a cell pickled while the decision thread fills one of its caches is pickled again


def _send_pickled(conn: Connection, msg: tuple[Any, ...]) -> None:
    """``conn.send(msg)`` from the sender thread while the decision thread may fill a lazy
    cache of the cell (a dict that changes size while it is pickled: RuntimeError, nothing
    written); tried again after a moment."""
    for _ in range(PICKLE_TRIES - 1):
        try:
            conn.send(msg)
            return
        except RuntimeError:
            time.sleep(0.01)
    conn.send(msg)


class PlannerProcess:
    """The parent's handle on the planner's child process (module docstring). What goes to
    the child is handed to a sender thread that keeps only the newest state (and the cell
    it belongs to): a child busy with a long round never blocks the parent. What comes back
    is read by a receiver thread, which keeps the newest plan, unpickled and made ready by
    ``prepare`` (in that thread: the result is the caller's once :meth:`latest` hands it over)."""

    def __init__(self, niceness: int = PLANNER_NICENESS, prepare: Callable[[PlanUpdate], Any] | None = None,
                 **options: Any) -> None:
        self.options = options
        self.niceness = niceness  # the child's, above the parent's (0: the parent's priority)
        self.prepare = prepare
        self._arrived: PlanUpdate | None = None  # the newest plan, not handed over yet
        self._receiver: threading.Thread | None = None
        self._receiving = False  # the receiver thread reads the child's pipe
        self.handed = False  # a plan was handed over (latest): plans from older states are dropped unread
        self.failure = ""  # why the receiver thread stopped reading, when something broke it
        self.process: BaseProcess | None = None
        self.inbox: Connection | None = None  # plans from the child
        self.outbox: Connection | None = None  # cells and states to the child
        self.cell: Instance | None = None  # the cell the child has (or will have)
        self.ready = False  # the child has started and said so
        self.starts = 0
        self._pending: tuple[Instance | None, int, StatePayload] | None = None  # the newest, not sent yet
        self.sent = 0  # states handed over (the newest one's number)
        self._wake = threading.Condition()
        self._sender: threading.Thread | None = None
        self._closed = False

    def start(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        to_child, into_child = ctx.Pipe(duplex=False)  # (read end, write end)
        from_child, out_of_child = ctx.Pipe(duplex=False)
        self.process = ctx.Process(target=_serve, args=(to_child, out_of_child, self.options, os.getpid(), self.niceness),
                                   daemon=True, name="lvws-planner")
        self.process.start()
        to_child.close()
        out_of_child.close()
        self.inbox, self.outbox, self.cell, self.ready = from_child, into_child, None, False
        self._pending, self._closed = None, False
        self._sender = threading.Thread(target=self._send_loop, args=(into_child,), daemon=True,
                                        name="lvws-planner-sender")
        self._sender.start()
        self._arrived, self._receiving = None, True
        self._receiver = threading.Thread(target=self._receive_loop, args=(from_child,), daemon=True,
                                          name="lvws-planner-receiver")
        self._receiver.start()
        self.starts += 1

    def _receive_loop(self, conn: Connection) -> None:
        """Read what the child sends; keep the newest plan (older ones dropped unread: a
        plan of 5,000 tasks takes ~10 ms to unpickle), prepared; wake whoever waits. Ends
        at :meth:`stop` or when the child is gone."""
        try:
            self._receive(conn)
        except Exception as exc:  # whatever breaks reading: the process counts as gone (alive), and says why
            self.failure = f"{type(exc).__name__}: {exc}"
        finally:
            with self._wake:
                self._receiving = False
                self._wake.notify_all()

    def _receive(self, conn: Connection) -> None:
        gone = False
        while not (self._closed or gone):
            newest: bytes | None = None
            try:
                for _ in range(RECEIVE_BURST):  # what arrived meanwhile; then the newest plan is prepared
                    if not conn.poll(0 if newest is not None else RECEIVE_POLL) or self._closed:
                        break
                    msg = conn.recv()
                    if msg[0] == "plan" and (msg[1] == self.sent or not self.handed):
                        newest = msg[2]
                    elif msg[0] == "ready":
                        with self._wake:
                            self.ready = True
                            self._wake.notify_all()
            except (EOFError, OSError):
                gone = True
            if newest is not None and not self._closed:
                update: PlanUpdate = pickle.loads(newest)  # our own child's (the pipe's pickles are too)
                if self.prepare is not None:
                    try:
                        update = replace(update, prepared=self.prepare(update))
                    except Exception:  # unprepared: the caller prepares it, as it did before
                        pass
                with self._wake:
                    self._arrived = update
                    self._wake.notify_all()

    def _send_loop(self, conn: Connection) -> None:
        while True:
            with self._wake:
                while self._pending is None and not self._closed:
                    self._wake.wait()
                if self._closed:
                    return
                cell, seq, payload = self._pending  # type: ignore[misc]
                self._pending = None
            try:
                if cell is not None:
                    _send_pickled(conn, ("cell", cell))
                conn.send(("state", seq, payload))
            except (BrokenPipeError, ConnectionResetError, EOFError, OSError):
                return

    def wait_ready(self, timeout: float) -> bool:
        """Wait at most ``timeout`` seconds for the child to have started (its imports and
        model loaded); True when it has."""
        with self._wake:
            self._wake.wait_for(lambda: self.ready or not self._receiving, timeout)
            return self.ready

    def alive(self) -> bool:
        """The child runs and its plans are read."""
        return self.process is not None and self.process.is_alive() and self._receiving

    def send(self, state: State) -> bool:
        """Hand ``state`` to the child (the cell first when it changed), at once: the sender
        thread sends it, replacing a state not sent yet; False when the child is gone."""
        if self.outbox is None or not self.alive():
            return False
        with self._wake:
            cell = None
            if self.cell is not state.instance:
                cell = self.cell = state.instance
            elif self._pending is not None:
                cell = self._pending[0]  # a new cell not sent yet goes with the newer state
            self.sent += 1
            self._pending = (cell, self.sent, _payload(state.copy()))
            self._wake.notify_all()
        return True

    def latest(self, wait: float = 0.0) -> PlanUpdate | None:
        """The newest plan the child sent since the last call (None: none), waiting at most
        ``wait`` seconds for one."""
        with self._wake:
            if self._arrived is None and wait > 0:
                self._wake.wait_for(lambda: self._arrived is not None or not self._receiving, wait)
            out, self._arrived = self._arrived, None
            self.handed = self.handed or out is not None
        return out

    def _drain(self, wait: float) -> None:
        """Read and drop what the child has sent, waiting at most ``wait`` seconds for it
        (at :meth:`stop`, the receiver thread ended)."""
        try:
            for _ in range(1000):  # a child sending without pause cannot hold this side here
                if self.inbox is None or not self.inbox.poll(wait):
                    return
                self.inbox.recv()
                wait = 0.0
        except (EOFError, OSError):
            pass

    def stop(self) -> None:
        """End the child (politely, then by force) and the sender thread. What the child
        sends meanwhile is read and dropped: a child blocked on a full pipe to this side
        would never read the stop (nor let the sender finish)."""
        with self._wake:
            self._closed = True
            self._wake.notify_all()
        if self._receiver is not None:  # this side's pipe gets one reader at a time
            self._receiver.join(2.0)
        end = time.perf_counter() + 2.0
        while self._sender is not None and self._sender.is_alive() and time.perf_counter() < end:
            self._drain(0.05)
        if self.outbox is not None and not (self._sender is not None and self._sender.is_alive()):
            try:  # the sender is done: this side is the pipe's only writer
                self.outbox.send(("stop",))
            except (BrokenPipeError, OSError):
                pass
        if self.process is not None:
            end = time.perf_counter() + 2.0
            while self.process.is_alive() and time.perf_counter() < end:
                self._drain(0.05)
                self.process.join(0.05)
            if self.process.is_alive():
                self.process.kill()
                self.process.join(2.0)
        for conn in (self.inbox, self.outbox):
            if conn is not None:
                conn.close()
        self.process = self.inbox = self.outbox = self._sender = self._receiver = None
