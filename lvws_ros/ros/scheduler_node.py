"""Scheduler node: ``ros2 run lvws_ros scheduler`` (also ``lvws scheduler``).

Subscribes to ``lvws/team_state`` (TeamState) and ``lvws/task_graph`` (TaskGraph,
latched) and publishes ``lvws/assignments`` (AssignmentArray) at each decision step:
whenever a robot becomes available or a task becomes ready. Names are relative
(:mod:`lvws_ros.ros.topics`): ``-r __ns:=/cellA`` moves them all. A thin shell over
:class:`lvws_ros.core.online.OnlineScheduler`: parameters, message conversion
(:mod:`lvws_ros.ros.convert`), the core, publish. Health goes to ``diagnostics`` once a
second and on every event, with the node's fully qualified name as ``hardware_id``.

A decision is computed on a worker thread beside the node's callbacks: messages, parameter
changes and diagnostics are served while a search policy (``auto``, ``lvws_sample``, ...)
spends its budget. What arrives meanwhile is applied, in order, as soon as the decision is
published (a guard condition hands it back to the executor's thread, where everything
else runs), so the core never sees a snapshot change in the middle of a decision.

Parameters (PARAMETERS: type, default, description, range; ``ros2 param describe``
shows them): policy, fallback_policy, model_path, seed, decision_budget_ms, beam_width,
samples and ack_timeout may change at runtime: the on-set callback builds the new policies and
applies them, or refuses the change with the reason (an unknown policy, a missing model,
a number out of range; without a fallback, also a policy that cannot serve the current
cell).
expect_subscribers is read-only. use_sim_time is rclpy's.
"""

from __future__ import annotations

import argparse
import gc
import sys
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from lvws_msgs.msg import AssignmentArray, CellChanges, TaskGraph, TeamState
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.clock import Clock, ClockType
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.parameter import Parameter

from lvws_ros.core.changes import ChangeFollower
from lvws_ros.core.executor import Policy
from lvws_ros.core.online import OnlineDecision, OnlineScheduler, close_policy
from lvws_ros.errors import ConfigError, LvwsError
from lvws_ros.planning import PLANNER_NICENESS
from lvws_ros.registry import LEARNED_POLICIES, POLICY_NAMES, make_policy
from lvws_ros.ros import convert, topics
from lvws_ros.ros.change_feed import ChangeFeed
from lvws_ros.ros.entry import node_main
from lvws_ros.sim.config import read_yaml

DESCRIPTION = (
    "LVWS scheduler node: subscribes to lvws/team_state and lvws/task_graph, publishes lvws/assignments "
    "(lvws_msgs/AssignmentArray) at every decision step, health on diagnostics; names are relative to the "
    "node's namespace. ROS parameters: " + ", ".join(
        ["policy", "fallback_policy", "model_path", "seed", "decision_budget_ms", "first_plan_wait", "planner_niceness",
         "ack_timeout",
         "retire_after", "expect_subscribers", "managed", "use_sim_time"])
    + " (--ros-args -p NAME:=VALUE or --params-file config/scheduler.yaml)."
)
DEFAULT_POLICY = "auto"


@dataclass(frozen=True)
class Param:
    """A parameter of the node: what ``ros2 param describe`` shows, and the params-file check."""

    kind: type
    default: Any
    description: str
    low: float | None = None  # inclusive range (numbers)
    high: float | None = None
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        kinds = {str: ParameterType.PARAMETER_STRING, int: ParameterType.PARAMETER_INTEGER,
                 float: ParameterType.PARAMETER_DOUBLE, bool: ParameterType.PARAMETER_BOOL}
        d = ParameterDescriptor(description=self.description, read_only=self.read_only, type=kinds[self.kind])
        if self.kind is int and self.low is not None and self.high is not None:
            d.integer_range = [IntegerRange(from_value=int(self.low), to_value=int(self.high), step=0)]
        elif self.kind is float and self.low is not None and self.high is not None:
            d.floating_point_range = [FloatingPointRange(from_value=float(self.low), to_value=float(self.high),
                                                         step=0.0)]
        return d


