"""Exact CDR payloads from ``rclpy.serialization.serialize_message``.

rclpy's ``serialize_message`` (Jazzy, rmw_fastrtps) returns a buffer as long as the
type support's size *estimate*, which can exceed the serialized data: a JointState
with two joints and no velocities comes back 8 bytes too long, an empty one 12, the
tail being stale memory. ROS 2 readers ignore the tail, but a strict reader (the
``rosbags`` package) rejects a message that has more than 3 bytes after its end.
``CdrTrimmer`` finds where the message ends and cuts the tail off: it walks the
buffer with the type's field layout (XCDR1: each primitive aligned to its size from
the start of the payload; strings and sequences prefixed by a uint32 count), jumping
over arrays of primitives and over runs of fixed-size structures (a marker's points)
in one step. Field layouts come from ``rosbags``' parser of the installed definitions.
"""
from __future__ import annotations

import struct
import threading
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from gripper_sim.recording import schemas

ENCAPSULATION_SIZE = 4
PRIMITIVE_SIZES = {'bool': 1, 'byte': 1, 'char': 1, 'int8': 1, 'uint8': 1, 'int16': 2,
                   'uint16': 2, 'int32': 4, 'uint32': 4, 'int64': 8, 'uint64': 8,
                   'float32': 4, 'float64': 8}


class _Truncated(Exception):
    """The buffer ends before the message does."""


def _align(pos: int, size: int) -> int:
    return pos + (-pos) % size


class CdrTrimmer:
    """Cuts rclpy-serialized messages to their exact CDR length.

    Types are learned from the installed definitions the first time they are seen.
    """

    def __init__(self) -> None:
        self._store = get_typestore(Stores.EMPTY)
        self._known: set[str] = set()
        self._lock = threading.Lock()
        self.fixed_types: dict[str, bool] = {}
        # (type, start offset mod 8) -> bytes a fixed-size structure takes from there
        self.fixed_sizes: dict[tuple[str, int], int] = {}

    def fields_of(self, type_name: str) -> list:
        """The field definitions of the message type ``type_name`` (rosbags' typestore
        ``fielddefs``: (name, (kind, spec)) each), registered on first use."""
        if type_name not in self._known:
            with self._lock:
                if type_name not in self._known:
                    text = schemas.message_definition(type_name)
                    types = get_types_from_msg(text, type_name)
                    self._store.register({k: v for k, v in types.items()
                                          if k not in self._store.fielddefs})
                    self._known.add(type_name)
        return self._store.fielddefs[type_name][1]

    def trim(self, type_name: str, data: bytes) -> bytes:
        """``data`` without whatever follows the end of the message.

        A buffer that does not walk as ``type_name`` is returned unchanged: the
        recording keeps every byte it was given rather than lose a message.
        """
        if len(data) < ENCAPSULATION_SIZE or data[0] != 0 or data[1] not in (0, 1):
            return data
        walk = _Walk(self, memoryview(data)[ENCAPSULATION_SIZE:], '<I' if data[1] else '>I')
        try:
            end = walk.struct(schemas.full_type_name(type_name), 0)
        except (_Truncated, struct.error, KeyError, ValueError):
            return data
        length = ENCAPSULATION_SIZE + end
        return data[:length] if length < len(data) else data


class _Walk:
    """One pass over one payload; positions are offsets from the payload's start."""

    def __init__(self, trimmer: CdrTrimmer, payload: Any, count_format: str):
        self.trimmer = trimmer
        self.payload = payload
        self.count_format = count_format

    def count(self, pos: int) -> tuple[int, int]:
        pos = _align(pos, 4)
        if pos + 4 > len(self.payload):
            raise _Truncated
        return struct.unpack_from(self.count_format, self.payload, pos)[0], pos + 4

    def struct(self, type_name: str, pos: int) -> int:
        key = (type_name, pos % 8)
        size = self.trimmer.fixed_sizes.get(key)
        if size is not None:
            end = pos + size
        else:
            end = pos
            for _, (kind, spec) in self.trimmer.fields_of(type_name):
                end = self.field(kind, spec, end)
            if self._fixed(Nodetype.NAME, type_name):
                self.trimmer.fixed_sizes[key] = end - pos
        if end > len(self.payload):
            raise _Truncated
        return end

    def field(self, kind: Any, spec: Any, pos: int) -> int:
        if kind == Nodetype.BASE:
            return self.base(spec[0], pos)
        if kind == Nodetype.NAME:
            return self.struct(spec, pos)
        (element_kind, element_spec), size = spec
        if kind == Nodetype.SEQUENCE:
            size, pos = self.count(pos)
        return self.elements(element_kind, element_spec, size, pos)

    def base(self, name: str, pos: int) -> int:
        size = PRIMITIVE_SIZES.get(name)
        if size is not None:
            return _align(pos, size) + size
        if name != 'string':
            raise ValueError(f'no CDR walk for {name}')
        length, pos = self.count(pos)
        return pos + length

    def elements(self, kind: Any, spec: Any, count: int, pos: int) -> int:
        if count == 0:
            return pos
        if kind == Nodetype.BASE and spec[0] in PRIMITIVE_SIZES:
            size = PRIMITIVE_SIZES[spec[0]]
            return _align(pos, size) + count * size
        # An element without strings or sequences takes the same bytes wherever it
        # starts at the same offset modulo 8: once one ends where it started (mod 8),
        # every following one does too, and the rest is one jump (a marker's points).
        fixed = self._fixed(kind, spec)
        for done in range(count):
            end = self.field(kind, spec, pos)
            if fixed and (end - pos) % 8 == 0:
                return end + (count - done - 1) * (end - pos)
            pos = end
        return pos

    def _fixed(self, kind: Any, spec: Any) -> bool:
        """Whether elements of this kind always take the same bytes (no string or
        sequence inside)."""
        if kind == Nodetype.BASE:
            return spec[0] in PRIMITIVE_SIZES
        if kind == Nodetype.SEQUENCE:
            return False
        if kind == Nodetype.ARRAY:
            (element_kind, element_spec), _ = spec
            return self._fixed(element_kind, element_spec)
        fixed = self.trimmer.fixed_types.get(spec)
        if fixed is None:
            fixed = all(self._fixed(k, s) for _, (k, s) in self.trimmer.fields_of(spec))
            self.trimmer.fixed_types[spec] = fixed
        return fixed
