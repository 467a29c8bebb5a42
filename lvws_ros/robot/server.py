"""One robot's ``ExecuteTask`` action server: :class:`TaskServer`, the base class a robot
subclasses to take its part of the tasks the dispatcher sends.

The dispatcher sends one goal per task to ``<robot id>/execute_task`` (a relative name: it
resolves under the cell's namespace) of every member of the task's subteam. A subclass
writes :meth:`TaskServer.execute`; the base class does the rest:

- **acceptance**: a goal whose ``subteam`` does not name this robot is rejected, and so is
  a goal that arrives while the robot works on another one; :meth:`TaskServer.refuse` can
  add reasons of its own. Every rejection is logged with its reason.
- **cancel**: every cancel request is accepted; ``execute`` stops cooperatively at its next
  :meth:`TaskFeedback.check` or :meth:`TaskFeedback.sleep`, which raise
  :class:`TaskCanceled`, and the goal ends canceled.
- **abort**: an :class:`~lvws_ros.errors.LvwsError` raised by ``execute`` (for instance
  :class:`TaskFailed`) aborts the goal with the exception's message; any other exception
  aborts it too, with its type in the message and its traceback in the log, and the server
  goes on serving.
- **result**: ``execute`` returns ``None``, a message, or an ``ExecuteTask.Result``; the
  result's ``duration`` is, unless ``execute`` set it, the seconds since the first
  ``working`` feedback (travel excluded), on the node's clock: wall time, or the
  simulated clock with ``use_sim_time``.

``execute`` blocks while the robot works, so run the servers with :func:`serve` (a
multi-threaded executor; each server's callbacks are in a reentrant group, so cancel
requests and the goals of other robots are answered while one executes).
"""

from __future__ import annotations

import math
import threading
import time
import traceback
from collections.abc import Sequence
from typing import Any

from geometry_msgs.msg import Pose2D
from lvws_msgs.action import ExecuteTask
from lvws_msgs.msg import PlannedStart
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.exceptions import InvalidNodeNameException, InvalidTopicNameException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.validate_node_name import validate_node_name
from rclpy.validate_topic_name import validate_topic_name

from lvws_ros.errors import ConfigError, LvwsError
from lvws_ros.rosbase.goals import ACTION_NAME, PLANNED_STARTS_QOS, PLANNED_STARTS_TOPIC
from lvws_ros.rosbase.names import check_namespace
from lvws_ros.rosbase.spin import RCLError, spin_once

__all__ = [
    "ACTION_NAME",
    "PHASES",
    "TaskCanceled",
    "TaskFailed",
    "TaskFeedback",
    "TaskServer",
    "action_name",
    "check_namespace",
    "serve",
]

PHASES = (ExecuteTask.Feedback.PHASE_TRAVELLING, ExecuteTask.Feedback.PHASE_WAITING,
          ExecuteTask.Feedback.PHASE_WORKING)
SHUTDOWN_CHECK = 0.5  # wall seconds between two looks at whether a signal shut the servers down
POLL_SECONDS = 0.02  # how often TaskFeedback.sleep looks for a cancel request (wall seconds)


class TaskCanceled(LvwsError):
    """The goal was cancelled (or the process is shutting down): raised by
    :meth:`TaskFeedback.check` and :meth:`TaskFeedback.sleep`; the server ends the goal
    canceled."""


class TaskFailed(LvwsError):
    """The robot cannot do its part of the task: raise it from ``execute`` to abort the goal
    with its message (any :class:`~lvws_ros.errors.LvwsError` does the same)."""


def action_name(robot_id: str) -> str:
    """The relative name of robot ``robot_id``'s ExecuteTask server (ConfigError when the
    id cannot be part of a ROS name: letters, digits and ``_``, not starting with a digit)."""
    name = f"{robot_id}/{ACTION_NAME}"
    try:
        validate_topic_name(name)
    except InvalidTopicNameException:
        raise ConfigError(f"robot {robot_id!r}: its id cannot name a ROS action ({name!r}): use letters, "
                          "digits and '_', not starting with a digit") from None
    return name


