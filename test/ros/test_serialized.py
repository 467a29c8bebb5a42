"""Reading serialized messages without a message object per field: the bytes rclpy
serializes read back as rclpy's own deserialization reads them (the snapshots, and other
packages' messages with arrays and nested sequences), the readers' snapshots from bytes
equal the whole conversion's, and bytes that do not read are refused, not misread."""

from __future__ import annotations

import pytest
from action_msgs.msg import GoalStatus, GoalStatusArray
from diagnostic_msgs.msg import DiagnosticArray
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from lvws_msgs.msg import CellChanges, TaskGraph, TeamState
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message, serialize_message
from rosidl_parser import definition

from lvws_ros.core.changes import CellChanges as Changes
from lvws_ros.core.online import GraphSnapshot, RobotInfo, TaskInfo, TeamSnapshot
from lvws_ros.errors import InstanceError
from lvws_ros.ros.convert import (
    GraphReader,
    TeamReader,
    changes_from_msg,
    changes_from_serialized,
    changes_to_msg,
    graph_from_msg,
    graph_to_msg,
    team_from_msg,
    team_to_msg,
)
from lvws_ros.ros.serialized import Layout, Unreadable, layout_of


def flat(msg: object) -> tuple:
    """The oracle: an rclpy message object flattened by the reader's rules."""
    out: list = []
    for name, t in zip(msg.get_fields_and_field_types(), msg.SLOT_TYPES, strict=True):  # type: ignore[attr-defined]
        v = getattr(msg, name)
        if isinstance(t, definition.NamespacedType):
            out.extend(flat(v))
        elif isinstance(t, definition.AbstractNestedType) and isinstance(t.value_type, definition.NamespacedType):
            out.append([flat(x) for x in v])
        elif isinstance(t, definition.AbstractNestedType):
            out.append(tuple(v.tolist() if hasattr(v, "tolist") else v))
        else:
            out.append(v)
    return tuple(out)


def read_back(msg: object) -> tuple | None:
    data = serialize_message(msg)
    return layout_of(type(msg)).read(data)


text = st.text(st.characters(codec="utf-8", exclude_characters="\x00"), max_size=9)  # lengths move the alignment
number = st.floats(allow_nan=False, width=64)


@st.composite
def tasks(draw: st.DrawFn) -> TaskInfo:
    status = draw(st.integers(0, 3))
    return TaskInfo(draw(text), status, tuple(draw(st.lists(st.integers(0, 1), max_size=5))), draw(number),
                    draw(number), tuple(draw(st.lists(text, max_size=3))), tuple(draw(st.lists(text, max_size=3))),
                    draw(st.integers(0, 10**6)) + 0.5 if status >= 2 else None,
                    draw(st.integers(0, 10**6)) + 0.25 if status == 3 else None, draw(text), draw(text),
                    tuple(draw(st.lists(number, max_size=3))), draw(st.integers(0, 2)))


@st.composite
def robots(draw: st.DrawFn) -> RobotInfo:
    return RobotInfo(draw(text), draw(text), draw(st.booleans()), tuple(draw(st.lists(st.integers(0, 1), max_size=4))),
                     draw(number), draw(text), draw(number), (draw(number), draw(number), draw(number)), draw(text),
                     draw(number), tuple(draw(st.lists(number, max_size=3))), draw(text))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(tasks(), max_size=6), st.lists(st.tuples(text, number, number), max_size=3),
       st.lists(number, max_size=4), st.lists(text, max_size=3), st.booleans(), text, text, st.integers(0, 10**6))
def test_a_task_graph_reads_from_its_bytes_as_rclpy_reads_it(items: list[TaskInfo], sites: list, distances: list,
                                                            traits: list, roles: bool, objective: str,
                                                            departure: str, stamp: int) -> None:
    snap = GraphSnapshot(stamp + 0.5, ("arm", "ü"), tuple(items), tuple(sites), tuple(distances), tuple(traits),
                         roles, objective, departure)
    msg = graph_to_msg(snap)
    data = serialize_message(msg)
    assert layout_of(TaskGraph).read(data) == flat(deserialize_message(data, TaskGraph))
    assert GraphReader().read_serialized(data) == graph_from_msg(msg)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(robots(), max_size=6), st.lists(text, max_size=3), st.integers(0, 10**6))
def test_a_team_state_reads_from_its_bytes_as_rclpy_reads_it(items: list[RobotInfo], traits: list,
                                                            stamp: int) -> None:
    msg = team_to_msg(TeamSnapshot(stamp + 0.5, ("arm",), tuple(items), tuple(traits)))
    data = serialize_message(msg)
    assert layout_of(TeamState).read(data) == flat(deserialize_message(data, TeamState))
    assert TeamReader().read_serialized(data) == team_from_msg(msg)


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**63), st.lists(tasks(), max_size=5), st.lists(text, max_size=3), st.lists(text, max_size=3),
       st.lists(robots(), max_size=5), st.lists(text, max_size=3), st.integers(0, 10**6))
