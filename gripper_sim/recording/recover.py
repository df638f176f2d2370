"""Rebuild a readable, indexed MCAP file from a truncated or damaged one.

A recorder killed with SIGKILL leaves a file with a header, whole chunks (the writer
closes a chunk at least every ``flush_interval``), perhaps half a chunk, and no summary
or footer. ``recover`` reads the data section record by record, keeps every schema,
channel, message and metadata record of every chunk that is whole and passes its CRC,
stops at the first cut record, and writes all of it to a new file with a fresh summary
and statistics. The output keeps the input's header (profile, library) and every
channel, also those without messages; only a ``ros2`` file gets a fresh rosbag2
metadata record. The input file is only ever opened for reading.

A bag folder is recovered file by file into a new bag folder with its own
``metadata.yaml``.
"""
from __future__ import annotations

import io
import os
import shutil
import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterator

from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Header, Message, Metadata, Schema
from mcap.stream_reader import breakup_chunk

from gripper_sim.recording.bag_folder import (bag_files, check_new_bag_path, is_single_file,
                                              storage_file_name)
from gripper_sim.recording.bag_metadata import (FileEntry, TopicEntry, bag_metadata_yaml,
                                                write_metadata_file)
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import (MCAP_MAGIC, READ_ERRORS, McapFile, check_mcap_start,
                                          has_footer)
from gripper_sim.recording.writer import BagWriter

_KNOWN_OPCODES = {int(op) for op in Opcode}
_MAX_RECORD = 4 * 2**30


@dataclass
class RecoverReport:
    """What ``recover`` found and kept.

    Attributes:
        messages: messages written to the output.
        topics: topic name -> messages kept.
        chunks: whole chunks read.
        damaged_chunks: chunks skipped because they failed to decompress or their CRC.
        complete: the input was whole: a data-end record, then the summary and the footer
            (a file cut anywhere, even after its data, is not complete).
        stopped_at: byte offset where reading stopped.
        input_size: bytes in the input.
        reason: why reading stopped before the end, '' when it reached the end.
        start_time, end_time: log-time range of the kept messages, ns.
    """

    messages: int = 0
    topics: dict = field(default_factory=dict)
    chunks: int = 0
    damaged_chunks: int = 0
    complete: bool = False
    stopped_at: int = 0
    input_size: int = 0
    reason: str = ''
    start_time: int = 0
    end_time: int = 0


@dataclass
class _Scan:
    header: Header | None = None
    records: list = field(default_factory=list)
    report: RecoverReport = field(default_factory=RecoverReport)


def _parse(opcode: int, body: bytes):
    stream = ReadDataStream(io.BytesIO(body))
    if opcode == Opcode.HEADER:
        return Header.read(stream)
    if opcode == Opcode.SCHEMA:
        return Schema.read(stream)
    if opcode == Opcode.CHANNEL:
        return Channel.read(stream)
    if opcode == Opcode.MESSAGE:
        return Message.read(stream, len(body))
    if opcode == Opcode.CHUNK:
        return Chunk.read(stream)
    if opcode == Opcode.METADATA:
        return Metadata.read(stream)
    return None  # indexes, attachments, summary records: rebuilt or not needed


def scan(path: str | os.PathLike) -> _Scan:
    """Read the data section of ``path`` as far as it is whole."""
    path = Path(path)
    check_mcap_start(path)
    result = _Scan()
    report = result.report
    report.input_size = path.stat().st_size
    with open(path, 'rb') as f:
        f.read(len(MCAP_MAGIC))
        offset = len(MCAP_MAGIC)
        while True:
            head = f.read(9)
            if len(head) == 0:
                report.reason = 'the file ends without a data-end record (not closed)'
                break
            if len(head) < 9:
                report.reason = f'a record header is cut at byte {offset}'
                break
            opcode, length = struct.unpack('<BQ', head)
            if opcode not in _KNOWN_OPCODES and opcode < 0x80:
                report.reason = f'unreadable data at byte {offset} (opcode {opcode:#x})'
                break
            if opcode == Opcode.DATA_END or opcode == Opcode.FOOTER:
                report.complete = has_footer(path)
                if not report.complete:
                    report.reason = 'the file is cut after its data (no footer)'
                break
            if length > min(_MAX_RECORD, report.input_size - offset - 9):
                report.reason = (f'the record at byte {offset} is cut: it needs {length} '
                                 f'bytes, {report.input_size - offset - 9} are left')
                break
            body = f.read(length)
            try:
                record = _parse(opcode, body)
            except READ_ERRORS as err:
                report.reason = f'unreadable record at byte {offset}: {err}'
                break
            if isinstance(record, Header):
                result.header = record
            elif isinstance(record, Chunk):
                try:
                    inner = breakup_chunk(record, validate_crc=True)
                except READ_ERRORS:
                    report.damaged_chunks += 1
                else:
                    report.chunks += 1
                    result.records.extend(inner)
            elif record is not None:
                result.records.append(record)
            offset += 9 + length
        report.stopped_at = offset
    return result


