"""Bag folders as rosbag2 writes them: ``NAME/NAME_0.mcap``, ``NAME_1.mcap``, ... and
``NAME/metadata.yaml``.

``BagFolderWriter`` has the writing interface of ``BagWriter`` (``add_topic``, ``write``,
``add_metadata``, ``flush_if_due``, ...) and splits the bag into a new file, as
rosbag2's sequential writer does, before the message that finds the current file at or
over ``max_bag_size`` bytes, or more than ``max_bag_duration`` seconds of log time after
the file's first message. Every file is a whole MCAP file of its own: it repeats the
topics (schemas and channels) and the Metadata records written so far (e.g. the
configuration), and holds a ``rosbag2`` Metadata record with the bag's BagMetadata at
the moment it was closed. ``metadata.yaml`` is written when the bag is closed.

``open_bag_writer`` picks the layout from the path: a name ending in ``.mcap`` is one
file, anything else a bag folder. ``bag_files`` lists the storage files of either.
"""
from __future__ import annotations

import os
import re
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping

from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording import schemas
from gripper_sim.recording.bag_metadata import (METADATA_FILE, FileEntry, TopicEntry,
                                                bag_metadata_yaml, read_metadata_file,
                                                write_metadata_file)
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.lifecycle import OpenClose
from gripper_sim.recording.writer import (DEFAULT_CHUNK_SIZE, DEFAULT_FLUSH_INTERVAL,
                                          BagWriter, check_options)

MCAP_SUFFIX = '.mcap'
#: rosbag2 refuses smaller split sizes for MCAP as well (its minimum split file size).
MIN_SPLIT_SIZE = 64 * 1024


def is_single_file(path: str | os.PathLike) -> bool:
    """Whether ``path`` names one MCAP file (``.mcap``) rather than a bag folder."""
    return Path(path).suffix == MCAP_SUFFIX


def storage_file_name(folder: Path, index: int) -> str:
    """rosbag2's name of the ``index``-th file of ``folder``: ``<folder name>_<index>.mcap``."""
    return f'{folder.name}_{index}{MCAP_SUFFIX}'


def check_new_bag_path(path: str | os.PathLike) -> Path:
    """The absolute path a new recording at ``path`` would take, or a RecordingError why not.

    A bag is never written over: an existing file or folder is refused, as is a path
    whose parent folder is missing or not writable.
    """
    text = os.fspath(path)
    if not text.strip():
        raise RecordingError('the recording path is empty')
    target = Path(text).expanduser().absolute()
    kind = 'file' if is_single_file(target) else 'bag folder'
    if target.is_dir():
        raise RecordingError(f'{target} is an existing directory; a recording never writes '
                             f'into an existing folder: give the name of a new {kind}')
    if target.exists():
        raise RecordingError(f'{target} already exists; choose another name or remove it '
                             '(recordings are never overwritten)')
    parent = target.parent
    if not parent.is_dir():
        raise RecordingError(f'{target}: directory {parent} does not exist')
    if not os.access(parent, os.W_OK | os.X_OK):
        raise RecordingError(f'cannot create {target}: directory {parent} is not writable')
    return target


