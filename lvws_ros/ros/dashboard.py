"""The operator's web page: ``lvws dashboard`` (a live cell over DDS, or a bag with a time slider).

One page, served on 127.0.0.1 by Starlette under uvicorn, charts drawn by plotly.js (served
from the ``plotly`` wheel), updated over a websocket twice a second:

* the Gantt chart, executed against planned (a decision's start plus the task's duration),
  the robots told to wait marked, subteams labelled with their size;
* the task graph, each task coloured by its status, the critical path of what is left
  (longest by duration) drawn thick;
* each robot's state (a table) and the cell picture: sites and robots at their poses;
* diagnostics and the decision latency per step;
* live: buttons for the world's services, the simulator's or the dispatcher's (submit tasks
  from a YAML file, cancel a task, fail or repair a robot), with the service's answer shown
  (none with ``--read-only``).

Access: the views (``/view``, the websocket) and every control action (``POST /world``)
need the dashboard's token, generated at start (:func:`~lvws_ros.ros.launcher.new_token`) and printed in the page's
URL (``?token=``) as Jupyter does, or given (``--token``, or the ``LVWS_DASHBOARD_TOKEN``
environment variable; a given token is never printed). The page passes the token of its
URL on; a request without it, with another, or from another page's origin gets 403 and
changes nothing. Tokens are compared in constant time (:func:`hmac.compare_digest`).

:class:`CellView` turns what the cell published (team and graph snapshots, decisions,
diagnostics) into the page's JSON; it is the same for a live cell (:class:`LiveFeed`, an
rclpy node in its namespace) and for a bag (:func:`~lvws_ros.ros.bag.read_run`). The page
reads nothing but that JSON.
"""

from __future__ import annotations

import argparse
import asyncio
import hmac
import json
import math
import os
import sys
import tempfile
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from lvws_ros.core.executor import TaskStatus
from lvws_ros.core.online import GraphSnapshot, OnlineDecision, TeamSnapshot
from lvws_ros.errors import LvwsError
from lvws_ros.ros.launcher import DASHBOARD_TOKEN_ENV as TOKEN_ENV
from lvws_ros.ros.launcher import new_token

DEFAULT_PORT = 8080
PUSH_SECONDS = 0.5  # the page is sent a new view this often
KEPT_DIAGNOSTICS = 200  # the latest statuses shown (and kept, live)
KEPT_DECISIONS = 20_000  # live: the latest decisions kept (the Gantt's assigned bars)
TOKEN_HEADER = "x-lvws-token"  # how a control action carries the token (the websocket: ?token=)
# The cell picture's labels are placed in data units for a plot of at least this many pixels
# (the page's cell panel is larger on any window the page fits), in the page's font.
CELL_PLOT_PX = (520.0, 240.0)
LABEL_CHAR_PX, LABEL_LINE_PX = 7.5, 16.0

__all__ = ["DEFAULT_PORT", "CellView", "LiveFeed", "main", "make_app"]

STATUS_NAMES = {int(s): s.name.lower() for s in TaskStatus}


