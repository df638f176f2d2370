"""Reading rosbag2 recordings: a bag folder or one MCAP file; topics, counts, messages.

``BagReader`` opens either a bag folder (``metadata.yaml`` and its split files, see
``bag_folder``) or a single ``.mcap`` file and shows them the same way: topics with
their counts over all files, one log-time-ordered message stream, the Metadata records
of every file.

Every failure of the underlying libraries (bad magic, truncated file, broken chunk,
CRC mismatch, undecodable message) is turned into a ``RecordingError`` that names the
file and says what to do; a reader never writes to the file it reads.
"""
from __future__ import annotations

import dataclasses
import heapq
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Iterator

from mcap.exceptions import McapError
from mcap.reader import SeekingReader
from mcap.records import Channel, Schema
from mcap.stream_reader import MAGIC_SIZE, CRCValidationError

from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording.bag_folder import bag_files
from gripper_sim.recording.bag_metadata import load_yaml
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.lifecycle import OpenClose

MCAP_MAGIC = b'\x89MCAP0\r\n'
FOOTER_RECORD_SIZE = 1 + 8 + 8 + 8 + 4  # opcode, length, summary start, offset start, crc

try:  # zstandard raises its own error class on a broken frame
    import zstandard
    _ZSTD_ERRORS: tuple[type[BaseException], ...] = (zstandard.ZstdError,)
except ImportError:  # pragma: no cover - zstandard is a dependency
    _ZSTD_ERRORS = ()

#: Errors of the mcap stack that mean "this file is damaged".
READ_ERRORS: tuple[type[BaseException], ...] = (
    McapError, CRCValidationError, struct.error, zlib.error, *_ZSTD_ERRORS, EOFError,
    UnicodeDecodeError, ValueError, KeyError, IndexError, MemoryError, OverflowError)


@dataclass(frozen=True)
class TopicInfo:
    """One topic (MCAP channel) of a file.

    Attributes:
        name: topic name.
        type: schema name, ``pkg/msg/Type`` for ROS 2 files.
        message_count: messages on the topic.
        message_encoding: 'cdr' for ROS 2.
        schema_encoding: 'ros2msg' for ROS 2.
        offered_qos_profiles: QoS profile dicts (see ``qos``), [] when none stored.
        type_hash: ``RIHS01_...`` or ''.
        channel_id: MCAP channel id.
    """

    name: str
    type: str
    message_count: int
    message_encoding: str
    schema_encoding: str
    offered_qos_profiles: list = field(default_factory=list, compare=False)
    type_hash: str = ''
    channel_id: int = 0


@dataclass(frozen=True)
class RawMessage:
    """One message as stored: CDR bytes and integer-ns times."""

    topic: str
    type: str
    log_time: int
    publish_time: int
    sequence: int
    data: bytes


def check_mcap_start(path: Path) -> None:
    """Raise a clear RecordingError if ``path`` is missing, empty or not MCAP."""
    if not path.exists():
        raise RecordingError(f'{path}: no such file')
    if path.is_dir():
        raise RecordingError(f'{path} is a directory; give the .mcap file inside it')
    try:
        with open(path, 'rb') as f:
            head = f.read(16)
    except OSError as err:
        raise RecordingError(f'cannot read {path}: {err.strerror}') from err
    if not head:
        raise RecordingError(f'{path} is empty (0 bytes): not an MCAP recording')
    if not head.startswith(MCAP_MAGIC):
        if head.startswith(b'SQLite format 3'):
            msg = (f'{path} is a rosbag2 SQLite (.db3) file, not MCAP; convert it with '
                   "'ros2 bag convert' or record with MCAP storage")
        elif len(head) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(head):
            msg = f'{path} is truncated to {len(head)} bytes: it holds no recording'
        else:
            msg = f'{path} is not an MCAP file (it does not start with the MCAP magic bytes)'
        raise RecordingError(msg)


def has_footer(path: Path) -> bool:
    """Whether the file ends with a footer record and the closing magic."""
    size = path.stat().st_size
    if size < MAGIC_SIZE * 2 + FOOTER_RECORD_SIZE:
        return False
    with open(path, 'rb') as f:
        f.seek(size - MAGIC_SIZE - FOOTER_RECORD_SIZE)
        tail = f.read()
    return tail[0] == 0x02 and tail[-MAGIC_SIZE:] == MCAP_MAGIC