BEAM_BUDGET_MS = 1000.0  # lvws_beam's search budget when decision_budget_ms is 0
SAMPLE_BUDGET_MS = 50.0  # lvws_sample's budget per decision when decision_budget_ms is 0
MAX_BEAM_WIDTH = 1_000_000  # the beam_width parameter's range (a search that wide never ends within a budget)
MAX_SAMPLES = 100_000  # the samples parameter's range

PARAMETERS: dict[str, Param] = {
    "policy": Param(str, DEFAULT_POLICY, f"scheduling policy: {' | '.join(POLICY_NAMES)}"),
    "fallback_policy": Param(str, "grp", "decides a step the main policy cannot serve (WARN on diagnostics); "
                                         "'' for none"),
    "model_path": Param(str, "", "checkpoint of a learned policy; '' for the shipped one"),
    "seed": Param(int, 0, "seed of the random policies", 0, 2**31 - 1),
    "decision_budget_ms": Param(float, 0.0, "time budget of a decision of the search policies (auto, lvws_sample, "
                                            "lvws_rollout, lvws_beam, exact) in ms; 0: their own limits "
                                            f"(auto: the planner in a process beside the node, decisions from its "
                                            f"plan; lvws_beam: {BEAM_BUDGET_MS:g} ms, "
                                            f"lvws_sample: {SAMPLE_BUDGET_MS:g} ms); auto, lvws_sample, lvws_rollout "
                                            "and lvws_beam count it from the arrival of the message that made the "
                                            "decision due",
                                0.0, 3.6e6),
    "samples": Param(int, 0, "lvws_sample: schedules sampled in lockstep per round; 0: the sampler's default "
                             "(lvws_ros/learning/sampling.py)", 0, MAX_SAMPLES),
    "beam_width": Param(int, 0, "lvws_beam: partial schedules kept at each depth of its search; 0: the search's "
                                "default (lvws_ros/learning/search.py)", 0, MAX_BEAM_WIDTH),
    "first_plan_wait": Param(float, 0.0, "auto (planner beside the node): seconds the cell's first decision waits "
                                         "for the planner's first plan (0: it is GRP's at once, and the plan takes "
                                         "over when it comes)", 0.0, 60.0),
    "planner_niceness": Param(int, PLANNER_NICENESS, "auto (planner beside the node): how far below the node's "
                                                     "CPU priority its planner's process runs (os.nice; 0: the "
                                                     "same), so that decisions are not held up by the plan's "
                                                     "improvement on a machine with few cores", 0, 19),
    "ack_timeout": Param(float, 5.0, "seconds (of the world's clock, the states' stamps) before an assignment the "
                         "world did not take is offered again, from when the decision went out "
                         "(lvws_ros.core.online.sent_at)", 0.01, 3.6e6),
    "expect_subscribers": Param(int, 0, "the first decision waits (at most 20 s) until this many nodes subscribe "
                                        "to lvws/assignments", 0, 1000, read_only=True),
    "managed": Param(bool, False, "a managed lifecycle node: configure loads the policies and the model, activate "
                                  "starts deciding and publishing, deactivate stops, cleanup frees; false: it "
                                  "configures and activates itself at start", read_only=True),
    "retire_after": Param(float, -1.0, "seconds after which a DONE task whose dependents have all started leaves "
                                       "the node's state, in a world that speaks changes; < 0: when the world "
                                       "retires it", -1.0, 1e9, read_only=True),
    "use_sim_time": Param(bool, False, "rclpy's: the node's clock follows /clock"),
}
RUNTIME_POLICY_PARAMETERS = ("policy", "fallback_policy", "model_path", "seed", "decision_budget_ms", "beam_width",
                             "samples", "first_plan_wait", "planner_niceness")
SUBSCRIBER_WAIT = 20.0  # wall seconds the first decision waits for expect_subscribers
SETTLE_SECONDS = 0.2  # wall time to wait for the matching team/graph message
LOG_NAMES = 12  # assignments and waiting robots named in a decision's log line (the rest counted)
FULL_COLLECTION_EVERY = 500  # decisions between two collections of everything (frozen objects included)