@dataclass
class CellView:
    """What the page shows, from the cell's messages in the order they came."""

    teams: list[TeamSnapshot] = field(default_factory=list)
    graphs: list[GraphSnapshot] = field(default_factory=list)
    decisions: list[OnlineDecision] = field(default_factory=list)
    diagnostics: list[dict[str, str]] = field(default_factory=list)
    namespace: str = "/"
    source: str = "live"  # "live" or the bag's path
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @classmethod
    def from_bag(cls, path: str | Path) -> CellView:
        from lvws_ros.ros.bag import read_run

        run = read_run(path)
        return cls(run.teams, run.graphs, run.decisions, run.diagnostics, run.namespace, str(run.path))

    def end_time(self) -> float:
        stamps = [s.stamp for s in self.teams] + [s.stamp for s in self.graphs] + [_when(d) for d in self.decisions]
        return max(stamps, default=0.0)

    def view(self, at: float | None = None) -> dict[str, Any]:
        """The page's JSON at sim time ``at`` (None: the latest)."""
        with self.lock:
            t = self.end_time() if at is None else at
            team = _latest(self.teams, t)
            graph = _latest(self.graphs, t)
            decisions = [d for d in self.decisions if _when(d) <= t + 1e-9]
            # at a chosen time (a bag's slider): the statuses sent before its next decision
            diags = list(self.diagnostics) if at is None else \
                [d for d in self.diagnostics if _count(d.get("decisions")) <= len(decisions)]
            return _finite({
                "source": self.source, "namespace": self.namespace, "time": t, "end": self.end_time(),
                "gantt": _gantt(graph, decisions, t), "waits": _waits(decisions),
                "graph": _task_graph(graph), "robots": _robots(team), "cell": _cell(team, graph),
                "diagnostics": diags[-KEPT_DIAGNOSTICS:], "latency": _latency(diags),
                "tasks": [] if graph is None else [{"id": x.id, "status": STATUS_NAMES.get(x.status, "?")}
                                                    for x in graph.tasks],
            })

    def take(self, kind: str, item: Any) -> None:
        """Live: a new team or graph snapshot (only the latest is kept), or a decision; a
        stamp earlier than the latest (the world restarted) clears the run so far."""
        with self.lock:
            stamp = _when(item) if kind == "decisions" else item.stamp
            if stamp < self.end_time() - 1e-6:
                self.teams, self.graphs, self.decisions, self.diagnostics = [], [], [], []
            if kind == "decisions":
                self.decisions.append(item)
                del self.decisions[:-KEPT_DECISIONS]
            else:
                setattr(self, kind, [item])