def _add_channel(bag: BagWriter, channel: Channel, schemas: dict[int, Schema],
                 topics: dict[int, str]) -> None:
    """Register ``channel`` in the output as it was (nothing if its schema was lost)."""
    if channel.id in topics:
        return
    schema = schemas.get(channel.schema_id)
    if schema is None and channel.schema_id != 0:
        return  # its schema record was in a lost chunk
    bag.add_topic(channel.topic, schema.name if schema else '',
                  definition=schema.data if schema else b'',
                  schema_encoding=schema.encoding if schema else '',
                  message_encoding=channel.message_encoding,
                  channel_metadata=channel.metadata)
    topics[channel.id] = channel.topic


def recover(src: str | os.PathLike, dst: str | os.PathLike, *,
            overwrite: bool = False) -> RecoverReport:
    """Write every whole message of ``src`` into a new, indexed file ``dst``.

    Raises:
        RecordingError: ``src`` is missing, empty or not MCAP; ``dst`` is ``src``, exists
            (without ``overwrite``; with it, is not a regular file: a device or FIFO is
            never replaced) or cannot be written; nothing could be recovered.
    """
    src, dst = Path(src), Path(dst)
    check_mcap_start(src)
    if dst.exists() and (os.path.samefile(src, dst)):
        raise RecordingError(f'output {dst} is the input file; give another name (the input '
                             'is never modified)')
    if dst.exists() and not overwrite:
        raise RecordingError(f'{dst} already exists; choose another name or remove it')
    if dst.exists() and not dst.is_file():
        raise RecordingError(f'{dst} is not a regular file; --force replaces only a file '
                             '(give the name of a new .mcap file)')
    result = scan(src)
    report = result.report
    if result.header is None:
        raise RecordingError(f'{src} has no readable MCAP header: nothing to recover')
    schemas: dict[int, Schema] = {}
    topics: dict[int, str] = {}   # channel id -> topic registered in the output
    dst_dir = dst.parent if str(dst.parent) else Path('.')
    if not dst_dir.is_dir():
        raise RecordingError(f'{dst}: directory {dst_dir} does not exist')
    try:
        fd, tmp_name = tempfile.mkstemp(prefix=f'.{dst.name}.', suffix='.part', dir=dst_dir)
    except OSError as err:
        raise RecordingError(f'cannot create {dst}: {err.strerror}') from err
    os.close(fd)
    tmp = Path(tmp_name)
    header = result.header
    try:
        with BagWriter(tmp, overwrite=True, profile=header.profile,
                       library=header.library) as bag:
            for record in result.records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    _add_channel(bag, record, schemas, topics)
                elif isinstance(record, Metadata):
                    if record.name != 'rosbag2':
                        bag.add_metadata(record.name, dict(record.metadata))
                elif isinstance(record, Message):
                    topic = topics.get(record.channel_id)
                    if topic is None:
                        continue  # its channel record was in a lost chunk
                    bag.write(topic, record.data, log_time=record.log_time,
                              publish_time=record.publish_time, sequence=record.sequence)
                    report.topics[topic] = report.topics.get(topic, 0) + 1
                    if report.messages == 0:
                        report.start_time = report.end_time = record.log_time
                    report.start_time = min(report.start_time, record.log_time)
                    report.end_time = max(report.end_time, record.log_time)
                    report.messages += 1
        if report.messages == 0:
            why = f' ({report.reason})' if report.reason else ''
            raise RecordingError(f'{src} holds no whole message{why}: nothing to recover')
        try:
            os.replace(tmp, dst)
        except OSError as err:
            raise RecordingError(f'cannot create {dst}: {err.strerror}') from err
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return report


def _counted(count: int, noun: str) -> str:
    """``count`` and ``noun``, the noun plural unless the count is one: '1 chunk'."""
    return f'{count} {noun}' if count == 1 else f'{count} {noun}s'