def collect_after_decision(decisions: int) -> None:
    """The garbage collector paced by the decisions: after each (the ``decisions``-th) what
    is alive is frozen, so that a collection that falls inside the next decision scans what
    that decision made, not a fleet's snapshots and plan (1000 x 5000: the longest pause
    in a decision 113 -> 22 ms, docs/scale.md); every FULL_COLLECTION_EVERY decisions
    everything is collected once, so what became garbage in cycles after it was frozen is
    freed."""
    if decisions % FULL_COLLECTION_EVERY == 0:
        gc.unfreeze()
        gc.collect()
    gc.freeze()


def _of_kind(value: Any, kind: type) -> bool:
    """rclpy's typing: a bool is not an int, an int is not a float."""
    return isinstance(value, kind) and (kind is bool or not isinstance(value, bool))


def check_value(name: str, value: Any) -> str:
    """Why ``value`` is not valid for parameter ``name`` ('' if it is)."""
    if name not in PARAMETERS:
        return f"unknown parameter (known: {', '.join(PARAMETERS)})"
    par = PARAMETERS[name]
    if not _of_kind(value, par.kind):
        hint = f" (write {value}.0)" if par.kind is float and isinstance(value, int) else ""
        return f"expected {par.kind.__name__}, got {value!r}{hint}"  # rclpy's rule: 5 is not a float
    if par.low is not None and par.high is not None and not par.low <= value <= par.high:
        return f"{value!r} is out of range [{par.low:g}, {par.high:g}]"
    if name in ("policy", "fallback_policy") and value not in POLICY_NAMES and not (name == "fallback_policy"
                                                                                   and value == ""):
        return f"unknown {value!r}; one of {', '.join(POLICY_NAMES)}" + (" or ''" if name == "fallback_policy"
                                                                           else "")
    if name == "model_path" and value and not Path(value).is_file():
        return f"no such file {value!r}"
    return ""


def check_params_file(path: str | Path, node: str = "scheduler", namespace: str = "") -> dict[str, Any]:
    """The scheduler's parameters in a ROS 2 params file, checked without starting
    anything: ConfigError naming the file and the parameter. Sections read, later ones
    winning (rcl's matching of a node's fully qualified name): ``/**``, ``/**/<node>``,
    ``<node>`` and ``/<node>`` (root namespace), ``<namespace>/<node>``."""
    p = Path(path)
    data = read_yaml(p, "parameter file")
    if not isinstance(data, dict):
        raise ConfigError(f"{p}: expected a mapping of node names to ros__parameters")
    ns = namespace.rstrip("/")
    keys = ["/**", f"/**/{node}", *([node, f"/{node}"] if not ns else []), *([f"{ns}/{node}"] if ns else [])]
    params: dict[str, Any] = {}
    for key in keys:
        section = data.get(key)
        if section is None:
            continue
        if not isinstance(section, dict) or not isinstance(section.get("ros__parameters"), dict):
            raise ConfigError(f"{p}: {key}: expected a 'ros__parameters' mapping")
        params.update(section["ros__parameters"])
    for name, value in params.items():
        why = check_value(name, value)
        if why:
            raise ConfigError(f"{p}: {node}.{name}: {why}")
    return params


def build_policies(values: dict[str, Any]) -> tuple[Policy, Policy | None]:
    """(main policy, fallback) from the node's parameter values (LvwsError if one cannot be made)."""
    name, budget = values["policy"], float(values["decision_budget_ms"])
    beam_budget = budget if budget > 0 else BEAM_BUDGET_MS  # a search without one could hold a cell for minutes
    options: dict[str, Any] = {}
    if name in LEARNED_POLICIES:
        options["model_path"] = values["model_path"]
    if name == "lvws_rollout" and budget > 0:
        options["budget_ms"] = budget
    beam = {"budget_ms": beam_budget, "width": int(values["beam_width"]) or None}  # 0: the search's default
    sample = {"budget_ms": budget if budget > 0 else SAMPLE_BUDGET_MS, "samples": int(values["samples"]) or None}
    if name == "lvws_beam":
        options.update(beam)
    if name == "lvws_sample":
        options.update(sample)
    if name == "auto":  # with a budget: the search within each decision's; without: the planner beside the node
        options.update({"budget_ms": budget} if budget > 0 else
                       {"background": True, "first_wait": float(values.get("first_plan_wait", 0.0)),
                        "niceness": int(values.get("planner_niceness", PLANNER_NICENESS))})
    if name == "exact" and budget > 0:
        options["time_limit"] = budget / 1000
    fallback = values["fallback_policy"]
    backup = beam if fallback == "lvws_beam" else sample if fallback == "lvws_sample" else {}
    return (make_policy(name, seed=int(values["seed"]), **options),
            make_policy(fallback, seed=int(values["seed"]), **backup) if fallback else None)