def _finite(value: Any) -> Any:
    """``value`` with every NaN or infinite number made None (JSON has neither)."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value


def _when(d: OnlineDecision) -> float:
    """The sim time a decision answers (the state it was made in)."""
    return max(d.team_stamp, d.graph_stamp)


def _count(value: str | None) -> int:
    try:
        return int(value or 0)
    except ValueError:
        return 0


def _latest(snaps: list[Any], t: float) -> Any:
    out = None
    for s in snaps:
        if s.stamp <= t + 1e-9:
            out = s
    return out


def _gantt(graph: GraphSnapshot | None, decisions: list[OnlineDecision], now: float) -> list[dict[str, Any]]:
    """Bars: executed (a task's start to its end, or to now while it runs) and planned (the
    decision that assigned it, plus its duration), one per robot of its subteam."""
    bars: list[dict[str, Any]] = []
    if graph is None:
        return bars
    duration = {x.id: x.duration for x in graph.tasks}
    for x in graph.tasks:
        if x.start is None or not x.assigned_robots:
            continue
        end = x.end if x.end is not None else max(now, x.start)
        for r in x.assigned_robots:
            bars.append({"robot": r, "task": x.id, "start": x.start, "end": end, "kind": "executed",
                         "running": x.end is None, "team": len(x.assigned_robots)})
    for d in decisions:
        for task, robots in d.assignments:
            if task in duration:
                for r in robots:
                    bars.append({"robot": r, "task": task, "start": _when(d), "end": _when(d) + duration[task],
                                 "kind": "planned", "running": False, "team": len(robots)})
    return bars


def _waits(decisions: list[OnlineDecision]) -> list[dict[str, Any]]:
    return [{"robot": r, "time": _when(d), "step": d.step} for d in decisions for r in d.waiting]


def _task_graph(graph: GraphSnapshot | None) -> dict[str, Any]:
    """Nodes in layers (longest chain of prerequisites before each), edges, and the critical
    path of the tasks not done (the longest chain by duration)."""
    if graph is None:
        return {"nodes": [], "edges": [], "critical": []}
    tasks = {x.id: x for x in graph.tasks}
    order: list[str] = []
    seen: set[str] = set()

    def visit(k: str) -> None:  # depth-first topological order (the graph is acyclic: checked on arrival)
        stack = [(k, iter(tasks[k].prerequisites))]
        seen.add(k)
        while stack:
            node, it = stack[-1]
            nxt = next((p for p in it if p in tasks and p not in seen), None)
            if nxt is None:
                order.append(node)
                stack.pop()
            else:
                seen.add(nxt)
                stack.append((nxt, iter(tasks[nxt].prerequisites)))

    for name in tasks:
        if name not in seen:
            visit(name)
    layer: dict[str, int] = {}
    longest: dict[str, float] = {}  # the longest chain of tasks not done ending with each
    before: dict[str, str | None] = {}
    for k in order:
        pre = [p for p in tasks[k].prerequisites if p in longest]  # (a cycle, refused upstream, is cut here)
        layer[k] = 1 + max((layer[p] for p in pre), default=-1)
        left = tasks[k].duration if tasks[k].status != TaskStatus.DONE else 0.0
        best = max(pre, key=lambda p: longest[p], default=None)
        longest[k] = left + (longest[best] if best is not None else 0.0)
        before[k] = best
    critical: list[str] = []
    if longest and max(longest.values()) > 0:
        last: str | None = max(longest, key=lambda n: longest[n])
        while last is not None and longest[last] > 0:
            critical.append(last)
            last = before[last]
    rows: dict[int, int] = {}
    nodes = []
    for k in order:
        y = rows.get(layer[k], 0)
        rows[layer[k]] = y + 1
        nodes.append({"id": k, "x": layer[k], "y": y, "status": STATUS_NAMES.get(tasks[k].status, "?"),
                      "robots": list(tasks[k].assigned_robots)})
    edges = [[p, k] for k in order for p in tasks[k].prerequisites if p in tasks]
    return {"nodes": nodes, "edges": edges, "critical": critical[::-1]}


def _robots(team: TeamSnapshot | None) -> list[dict[str, Any]]:
    if team is None:
        return []
    return [{"id": r.id, "kind": r.kind, "available": r.available, "task": r.current_task,
             "busy_for": round(r.busy_for, 2), "site": r.site, "x": r.pose[0], "y": r.pose[1]} for r in team.robots]


def _cell(team: TeamSnapshot | None, graph: GraphSnapshot | None) -> dict[str, Any]:
    sites = [] if graph is None else [{"name": n, "x": x, "y": y} for n, x, y in graph.sites]
    robots = [] if team is None else [{"id": r.id, "x": r.pose[0], "y": r.pose[1], "busy": not r.available}
                                      for r in team.robots]
    marks = ([(n, x, y, "site") for n, x, y in graph.sites] if graph is not None else []) + \
        ([(r.id, r.pose[0], r.pose[1], "robot") for r in team.robots] if team is not None else [])
    labels, box = _labels(marks)
    return {"sites": sites, "robots": robots, "labels": labels, "range": box}


def _labels(marks: list[tuple[str, float, float, str]]) -> tuple[list[dict[str, Any]], dict[str, list[float]] | None]:
    """A label per (text, x, y, kind), placed by the GIF's rule
    (:func:`~lvws_ros.sim.labels.place_labels`: right of its anchor, moved down until it
    overlaps no other), so that robots sharing a site keep readable labels; and the axes'
    ranges, at most ``unit`` data units per pixel on a plot of ``CELL_PLOT_PX``, the scale
    the labels' sizes were reckoned in (a larger plot only adds room between them)."""
    from lvws_ros.sim.labels import place_labels

    if not marks:
        return [], None
    xs, ys = [m[1] for m in marks], [m[2] for m in marks]
    unit = max((max(xs) - min(xs) + 4) / CELL_PLOT_PX[0], (max(ys) - min(ys) + 4) / CELL_PLOT_PX[1])  # data per px
    for _ in range(8):  # the ranges grow with the labels, the labels with the scale: to a fixed point
        height = LABEL_LINE_PX * unit
        widths = [(len(m[0]) * LABEL_CHAR_PX + 6) * unit for m in marks]
        corners = place_labels([(m[1], m[2]) for m in marks], widths, height, dx=8 * unit, dy=height / 2)
        box = {"x": [min(xs) - 24 * unit, max(max(xs), *(c[0] + w for c, w in zip(corners, widths, strict=True)))
                     + 12 * unit],
               "y": [min(min(ys), *(c[1] - height for c in corners)) - 12 * unit, max(ys) + 24 * unit]}
        need = max((box["x"][1] - box["x"][0]) / CELL_PLOT_PX[0], (box["y"][1] - box["y"][0]) / CELL_PLOT_PX[1])
        if need <= unit * (1 + 1e-9):
            break
        unit = need
    labels = [{"text": text, "kind": kind, "x": left, "y": top, "width": w, "height": height, "anchor": [x, y]}
              for (text, x, y, kind), (left, top), w in zip(marks, corners, widths, strict=True)]
    return labels, box