def test_a_batch_of_changes_reads_from_its_bytes_as_rclpy_reads_it(seq: int, items: list[TaskInfo], cancelled: list,
                                                                  retired: list, members: list[RobotInfo], left: list,
                                                                  stamp: int) -> None:
    msg = changes_to_msg(Changes(seq, stamp + 0.5, tuple(items), tuple(cancelled), tuple(retired), tuple(members),
                                 tuple(left)))
    data = serialize_message(msg)
    assert layout_of(CellChanges).read(data) == flat(deserialize_message(data, CellChanges))
    assert changes_from_serialized(data) == changes_from_msg(msg)


def test_a_batch_whose_bytes_do_not_read_is_refused_naming_the_message() -> None:
    data = serialize_message(changes_to_msg(Changes(3, 1.0, graph().tasks)))
    for bad in (data[: len(data) // 2], b"", bytes(7)):
        with pytest.raises(InstanceError, match="CellChanges"):
            changes_from_serialized(bad)


@settings(max_examples=60, deadline=None)
@given(st.lists(number, min_size=36, max_size=36), text, st.lists(st.tuples(st.binary(min_size=16, max_size=16),
                                                                            st.integers(-6, 6)), max_size=4))
def test_other_packages_messages_read_as_rclpy_reads_them(covariance: list[float], frame: str,
                                                          goals: list[tuple[bytes, int]]) -> None:
    """Arrays (a covariance of 36, a 16-byte uuid), nested messages and sequences of them."""
    odom = Odometry(child_frame_id=frame)
    odom.header.frame_id = frame[::-1]
    odom.pose.covariance = covariance
    odom.twist.twist.angular.z = covariance[0]
    statuses = GoalStatusArray(status_list=[GoalStatus(status=s) for _, s in goals])
    for g, (uuid, _) in zip(statuses.status_list, goals, strict=True):
        g.goal_info.goal_id.uuid = list(uuid)
    for msg in (odom, statuses):
        assert read_back(msg) == flat(msg)


def graph() -> GraphSnapshot:
    return GraphSnapshot(0.0, ("arm",), tuple(TaskInfo(f"t{j}", 1, (1,), 1.0, 2.0, (f"t{j - 1}",) if j else ())
                                              for j in range(4)))


def test_bytes_that_end_too_soon_are_refused_naming_the_message() -> None:
    data = serialize_message(graph_to_msg(graph()))
    end = layout_of(TaskGraph).read_one(data, 4)[1]  # rclpy's buffer may run on past the message
    for cut in (end // 2, end - 3, 30):
        with pytest.raises(ValueError):
            layout_of(TaskGraph).read(data[:cut])
        with pytest.raises(InstanceError, match="TaskGraph"):
            GraphReader().read_serialized(data[:cut])


def test_bytes_rclpy_cannot_read_either_are_refused_naming_the_message() -> None:
    for bad in (b"", b"\x00", b"\x00\x00\x00\x00", bytes(7)):
        with pytest.raises(InstanceError, match="TaskGraph"):
            GraphReader().read_serialized(bad)
        with pytest.raises(InstanceError, match="TeamState"):
            TeamReader().read_serialized(bad)


@pytest.mark.parametrize("text", ["a\x00", "abc"])
def test_a_string_rclpy_reads_otherwise_than_its_bytes_is_read_as_rclpy_reads_it(text: str) -> None:
    """A string whose last byte is not its NUL, or with a NUL inside (hostile bytes):
    rclpy's reading decides, so the node sees what any other reader of the topic sees."""
    data = bytearray(serialize_message(TaskGraph(objective="ab")))
    at = data.rfind(b"ab\x00")
    data[at:at + 3] = text.encode()
    with pytest.raises(ValueError, match="NUL"):
        layout_of(TaskGraph).read(bytes(data))
    assert GraphReader().read_serialized(bytes(data)) == graph_from_msg(deserialize_message(bytes(data), TaskGraph))


def test_an_empty_message_takes_its_one_byte() -> None:
    """CDR gives a message without fields one byte: what follows it stays aligned."""
    from lifecycle_msgs.msg import State
    from lifecycle_msgs.srv import GetState

    event = GetState.Event(request=[GetState.Request()], response=[GetState.Response(current_state=State(id=3,
                                                                                                           label="x"))])
    assert read_back(event) == flat(event)


def test_a_field_type_only_its_action_knows_is_not_read_here() -> None:
    from lvws_msgs.action import ExecuteTask

    with pytest.raises(Unreadable):
        layout_of(ExecuteTask.Impl.SendGoalService.Request)


def test_another_encapsulation_is_left_to_rclpy() -> None:
    data = serialize_message(graph_to_msg(graph()))
    assert layout_of(TaskGraph).read(b"\x00\x00" + data[2:]) is None  # big-endian CDR: not read here
    assert GraphReader().read_serialized(data) == graph_from_msg(graph_to_msg(graph()))


def test_fields_the_reader_does_not_take_leave_the_message_to_rclpy() -> None:
    """A byte field (DiagnosticStatus.level) is bytes in rclpy, not a number: such classes
    are not read here, and their readers deserialize with rclpy."""
    with pytest.raises(Unreadable):
        layout_of(DiagnosticArray)
    with pytest.raises(Unreadable):
        Layout(type("Wide", (), {"SLOT_TYPES": (definition.UnboundedWString(),),
                                 "get_fields_and_field_types": staticmethod(lambda: {"w": "wstring"})}))
