"""A rosbag2-compatible MCAP writer on the core ``mcap`` writer.

What makes a file read by ``ros2 bag info/play`` like one rosbag2 wrote:

- header profile ``ros2``;
- one schema per message type: name ``pkg/msg/Type``, encoding ``ros2msg``, data the
  full definition text (see ``schemas``);
- one channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles``
  (YAML) and ``topic_type_hash`` (``RIHS01_...`` where known);
- messages with ``log_time`` = receive time and ``publish_time`` = send time, integer ns;
- zstd-compressed chunks with message indexes, a Statistics record and a summary;
- a Metadata record ``rosbag2`` whose ``serialized_metadata`` is the BagMetadata YAML
  (version 9, ``ros_distro: jazzy``, see ``bag_metadata``), written on close: of this
  file alone, or of the whole bag when ``close`` is given the bag's document.

No data lost: a chunk is closed and handed to the operating system when it reaches
``chunk_size`` bytes or when ``flush_interval`` seconds (wall clock) have passed since
the last flush, checked on every write and by ``flush_if_due()`` (call it from a timer).
A process killed with SIGKILL therefore loses at most about ``flush_interval`` seconds of
messages; ``recover`` rebuilds an indexed file from what is on disk.
"""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from mcap.writer import CompressionType, IndexType, Writer

from gripper_sim import __version__
from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording import schemas
from gripper_sim.recording.bag_metadata import FileEntry, TopicEntry, bag_metadata_yaml
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.lifecycle import OpenClose

PROFILE = 'ros2'
LIBRARY = f'gripper_sim.recording {__version__}'
DEFAULT_CHUNK_SIZE = 1024 * 1024
DEFAULT_FLUSH_INTERVAL = 0.5  # s; SIGKILL loses at most about this much
COMPRESSIONS = ('zstd', 'lz4', 'none')


def check_options(*, chunk_size: int, flush_interval: float, compression: str) -> Any:
    """The MCAP compression type for ``compression``, after checking every option.

    Raises:
        RecordingError: a non-positive chunk size or flush interval, an unknown compression.
    """
    if chunk_size <= 0:
        raise RecordingError(f'chunk_size must be positive, got {chunk_size}')
    if not flush_interval > 0:
        raise RecordingError(f'flush_interval must be positive, got {flush_interval}')
    types = {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
             'none': CompressionType.NONE}
    if compression not in types:
        msg = f"compression must be one of {', '.join(COMPRESSIONS)}, got {compression!r}"
        raise RecordingError(msg)
    return types[compression]