class SchedulerNode(LifecycleNode):
    """The scheduler, a lifecycle node. Unmanaged (``managed`` false, the default) it
    configures and activates itself at start; managed, it waits for a lifecycle manager
    (``lifecycle_msgs`` services ``change_state`` and ``get_state`` under the node's name).
    Inactive, it keeps taking team and graph messages (the latest are replayed into a new
    core at configure) but decides and publishes nothing."""

    def __init__(self) -> None:
        super().__init__("scheduler")
        for name, par in PARAMETERS.items():
            try:
                if name == "use_sim_time":  # declared by rclpy: only described here
                    self.set_descriptor(name, par.descriptor())
                else:
                    self.declare_parameter(name, par.default, par.descriptor())
            except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
                raise LvwsError(f"parameter {name}: {exc}") from None
        values = self.values()
        for name, value in values.items():  # overrides from the command line or a params file
            why = check_value(name, value)
            if why:
                raise LvwsError(f"parameter {name}: {why}")
        self.policy_name = str(values["policy"])
        self.seed = int(values["seed"])
        # the first decision waits (at most SUBSCRIBER_WAIT) until this many nodes (a recorder,
        # the world) subscribe to lvws/assignments, so none of them misses it
        self.expect_subscribers = int(values["expect_subscribers"])
        self.started_at = time.monotonic()
        self.core: OnlineScheduler | None = None  # made at configure, freed at cleanup
        self.active = False  # between activate and deactivate: deciding and publishing
        self.latest: dict[str, Callable[[], None]] = {}  # the latest message of each kind, for a new core
        self.team_reader, self.graph_reader = convert.TeamReader(), convert.GraphReader()  # O(changes) per message
        self.worker = ThreadPoolExecutor(max_workers=1, thread_name_prefix="decide")
        self.in_flight: Future[OnlineDecision | None] | None = None  # the decision being computed
        self.deciding_core: OnlineScheduler | None = None  # the core it is computed by
        self.deferred: list[Callable[[], None]] = []  # what arrived meanwhile, applied after it
        self.decided = self.create_guard_condition(lambda: self.guarded(self.on_decided))
        self.add_on_set_parameters_callback(self.on_set_parameters)
        self.pub = self.create_publisher(AssignmentArray, topics.ASSIGNMENTS_TOPIC, topics.ASSIGNMENTS_QOS)
        self.diag_pub = self.create_publisher(DiagnosticArray, topics.DIAGNOSTICS_TOPIC, topics.DIAGNOSTICS_QOS)
        # the snapshots come as their serialized bytes: read without a message object per task
        self.create_subscription(TeamState, topics.TEAM_TOPIC, self.on_team, topics.TEAM_QOS, raw=True)
        self.create_subscription(TaskGraph, topics.GRAPH_TOPIC, self.on_graph, topics.GRAPH_QOS, raw=True)
        self.create_subscription(CellChanges, topics.CHANGES_TOPIC, self.on_changes, topics.CHANGES_QOS, raw=True)
        self.follower = ChangeFollower(float(values["retire_after"]))  # the world's changes, once it sends some
        self.feed = ChangeFeed(self, self.follower, lambda res: self.guarded(lambda: self.resynced(res)),
                               self.when_idle)
        self.snapshots_ignored = 0  # snapshot messages of a world that speaks changes (its resync is the truth)
        self.step_started = 0.0  # perf_counter: the arrival of the state the decision in flight answers
        self.last_state_latency = 0.0
        # wall-clock timers: with use_sim_time a paused simulator would stop ROS-time ones
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(1.0, self.publish_diagnostics, clock=steady)
        self.create_timer(0.05, self.on_settle, clock=steady)
        self.unsynced_since: float | None = None
        self.error = ""
        self.rejected: dict[str, str] = {}  # message kind -> why its latest one was ignored
        self.last_latency = 0.0
        self.last_latency_step = 0  # decisions made when last_latency was measured (0: none yet)
        self.received = 0
        self.arrived = self.decided_at = 0.0  # perf_counter: the latest message's arrival, the latest decision's end
        if not values["managed"]:
            self.trigger_configure()
            if self.core is None:
                raise LvwsError(self.error)
            self.trigger_activate()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load the policies and the model; the latest messages go to the new core."""
        values = self.values()
        try:
            policy, fallback = build_policies(values)
        except LvwsError as exc:
            self.error = str(exc)
            self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        except Exception as exc:  # a bug or a broken install: said, with the traceback
            self.error = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"configure failed:\n{traceback.format_exc()}")
            return TransitionCallbackReturn.FAILURE
        self.error = ""
        warm_up = getattr(policy, "warm_up", None)
        if callable(warm_up):  # the planner's process started and its model loaded now, not in the first decision
            warm_up()
        self.core = OnlineScheduler(policy, float(values["ack_timeout"]), fallback=fallback)
        for offer in list(self.latest.values()):
            offer()
        self.get_logger().info(f"policy {self.policy_name}, seed {self.seed}, model {values['model_path'] or 'shipped'}"
                               f", fallback {values['fallback_policy'] or 'none'}; topics under "
                               f"{self.get_namespace()}")
        # The start-up objects (torch, rclpy, the model) live as long as the node: freezing
        # them keeps a full garbage collection from pausing a decision (100 x 500: p99 of the
        # decision latency 48 -> 37 ms, docs/scale.md).
        gc.freeze()
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        self.arrived = self.decided_at = time.perf_counter()  # what came before waited for this: a budget from now
        self.report(DiagnosticStatus.OK, "active: deciding")
        self.when_idle(lambda: self.guarded(self.maybe_step))
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False  # a decision in flight is not published
        self.report(DiagnosticStatus.OK, "inactive: not deciding")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.free()  # a decision in flight keeps its own core; its result is dropped (on_decided)
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def free(self) -> None:
        """Drop the core with its policies and model (cleanup), and the planner's process."""
        if self.core is not None:
            self.core.close()
        self.core = None
        gc.unfreeze()  # what configure froze may go now
        gc.collect()

    def values(self, changes: list[Parameter] | None = None) -> dict[str, Any]:
        """The node's parameter values, with ``changes`` applied."""
        out = {name: self.get_parameter(name).value for name in PARAMETERS}
        out.update({p.name: p.value for p in changes or []})
        return out

    def on_set_parameters(self, changes: list[Parameter]) -> SetParametersResult:
        """Validate a runtime change and apply it, or refuse it with the reason (ranges and
        read-only are rclpy's, from the descriptors)."""
        for p in changes:
            why = check_value(p.name, p.value) if p.name in PARAMETERS else ""
            if why:
                return SetParametersResult(successful=False, reason=f"{p.name}: {why}")
        names = {p.name for p in changes}
        values = self.values(changes)
        if names & set(RUNTIME_POLICY_PARAMETERS):
            built: tuple[Policy, Policy | None] | None = None
            try:
                policy, fallback = built = build_policies(values)
                core = self.core
                if core is not None and core.team is not None and core.graph is not None and fallback is None:
                    policy.reset(core.pure_instance())  # no fallback: the new policy must serve this cell
            except Exception as exc:  # a model that does not load, a policy that cannot serve the cell
                for refused in built or ():
                    close_policy(refused)  # a planner's process started for it ends with it
                return SetParametersResult(successful=False, reason=f"{type(exc).__name__}: {exc}")
            self.when_idle(lambda: self.core.set_policies(policy, fallback) if self.core is not None else None)
            self.policy_name, self.seed = str(values["policy"]), int(values["seed"])
            self.report(DiagnosticStatus.OK,
                        f"parameters {', '.join(sorted(names))} changed: policy {self.policy_name}, fallback "
                        f"{values['fallback_policy'] or 'none'}")
        if "ack_timeout" in names:
            timeout = float(values["ack_timeout"])
            self.when_idle(lambda: setattr(self.core, "ack_timeout", timeout) if self.core is not None else None)
        return SetParametersResult(successful=True)

    def on_team(self, data: bytes) -> None:
        self.received += 1
        if self.follower.cell is not None:  # a world that speaks changes: its resync answers are the snapshots
            self.snapshots_ignored += 1
            return
        self.arrived = time.perf_counter()
        self.take("TeamState", lambda core: core.offer_team(self.team_reader.read_serialized(data)))

    def on_graph(self, data: bytes) -> None:
        self.received += 1
        if self.follower.cell is not None:
            self.snapshots_ignored += 1
            return
        self.arrived = time.perf_counter()
        self.take("TaskGraph", lambda core: core.offer_graph(self.graph_reader.read_serialized(data)))

    def on_changes(self, msg: bytes) -> None:
        """A batch of the world's changes: taken in order (a gap or a batch that cannot
        apply: a WARN and a resync), then the cell as it now is goes to the core."""
        self.received += 1
        self.arrived = time.perf_counter()
        batch, why = self.feed.read(msg)
        if batch is None:
            self.report(DiagnosticStatus.WARN, why)
            return
        self.when_idle(lambda: self.guarded(lambda: self.follow(lambda: self.take_batch(batch))))

    def take_batch(self, batch: Any) -> bool:
        """Let the follower take a batch; batch 1 to a node that holds the world's first
        snapshots (change 0) starts from them, without a resync."""
        core = self.core
        if self.follower.cell is None and core is not None and core.team is not None and core.graph is not None:
            try:
                self.follower.start_from(core.team, core.graph, batch, checked=True)  # the core took them
            except LvwsError:
                pass  # the follower asks for the world's snapshots
        return self.follower.take(batch)

    def follow(self, take: Callable[[], bool]) -> None:
        """Let the follower take a batch or a resync; offer the cell to the core if it changed."""
        changed = take()
        while self.follower.notices:
            self.report(DiagnosticStatus.WARN, self.follower.notices.pop(0))
        self.feed.ask()
        if changed and self.follower.cell is not None:
            self.latest.pop("TeamState", None)
            self.latest.pop("TaskGraph", None)
            self.latest["cell"] = lambda: self.when_idle(lambda: self.guarded(self.offer_cell))  # for a new core
            self.offer_cell()

    def offer_cell(self) -> None:
        """The cell the world's changes describe, to the core as a snapshot pair."""
        cell, core = self.follower.cell, self.core
        if cell is None or core is None:
            return
        team, graph, delta = cell.view()
        self.offer("CellChanges", lambda: core.offer_cell(team, graph, delta))

    def resynced(self, res: Any) -> None:
        """The world's answer to a resync request (``None``: the call failed)."""
        if res is None:
            return
        self.arrived = time.perf_counter()
        team, graph = self.team_reader.read(res.team), self.graph_reader.read(res.graph)

        def take() -> bool:
            try:
                self.follower.resync(team, graph, int(res.seq))
            except LvwsError as exc:
                self.report(DiagnosticStatus.ERROR, f"resync snapshots ignored: {exc}")
                return False
            self.report(DiagnosticStatus.OK, f"resynced: the world's cell as of change {int(res.seq)}")
            return True
        self.follow(take)

    def take(self, kind: str, offer: Callable[[OnlineScheduler], bool]) -> None:
        """Offer a message to the core (once it is configured and idle); kept as the
        latest of its kind for a core made later."""
        def work() -> None:
            if self.core is not None:
                core = self.core
                self.guarded(lambda: self.offer(kind, lambda: offer(core)))
        self.latest[kind] = lambda: self.when_idle(work)
        self.when_idle(work)

    def when_idle(self, work: Callable[[], None]) -> None:
        """Do ``work`` now, or after the decision in flight (the core is the worker's then)."""
        if self.in_flight is None:
            work()
        else:
            self.deferred.append(work)

    def guarded(self, work: Callable[[], None]) -> None:
        """No message content may stop the node: a bug is logged with its traceback and
        reported (ERROR), and the node serves the next message."""
        try:
            work()
        except Exception as exc:
            if not self.context.ok():  # shutting down (Ctrl-C) while it ran: nothing to report
                return
            self.error = f"internal error {type(exc).__name__}: {exc}"
            self.get_logger().error(traceback.format_exc())
            self.publish_diagnostics(DiagnosticStatus.ERROR, self.error)

    def offer(self, kind: str, take: Callable[[], bool]) -> None:
        """Hand a snapshot to the core; a malformed one is reported (ERROR) and ignored."""
        try:
            taken = take()
        except LvwsError as exc:
            self.rejected[kind] = str(exc)
            self.report(DiagnosticStatus.ERROR, f"{kind} ignored: {exc}")
            return
        self.rejected.pop(kind, None)
        self.flush_notices()
        if taken:
            self.maybe_step()

    def maybe_step(self) -> None:
        """Decide when team and graph describe the same instant; a publisher that
        never stamps them alike is served after SETTLE_SECONDS."""
        if self.core is None or not self.active:
            return
        team, graph = self.core.team, self.core.graph
        if team is not None and graph is not None and abs(team.stamp - graph.stamp) < 1e-9:
            self.unsynced_since = None
            # The budget counts from the arrival of the message that made the decision due
            # (its conversion included), or from the end of the decision it waited for.
            self.step(max(self.arrived, self.decided_at))
        elif self.unsynced_since is None:
            self.unsynced_since = time.monotonic()

    def on_settle(self) -> None:
        self.feed.ask()
        if self.in_flight is None and self.unsynced_since is not None \
                and time.monotonic() - self.unsynced_since > SETTLE_SECONDS:
            self.unsynced_since = None
            self.guarded(self.step)

    def audience_ready(self) -> bool:
        """Whether the expected subscribers of lvws/assignments are there (or the wait is over)."""
        if (self.core is not None and self.core.step > 0) \
                or self.pub.get_subscription_count() >= self.expect_subscribers:
            return True
        return time.monotonic() - self.started_at > SUBSCRIBER_WAIT

    def step(self, started: float | None = None) -> None:
        """Start a decision on the worker thread (:meth:`on_decided` publishes it); a
        budget counts from ``started`` (a perf_counter time; None: from now)."""
        if not self.audience_ready():
            self.unsynced_since = time.monotonic()  # on_settle tries again
            return
        if self.core is None or not self.active:
            return
        if self.in_flight is not None:  # after the one in flight, with what arrived meanwhile
            self.deferred.append(self.maybe_step)
            return
        self.deciding_core = self.core
        self.step_started = self.arrived or time.perf_counter()  # the state it answers arrived then
        self.in_flight = self.worker.submit(self.core.decide, started)
        self.in_flight.add_done_callback(lambda _done: self.decided.trigger())

    def on_decided(self) -> None:
        """The decision is made: publish it, then apply what arrived meanwhile, in order."""
        done, self.in_flight = self.in_flight, None
        self.decided_at = time.perf_counter()
        if done is None or not done.done():
            self.in_flight = done
            return
        try:
            self.publish_decision(done)
        finally:
            work, self.deferred = self.deferred, []
            for item in work if self.context.ok() else ():
                self.when_idle(partial(self.guarded, item))

    def publish_decision(self, done: Future[OnlineDecision | None]) -> None:
        core, self.deciding_core = self.deciding_core, None
        if core is not self.core:  # cleaned up meanwhile: that core's decision is void
            return
        try:
            decision = done.result()
        except LvwsError as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.report(DiagnosticStatus.ERROR, self.error)
            return
        assert core is not None
        self.error = ""
        self.flush_notices()
        if decision is not None and not self.active:  # deactivated meanwhile: nothing goes out
            core.forget(decision)
            return
        if decision is None:
            return
        self.last_latency, self.last_latency_step = decision.latency, decision.step + 1  # as "decisions" counts
        # never stamped before the inputs it answers (a sim clock may lag the state)
        stamp = max(self.get_clock().now().nanoseconds / 1e9, decision.team_stamp, decision.graph_stamp)
        decision = replace(decision, state_latency=time.perf_counter() - self.step_started, published=stamp)
        self.last_state_latency = decision.state_latency
        self.pub.publish(convert.decision_to_msg(decision, convert.to_time(stamp)))
        core.published(decision)
        made = ", ".join(f"{t}<-{'+'.join(r)}" for t, r in decision.assignments[:LOG_NAMES]) or "-"
        made += f" (+{len(decision.assignments) - LOG_NAMES} more)" if len(decision.assignments) > LOG_NAMES else ""
        waiting = ", ".join(decision.waiting[:LOG_NAMES]) or "-"
        waiting += f" (+{len(decision.waiting) - LOG_NAMES} more)" if len(decision.waiting) > LOG_NAMES else ""
        self.get_logger().info(f"step {decision.step}: {made}; waiting {waiting} "
                               f"({1000 * decision.latency:.1f} ms)")
        collect_after_decision(decision.step + 1)

    def flush_notices(self) -> None:
        """The world's changes (tasks added or cancelled, robots back) as OK, the core's
        notices (robots gone, tasks interrupted, world restarts, released assignments,
        untrusted readiness) as WARN."""
        core = self.core
        while core is not None and core.changes:
            self.report(DiagnosticStatus.OK, core.changes.pop(0))
        while core is not None and core.notices:
            self.report(DiagnosticStatus.WARN, core.notices.pop(0))

    def report(self, level: bytes, message: str) -> None:
        """Log and publish one diagnostics status now (besides the periodic one)."""
        if level == DiagnosticStatus.ERROR:  # one call site per severity (rclpy's rule)
            self.get_logger().error(message)
        elif level == DiagnosticStatus.WARN:
            self.get_logger().warning(message)
        else:
            self.get_logger().info(message)
        self.publish_diagnostics(level, message)

    def publish_diagnostics(self, level: bytes | None = None, message: str = "") -> None:
        """The node's health: ERROR while the latest message of a kind was refused or the
        last step failed, else OK; ``level``/``message`` publish one event now."""
        status = DiagnosticStatus(name="lvws_scheduler", hardware_id=self.get_fully_qualified_name())
        problem = self.error or "; ".join(f"{k} ignored: {v}" for k, v in sorted(self.rejected.items()))
        status.level = level if level is not None else (DiagnosticStatus.ERROR if problem else DiagnosticStatus.OK)
        core = self.core
        idle = "unconfigured" if core is None else "inactive" if not self.active else \
            "waiting for team and task graph" if core.team is None or core.graph is None else "ok"
        status.message = message or problem or idle
        status.values = [KeyValue(key=k, value=str(v)) for k, v in (
            ("policy", self.policy_name), ("seed", self.seed), ("decisions", core.step if core else 0),
            ("last_latency_ms", f"{1000 * self.last_latency:.3f}"), ("last_latency_step", self.last_latency_step),
            ("last_state_latency_ms", f"{1000 * self.last_state_latency:.3f}"), ("messages", self.received),
            ("changes_seq", self.follower.cell.seq if self.follower.cell is not None else 0),
            ("changes_resyncs", self.follower.resyncs), ("changes_gaps", self.follower.gaps),
            ("changes_refused", self.follower.refused),
            ("retired", self.follower.cell.retired_count if self.follower.cell is not None else 0),
            ("out_of_order_dropped", core.dropped if core else 0), ("world_restarts", core.restarts if core else 0),
            ("pending", len(core.pending) if core else 0), ("fallback_steps", core.fallbacks if core else 0),
            ("lifecycle", "active" if self.active else "inactive" if core is not None else "unconfigured"))]
        planned = getattr(core.policy, "status_values", None) if core is not None else None
        if callable(planned):  # auto's planner: the plan's makespan, bound and gap as of the latest decision
            status.values += [KeyValue(key=k, value=str(v)) for k, v in planned()]
        msg = DiagnosticArray(status=[status])
        msg.header.stamp = self.get_clock().now().to_msg()
        self.diag_pub.publish(msg)


    def destroy_node(self) -> None:
        self.worker.shutdown(wait=True, cancel_futures=True)  # a decision in flight ends first
        if self.core is not None:
            self.core.close()
        super().destroy_node()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="scheduler", description=DESCRIPTION)
    return node_main("scheduler", argv, parser, lambda _args: SchedulerNode())


if __name__ == "__main__":
    sys.exit(main())
