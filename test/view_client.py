"""A plain Foxglove WebSocket client for the view tests, written from the protocol spec.

Only what the tests need: the handshake (subprotocol ``foxglove.sdk.v1``, the one
``foxglove-sdk`` 0.30 accepts, offered with ``foxglove.websocket.v1``), the JSON
``serverInfo`` and ``advertise`` messages, the JSON ``subscribe`` request and the binary
Message Data frames (opcode 0x01, uint32 subscription id, uint64 timestamp in ns,
payload; little-endian). Plus a protobuf decoder driven by the channel's schema (a
base64 ``FileDescriptorSet``), so a ``foxglove.SceneUpdate`` is read without the
protobuf package.
"""
from __future__ import annotations

import asyncio
import base64
import json
import struct
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import websockets

SUBPROTOCOLS = ['foxglove.sdk.v1', 'foxglove.websocket.v1']
MESSAGE_DATA = 0x01


@dataclass
class Capture:
    """What a client saw: the server info, the channels by id and messages by topic."""

    server_info: dict
    channels: dict[int, dict]
    messages: dict[str, list[tuple[int, bytes]]] = field(default_factory=dict)

    def channel(self, topic: str) -> dict:
        return next(c for c in self.channels.values() if c['topic'] == topic)


async def _capture(url: str, topics: set[str], per_topic: int, timeout: float,
                   stall: float) -> Capture:
    async with asyncio.timeout(timeout):
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, proxy=None,
                                      compression=None, max_size=None) as socket:
            info = json.loads(await socket.recv())
            assert info['op'] == 'serverInfo', info
            channels: dict[int, dict] = {}
            while not topics <= {c['topic'] for c in channels.values()}:
                text = await socket.recv()
                if isinstance(text, str):
                    message = json.loads(text)
                    if message['op'] == 'advertise':
                        for channel in message['channels']:
                            channels[int(channel['id'])] = channel
            capture = Capture(info, channels)
            by_subscription = {k: channel['topic'] for k, channel in enumerate(channels.values())}
            await socket.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': k, 'channelId': int(channel['id'])}
                for k, channel in enumerate(channels.values())]}))
            time.sleep(stall)   # a busy client: its event loop blocked, nothing read
            while any(len(capture.messages.get(t, ())) < per_topic for t in topics):
                frame = await socket.recv()
                if isinstance(frame, bytes) and frame[0] == MESSAGE_DATA:
                    subscription, stamp = struct.unpack_from('<IQ', frame, 1)
                    topic = by_subscription[subscription]
                    capture.messages.setdefault(topic, []).append((stamp, frame[13:]))
            return capture


def capture(url: str, topics: set[str], *, per_topic: int = 2, timeout: float = 120.0,
            stall: float = 0.0) -> Capture:
    """Connect, wait until ``topics`` are advertised, subscribe to every channel, read
    nothing for ``stall`` s (a busy client), and collect until each of ``topics`` brought
    ``per_topic`` messages (or ``timeout`` s)."""
    return asyncio.run(_capture(url, set(topics), per_topic, timeout, stall))


@dataclass
class Stalled:
    """What a client that stopped reading saw: its own address (``host:port``, as the
    server names it) and the text messages it read once it read again, up to the
    server closing the connection (``closed``)."""

    address: str = ''
    texts: list[str] = field(default_factory=list)
    closed: bool = False


async def _stall(url: str, topic: str, stalled: Stalled, subscribed: threading.Event,
                 release: threading.Event, timeout: float) -> None:
    async with asyncio.timeout(timeout):
        async with websockets.connect(url, subprotocols=SUBPROTOCOLS, proxy=None,
                                      compression=None, max_size=None) as socket:
            host, port = socket.local_address[:2]
            stalled.address = f'{host}:{port}'
            await socket.recv()   # serverInfo
            channel = None
            while channel is None:
                message = await socket.recv()
                if isinstance(message, str) and json.loads(message)['op'] == 'advertise':
                    channel = next((c for c in json.loads(message)['channels']
                                    if c['topic'] == topic), None)
            await socket.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 0, 'channelId': int(channel['id'])}]}))
            subscribed.set()
            release.wait(timeout)   # its event loop blocked: nothing read
            try:
                while True:
                    message = await socket.recv()
                    if isinstance(message, str):
                        stalled.texts.append(message)
            except websockets.ConnectionClosed:
                stalled.closed = True


def stall(url: str, topic: str, subscribed: threading.Event, release: threading.Event,
          timeout: float = 120.0) -> Stalled:
    """Connect, subscribe to ``topic``, set ``subscribed``, read nothing until
    ``release`` is set (a client that stopped reading), then read until the server
    closes the connection (or ``timeout`` s in all)."""
    stalled = Stalled()
    asyncio.run(_stall(url, topic, stalled, subscribed, release, timeout))
    return stalled


# ---------------------------------------------------------------- protobuf
# descriptor.proto field numbers (FileDescriptorSet, FileDescriptorProto, DescriptorProto,
# FieldDescriptorProto) and wire types; a fact of the format, written out here.
LABEL_REPEATED = 3
TYPE_DOUBLE, TYPE_FLOAT, TYPE_STRING, TYPE_MESSAGE, TYPE_BYTES = 1, 2, 9, 11, 12
TYPE_FIXED64, TYPE_FIXED32, TYPE_SFIXED32, TYPE_SFIXED64 = 6, 7, 15, 16
TYPE_BOOL, TYPE_SINT32, TYPE_SINT64 = 8, 17, 18
VARINT, FIXED64, LENGTH, FIXED32 = 0, 1, 2, 5