def _latency(diags: list[dict[str, str]]) -> list[dict[str, float]]:
    out: dict[int, float] = {}
    for d in diags:
        try:
            # the step the latency was measured at; a bag recorded before that key: the step count
            step, ms = int(d.get("last_latency_step", d["decisions"])), float(d["last_latency_ms"])
        except (KeyError, ValueError):
            continue
        if step > 0 and math.isfinite(ms):
            out[step] = ms
    return [{"step": k, "ms": v} for k, v in sorted(out.items())]


class LiveFeed:
    """An rclpy node in the cell's namespace feeding a :class:`CellView`, and the
    simulator's service clients; spins on its own thread."""

    def __init__(self, view: CellView, namespace: str = "") -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from lvws_msgs.msg import AssignmentArray, TaskGraph, TeamState
        from rclpy.executors import SingleThreadedExecutor

        from lvws_ros.ros import convert, topics

        if not rclpy.ok():
            rclpy.init(args=["lvws_dashboard"])
        self.view = view
        self.node = rclpy.create_node("lvws_dashboard", namespace=namespace or None)
        view.namespace = self.node.get_namespace()

        log = self.node.get_logger()

        def add(kind: str, convert_msg: Callable[[Any], Any]) -> Callable[[Any], None]:
            def take(msg: Any) -> None:
                try:
                    view.take(kind, convert_msg(msg))
                except LvwsError as exc:  # a malformed message: shown as the scheduler would say it
                    log.warning(f"{kind}: ignored: {exc}")
            return take

        def diagnostics(msg: Any) -> None:
            with view.lock:
                view.diagnostics.extend(convert.diagnostics_from_msg(msg))
                del view.diagnostics[:-KEPT_DIAGNOSTICS]

        n = self.node
        self.follow_changes(view)
        n.create_subscription(TeamState, topics.TEAM_TOPIC, add("teams", convert.team_from_msg), topics.TEAM_QOS)
        n.create_subscription(TaskGraph, topics.GRAPH_TOPIC, add("graphs", convert.graph_from_msg), topics.GRAPH_QOS)
        n.create_subscription(AssignmentArray, topics.ASSIGNMENTS_TOPIC, add("decisions", convert.decision_from_msg),
                              topics.ASSIGNMENTS_QOS)
        n.create_subscription(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, diagnostics, topics.DIAGNOSTICS_QOS)
        self.executor = SingleThreadedExecutor()
        self.closing = False
        self.executor.add_node(n)
        self.thread = threading.Thread(target=self._spin, name="dashboard-ros", daemon=True)
        self.thread.start()

    def follow_changes(self, view: CellView) -> None:
        """A world that speaks changes (docs/ros.md): its batches followed in order, the
        world's snapshots asked for on the resync service at the first batch, on a gap or on
        a batch that cannot apply; the cell they describe shown as the latest team and graph."""
        from lvws_msgs.msg import CellChanges

        from lvws_ros.core.changes import ChangeFollower
        from lvws_ros.ros import convert, topics
        from lvws_ros.ros.change_feed import ChangeFeed

        follower, log = ChangeFollower(), self.node.get_logger()

        def show() -> None:
            while follower.notices:
                log.warning(follower.notices.pop(0))
            if follower.cell is not None and not follower.needs_resync:
                team, graph = follower.cell.snapshots()
                view.take("teams", team)
                view.take("graphs", graph)

        def resynced(res: Any) -> None:
            if res is None:
                return
            try:
                follower.resync(convert.team_from_msg(res.team), convert.graph_from_msg(res.graph), int(res.seq))
            except LvwsError as exc:
                log.warning(f"resync snapshots ignored: {exc}")
            show()

        feed = ChangeFeed(self.node, follower, resynced)

        def take(msg: Any) -> None:
            batch, why = feed.read(msg)
            if batch is None:
                log.warning(why)
            else:
                follower.take(batch)
                feed.ask()
            show()

        self.node.create_subscription(CellChanges, topics.CHANGES_TOPIC, take, topics.CHANGES_QOS)

    def _spin(self) -> None:
        from rclpy.executors import ExternalShutdownException

        from lvws_ros.ros.entry import SHUTDOWN_CHECK, spin_once

        try:
            while self.node.context.ok() and not self.closing:
                spin_once(self.node, SHUTDOWN_CHECK, self.executor)
        except ExternalShutdownException:
            pass

    def call(self, kind: str, *, tasks: list[dict[str, Any]] | None = None, target: str = "",
             failed: bool = True, timeout: float = 10.0) -> tuple[bool, str]:
        """One of the world's services (the simulator's or the dispatcher's: for a submit,
        the type served decides, as for ``lvws submit``); (accepted, its message)."""
        from lvws_ros.ros.service_call import call as call_service
        from lvws_ros.ros.service_call import ready
        from lvws_ros.ros.world_client import SERVICES, served_type, world_request

        submit_type = served_type(self.node, SERVICES[kind], timeout) if kind == "submit" else ""
        if kind == "submit" and not submit_type:  # nothing serves it: say so now (not after a second wait)
            return False, f"no world answers on {self.node.resolve_service_name(SERVICES[kind])}"
        srv, request = world_request(kind, tasks=tasks or [], target=target, failed=failed, submit_type=submit_type)
        client = self.node.create_client(srv, SERVICES[kind])
        try:
            if not ready(client, timeout):
                return False, f"no world answers on {client.srv_name}"

            def wait(future: Any, seconds: float) -> bool:  # the executor's thread completes it
                done = threading.Event()
                future.add_done_callback(lambda _f: done.set())
                return done.wait(seconds)

            res = call_service(client, request, wait, timeout)  # sent once: a change is not repeated
            if res is None:
                return False, f"{client.srv_name}: no answer within {timeout:g} s"
            return bool(res.success), str(res.message)
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        import rclpy

        self.closing = True
        self.executor.shutdown()
        self.thread.join(timeout=2 * 0.5)
        self.node.destroy_node()
        rclpy.try_shutdown()


