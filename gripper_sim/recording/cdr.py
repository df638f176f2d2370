"""Exact CDR payloads from ``rclpy.serialization.serialize_message``.

rclpy's ``serialize_message`` (Jazzy, rmw_fastrtps) returns a buffer as long as the
type support's size *estimate*, which can exceed the serialized data: a JointState
with two joints comes back 8 bytes too long, an empty one 12, the tail being stale
memory. ROS 2 readers ignore the tail, but a strict reader (the ``rosbags`` package)
rejects a message that has more than 3 bytes after its end. ``CdrTrimmer`` finds where
the message ends by walking it with ``rosbags``' generated deserializer (a few
microseconds for a JointState) and cuts the tail off.
"""
from __future__ import annotations

import struct
import threading

from rosbags.typesys import Stores, get_typestore, get_types_from_msg

from gripper_sim.recording import schemas

ENCAPSULATION_SIZE = 4


class CdrTrimmer:
    """Cuts rclpy-serialized messages to their exact CDR length.

    Types are learned from the installed definitions the first time they are seen.
    """

    def __init__(self) -> None:
        self._store = get_typestore(Stores.EMPTY)
        self._known: set[str] = set()
        self._lock = threading.Lock()

    def _msgdef(self, type_name: str):
        if type_name not in self._known:
            with self._lock:
                if type_name not in self._known:
                    text = schemas.message_definition(type_name)
                    types = get_types_from_msg(text, type_name)
                    self._store.register({k: v for k, v in types.items()
                                          if k not in self._store.fielddefs})
                    self._known.add(type_name)
        return self._store.get_msgdef(type_name)

    def trim(self, type_name: str, data: bytes) -> bytes:
        """``data`` without whatever follows the end of the message.

        A buffer that does not parse as ``type_name`` is returned unchanged: the recording
        keeps every byte it was given rather than lose a message.
        """
        if len(data) < ENCAPSULATION_SIZE or data[0] != 0 or data[1] not in (0, 1):
            return data
        msgdef = self._msgdef(schemas.full_type_name(type_name))
        walk = msgdef.deserialize_cdr_le if data[1] else msgdef.deserialize_cdr_be
        try:
            _, end = walk(memoryview(data)[ENCAPSULATION_SIZE:], 0, msgdef.cls, self._store)
        except (struct.error, UnicodeDecodeError, ValueError, IndexError):
            return data
        length = ENCAPSULATION_SIZE + end
        return data[:length] if length < len(data) else data