def _varint(data: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        byte = data[pos]
        pos += 1
        value |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return value, pos


def wire_fields(data: bytes):
    """(field number, wire type, value) of every field of a protobuf message; value is
    an int (varint), bytes (length-delimited) or raw 4/8 bytes (fixed)."""
    pos = 0
    while pos < len(data):
        key, pos = _varint(data, pos)
        number, wire = key >> 3, key & 7
        if wire == VARINT:
            value, pos = _varint(data, pos)
        elif wire == LENGTH:
            size, pos = _varint(data, pos)
            value, pos = data[pos:pos + size], pos + size
        elif wire == FIXED64:
            value, pos = data[pos:pos + 8], pos + 8
        elif wire == FIXED32:
            value, pos = data[pos:pos + 4], pos + 4
        else:
            raise ValueError(f'unsupported wire type {wire}')
        yield number, wire, value


def message_types(descriptor_set: bytes) -> dict[str, dict[int, tuple[str, int, int, str]]]:
    """``{'.pkg.Type': {number: (name, label, type, type_name)}}`` of a FileDescriptorSet."""
    types: dict[str, dict[int, tuple[str, int, int, str]]] = {}

    def message(data: bytes, prefix: str) -> None:
        name, fields, nested = '', {}, []
        for number, _, value in wire_fields(data):
            if number == 1:
                name = value.decode()
            elif number == 2:
                f = {n: v for n, _, v in wire_fields(value)}
                fields[f[3]] = (f[1].decode(), f.get(4, 1), f[5], f.get(6, b'').decode())
            elif number == 3:
                nested.append(value)
        types[f'{prefix}.{name}'] = fields
        for inner in nested:
            message(inner, f'{prefix}.{name}')

    for number, _, file_data in wire_fields(descriptor_set):
        if number != 1:
            continue
        package = next((v.decode() for n, _, v in wire_fields(file_data) if n == 2), '')
        for n, _, value in wire_fields(file_data):
            if n == 4:
                message(value, f'.{package}' if package else '')
    return types


def _scalar(kind: int, wire: int, value: Any) -> Any:
    if kind == TYPE_DOUBLE:
        return struct.unpack('<d', value)[0]
    if kind == TYPE_FLOAT:
        return struct.unpack('<f', value)[0]
    if kind == TYPE_FIXED64 or kind == TYPE_SFIXED64:
        return struct.unpack('<Q' if kind == TYPE_FIXED64 else '<q', value)[0]
    if kind == TYPE_FIXED32 or kind == TYPE_SFIXED32:
        return struct.unpack('<I' if kind == TYPE_FIXED32 else '<i', value)[0]
    if kind == TYPE_BOOL:
        return bool(value)
    if kind in (TYPE_SINT32, TYPE_SINT64):
        return (value >> 1) ^ -(value & 1)
    return value   # int32/int64/uint/enum varints


def _packed(kind: int, data: bytes) -> list:
    if kind == TYPE_DOUBLE:
        return list(struct.unpack(f'<{len(data) // 8}d', data))
    if kind == TYPE_FLOAT:
        return list(struct.unpack(f'<{len(data) // 4}f', data))
    values, pos = [], 0
    while pos < len(data):
        value, pos = _varint(data, pos)
        values.append(_scalar(kind, VARINT, value))
    return values


def decode_protobuf(types: dict, type_name: str, data: bytes) -> dict[str, Any]:
    """A protobuf message as a dict (repeated fields as lists) by its schema ``types``."""
    fields = types[type_name]
    out: dict[str, Any] = {}
    for name, label, kind, _ in fields.values():   # proto3 leaves defaults out
        if label == LABEL_REPEATED:
            out[name] = []
        elif kind == TYPE_STRING:
            out[name] = ''
        elif kind == TYPE_BOOL:
            out[name] = False
        elif kind not in (TYPE_MESSAGE, TYPE_BYTES):
            out[name] = 0
    for number, wire, value in wire_fields(data):
        if number not in fields:
            continue
        name, label, kind, inner = fields[number]
        if kind == TYPE_MESSAGE:
            decoded: Any = decode_protobuf(types, inner, value)
        elif kind == TYPE_STRING:
            decoded = value.decode()
        elif kind == TYPE_BYTES:
            decoded = value
        elif wire == LENGTH:   # a packed repeated scalar
            out[name].extend(_packed(kind, value))
            continue
        else:
            decoded = _scalar(kind, wire, value)
        if label == LABEL_REPEATED:
            out[name].append(decoded)
        else:
            out[name] = decoded
    return out


def protobuf_decoder(channel: dict):
    """``decode(payload) -> dict`` for a channel advertised with a protobuf schema."""
    assert channel['encoding'] == 'protobuf' and channel['schemaEncoding'] == 'protobuf'
    types = message_types(base64.b64decode(channel['schema']))
    name = '.' + channel['schemaName']
    assert name in types, sorted(types)
    return lambda payload: decode_protobuf(types, name, payload)


def decode_foxglove(message: Any) -> dict[str, Any]:
    """A ``foxglove.messages`` object (write-only from Python) as a dict, through its
    own protobuf encoding and schema."""
    schema = type(message).get_schema()
    types = message_types(bytes(schema.data))
    return decode_protobuf(types, '.' + schema.name, bytes(message.encode()))