def iter_report_lines(report: RecoverReport, src: Path, dst: Path) -> Iterator[str]:
    """Human-readable lines describing a recovery."""
    state = 'complete' if report.complete else 'cut short'
    yield f'input:  {src} ({report.input_size} bytes, {state})'
    if report.reason:
        yield f'        stopped at byte {report.stopped_at}: {report.reason}'
    yield (f"output: {dst}: {_counted(report.messages, 'message')} from "
           f"{_counted(report.chunks, 'chunk')}"
           + (f", {_counted(report.damaged_chunks, 'damaged chunk')} skipped"
              if report.damaged_chunks else ''))
    if report.messages:
        span = (report.end_time - report.start_time) / 1e9
        yield f'        {span:.3f} s of messages'
    for topic, count in sorted(report.topics.items()):
        yield f'        {topic}: {count}'


@dataclass
class BagRecoverReport:
    """What ``recover_bag`` did: one ``RecoverReport`` per input file it rebuilt.

    Attributes:
        files: (input file, output file or None when it held nothing whole, report or
            the reason it was skipped).
        metadata_file: the ``metadata.yaml`` written.
    """

    files: list = field(default_factory=list)
    metadata_file: Path | None = None

    @property
    def messages(self) -> int:
        return sum(r.messages for _, _, r in self.files if isinstance(r, RecoverReport))


def _folder_metadata(files: list[Path]) -> str:
    """The BagMetadata YAML of a bag made of the (whole, readable) ``files``."""
    topics: dict[str, TopicEntry] = {}
    entries = []
    for path in files:
        with McapFile(path) as part:
            entry = FileEntry(path.name, message_count=part.message_count)
            if part.message_count:
                entry.start_ns, entry.end_ns = part.start_time, part.end_time
            entries.append(entry)
            for name, info in part.topics.items():
                if info.message_encoding != 'cdr':
                    continue
                total = topics.setdefault(name, TopicEntry(
                    name=name, type=info.type, channel_id=info.channel_id,
                    offered_qos_profiles=info.offered_qos_profiles, type_hash=info.type_hash))
                total.message_count += info.message_count
    return bag_metadata_yaml(topics=list(topics.values()), files=entries)


def _check_readable(path: Path) -> None:
    """Raise RecordingError if ``path`` cannot be opened for reading (permissions)."""
    try:
        with open(path, 'rb'):
            pass
    except OSError as err:
        raise RecordingError(f'cannot read {path}: {err.strerror}') from None


def recover_bag(src: str | os.PathLike, dst: str | os.PathLike) -> BagRecoverReport:
    """Recover every file of the bag folder ``src`` into the new bag folder ``dst``.

    The files are those ``src/metadata.yaml`` lists or, when the recorder died before
    writing it, the folder's ``*.mcap`` files in split order. A file holding nothing
    whole is left out; ``dst/metadata.yaml`` describes what was kept.

    Raises:
        RecordingError: ``src`` is not a recording folder or a file of it cannot be
            read; ``dst`` exists, is inside ``src`` or cannot be created; no file held a
            whole message.
    """
    src, dst = Path(src), Path(dst)
    files, _ = bag_files(src)
    for path in files:   # a file that cannot be read is an error, not a file skipped
        _check_readable(path)
    target = check_new_bag_path(dst)
    if is_single_file(target):
        raise RecordingError(f'{dst}: a bag folder is recovered into a new bag folder; give '
                             'a name without .mcap')
    if target.resolve().is_relative_to(src.resolve()):
        raise RecordingError(f'{dst} is inside the bag folder {src}, which recover never '
                             'modifies: give a folder outside it')
    try:
        target.mkdir()
    except OSError as err:
        raise RecordingError(f'cannot create {target}: {err.strerror}') from err
    report = BagRecoverReport()
    written: list[Path] = []
    for path in files:
        out = target / storage_file_name(target, len(written))
        try:
            report.files.append((path, out, recover(path, out)))
        except RecordingError as err:
            report.files.append((path, None, str(err)))
            continue
        written.append(out)
    if not written:
        shutil.rmtree(target, ignore_errors=True)
        raise RecordingError(f'{src}: no file holds a whole message: nothing to recover')
    report.metadata_file = write_metadata_file(target, _folder_metadata(written))
    return report


def iter_bag_report_lines(report: BagRecoverReport, src: Path, dst: Path) -> Iterator[str]:
    """Human-readable lines describing a bag folder recovery."""
    yield f'bag:    {src} -> {dst} ({report.messages} messages)'
    for path, out, file_report in report.files:
        if out is None:
            yield f'input:  {path}: skipped ({file_report})'
        else:
            yield from iter_report_lines(file_report, path, out)
    yield f'wrote:  {report.metadata_file}'