class BagWriter(OpenClose):
    """Writes one rosbag2-compatible MCAP file.

    Use as a context manager::

        with BagWriter(path) as bag:
            bag.add_topic('/chatter', 'std_msgs/msg/String')
            bag.write('/chatter', cdr_bytes, log_time=t_ns)

    Args:
        path: the file to create.
        overwrite: replace an existing file (default: refuse, so no recording is lost).
        chunk_size: bytes of uncompressed records after which a chunk is closed.
        flush_interval: seconds (wall clock) after which a non-empty chunk is closed and
            written to the operating system, even if not full.
        compression: 'zstd' (default), 'lz4' or 'none'.
        library: the header's library string.
        profile: the header's profile: 'ros2' (default) adds the rosbag2 metadata record
            on close; another profile (a foreign file being recovered) does not.
        clock: monotonic seconds for the flush policy (tests pass a fake one).

    Thread-safe: ``write`` may be called from several threads.
    """

    def __init__(self, path: str | os.PathLike, *, overwrite: bool = False,
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_interval: float = DEFAULT_FLUSH_INTERVAL,
                 compression: str = 'zstd', library: str = LIBRARY, profile: str = PROFILE,
                 clock: Callable[[], float] = time.monotonic):
        self.path = Path(path)
        self._overwrite = overwrite
        self._compression = check_options(chunk_size=chunk_size,
                                          flush_interval=flush_interval,
                                          compression=compression)
        self._chunk_size = int(chunk_size)
        self._flush_interval = float(flush_interval)
        self._library = library
        self._profile = profile
        self._clock = clock
        self._lock = threading.RLock()
        self._stream: Any = None
        self._writer: Writer | None = None
        self._closed = False
        self._topics: dict[str, TopicEntry] = {}
        self._schema_ids: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._custom_data: dict[str, str] = {}
        self._file = FileEntry(self.path.name)
        self._bytes_written = 0
        self._pending_bytes = 0
        self._last_flush = 0.0
        self._pending = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def is_open(self) -> bool:
        return self._writer is not None

    def open(self) -> None:
        """Create the file and write the header.

        Raises:
            RecordingError: already opened, the file exists (and ``overwrite`` is False),
                or it cannot be created.
        """
        with self._lock:
            if self._writer is not None or self._closed:
                raise RecordingError(f'{self.path}: writer was already opened')
            if self.path.is_dir():
                raise RecordingError(f'{self.path} is a directory; give a file name ending '
                                     'in .mcap')
            mode = 'wb' if self._overwrite else 'xb'
            try:
                if self.path.parent and not self.path.parent.exists():
                    raise RecordingError(f'{self.path}: directory {self.path.parent} does '
                                         'not exist')
                self._stream = open(self.path, mode)  # noqa: SIM115 - closed in close()
            except FileExistsError:
                msg = (f'{self.path} already exists; choose another name or remove it '
                       '(recordings are never overwritten silently)')
                raise RecordingError(msg) from None
            except OSError as err:
                raise RecordingError(f'cannot create {self.path}: {err.strerror}') from err
            self._writer = Writer(
                self._stream, chunk_size=self._chunk_size, compression=self._compression,
                index_types=IndexType.ALL, repeat_channels=True, repeat_schemas=True,
                use_chunking=True, use_statistics=True, use_summary_offsets=True,
                enable_crcs=True)
            self._writer.start(profile=self._profile, library=self._library)
            self._stream.flush()
            self._last_flush = self._clock()

    def close(self, bag_document: str | None = None) -> None:
        """Write the rosbag2 metadata record, the summary and the footer; close the file.

        Args:
            bag_document: the BagMetadata YAML to store (a split bag's writer passes the
                whole bag's); default: this file's own.

        Closing twice is allowed and does nothing the second time.
        """
        with self._lock:
            if self._writer is None:
                self._closed = True
                return
            writer, self._writer = self._writer, None
            self._closed = True
            try:
                if self._profile == PROFILE:
                    document = self.bag_metadata() if bag_document is None else bag_document
                    writer.add_metadata('rosbag2', {'serialized_metadata': document})
                writer.finish()
                self._stream.flush()
                os.fsync(self._stream.fileno())
            except OSError as err:
                raise RecordingError(f'cannot finish {self.path}: {err.strerror}') from err
            finally:
                self._stream.close()

    def _require_open(self) -> Writer:
        if self._writer is None:
            state = 'closed' if self._closed else 'not opened yet'
            raise RecordingError(f'{self.path}: writer is {state}')
        return self._writer

    # ------------------------------------------------------------------ content
    def add_topic(self, name: str, type_name: str, *,
                  offered_qos_profiles: Iterable[Mapping[str, Any]] | None = None,
                  type_hash: str | None = None, definition: str | bytes | None = None,
                  schema_encoding: str = 'ros2msg',
                  message_encoding: str = 'cdr',
                  channel_metadata: Mapping[str, str] | None = None) -> TopicEntry:
        """Register a topic (idempotent for the same name and type).

        Args:
            name: topic name (absolute, e.g. ``/gripper_sim/fruit/state``).
            type_name: ``pkg/msg/Type``.
            offered_qos_profiles: QoS profile dicts of its publishers (default: one
                reliable keep-last-10 profile).
            type_hash: RIHS01 hash; default: looked up from the installed type description.
            definition: schema text (or bytes); default: built from the installed .msg files.
            schema_encoding: 'ros2msg' (default) or 'ros2idl' with ``definition``; '' with
                an empty ``definition`` for a channel without a schema (foreign files).
            message_encoding: 'cdr' (default; the only one ROS 2 tools play).
            channel_metadata: channel metadata to store verbatim (e.g. copied from another
                file); overrides ``offered_qos_profiles`` and ``type_hash``.

        Raises:
            RecordingError: the name is taken by another type, or no definition is found.
        """
        if schema_encoding in ('ros2msg', 'ros2idl'):
            type_name = schemas.full_type_name(type_name)
        if not name.startswith('/') and message_encoding == 'cdr' and channel_metadata is None:
            raise RecordingError(f"topic name '{name}' must be absolute (start with '/')")
        with self._lock:
            writer = self._require_open()
            existing = self._topics.get(name)
            if existing is not None:
                if existing.type != type_name:
                    msg = (f"topic '{name}' is already recorded with type {existing.type}, "
                           f'cannot add it again as {type_name}')
                    raise RecordingError(msg)
                return existing
            schema_id = 0 if schema_encoding == '' and not definition else \
                self._schema_ids.get(type_name)
            if schema_id is None:
                if definition is None:
                    definition = schemas.message_definition(type_name)
                data = definition.encode('utf-8') if isinstance(definition, str) \
                    else bytes(definition)
                schema_id = writer.register_schema(type_name, schema_encoding, data)
                self._schema_ids[type_name] = schema_id
            if channel_metadata is not None:
                metadata = {str(k): str(v) for k, v in channel_metadata.items()}
                try:
                    profiles = qos_mod.from_yaml(metadata.get('offered_qos_profiles', ''))
                except RecordingError:
                    profiles = []
                type_hash = metadata.get('topic_type_hash', '')
            else:
                if type_hash is None:
                    type_hash = schemas.type_hash(type_name) or ''
                profiles = [qos_mod.normalize(p) for p in (offered_qos_profiles
                                                           or [qos_mod.default_profile()])]
                metadata = {'offered_qos_profiles': qos_mod.to_yaml(profiles),
                            'topic_type_hash': type_hash}
            channel_id = writer.register_channel(name, message_encoding, schema_id, metadata)
            entry = TopicEntry(name=name, type=type_name, channel_id=channel_id,
                               offered_qos_profiles=profiles, type_hash=type_hash)
            self._topics[name] = entry
            self._sequence[name] = 0
            return entry

    def has_topic(self, name: str) -> bool:
        return name in self._topics

    @property
    def topics(self) -> dict[str, TopicEntry]:
        """Registered topics by name (a copy)."""
        with self._lock:
            return dict(self._topics)

    def write(self, topic: str, data: bytes, *, log_time: int,
              publish_time: int | None = None, sequence: int | None = None) -> None:
        """Append one serialized (CDR) message.

        Args:
            topic: a topic registered with ``add_topic``.
            data: the CDR bytes as published.
            log_time: receive time, integer ns.
            publish_time: send time, integer ns (default: ``log_time``).
            sequence: publisher sequence number (default: a per-topic counter from 1).
        """
        if not isinstance(log_time, int) or isinstance(log_time, bool) or log_time < 0:
            raise RecordingError(f'log_time must be a non-negative integer of ns, got '
                                 f'{log_time!r}')
        if publish_time is None:
            publish_time = log_time
        with self._lock:
            writer = self._require_open()
            entry = self._topics.get(topic)
            if entry is None:
                raise RecordingError(f"topic '{topic}' was not added to {self.path}; call "
                                     'add_topic first')
            if sequence is None:
                self._sequence[topic] += 1
                sequence = self._sequence[topic]
            try:
                writer.add_message(entry.channel_id, log_time, bytes(data), int(publish_time),
                                   int(sequence) & 0xFFFFFFFF)
            except OSError as err:
                raise RecordingError(f'cannot write {self.path}: {err.strerror}') from err
            entry.message_count += 1
            self._file.add(log_time)
            self._pending += 1
            self._pending_bytes += len(data)
            self._bytes_written += len(data)
            if self._clock() - self._last_flush >= self._flush_interval:
                self._flush_locked()

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write an MCAP Metadata record now (e.g. the run's configuration).

        Written at once, outside chunks, so it survives a crash and ``recover`` keeps it.
        """
        if name == 'rosbag2':
            raise RecordingError("metadata name 'rosbag2' is reserved for the bag metadata")
        if not all(isinstance(k, str) and isinstance(v, str) for k, v in data.items()):
            raise RecordingError(f"metadata '{name}': keys and values must be strings")
        with self._lock:
            writer = self._require_open()
            try:
                writer.add_metadata(name, dict(data))
                self._stream.flush()
            except OSError as err:
                raise RecordingError(f'cannot write {self.path}: {err.strerror}') from err

    def set_custom_data(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of the rosbag2 metadata."""
        with self._lock:
            self._custom_data[str(key)] = str(value)

    # ------------------------------------------------------------------ flushing
    def _flush_locked(self) -> None:
        assert self._writer is not None
        try:
            self._writer.flush()
        except OSError as err:
            raise RecordingError(f'cannot write {self.path}: {err.strerror}') from err
        self._pending = 0
        self._pending_bytes = 0
        self._last_flush = self._clock()

    def flush(self) -> None:
        """Close the open chunk and hand everything to the operating system now."""
        with self._lock:
            if self._writer is not None:
                self._flush_locked()

    def flush_if_due(self) -> bool:
        """Flush when messages are pending and ``flush_interval`` has passed; True if so."""
        with self._lock:
            if (self._writer is not None and self._pending
                    and self._clock() - self._last_flush >= self._flush_interval):
                self._flush_locked()
                return True
            return False

    # ------------------------------------------------------------------ statistics
    @property
    def flush_interval(self) -> float:
        """Seconds after which a non-empty chunk is written out."""
        return self._flush_interval

    @property
    def message_count(self) -> int:
        return self._file.message_count

    @property
    def file_entry(self) -> FileEntry:
        """This file's name, log-time span and message count so far."""
        return self._file

    @property
    def size(self) -> int:
        """Bytes of the file so far: what is on disk plus the payload of the open chunk."""
        with self._lock:
            if self._stream is None or self._stream.closed:
                return self.path.stat().st_size if self.path.exists() else 0
            return self._stream.tell() + self._pending_bytes

    @property
    def payload_bytes(self) -> int:
        """Sum of the CDR payload sizes written."""
        return self._bytes_written

    def bag_metadata(self) -> str:
        """The rosbag2 BagMetadata YAML of this file alone, for what was written so far."""
        with self._lock:
            return bag_metadata_yaml(topics=list(self._topics.values()), files=[self._file],
                                     custom_data=self._custom_data)
