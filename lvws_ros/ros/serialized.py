"""Reading a message's serialized bytes (what an rclpy subscription with ``raw=True``
gives) into plain tuples, without building a Python message object per field.

rclpy's own deserialization makes an object of every message, nested ones included (a
TaskGraph of 5,000 tasks: 5,000 Task objects and 10,000 Time objects), and the readers then
read each of their fields again; this reads the bytes once. The layout comes from the
generated message class itself (``SLOT_TYPES``, the ``rosidl_parser`` definitions of its
fields), so it follows the ``.msg`` files, and the encoding is plain CDR, little-endian
(the encapsulation ``CDR_LE``, the one the Jazzy middlewares write): primitives aligned to
their size from the start of the payload, strings and sequences a 32-bit length first.
Bytes in another encapsulation are not read here (:meth:`Layout.read` returns ``None``),
nor are classes with fields this does not read (:func:`layout_of` raises Unreadable: bytes,
chars, wide strings, arrays of strings or of messages); their callers deserialize them with
rclpy. Where rclpy would read a string otherwise than its bytes say (no NUL at its end, or
one inside it), :meth:`Layout.read` raises ValueError, so that rclpy's reading decides.

A message reads as one flat tuple: nested messages (not in sequences) inline, in field
order (``header.stamp.sec``, ``header.stamp.nanosec``, ``header.frame_id``, ...); a
sequence of messages as a list of such tuples; a sequence or array of numbers, or of
strings, as a tuple. :attr:`Layout.names` names the flat fields."""

from __future__ import annotations

import importlib
import struct
from collections.abc import Callable
from typing import Any

from rosidl_parser import definition

from lvws_ros.errors import LvwsError

__all__ = ["CDR_LE", "Layout", "Unreadable", "layout_of"]

CDR_LE = b"\x00\x01"  # the encapsulation identifier of plain little-endian CDR
_BASE = 4  # alignment counts from the end of the 4-byte encapsulation header

# The struct codes of the primitive types (their size is also their alignment in plain CDR).
_CODES = {"boolean": "?", "uint8": "B", "int8": "b", "uint16": "H", "int16": "h",
          "uint32": "I", "int32": "i", "uint64": "Q", "int64": "q", "float": "f", "double": "d"}

_U32 = struct.Struct("<I").unpack_from

Step = Callable[[bytes, int, list], int]  # reads its fields at a position into a list; the position after them


class Unreadable(LvwsError):
    """A field type this reader does not take (the caller lets rclpy deserialize)."""


def _align(pos: int, width: int) -> int:
    """``pos`` moved on to the next multiple of ``width`` (1, 2, 4 or 8) from the payload's start."""
    return pos + (-(pos - _BASE) & (width - 1))


def _count(buf: bytes, pos: int) -> tuple[int, int]:
    """A string's or a sequence's 32-bit length, and the position after it."""
    pos = _align(pos, 4)
    return _U32(buf, pos)[0], pos + 4


def _string_step(buf: bytes, pos: int, out: list) -> int:
    n, pos = _count(buf, pos)
    end = pos + n
    if end > len(buf):
        raise ValueError(f"a string of {n} bytes at {pos} runs past the end ({len(buf)} bytes)")
    if not n:
        out.append("")
        return end
    s = str(buf[pos:end - 1], "utf-8")
    if buf[end - 1] or "\0" in s:
        raise ValueError(f"the string at {pos} is not ended by its only NUL")
    out.append(s)
    return end


def _strings_step(buf: bytes, pos: int, out: list) -> int:
    n, pos = _count(buf, pos)
    items: list = []
    for _ in range(n):
        pos = _string_step(buf, pos, items)
    out.append(tuple(items))
    return pos


def _numbers_step(code: str, size: int | None) -> Step:
    """A sequence of primitives of ``code`` (``size`` None: its 32-bit length first) or an
    array of ``size`` of them, aligned to their size when there are any."""
    width, octets = struct.calcsize(code), code == "B"

    def step(buf: bytes, pos: int, out: list) -> int:
        if size is None:
            n, pos = _count(buf, pos)
        else:
            n = size
        if not n:
            out.append(())
            return pos
        pos = _align(pos, width)
        end = pos + n * width
        if end > len(buf):
            raise ValueError(f"{n} items of {width} bytes at {pos} run past the end ({len(buf)} bytes)")
        out.append(tuple(buf[pos:end]) if octets else struct.unpack_from(f"<{n}{code}", buf, pos))
        return end
    return step


def _messages_step(layout: Layout) -> Step:
    """A sequence of messages: a list of flat tuples."""
    def step(buf: bytes, pos: int, out: list) -> int:
        n, pos = _count(buf, pos)
        items, pos = layout.read_many(buf, pos, n)
        out.append(items)
        return pos
    return step