class BagFolderWriter(OpenClose):
    """Writes a rosbag2 bag folder of MCAP files, split by size and/or duration.

    Use as a context manager, like ``BagWriter``::

        with BagFolderWriter('run1', max_bag_size=50 * 2**20) as bag:
            bag.add_topic('/chatter', 'std_msgs/msg/String')
            bag.write('/chatter', cdr_bytes, log_time=t_ns)

    Args:
        folder: the bag folder to create (it must not exist; its parent must).
        max_bag_size: split when the current file reaches this many bytes (0 = never;
            else at least ``MIN_SPLIT_SIZE``).
        max_bag_duration: split when a message is logged more than this many seconds
            after the current file's first message (0 = never).
        compression: MCAP chunk compression, 'zstd' (default), 'lz4' or 'none'.
        chunk_size, flush_interval, clock: passed to each file's ``BagWriter``.
        custom_data: the BagMetadata ``custom_data`` entries.

    Thread-safe: ``write`` may be called from several threads.
    """

    def __init__(self, folder: str | os.PathLike, *, max_bag_size: int = 0,
                 max_bag_duration: float = 0.0, compression: str = 'zstd',
                 chunk_size: int = DEFAULT_CHUNK_SIZE,
                 flush_interval: float = DEFAULT_FLUSH_INTERVAL,
                 clock: Callable[[], float] = time.monotonic,
                 custom_data: Mapping[str, str] | None = None):
        self.path = Path(folder)
        if is_single_file(self.path):
            raise RecordingError(f"{self.path}: a bag folder's name must not end in .mcap")
        if isinstance(max_bag_size, bool) or not isinstance(max_bag_size, int) or \
                max_bag_size < 0:
            raise RecordingError(f'max_bag_size must be a whole number of bytes >= 0, got '
                                 f'{max_bag_size!r}')
        if 0 < max_bag_size < MIN_SPLIT_SIZE:
            raise RecordingError(f'max_bag_size {max_bag_size} is too small: give 0 (no '
                                 f'split) or at least {MIN_SPLIT_SIZE} bytes')
        if not (max_bag_duration >= 0 and max_bag_duration < float('inf')):
            raise RecordingError(f'max_bag_duration must be a finite number of seconds >= 0, '
                                 f'got {max_bag_duration!r}')
        self.max_bag_size = max_bag_size
        self.max_bag_duration_ns = int(round(max_bag_duration * 1e9))
        self._writer_options: dict[str, Any] = {
            'compression': compression, 'chunk_size': chunk_size,
            'flush_interval': flush_interval, 'clock': clock}
        check_options(chunk_size=chunk_size, flush_interval=flush_interval,
                      compression=compression)
        self._lock = threading.RLock()
        self._current: BagWriter | None = None
        self._files: list[FileEntry] = []
        self._topics: dict[str, TopicEntry] = {}
        self._registrations: dict[str, dict[str, Any]] = {}
        self._metadata_records: list[tuple[str, dict[str, str]]] = []
        self._custom_data = {str(k): str(v) for k, v in (custom_data or {}).items()}
        self._closed = False
        self._bytes_written = 0

    # ------------------------------------------------------------------ lifecycle
    @property
    def is_open(self) -> bool:
        return self._current is not None

    def open(self) -> None:
        """Create the folder and its first file.

        Raises:
            RecordingError: already opened, the folder exists, or it cannot be created.
        """
        with self._lock:
            if self._current is not None or self._closed:
                raise RecordingError(f'{self.path}: writer was already opened')
            check_new_bag_path(self.path)
            try:
                self.path.mkdir()
            except FileExistsError:
                raise RecordingError(f'{self.path} already exists; choose another name or '
                                     'remove it (recordings are never overwritten)') from None
            except OSError as err:
                raise RecordingError(f'cannot create {self.path}: {err.strerror}') from err
            self._open_next()

    def _open_next(self) -> None:
        name = storage_file_name(self.path, len(self._files))
        writer = BagWriter(self.path / name, **self._writer_options)
        writer.open()
        self._current = writer
        self._files.append(writer.file_entry)
        for topic, registration in self._registrations.items():
            writer.add_topic(topic, **registration)
        for record_name, data in self._metadata_records:
            writer.add_metadata(record_name, data)

    def _document(self) -> str:
        return bag_metadata_yaml(topics=list(self._topics.values()), files=self._files,
                                 custom_data=self._custom_data)

    def close(self) -> None:
        """Finish the current file and write ``metadata.yaml`` (closing twice is allowed)."""
        with self._lock:
            writer, self._current = self._current, None
            if writer is None:
                self._closed = True
                return
            self._closed = True
            writer.close(self._document())
            write_metadata_file(self.path, self._document())

    def _require_open(self) -> BagWriter:
        if self._current is None:
            state = 'closed' if self._closed else 'not opened yet'
            raise RecordingError(f'{self.path}: writer is {state}')
        return self._current

    # ------------------------------------------------------------------ content
    def add_topic(self, name: str, type_name: str, *,
                  offered_qos_profiles: Iterable[Mapping[str, Any]] | None = None,
                  type_hash: str | None = None, definition: str | None = None,
                  schema_encoding: str = 'ros2msg', message_encoding: str = 'cdr',
                  channel_metadata: Mapping[str, str] | None = None) -> TopicEntry:
        """Register a topic in this and every later file (see ``BagWriter.add_topic``)."""
        with self._lock:
            writer = self._require_open()
            existing = self._topics.get(name)
            if existing is not None:
                writer.add_topic(name, type_name)  # raises on a type mismatch
                return existing
            if definition is None and schema_encoding in ('ros2msg', 'ros2idl'):
                definition = schemas.message_definition(type_name)
            entry = writer.add_topic(
                name, type_name, offered_qos_profiles=offered_qos_profiles,
                type_hash=type_hash, definition=definition, schema_encoding=schema_encoding,
                message_encoding=message_encoding, channel_metadata=channel_metadata)
            metadata = channel_metadata if channel_metadata is not None else {
                'offered_qos_profiles': qos_mod.to_yaml(entry.offered_qos_profiles),
                'topic_type_hash': entry.type_hash}
            self._registrations[name] = {
                'type_name': type_name, 'definition': definition,
                'schema_encoding': schema_encoding, 'message_encoding': message_encoding,
                'channel_metadata': dict(metadata)}
            total = TopicEntry(name=entry.name, type=entry.type, channel_id=entry.channel_id,
                               offered_qos_profiles=entry.offered_qos_profiles,
                               type_hash=entry.type_hash)
            self._topics[name] = total
            return total

    def has_topic(self, name: str) -> bool:
        return name in self._topics

    @property
    def topics(self) -> dict[str, TopicEntry]:
        """Registered topics by name with their message counts over all files (a copy)."""
        with self._lock:
            return dict(self._topics)

    def _should_split(self, writer: BagWriter, log_time: int) -> bool:
        entry = writer.file_entry
        if entry.message_count == 0:
            return False
        if self.max_bag_size and writer.size >= self.max_bag_size:
            return True
        return bool(self.max_bag_duration_ns and entry.start_ns is not None
                    and log_time - entry.start_ns > self.max_bag_duration_ns)

    def write(self, topic: str, data: bytes, *, log_time: int,
              publish_time: int | None = None, sequence: int | None = None) -> None:
        """Append one CDR message, first starting a new file when a split is due."""
        with self._lock:
            writer = self._require_open()
            total = self._topics.get(topic)
            if total is None:
                raise RecordingError(f"topic '{topic}' was not added to {self.path}; call "
                                     'add_topic first')
            if isinstance(log_time, int) and self._should_split(writer, log_time):
                writer.close(self._document())
                self._open_next()
                writer = self._require_open()
            writer.write(topic, data, log_time=log_time, publish_time=publish_time,
                         sequence=sequence)
            total.message_count += 1
            self._bytes_written += len(data)

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """A Metadata record, written now and repeated at the start of every later file."""
        with self._lock:
            self._require_open().add_metadata(name, data)
            self._metadata_records.append((name, dict(data)))

    def set_custom_data(self, key: str, value: str) -> None:
        """A ``custom_data`` entry of the rosbag2 metadata."""
        with self._lock:
            self._custom_data[str(key)] = str(value)

    # ------------------------------------------------------------------ flushing
    def flush(self) -> None:
        with self._lock:
            if self._current is not None:
                self._current.flush()

    def flush_if_due(self) -> bool:
        with self._lock:
            return self._current is not None and self._current.flush_if_due()

    # ------------------------------------------------------------------ statistics
    @property
    def flush_interval(self) -> float:
        return float(self._writer_options['flush_interval'])

    @property
    def message_count(self) -> int:
        with self._lock:
            return sum(f.message_count for f in self._files)

    @property
    def payload_bytes(self) -> int:
        return self._bytes_written

    @property
    def files(self) -> list[Path]:
        """The storage files written so far, in order."""
        with self._lock:
            return [self.path / f.path for f in self._files]

    def bag_metadata(self) -> str:
        """The BagMetadata YAML of the bag so far."""
        with self._lock:
            return self._document()