class _Summary(OpenClose):
    """What a file and a whole bag both tell: header strings, counts, times, Metadata
    records."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._topics: dict[str, TopicInfo] = {}
        self.profile = ''
        self.library = ''
        self.start_time = 0
        self.end_time = 0
        self.message_count = 0
        self.chunk_count = 0
        self.compression: set[str] = set()
        self.metadata: list[tuple[str, dict[str, str]]] = []

    @property
    def topics(self) -> dict[str, TopicInfo]:
        """Topics by name."""
        return dict(self._topics)


class McapFile(_Summary):
    """One MCAP file written by rosbag2, by ``BagWriter`` or by any MCAP writer.

    The storage layer of ``BagReader``: its summary (schemas, channels, counts, times),
    Metadata records, verification and message stream.

    Raises (on open):
        RecordingError: missing, empty, non-MCAP, truncated (suggests ``recover``) or
            corrupt file.
    """

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)
        self._file: Any = None
        self._reader: SeekingReader | None = None
        self._schemas: dict[int, Schema] = {}
        self._channels: dict[int, Channel] = {}
        self._counts: dict[int, int] = {}

    # ------------------------------------------------------------------ lifecycle
    def open(self) -> None:
        if self._file is not None:
            raise RecordingError(f'{self.path}: reader is already open')
        check_mcap_start(self.path)
        if not has_footer(self.path):
            msg = (f'{self.path} is truncated or not closed (no MCAP footer): it is still '
                   'being recorded, or its recorder was killed; read what it holds so far '
                   f"with 'gripper-sim recover {self.path} FIXED.mcap'")
            raise RecordingError(msg)
        try:
            self._file = open(self.path, 'rb')  # noqa: SIM115 - closed in close()
        except OSError as err:
            raise RecordingError(f'cannot read {self.path}: {err.strerror}') from err
        try:
            self._load()
        except RecordingError:
            self.close()
            raise
        except READ_ERRORS as err:
            self.close()
            raise self._corrupt(err) from err

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
        self._file = None
        self._reader = None

    def _corrupt(self, err: BaseException) -> RecordingError:
        detail = str(err) or type(err).__name__
        return RecordingError(f'{self.path} is corrupt ({detail}); if it was cut short, try '
                              f"'gripper-sim recover {self.path} FIXED.mcap'")

    def _load(self) -> None:
        reader = SeekingReader(self._file, validate_crcs=True)
        self._reader = reader
        header = reader.get_header()
        self.profile, self.library = header.profile, header.library
        summary = reader.get_summary()
        if summary is None or summary.statistics is None:
            self._scan_without_summary()
        else:
            self._schemas = dict(summary.schemas)
            self._channels = dict(summary.channels)
            stats = summary.statistics
            self._counts = dict(stats.channel_message_counts)
            self.message_count = stats.message_count
            self.start_time = stats.message_start_time
            self.end_time = stats.message_end_time
            self.chunk_count = stats.chunk_count
            self.compression = {c.compression for c in summary.chunk_indexes}
        self.metadata = [(m.name, dict(m.metadata)) for m in reader.iter_metadata()]
        for cid, channel in sorted(self._channels.items()):
            schema = self._schemas.get(channel.schema_id)
            profiles: list = []
            text = channel.metadata.get('offered_qos_profiles', '')
            try:
                profiles = qos_mod.from_yaml(text)
            except RecordingError:
                profiles = []
            self._topics[channel.topic] = TopicInfo(
                name=channel.topic,
                type=schema.name if schema is not None else '',
                message_count=self._counts.get(cid, 0),
                message_encoding=channel.message_encoding,
                schema_encoding=schema.encoding if schema is not None else '',
                offered_qos_profiles=profiles,
                type_hash=channel.metadata.get('topic_type_hash', ''),
                channel_id=cid)

    def _scan_without_summary(self) -> None:
        """Files without a summary: count by reading every record once."""
        from mcap.records import Chunk, Message
        from mcap.stream_reader import StreamReader

        self._file.seek(0)
        start = end = None
        for record in StreamReader(self._file, validate_crcs=True, emit_chunks=True).records:
            if isinstance(record, Chunk):
                self.chunk_count += 1
                self.compression.add(record.compression)
                from mcap.stream_reader import breakup_chunk
                inner = breakup_chunk(record, validate_crc=True)
            else:
                inner = [record]
            for rec in inner:
                if isinstance(rec, Schema):
                    self._schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    self._channels[rec.id] = rec
                elif isinstance(rec, Message):
                    self._counts[rec.channel_id] = self._counts.get(rec.channel_id, 0) + 1
                    self.message_count += 1
                    start = rec.log_time if start is None else min(start, rec.log_time)
                    end = rec.log_time if end is None else max(end, rec.log_time)
        self.start_time = start or 0
        self.end_time = end or 0

    def verify(self) -> int:
        """Decompress every chunk and check its CRC; return the number of chunks checked.

        Raises:
            RecordingError: a chunk is damaged.
        """
        reader = self._require_open()
        from mcap.records import Chunk
        from mcap.stream_reader import breakup_chunk

        summary = reader.get_summary()
        if summary is None:
            return self.chunk_count  # already read in full by _scan_without_summary
        checked = 0
        try:
            for index in summary.chunk_indexes:
                self._file.seek(index.chunk_start_offset + 1 + 8)
                from mcap.data_stream import ReadDataStream
                chunk = Chunk.read(ReadDataStream(self._file))
                breakup_chunk(chunk, validate_crc=True)
                checked += 1
        except READ_ERRORS as err:
            raise self._corrupt(err) from err
        return checked

    def _require_open(self) -> SeekingReader:
        if self._reader is None:
            raise RecordingError(f'{self.path}: reader is not open')
        return self._reader

    # ------------------------------------------------------------------ contents
    def messages(self, topics: Iterable[str] | None = None, *, start: int | None = None,
                 end: int | None = None) -> Iterator[RawMessage]:
        """Messages in log-time order.

        Args:
            topics: topic names (all if None); names not in this file are skipped.
            start: first log time included, ns.
            end: log times before this are included, ns.
        """
        reader = self._require_open()
        wanted = None if topics is None else [t for t in topics if t in self._topics]
        if wanted == []:
            return
        types = {c.id: (self._schemas[c.schema_id].name if c.schema_id in self._schemas
                        else '') for c in self._channels.values()}
        iterator = reader.iter_messages(topics=wanted, starting_at=start, ending_before=end,
                                        log_time_order=True)
        while True:
            try:
                item = next(iterator)
            except StopIteration:
                return
            except READ_ERRORS as err:
                raise self._corrupt(err) from err
            _schema, channel, message = item
            yield RawMessage(topic=channel.topic, type=types.get(channel.id, ''),
                             log_time=message.log_time, publish_time=message.publish_time,
                             sequence=message.sequence, data=message.data)

    def decoder(self, topic: str) -> Callable[[bytes], Any]:
        """A function decoding the CDR bytes of ``topic`` with its stored ros2msg schema.

        Uses ``mcap-ros2-support``'s decoder: works from the file alone, without ROS.
        """
        from mcap_ros2.decoder import DecoderFactory

        info = self._topics.get(topic)
        if info is None:
            raise RecordingError(f"{self.path} has no topic '{topic}'")
        channel = self._channels[info.channel_id]
        schema = self._schemas.get(channel.schema_id)
        if channel.message_encoding != 'cdr' or schema is None or \
                schema.encoding != 'ros2msg':
            msg = (f"{self.path}: topic '{topic}' is not a ROS 2 CDR topic with a ros2msg "
                   f"schema (encoding '{channel.message_encoding}', schema "
                   f"'{schema.encoding if schema else 'none'}')")
            raise RecordingError(msg)
        try:
            decode = DecoderFactory().decoder_for('cdr', schema)
        except READ_ERRORS as err:
            msg = f"{self.path}: the schema of '{topic}' ({schema.name}) cannot be parsed: {err}"
            raise RecordingError(msg) from err
        if decode is None:
            raise RecordingError(f"{self.path}: no decoder for topic '{topic}'")

        def safe_decode(data: bytes) -> Any:
            try:
                return decode(data)
            except READ_ERRORS as err:
                msg = (f"{self.path}: a message on '{topic}' does not decode as "
                       f'{schema.name}: {err}')
                raise RecordingError(msg) from err
        return safe_decode


class BagReader(_Summary):
    """Reads a recording: a rosbag2 bag folder of MCAP files, or one MCAP file.

    Use as a context manager::

        with BagReader(path) as bag:
            print(bag.topics, bag.duration_ns)
            for msg in bag.messages(['/chatter']):
                ...

    Attributes (once open):
        path: the folder or file given.
        files: the MCAP files, in order.
        folder_metadata: the ``metadata.yaml`` mapping of a folder (None for a file, or
            for a folder whose recorder died before writing it).

    Raises (on open):
        RecordingError: missing path, broken ``metadata.yaml``, or a missing, empty,
            non-MCAP, truncated (suggests ``recover``) or corrupt file.
    """

    def __init__(self, path: str | os.PathLike):
        super().__init__(path)
        self.files: list[Path] = []
        self.folder_metadata: dict | None = None
        self._parts: list[McapFile] = []

    # ------------------------------------------------------------------ lifecycle
    @property
    def is_folder(self) -> bool:
        return self.path.is_dir()

    def open(self) -> None:
        if self._parts:
            raise RecordingError(f'{self.path}: reader is already open')
        self.files, self.folder_metadata = bag_files(self.path)
        try:
            for file in self.files:
                part = McapFile(file)
                part.open()
                self._parts.append(part)
        except RecordingError as err:
            self.close()
            if not self.path.is_dir() or str(err).startswith('cannot read'):
                raise
            raise RecordingError(f'{err} (for the whole bag: gripper-sim recover '
                                 f'{self.path} FIXED)') from err
        first = self._parts[0]
        self.profile, self.library = first.profile, first.library
        with_messages = [p for p in self._parts if p.message_count]
        self.start_time = min((p.start_time for p in with_messages), default=0)
        self.end_time = max((p.end_time for p in with_messages), default=0)
        self.message_count = sum(p.message_count for p in self._parts)
        self.chunk_count = sum(p.chunk_count for p in self._parts)
        self.compression = set().union(*(p.compression for p in self._parts))
        self.metadata = [record for p in self._parts for record in p.metadata]
        for part in self._parts:
            for name, info in part.topics.items():
                known = self._topics.get(name)
                if known is None:
                    self._topics[name] = info
                else:
                    self._topics[name] = dataclasses.replace(
                        known, message_count=known.message_count + info.message_count)

    def close(self) -> None:
        for part in self._parts:
            part.close()
        self._parts = []

    def verify(self) -> int:
        """Check every chunk of every file; return the number of chunks checked."""
        return sum(part.verify() for part in self._parts)

    # ------------------------------------------------------------------ contents
    @property
    def duration_ns(self) -> int:
        return max(0, self.end_time - self.start_time) if self.message_count else 0

    def metadata_named(self, name: str) -> dict[str, str] | None:
        """The last Metadata record called ``name`` (of the last file having one), or None."""
        found = None
        for rec_name, data in self.metadata:
            if rec_name == name:
                found = data
        return found

    def bag_metadata(self) -> dict | None:
        """The bag's BagMetadata: ``metadata.yaml`` of a folder, else the last file's
        ``rosbag2`` record (parsed), or None if there is neither."""
        if self.folder_metadata is not None:
            return self.folder_metadata
        rec = self.metadata_named('rosbag2')
        if not rec or 'serialized_metadata' not in rec:
            return None
        data = load_yaml(rec['serialized_metadata'], f"{self.path}'s rosbag2 metadata")
        return data if isinstance(data, dict) else None

    def check_topics(self, topics: Iterable[str] | None) -> list[str] | None:
        """Validate requested topic names; None means all topics."""
        if topics is None:
            return None
        wanted = list(topics)
        missing = [t for t in wanted if t not in self._topics]
        if missing:
            have = ', '.join(sorted(self._topics)) or 'none'
            msg = (f"{self.path} has no topic {', '.join(repr(m) for m in missing)} "
                   f'(topics: {have})')
            raise RecordingError(msg)
        return wanted

    def messages(self, topics: Iterable[str] | None = None, *, start: int | None = None,
                 end: int | None = None) -> Iterator[RawMessage]:
        """Messages of all files in log-time order.

        Args:
            topics: topic names (all if None); an unknown name raises RecordingError.
            start: first log time included, ns.
            end: log times before this are included, ns.
        """
        wanted = self.check_topics(topics)
        streams = [part.messages(wanted, start=start, end=end) for part in self._parts]
        if len(streams) == 1:
            yield from streams[0]
            return
        yield from heapq.merge(*streams, key=lambda m: m.log_time)

    def decoder(self, topic: str) -> Callable[[bytes], Any]:
        """A function decoding the CDR bytes of ``topic`` with its stored ros2msg schema.

        Uses ``mcap-ros2-support``'s decoder: works from the files alone, without ROS.
        """
        self.check_topics([topic])
        part = next(p for p in self._parts if topic in p.topics)
        return part.decoder(topic)

    def decoded_messages(self, topics: Iterable[str] | None = None, *,
                         start: int | None = None,
                         end: int | None = None) -> Iterator[tuple[RawMessage, Any]]:
        """(raw message, decoded message) pairs in log-time order."""
        decoders: dict[str, Callable[[bytes], Any]] = {}
        for raw in self.messages(topics, start=start, end=end):
            dec = decoders.get(raw.topic)
            if dec is None:
                dec = decoders[raw.topic] = self.decoder(raw.topic)
            yield raw, dec(raw.data)
