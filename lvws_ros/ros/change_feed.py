"""Following a world that speaks changes (docs/ros.md, "Changes instead of snapshots"), as
every reader of one does it: each ``CellChanges`` message read into the core's batch (one
that cannot be read asks for a snapshot), and the world's snapshots asked for on its resync
service, one request at a time, whenever the :class:`~lvws_ros.core.changes.ChangeFollower`
needs them. The scheduler node and the dashboard both follow a world through it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from lvws_msgs.srv import Resync
from rclpy.node import Node

from lvws_ros.core.changes import CellChanges, ChangeFollower
from lvws_ros.errors import InstanceError
from lvws_ros.ros import convert, topics

__all__ = ["ChangeFeed"]


class ChangeFeed:
    """``follower``'s link to the world: :meth:`read` a batch, :meth:`ask` for snapshots;
    ``answered(response)`` is called with each resync answer (``None`` when the call failed),
    through ``defer`` (default: at once, on the thread that spins ``node``); no second request
    goes out before it ran."""

    def __init__(self, node: Node, follower: ChangeFollower, answered: Callable[[Any], None],
                 defer: Callable[[Callable[[], None]], None] = lambda work: work()) -> None:
        self.follower, self.answered, self.defer = follower, answered, defer
        self.client = node.create_client(Resync, topics.RESYNC_SERVICE)
        self.pending: Any = None  # the request in flight

    def read(self, msg: Any) -> tuple[CellChanges | None, str]:
        """The message (or its serialized bytes: a raw subscription's) as a batch, or
        ``(None, why)`` for one that cannot be read (the follower then needs a snapshot,
        and one is asked for)."""
        try:
            if isinstance(msg, bytes):
                return convert.changes_from_serialized(msg), ""
            return convert.changes_from_msg(msg), ""
        except (TypeError, ValueError, InstanceError) as exc:
            self.follower.needs_resync = True
            self.ask()
            what = "a CellChanges" if isinstance(msg, bytes) else f"CellChanges {msg.seq}"
            return None, f"{what} ignored: {exc}; asking for a snapshot"

    def ask(self) -> None:
        """Ask the world for its snapshots if the follower needs them, no request is in
        flight and the service is there (else: asked again at the next batch or call)."""
        if not self.follower.needs_resync or self.pending is not None or not self.client.service_is_ready():
            return
        self.pending = self.client.call_async(Resync.Request())
        self.pending.add_done_callback(self._done)

    def _done(self, future: Any) -> None:
        res = future.result()

        def answer() -> None:
            self.pending = None
            self.answered(res)
        self.defer(answer)