def open_bag_writer(path: str | os.PathLike, *, max_bag_size: int = 0,
                    max_bag_duration: float = 0.0, **options: Any) -> Any:
    """A (not yet opened) writer for ``path``: one file for ``*.mcap``, else a bag folder.

    Raises:
        RecordingError: splitting asked for a single file, or a bad option.
    """
    if is_single_file(path):
        if max_bag_size or max_bag_duration:
            raise RecordingError(f'{path} is a single .mcap file and cannot be split; give a '
                                 'bag folder name (without .mcap) to split by size or duration')
        return BagWriter(path, **options)
    if options.pop('overwrite', False):
        raise RecordingError(f'{path}: a bag folder is never overwritten; remove it first')
    return BagFolderWriter(path, max_bag_size=max_bag_size, max_bag_duration=max_bag_duration,
                           **options)


_INDEX = re.compile(r'_(\d+)\.mcap$')


def bag_files(path: str | os.PathLike) -> tuple[list[Path], dict[str, Any] | None]:
    """The MCAP files of a recording, in order, and its ``metadata.yaml`` mapping (or None).

    ``path`` is an ``.mcap`` file (itself, no metadata) or a bag folder: the files its
    ``metadata.yaml`` lists, or, when the recorder was killed before writing it, the
    folder's ``*.mcap`` files by their split index.

    Raises:
        RecordingError: missing path, broken metadata, a listed file missing or listed
            twice, a folder with no MCAP file, or (without metadata) with the files of
            several recordings; a folder that cannot be read (permissions).
    """
    path = Path(path)
    try:
        return _list_bag_files(path)
    except OSError as err:   # e.g. a folder without read or search permission
        raise RecordingError(f'cannot read {err.filename or path}: {err.strerror}') from None


