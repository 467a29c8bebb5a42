"""A world's state on the wire (docs/ros.md), by either protocol: ``snapshots`` publishes the
whole TeamState and TaskGraph at every state; ``changes`` publishes them once, then each state
as the next numbered ``CellChanges`` (what changed since the last one sent), serves the
snapshots of the last batch on the resync service, and lets done work retire from the live
cell ``retire_after`` seconds after it ended once its dependents have all started
(:meth:`~lvws_ros.core.changes.LiveCell.retire`). The simulator and the dispatcher both
publish through it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from lvws_msgs.msg import CellChanges, TaskGraph, TeamState
from lvws_msgs.srv import Resync
from rclpy.node import Node

from lvws_ros.core.changes import LiveCell, changes_between, without_retired
from lvws_ros.core.online import GraphSnapshot, TeamSnapshot
from lvws_ros.errors import ConfigError
from lvws_ros.ros import convert, topics

__all__ = ["PROTOCOLS", "StatePublisher"]

PROTOCOLS = ("snapshots", "changes")  # how a world's state goes out


class StatePublisher:
    """The publishers (and, for changes, the resync service) of a world ``node``."""

    def __init__(self, node: Node, now: Callable[[], tuple[TeamSnapshot, GraphSnapshot]], protocol: str = "snapshots",
                 retire_after: float = -1.0, frame_id: str = "map") -> None:
        if protocol not in PROTOCOLS:
            raise ConfigError(f"parameter protocol: one of {', '.join(PROTOCOLS)}, got {protocol!r}")
        if retire_after >= 0 and protocol != "changes":
            raise ConfigError("parameter retire_after: done work retires only with protocol changes "
                              "(a snapshot carries every task)")
        self.now, self.protocol, self.retire_after, self.frame_id = now, protocol, retire_after, frame_id
        self.team_pub = node.create_publisher(TeamState, topics.TEAM_TOPIC, topics.TEAM_QOS)
        self.graph_pub = node.create_publisher(TaskGraph, topics.GRAPH_TOPIC, topics.GRAPH_QOS)
        self.changes_pub = node.create_publisher(CellChanges, topics.CHANGES_TOPIC, topics.CHANGES_QOS)
        node.create_service(Resync, topics.RESYNC_SERVICE, self.on_resync)
        self.seq = 0  # the last CellChanges published
        self.sent: tuple[TeamSnapshot, GraphSnapshot] | None = None  # the cell as of it
        self.said: LiveCell | None = None  # the same, kept by its batches (retirement's rule)
        self.retired: set[str] = set()

    def publish(self, team: TeamSnapshot, graph: GraphSnapshot) -> None:
        """The world's state: snapshots (always the first), or the next batch."""
        if self.protocol == "changes" and self.sent is not None:
            self._publish_changes(team, graph)
            return
        self.team_pub.publish(convert.team_to_msg(team, self.frame_id))
        self.graph_pub.publish(convert.graph_to_msg(graph, self.frame_id))
        self.sent = (team, graph)

    def publish_team(self, team: TeamSnapshot) -> None:
        """The team alone (robots moved): a TeamState, or a batch with the tasks as sent."""
        if self.protocol == "changes" and self.sent is not None:
            self._publish_changes(team, replace(self.sent[1], stamp=team.stamp))
        else:
            self.team_pub.publish(convert.team_to_msg(team, self.frame_id))

    def _publish_changes(self, team: TeamSnapshot, graph: GraphSnapshot) -> None:
        assert self.sent is not None
        if self.retire_after >= 0:
            if self.said is None:
                self.said = LiveCell(*self.sent)
            self.retired.update(self.said.retire(self.retire_after))  # DONE already sent, dependents started
            graph = replace(graph, tasks=tuple(without_retired(graph.tasks, self.retired)))
        self.seq += 1
        batch = changes_between(self.sent, (team, graph), self.seq)
        if self.said is not None:  # it retired them already
            self.said.apply(replace(batch, retired=()))
        self.changes_pub.publish(convert.changes_to_msg(batch, self.frame_id))
        self.sent = (team, graph)

    def on_resync(self, _req: Any, res: Any) -> Any:
        """The cell as of the last batch sent (none yet: the world's state, published first as
        the snapshots of change 0)."""
        if self.sent is None:
            self.publish(*self.now())
        assert self.sent is not None
        team, graph = self.sent
        res.team, res.graph = convert.team_to_msg(team, self.frame_id), convert.graph_to_msg(graph, self.frame_id)
        res.seq = self.seq
        return res