PAGE = Path(__file__).with_name("dashboard.html")


def check_token(token: str) -> str:
    """``token`` when it can be a token (printable ASCII without spaces, 8 characters or
    more); LvwsError otherwise (the token itself is not repeated)."""
    if len(token) < 8 or not all(33 <= ord(c) < 127 for c in token):
        raise LvwsError("--token: a token is 8 or more printable ASCII characters without spaces")
    return token


def _same_token(given: str | None, token: str) -> bool:
    """Whether ``given`` is ``token``, compared in constant time."""
    return given is not None and hmac.compare_digest(given.encode("utf-8", "replace"), token.encode())


def make_app(view: CellView, feed: LiveFeed | None = None, *, token: str, read_only: bool = False) -> Any:
    """The Starlette app: the page, plotly.js, the view as JSON (``/view?t=``), a websocket
    pushing it (``/ws``), and, live, ``POST /world`` for the simulator's services. The
    views and ``/world`` need ``token`` (a ``?token=`` parameter, or the ``X-LVWS-Token``
    header) and this page's origin; else 403, and nothing is done. ``read_only``: no
    ``/world`` (403) and the page shows no controls."""
    import plotly
    from starlette.applications import Starlette
    from starlette.requests import HTTPConnection, Request
    from starlette.responses import FileResponse, HTMLResponse, JSONResponse
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocket, WebSocketDisconnect

    plotly_js = Path(plotly.__file__).parent / "package_data" / "plotly.min.js"
    controls = feed is not None and not read_only

    async def page(_request: Request) -> HTMLResponse:
        return HTMLResponse(PAGE.read_text(encoding="utf-8"))

    async def script(_request: Request) -> FileResponse:
        return FileResponse(plotly_js, media_type="application/javascript")

    def at(value: str | None) -> float | None:
        try:
            t = float(value) if value not in (None, "") else None
        except ValueError:
            return None
        return t if t is None or math.isfinite(t) else None

    def refused(conn: HTTPConnection) -> str | None:
        """Why a request may not see or act on the cell (None: it may): another site's page,
        or not this dashboard's token."""
        origin, host = conn.headers.get("origin"), conn.headers.get("host", "")
        if origin is not None and origin not in (f"http://{host}", f"https://{host}"):  # (https: behind a TLS proxy)
            return "refused: not from this page"
        if not _same_token(conn.headers.get(TOKEN_HEADER) or conn.query_params.get("token"), token):
            return "refused: the dashboard's token is needed (the URL printed at its start carries it)"
        return None

    def payload(t: float | None) -> dict[str, Any]:
        return {**view.view(t), "controls": controls}

    async def view_json(request: Request) -> JSONResponse:
        if (why := refused(request)) is not None:
            return JSONResponse({"success": False, "message": why}, status_code=403)
        return JSONResponse(payload(at(request.query_params.get("t"))))

    async def ws(socket: WebSocket) -> None:
        if refused(socket) is not None:
            await socket.close(code=1008)  # before accept: the handshake is answered 403
            return
        await socket.accept()
        t: float | None = None
        try:
            while True:
                await socket.send_text(json.dumps(payload(t)))
                try:  # the page may pick a time (bag mode: the slider); else the latest
                    msg = json.loads(await asyncio.wait_for(socket.receive_text(), timeout=PUSH_SECONDS))
                    t = at(msg.get("t")) if isinstance(msg, dict) else t
                except asyncio.TimeoutError:  # (TimeoutError itself from Python 3.11 on)
                    pass
                except (ValueError, KeyError):  # not a time: ignored
                    pass
        except (WebSocketDisconnect, RuntimeError):
            return

    async def world(request: Request) -> JSONResponse:
        why = refused(request) or (None if request.headers.get("content-type") == "application/json"
                                   else "refused: not from this page")
        if why is None and read_only:
            why = "refused: a read-only dashboard"
        if why is not None:
            return JSONResponse({"success": False, "message": why}, status_code=403)
        if feed is None:
            return JSONResponse({"success": False, "message": "a recorded run: the world cannot be changed"})
        return JSONResponse(await _act(feed, request))

    return Starlette(routes=[Route("/", page), Route("/plotly.min.js", script), Route("/view", view_json),
                             WebSocketRoute("/ws", ws), Route("/world", world, methods=["POST"])])


