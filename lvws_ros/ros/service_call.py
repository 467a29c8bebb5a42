"""Calling a ROS 2 service when DDS may drop the answer.

A server answers over a writer of its own, which must have matched the client's reader
of answers; a client sees the server once its own endpoints have matched, which can be
before the server's side has. Fast DDS, the default RMW, waits 100 ms for that match
when it sends an answer, then drops the answer ("client will not receive response");
the request was carried out, but the client's future never completes. On a loaded
machine that happens to a client's first request now and then.

So a new client waits :data:`SETTLE` seconds after it first sees its server
(:func:`ready`), and :func:`call` bounds the wait for an answer: a request that may be
repeated (a query, or a change whose effect is checked) is sent again after ``resend``
seconds without an answer; any other is sent once.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from rclpy.client import Client
from rclpy.task import Future

__all__ = ["SETTLE", "call", "ready"]

SETTLE = 0.5  # wall seconds a new client waits once its server is seen, before its first request

Wait = Callable[[Future, float], bool]  # wait up to that many seconds for the future; whether it is done


def ready(client: Client, timeout: float, settle: float = SETTLE) -> bool:
    """Whether ``client``'s server is seen within ``timeout`` wall seconds; then wait
    ``settle`` seconds more, so the server's side has matched the client too."""
    if not client.wait_for_service(timeout_sec=timeout):
        return False
    time.sleep(settle)
    return True


def call(client: Client, request: Any, wait: Wait, timeout: float, resend: float = 0.0) -> Any | None:
    """The answer to ``request``, or None when none came within ``timeout`` wall seconds.
    With ``resend`` > 0 the request is sent again after that many seconds without an answer
    (only for requests that may be repeated); the unanswered one is forgotten."""
    end = time.monotonic() + timeout
    while True:
        future = client.call_async(request)
        left = end - time.monotonic()
        if wait(future, max(0.0, min(left, resend) if resend > 0 else left)):
            return future.result()
        client.remove_pending_request(future)
        if time.monotonic() >= end:
            return None