def _list_bag_files(path: Path) -> tuple[list[Path], dict[str, Any] | None]:
    """``bag_files`` of ``path``, letting the operating system's errors through."""
    if not path.exists():
        raise RecordingError(f'{path}: no such file or bag folder')
    if not path.is_dir():
        return [path], None
    if (path / METADATA_FILE).exists():
        info = read_metadata_file(path)
        files = [path / Path(name).name for name in info['relative_file_paths']]
        twice = sorted({f.name for f in files if files.count(f) > 1})
        if twice:
            raise RecordingError(f"{path / METADATA_FILE} lists {', '.join(twice)} more than "
                                 'once: its messages would be read twice')
        missing = [str(f) for f in files if not f.exists()]
        if missing:
            raise RecordingError(f"{path}: files listed in {METADATA_FILE} are missing: "
                                 f"{', '.join(missing)}")
        not_files = [str(f) for f in files if not f.is_file()]
        if not_files:
            raise RecordingError(f"{path}: {', '.join(not_files)}, listed in {METADATA_FILE}, "
                                 'is not a file')
        if not files:
            raise RecordingError(f'{path}: {METADATA_FILE} lists no storage file')
        return files, info

    def order(file: Path) -> tuple[int, str]:
        match = _INDEX.search(file.name)
        return (int(match.group(1)) if match else -1, file.name)

    files = sorted((f for f in path.glob('*.mcap') if f.is_file()), key=order)
    if not files:
        raise RecordingError(f'{path} is a directory with neither {METADATA_FILE} nor .mcap '
                             'files: not a recording')
    check_one_series(path, files)
    return files, None


def check_one_series(folder: Path, files: list[Path]) -> None:
    """Raise RecordingError unless ``files`` (a folder's ``.mcap`` files, no
    ``metadata.yaml``) are one file or the split files ``NAME_0.mcap``, ``NAME_1.mcap``,
    ... of one recording: files of several recordings would be merged into one."""
    if len(files) < 2:
        return
    names = {_INDEX.sub('', file.name) if _INDEX.search(file.name) else None
             for file in files}
    if len(names) == 1 and None not in names:
        return
    listed = ', '.join(file.name for file in files)
    raise RecordingError(f'{folder} has no {METADATA_FILE} and holds .mcap files of more than '
                         f'one recording ({listed}): give one file, or move the others out')