async def _act(feed: LiveFeed, request: Any) -> dict[str, Any]:
    """One control action of the page (a JSON body: kind, target, or a YAML file's text):
    the simulator's answer."""
    try:
        body = await request.json()
        if not isinstance(body, dict):
            raise ValueError("expected a JSON object")
        kind, target = str(body.get("kind", "")), str(body.get("target", ""))
        tasks = None
        if kind == "submit":
            tasks = _tasks_from_text(str(body.get("text", "")), str(body.get("file", "tasks.yaml")))
        if kind in ("fault", "repair"):
            ok, message = await asyncio.to_thread(feed.call, "fault", target=target, failed=kind == "fault")
        else:
            ok, message = await asyncio.to_thread(feed.call, kind, tasks=tasks, target=target)
    except (LvwsError, ValueError) as exc:
        ok, message = False, str(exc)
    return {"success": ok, "message": message}


def _tasks_from_text(text: str, name: str) -> list[dict[str, Any]]:
    """Task entries from an uploaded YAML file's text (the rules of ``lvws submit``)."""
    from lvws_ros.ros.world_client import tasks_from_file

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / Path(name).name
        path.write_text(text, encoding="utf-8")
        return tasks_from_file(path)


def serve(view: CellView, feed: LiveFeed | None, host: str, port: int, *, token: str | None = None,
          read_only: bool = False, started: Callable[[str], None] | None = None) -> None:
    """Serve the page until Ctrl-C (or the server stops). ``token`` None: a new one, printed
    in the page's URL; a given one is not printed. uvicorn's access log is off (it would
    show the websocket's ``?token=``)."""
    import uvicorn

    from lvws_ros.ros.launcher import check_port

    check_port(host, port)
    given = token is not None
    token = token if token is not None else new_token()
    app = make_app(view, feed, token=token, read_only=read_only)
    config = uvicorn.Config(app, host=host, port=port, log_level="warning", lifespan="off", access_log=False)
    server = uvicorn.Server(config)
    shown = socket_host(host)
    query = "" if given else f"?token={token}"
    line = (f"dashboard: http://{shown}:{port}/{query} ({view.source}"
            f"{', read-only' if read_only or feed is None else ''}{'; open it with your token' if given else ''})")
    if started is None:
        print(line, flush=True)
    else:
        started(line)
    server.run()


