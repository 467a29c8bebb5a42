"""Service calls that bound their wait, over real DDS: a query unanswered in time (here: a
server that does not spin for its first seconds, standing for an answer dropped on the
way) is sent again and the answer that comes is taken; a change is sent once, and a
server that never answers gives None at the timeout, not a hang. And a node's spin goes
on past an answer the middleware would not send, as rclcpp's does."""

from __future__ import annotations

import time
from typing import Any

import pytest
import rclpy
from lifecycle_msgs.srv import GetState

from lvws_ros.ros.service_call import call, ready

pytestmark = pytest.mark.ros


def _pair(ros_context: Any, name: str) -> tuple[Any, Any, Any, list[int]]:
    """A client node and a server node (each its own executor) and the requests the server took."""
    client_node = rclpy.create_node(f"{name}_client", context=ros_context)
    server_node = rclpy.create_node(f"{name}_server", context=ros_context)
    taken: list[int] = []

    def answer(request: Any, response: Any) -> Any:
        taken.append(1)
        response.current_state.label = "answered"
        return response

    server_node.create_service(GetState, f"{name}/get_state", answer)
    return client_node, server_node, client_node.create_client(GetState, f"{name}/get_state"), taken


def _executor(ros_context: Any, node: Any) -> Any:
    ex = rclpy.executors.SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    return ex


def test_a_query_unanswered_in_time_is_sent_again_and_the_answer_taken(ros_context):
    client_node, server_node, client, taken = _pair(ros_context, "lvws_call_resend")
    cex, sex = _executor(ros_context, client_node), _executor(ros_context, server_node)
    began = time.monotonic()

    def wait(future: Any, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while not future.done() and time.monotonic() < end:
            cex.spin_once(timeout_sec=0.02)
            if time.monotonic() - began > 2.0:  # the server is deaf for its first 2 s
                sex.spin_once(timeout_sec=0.02)
        return bool(future.done())

    try:
        assert ready(client, 30.0)
        began = time.monotonic()
        res = call(client, GetState.Request(), wait, 30.0, resend=0.5)
        assert res is not None and res.current_state.label == "answered"
        assert len(taken) >= 2  # sent again while the first went unanswered
    finally:
        cex.shutdown()
        sex.shutdown()
        client_node.destroy_node()
        server_node.destroy_node()


def test_a_change_is_sent_once_and_a_silent_server_gives_none_at_the_timeout(ros_context):
    client_node, server_node, client, taken = _pair(ros_context, "lvws_call_once")
    cex, sex = _executor(ros_context, client_node), _executor(ros_context, server_node)
    spin_server = False

    def wait(future: Any, seconds: float) -> bool:
        end = time.monotonic() + seconds
        while not future.done() and time.monotonic() < end:
            cex.spin_once(timeout_sec=0.02)
            if spin_server:
                sex.spin_once(timeout_sec=0.02)
        return bool(future.done())

    try:
        assert ready(client, 30.0)
        began = time.monotonic()
        assert call(client, GetState.Request(), wait, 1.5) is None  # the server is never spun: no answer
        assert 1.5 <= time.monotonic() - began < 10.0
        spin_server = True
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            sex.spin_once(timeout_sec=0.05)
        assert len(taken) == 1  # sent once, and carried out once
        res = call(client, GetState.Request(), wait, 30.0)
        assert res is not None and len(taken) == 2
    finally:
        cex.shutdown()
        sex.shutdown()
        client_node.destroy_node()
        server_node.destroy_node()


def test_a_spin_goes_on_past_an_answer_the_middleware_would_not_send(ros_context):
    from rclpy._rclpy_pybind11 import RCLError

    from lvws_ros.ros.entry import spin_once

    node = rclpy.create_node("lvws_spin_guard", context=ros_context)
    ex = _executor(ros_context, node)
    raised: list[str] = []

    def fail() -> None:  # what rclpy's executor raises when Fast DDS refuses to send an answer
        raised.append(raised[0] if raised else "failed to send response: client will not receive response")
        raise RCLError(raised[-1])

    timer = node.create_timer(0.01, fail)
    try:
        end = time.monotonic() + 5.0
        while len(raised) < 3 and time.monotonic() < end:
            spin_once(node, 0.1, ex)  # logged, not raised
        assert len(raised) >= 3
        raised[0] = "failed to publish: a real error"
        with pytest.raises(RCLError, match="failed to publish"):
            for _ in range(50):
                spin_once(node, 0.1, ex)
    finally:
        node.destroy_timer(timer)
        ex.shutdown()
        node.destroy_node()