class TaskFeedback:
    """What ``execute`` is handed beside the goal: feedback to send, the cancel request to
    look at, and a sleep that wakes up for it."""

    def __init__(self, server: TaskServer, goal_handle: ServerGoalHandle) -> None:
        self._server = server
        self._handle = goal_handle
        self._work_start: float | None = None
        self.phase = ""

    @property
    def goal(self) -> Any:
        """The ``ExecuteTask.Goal``."""
        return self._handle.request

    @property
    def planned_start(self) -> float:
        """When the plan starts the task (ROS time; 0: no plan): the goal's, or a later one
        the dispatcher published on ``lvws/planned_starts`` for this goal's task and subteam
        while the robot serves it (a member set out later than planned). A server that
        waits at the site for its subteam waits for this."""
        return self._server._latest_start(self.goal)

    @property
    def cancelled(self) -> bool:
        """True once a cancel was requested (or the process is shutting down)."""
        return bool(self._handle.is_cancel_requested) or not self._server.context.ok()

    def check(self) -> None:
        """Raise :class:`TaskCanceled` when :attr:`cancelled`."""
        if self.cancelled:
            why = "canceled" if self._handle.is_cancel_requested else "the robot's server is shutting down"
            raise TaskCanceled(f"{self._server.robot_id}: task {self.goal.task_id!r} {why}")

    def send(self, phase: str, progress: float, site: str = "",
             pose: Pose2D | Sequence[float] | None = None) -> None:
        """Publish feedback: ``phase`` (one of :data:`PHASES`; others are allowed and
        logged by the dispatcher), ``progress`` in [0, 1] of this robot's part, ``site``
        where the robot is (empty: between sites), ``pose`` (x, y, theta) when known.
        The first ``working`` feedback starts the result's duration."""
        if phase == ExecuteTask.Feedback.PHASE_WORKING and self._work_start is None:
            self._work_start = self._server.now()
        self.phase = phase
        msg = ExecuteTask.Feedback(phase=phase, progress=float(min(max(progress, 0.0), 1.0)), site=site)
        if isinstance(pose, Pose2D):
            msg.pose = pose
        elif pose is not None:
            x, y, theta = (float(v) for v in pose)
            msg.pose = Pose2D(x=x, y=y, theta=theta)
        if self._handle.is_active and self._server.context.ok():
            self._handle.publish_feedback(msg)

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` on the node's clock (simulated with ``use_sim_time``); raise
        :class:`TaskCanceled` as soon as the goal is cancelled."""
        clock = self._server.get_clock()
        deadline = clock.now().nanoseconds + max(seconds, 0.0) * 1e9
        self.check()
        while (left := (deadline - clock.now().nanoseconds) / 1e9) > 0:
            time.sleep(min(POLL_SECONDS, left))
            self.check()

    def worked(self) -> float:
        """Seconds since the first ``working`` feedback (0 before it), on the node's clock."""
        return 0.0 if self._work_start is None else max(self._server.now() - self._work_start, 0.0)


class TaskServer(Node):
    """One robot's ``<robot_id>/execute_task`` action server. Subclass it and write
    :meth:`execute`; see the module's documentation for what the base class handles.

    ``namespace`` is the cell's (empty: the node's, which ``--ros-args -r __ns:=/cell``
    sets); the node is named ``<robot_id>_task_server`` unless ``node_name`` is given.
    Other keyword arguments go to :class:`rclpy.node.Node` (``parameter_overrides``,
    ``context``...). Raises ConfigError for a robot id or namespace that ROS cannot name.
    """

    def __init__(self, robot_id: str, *, namespace: str = "", node_name: str | None = None, **node_args: Any) -> None:
        name = action_name(robot_id)
        node_name = node_name or f"{robot_id}_task_server"
        try:
            validate_node_name(node_name)
        except InvalidNodeNameException:
            raise ConfigError(f"robot {robot_id!r}: {node_name!r} is not a valid node name") from None
        super().__init__(node_name, namespace=check_namespace(namespace), **node_args)
        self.robot_id = robot_id
        self._lock = threading.Lock()
        self._busy: str | None = None  # the task id of the goal accepted and not yet finished
        self._starts: dict[str, tuple[tuple[str, ...], float]] = {}  # task -> (subteam, latest planned start)
        self.create_subscription(PlannedStart, PLANNED_STARTS_TOPIC, self._on_start, PLANNED_STARTS_QOS)
        self._action = ActionServer(self, ExecuteTask, name, execute_callback=self._execute,
                                    goal_callback=self._on_goal, cancel_callback=self._on_cancel,
                                    callback_group=ReentrantCallbackGroup())

    # ------------------------------------------------------------ for subclasses

    def execute(self, goal: Any, feedback: TaskFeedback) -> Any:
        """Do this robot's part of ``goal`` (an ``ExecuteTask.Goal``): travel to
        ``goal.site``, work, end at ``goal.site_to`` (or ``goal.site``), sending feedback
        on the way and calling ``feedback.check()`` (or ``feedback.sleep``) often.
        Return ``None``, a message, or an ``ExecuteTask.Result``; raise
        :class:`TaskFailed` to abort with a message."""
        raise NotImplementedError(f"{type(self).__name__} must define execute(goal, feedback)")

    def refuse(self, goal: Any) -> str | None:
        """A reason to reject ``goal`` beyond the base checks, or None to accept it
        (called before the robot is reserved; keep it quick)."""
        return None

    def now(self) -> float:
        """Seconds on the node's clock (ROS time: simulated with ``use_sim_time``)."""
        return float(self.get_clock().now().nanoseconds) / 1e9

    def _latest_start(self, goal: Any) -> float:
        """:attr:`TaskFeedback.planned_start` of ``goal``, the goal in hand."""
        with self._lock:
            moved = self._starts.get(goal.task_id)
        if moved is None or moved[0] != tuple(goal.subteam):
            return float(goal.planned_start)
        return max(float(goal.planned_start), moved[1])

    def _on_start(self, msg: Any) -> None:
        """A planned start that moved: kept for the goal in hand only (another task's, or
        one of an attempt over, would hold a later goal back)."""
        with self._lock:
            if self._busy == msg.task_id and self.robot_id in msg.subteam:
                self._starts[msg.task_id] = (tuple(msg.subteam), float(msg.planned_start))

    @property
    def busy_with(self) -> str | None:
        """The task id of the goal in hand, or None when free."""
        return self._busy

    def destroy_node(self) -> None:
        self._action.destroy()
        super().destroy_node()

    # ------------------------------------------------------------ action callbacks

    def _on_goal(self, goal: Any) -> GoalResponse:
        reason = None
        if self.robot_id not in goal.subteam:
            reason = f"its subteam {list(goal.subteam)} does not name this robot"
        else:
            reason = self.refuse(goal)
        if reason is None:
            with self._lock:
                if self._busy is not None:
                    reason = f"busy with task {self._busy!r}"
                else:
                    self._busy = goal.task_id
                    self._starts.clear()  # whatever moved before this goal was in hand is not its
        if reason is not None:
            self.get_logger().warning(f"{self.robot_id}: rejected the goal of task {goal.task_id!r}: {reason}")
            return GoalResponse.REJECT
        self.get_logger().info(f"{self.robot_id}: accepted task {goal.task_id!r}")
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle: ServerGoalHandle) -> CancelResponse:
        self.get_logger().info(f"{self.robot_id}: cancel requested for task {goal_handle.request.task_id!r}")
        return CancelResponse.ACCEPT

    def _execute(self, goal_handle: ServerGoalHandle) -> Any:
        feedback = TaskFeedback(self, goal_handle)
        task = goal_handle.request.task_id
        try:
            out = self.execute(goal_handle.request, feedback)
        except TaskCanceled as exc:
            return self._end(goal_handle, "canceled" if goal_handle.is_cancel_requested else "abort",
                             _result(None, feedback, False, str(exc)))
        except LvwsError as exc:
            return self._end(goal_handle, "abort", _result(None, feedback, False, str(exc)))
        except Exception as exc:  # a bug in execute: this goal fails, the server goes on serving
            self.get_logger().error(f"{self.robot_id}: task {task!r}: execute raised\n{traceback.format_exc()}")
            return self._end(goal_handle, "abort", _result(None, feedback, False, f"{type(exc).__name__}: {exc}"))
        finally:
            with self._lock:
                self._busy = None
                self._starts.pop(task, None)
        return self._end(goal_handle, "succeed", _result(out, feedback, True, f"{self.robot_id} did task {task!r}"))

    def _end(self, goal_handle: ServerGoalHandle, how: str, result: Any) -> Any:
        task = goal_handle.request.task_id
        line = f"{self.robot_id}: task {task!r}: {how} ({result.message}; {result.duration:.2f} s of work)"
        if how == "succeed":  # one severity per call site: rclpy's loggers insist
            self.get_logger().info(line)
        else:
            self.get_logger().warning(line)
        try:
            getattr(goal_handle, how)()
        except Exception as exc:  # a goal already ended, or a context shut down under us
            if self.context.ok():
                self.get_logger().warning(f"{self.robot_id}: task {task!r}: could not {how}: {exc}")
        return result


def _result(out: Any, feedback: TaskFeedback, success: bool, message: str) -> Any:
    """The ExecuteTask.Result of an ``execute`` that returned ``out`` (None, a message or
    a Result); its duration is the worked seconds unless set."""
    if isinstance(out, ExecuteTask.Result):
        result = out
    else:
        result = ExecuteTask.Result(success=success, message=out if isinstance(out, str) and out else message)
    if not (result.duration > 0 and math.isfinite(result.duration)):
        result.duration = feedback.worked()
    return result


def serve(servers: Sequence[Node], threads: int | None = None) -> int:
    """Spin ``servers`` (task servers, and any other nodes) on one multi-threaded executor
    until Ctrl-C, SIGTERM or shutdown; destroy them and shut rclpy down. Two threads per
    server by default: one may execute while the other answers its goals and cancels."""
    if not servers:
        raise ConfigError("no robot to serve")
    context = servers[0].context
    executor = MultiThreadedExecutor(num_threads=threads or 2 * len(servers) + 2, context=context)
    for node in servers:
        executor.add_node(node)
    try:
        while context.ok():  # not executor.spin(): a shutdown whose wake-up came while the executor was
            spin_once(servers[0], SHUTDOWN_CHECK, executor)  # between waits would leave it waiting for the next event
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RCLError:
        if context.ok():
            raise
        # a signal shut the context down while the executor made its wait set (an rclpy
        # race under load): the same as ExternalShutdownException
    finally:
        context.try_shutdown()  # running execute calls see it and stop at their next check
        executor.shutdown(timeout_sec=5.0)
        for node in servers:
            node.destroy_node()
    return 0