def socket_host(host: str) -> str:
    """How a browser reaches ``host``: this machine's name for an address of every interface."""
    import socket

    if host in ("0.0.0.0", "::", ""):
        return socket.gethostname()
    return f"[{host}]" if ":" in host else host


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="lvws dashboard", description="the operator's web page of a cell (live or a bag)")
    add_arguments(p)
    return p


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bag", default=None, help="show this recorded run (a time slider) instead of a live cell")
    p.add_argument("--namespace", default="", help="the live cell's ROS namespace (e.g. /cellA)")
    p.add_argument("--domain-id", type=int, default=None, help="the live cell's ROS_DOMAIN_ID")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT})")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (default 127.0.0.1: this machine only)")
    p.add_argument("--token", default=None,
                   help=f"the token the page and its controls need (default: ${TOKEN_ENV} if set, else a new one, "
                        "printed in the page's URL)")
    p.add_argument("--read-only", action="store_true", help="serve the views without the controls")


def run(args: argparse.Namespace) -> int:
    if not 0 < args.port < 65536:
        raise LvwsError(f"--port must be in 1..65535, got {args.port}")
    given = args.token if args.token is not None else os.environ.get(TOKEN_ENV) or None
    token = None if given is None else check_token(given)
    if args.bag:
        serve(CellView.from_bag(args.bag), None, args.host, args.port, token=token, read_only=True)
        return 0
    from lvws_ros.ros.world_client import join_domain
    from lvws_ros.rosbase.names import check_namespace

    join_domain(args.domain_id)

    view = CellView()
    feed = LiveFeed(view, check_namespace(args.namespace, "--namespace"))
    try:
        serve(view, feed, args.host, args.port, token=token, read_only=args.read_only)
    finally:
        feed.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        return run(args)
    except LvwsError as exc:
        sys.stderr.write(f"lvws dashboard: {exc}\n")
        return 2
    except KeyboardInterrupt:
        return 0


if __name__ == "__main__":
    sys.exit(main())
