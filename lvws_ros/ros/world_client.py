"""``lvws submit / cancel / fault``: change a running cell through its world's services
(``submit_tasks``, ``cancel_task``, ``set_robot_fault`` in the cell's namespace): the
simulator's, or the dispatcher's (its ``submit_tasks`` takes tasks as instance files write
them, ``lvws_msgs/srv/SubmitInstanceTasks``: the type served decides).

Run on the cell's DDS domain (``--domain-id``, or ``ROS_DOMAIN_ID``; ``lvws launch``
prints its domain). Returns the world's answer: (accepted, message).
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from lvws_ros.errors import ConfigError, LvwsError
from lvws_ros.ros.convert import cell_task_to_msg
from lvws_ros.sim.config import read_yaml

__all__ = ["SERVICES", "call_world", "join_domain", "served_type", "tasks_from_file", "world_request"]

SERVICES = {"submit": "submit_tasks", "cancel": "cancel_task", "fault": "set_robot_fault"}


def tasks_from_file(path: str | Path) -> list[dict[str, Any]]:
    """Task entries (like config/assembly_cell.yaml's ``tasks``) from a YAML file: a list,
    or a mapping with a ``tasks`` list."""
    p = Path(path)
    data = read_yaml(p, "task file")
    items = data.get("tasks") if isinstance(data, dict) else data
    if not isinstance(items, list) or not items or not all(isinstance(t, dict) for t in items):
        raise ConfigError(f"{p}: expected a non-empty list of task entries (or a mapping with a 'tasks' list)")
    return items


def join_domain(domain_id: int | None) -> None:
    """Talk on DDS domain ``domain_id`` (None: as the environment says), on this machine
    only unless the environment says otherwise (what ``lvws launch`` uses)."""
    if domain_id is not None:
        os.environ["ROS_DOMAIN_ID"] = str(domain_id)
        os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


INSTANCE_SUBMIT = "lvws_msgs/srv/SubmitInstanceTasks"  # the dispatcher's submit_tasks (tasks as instance files write them)


def world_request(kind: str, *, tasks: Sequence[dict[str, Any]] = (), target: str = "",
                  failed: bool = True, submit_type: str = "") -> tuple[Any, Any]:
    """(service type, request) of one of the world's services (LvwsError: unknown kind);
    ``submit_type`` :data:`INSTANCE_SUBMIT`: the dispatcher's, else the simulator's."""
    from lvws_msgs.srv import CancelTask, SetRobotFault, SubmitInstanceTasks, SubmitTasks

    if kind == "submit" and submit_type == INSTANCE_SUBMIT:
        from lvws_ros.ros.convert import instance_task_to_msg

        return SubmitInstanceTasks, SubmitInstanceTasks.Request(
            tasks=[instance_task_to_msg(t, k) for k, t in enumerate(tasks)])
    if kind == "submit":
        return SubmitTasks, SubmitTasks.Request(tasks=[cell_task_to_msg(t, k) for k, t in enumerate(tasks)])
    if kind == "cancel":
        return CancelTask, CancelTask.Request(task_id=target)
    if kind == "fault":
        return SetRobotFault, SetRobotFault.Request(robot_id=target, failed=failed)
    raise LvwsError(f"unknown world change {kind!r}; one of {', '.join(SERVICES)}")


def served_type(node: Any, name: str, timeout: float) -> str:
    """The type of the service ``name`` (relative to ``node``) once it is seen ('' if never)."""
    full = node.resolve_service_name(name)
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for served, types in node.get_service_names_and_types():
            if served == full and types:
                return str(types[0])
        time.sleep(0.1)
    return ""


def call_world(kind: str, *, namespace: str = "", tasks: Sequence[dict[str, Any]] = (), target: str = "",
               failed: bool = True, domain_id: int | None = None, timeout: float = 20.0) -> tuple[bool, str]:
    """Call one of the simulator's services and return (accepted, message); LvwsError when
    no simulator answers within ``timeout`` wall seconds."""
    join_domain(domain_id)
    import rclpy

    from lvws_ros.ros.service_call import call, ready

    rclpy.init(args=["lvws_world_client"])
    try:
        node = rclpy.create_node("lvws_world_client", namespace=namespace or None)
        srv, request = world_request(kind, tasks=tasks, target=target, failed=failed,
                                     submit_type=served_type(node, SERVICES[kind], timeout) if kind == "submit" else "")
        client = node.create_client(srv, SERVICES[kind])
        name = client.srv_name
        if not ready(client, timeout):
            raise LvwsError(f"no simulator answers on {name} within {timeout:g} s "
                            f"(ROS_DOMAIN_ID={os.environ.get('ROS_DOMAIN_ID', '0')}; is the cell running there?)")

        def wait(future: Any, seconds: float) -> bool:
            rclpy.spin_until_future_complete(node, future, timeout_sec=seconds)
            return bool(future.done())

        res = call(client, request, wait, timeout)  # sent once: a change is not repeated
        if res is None:
            raise LvwsError(f"{name}: no answer within {timeout:g} s")
        return bool(res.success), str(res.message)
    finally:
        rclpy.try_shutdown()