def _fixed(codes: list[str]) -> Step:
    """One step for consecutive primitives none larger than the first: aligned as the first
    one is, the padding between them is the same wherever they are."""
    first = struct.calcsize(codes[0])
    layout = struct.Struct("<" + "".join(codes))  # codes: padding bytes ("x") included
    unpack, size = layout.unpack_from, layout.size

    def step(buf: bytes, pos: int, out: list) -> int:
        pos = _align(pos, first)
        out.extend(unpack(buf, pos))
        return pos + size
    return step


def _narrow_string(t: Any) -> bool:
    return isinstance(t, definition.AbstractString) and not isinstance(t, definition.AbstractWString)


def _message_class(t: definition.NamespacedType) -> Any:
    try:
        return getattr(importlib.import_module(".".join(t.namespaces)), t.name)
    except (ImportError, AttributeError):  # a type only its action's or service's module knows
        raise Unreadable(f"a field of type {'/'.join((*t.namespaces, t.name))}") from None


class Layout:
    """How the serialized bytes of one message class read (see the module's text)."""

    def __init__(self, cls: Any) -> None:
        names: list[str] = []
        steps: list[Step] = []
        codes: list[str] = []  # primitives waiting to be read in one step

        def flush() -> None:
            if codes:
                steps.append(_fixed(codes[:]))
                codes.clear()

        def add(prefix: str, msg_cls: Any) -> None:
            if not msg_cls.SLOT_TYPES:  # an empty message is one byte on the wire
                codes.append("x")
            for name, t in zip(msg_cls.get_fields_and_field_types(), msg_cls.SLOT_TYPES, strict=True):
                if isinstance(t, definition.BasicType) and t.typename in _CODES:
                    code = _CODES[t.typename]
                    size = struct.calcsize(code)
                    if codes and size > struct.calcsize(codes[0]):
                        flush()
                    if codes:
                        codes.append("x" * (-struct.calcsize("<" + "".join(codes)) % size))
                    codes.append(code)
                    names.append(prefix + name)
                elif isinstance(t, definition.NamespacedType):
                    add(f"{prefix}{name}.", _message_class(t))
                else:
                    flush()
                    steps.append(self._step(t))
                    names.append(prefix + name)
        add("", cls)
        flush()
        self.names: tuple[str, ...] = tuple(names)
        self.steps: tuple[Step, ...] = tuple(steps)

    @staticmethod
    def _step(t: Any) -> Step:
        if _narrow_string(t):
            return _string_step
        if isinstance(t, definition.AbstractNestedType):
            size = t.size if isinstance(t, definition.Array) else None
            item = t.value_type
            if isinstance(item, definition.BasicType) and item.typename in _CODES:
                return _numbers_step(_CODES[item.typename], size)
            if size is None and _narrow_string(item):
                return _strings_step
            if size is None and isinstance(item, definition.NamespacedType):
                return _messages_step(layout_of(_message_class(item)))
        raise Unreadable(f"a field of type {type(t).__name__}")

    def read_one(self, buf: bytes, pos: int) -> tuple[tuple[Any, ...], int]:
        """The message at ``pos`` of a payload (a flat tuple), and the position after it."""
        items, pos = self.read_many(buf, pos, 1)
        return items[0], pos

    def read_many(self, buf: bytes, pos: int, n: int) -> tuple[list[tuple[Any, ...]], int]:
        """``n`` messages one after the other from ``pos``."""
        steps = self.steps
        items = []
        for _ in range(n):
            out: list = []
            for step in steps:
                pos = step(buf, pos, out)
            items.append(tuple(out))
        return items, pos

    def read(self, data: bytes) -> tuple[Any, ...] | None:
        """The serialized message ``data`` (4 bytes of encapsulation, then the payload) as a
        flat tuple; ``None`` for an encapsulation other than plain little-endian CDR.
        ValueError for bytes that end too soon, or hold a string that is not UTF-8 or that
        rclpy would read otherwise (module text)."""
        if bytes(data[:2]) != CDR_LE:
            return None
        try:
            return self.read_one(bytes(data), _BASE)[0]
        except struct.error as exc:
            raise ValueError(str(exc)) from None


_LAYOUTS: dict[Any, Layout | None] = {}


def layout_of(cls: Any) -> Layout:
    """The layout of a message class (made once); Unreadable for a class with fields this
    does not read."""
    if cls not in _LAYOUTS:
        try:
            _LAYOUTS[cls] = Layout(cls)
        except Unreadable:
            _LAYOUTS[cls] = None
    layout = _LAYOUTS[cls]
    if layout is None:
        raise Unreadable(f"{cls.__name__}: a field this reader does not take")
    return layout
