"""rosbag2's BagMetadata (Jazzy, version 9) as YAML: written and read without ROS.

The same document appears twice in a bag folder, as rosbag2 writes it:

- ``metadata.yaml`` beside the storage files, under the top-level key
  ``rosbag2_bagfile_information``;
- in every MCAP file, as the ``serialized_metadata`` value of a Metadata record called
  ``rosbag2`` (without the top-level key).

Key order and layout follow rosbag2_storage's yaml-cpp encoder (``yaml.hpp`` on the
jazzy branch): version, storage_identifier, duration, starting_time, message_count,
topics_with_message_count (topic_metadata: name, type, serialization_format,
offered_qos_profiles as a YAML list, type_description_hash; message_count),
compression_format, compression_mode, relative_file_paths, files (path, starting_time,
duration, message_count), custom_data, ros_distro. A bag or file without messages has
``starting_time`` INT64_MAX and duration 0, as rosbag2 leaves them.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import yaml

from gripper_sim.configuration import yaml_problem
from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording.errors import RecordingError

ROS_DISTRO = 'jazzy'
BAG_METADATA_VERSION = 9
METADATA_FILE = 'metadata.yaml'
TOP_KEY = 'rosbag2_bagfile_information'
NO_TIME = 2**63 - 1  # rosbag2's starting_time before the first message (ns max)


@dataclass
class TopicEntry:
    """A topic of a bag.

    Attributes:
        name: topic name, e.g. ``/gripper_sim/fruit/state``.
        type: message type, ``pkg/msg/Type``.
        channel_id: MCAP channel id in the file being written.
        offered_qos_profiles: profiles (dicts, see ``qos``) of the publishers seen.
        type_hash: ``RIHS01_...`` or '' when unknown.
        message_count: messages written so far.
    """

    name: str
    type: str
    channel_id: int
    offered_qos_profiles: list = field(default_factory=list)
    type_hash: str = ''
    message_count: int = 0


@dataclass
class FileEntry:
    """One storage file of a bag: name relative to the folder, log-time span, count."""

    path: str
    start_ns: int | None = None
    end_ns: int | None = None
    message_count: int = 0

    def add(self, log_time: int) -> None:
        """Count one message logged at ``log_time`` (ns)."""
        self.message_count += 1
        self.start_ns = log_time if self.start_ns is None else min(self.start_ns, log_time)
        self.end_ns = log_time if self.end_ns is None else max(self.end_ns, log_time)


def yaml_scalar(value: str) -> str:
    """A YAML scalar for ``value``, quoted only when needed (as yaml-cpp does)."""
    if value == '':
        return '""'
    if any(c in value for c in ':#{}[],&*!|>\'"%@`\n') or value.strip() != value or \
            value.lower() in ('~', 'null', 'true', 'false', 'yes', 'no', 'on', 'off'):
        escaped = value.replace('\\', '\\\\').replace('"', '\\"').replace('\n', '\\n')
        return f'"{escaped}"'
    return value


def _span(start: int | None, end: int | None) -> tuple[int, int]:
    if start is None or end is None:
        return NO_TIME, 0
    return start, max(0, end - start)


def bag_metadata_yaml(*, topics: Iterable[TopicEntry], files: Iterable[FileEntry],
                      custom_data: Mapping[str, str] | None = None,
                      compression_format: str = '', compression_mode: str = '') -> str:
    """The BagMetadata YAML document (no top-level key) for a bag made of ``files``."""
    files = list(files)
    starts = [f.start_ns for f in files if f.start_ns is not None]
    ends = [f.end_ns for f in files if f.end_ns is not None]
    start, duration = _span(min(starts) if starts else None, max(ends) if ends else None)
    topic_list = list(topics)
    lines = [
        f'version: {BAG_METADATA_VERSION}',
        'storage_identifier: mcap',
        'duration:',
        f'  nanoseconds: {duration}',
        'starting_time:',
        f'  nanoseconds_since_epoch: {start}',
        f'message_count: {sum(t.message_count for t in topic_list)}',
    ]
    if topic_list:
        lines.append('topics_with_message_count:')
        for t in topic_list:
            lines += [
                '  - topic_metadata:',
                f'      name: {yaml_scalar(t.name)}',
                f'      type: {yaml_scalar(t.type)}',
                '      serialization_format: cdr',
            ]
            if t.offered_qos_profiles:
                lines.append('      offered_qos_profiles:')
                qos_yaml = qos_mod.to_yaml(t.offered_qos_profiles)
                lines += ['        ' + line for line in qos_yaml.splitlines()]
            else:
                lines.append('      offered_qos_profiles: []')
            lines += [
                f'      type_description_hash: {yaml_scalar(t.type_hash)}',
                f'    message_count: {t.message_count}',
            ]
    else:
        lines.append('topics_with_message_count: []')
    lines += [
        f'compression_format: {yaml_scalar(compression_format)}',
        f'compression_mode: {yaml_scalar(compression_mode)}',
    ]
    lines.append('relative_file_paths:' if files else 'relative_file_paths: []')
    lines += [f'  - {yaml_scalar(f.path)}' for f in files]
    lines.append('files:' if files else 'files: []')
    for f in files:
        file_start, file_duration = _span(f.start_ns, f.end_ns)
        lines += [
            f'  - path: {yaml_scalar(f.path)}',
            '    starting_time:',
            f'      nanoseconds_since_epoch: {file_start}',
            '    duration:',
            f'      nanoseconds: {file_duration}',
            f'    message_count: {f.message_count}',
        ]
    if custom_data:
        lines.append('custom_data:')
        lines += [f'  {yaml_scalar(k)}: {yaml_scalar(v)}' for k, v in custom_data.items()]
    else:
        lines.append('custom_data: ~')
    lines.append(f'ros_distro: {ROS_DISTRO}')
    return '\n'.join(lines) + '\n'


def metadata_file_text(document: str) -> str:
    """``metadata.yaml`` content: ``document`` under ``rosbag2_bagfile_information``."""
    body = ''.join(f'  {line}\n' if line else '\n' for line in document.splitlines())
    return f'{TOP_KEY}:\n{body}'


def write_metadata_file(folder: Path, document: str) -> Path:
    """Write ``folder/metadata.yaml`` atomically (a reader never sees half of it)."""
    target = folder / METADATA_FILE
    tmp = folder / f'.{METADATA_FILE}.part'
    try:
        with open(tmp, 'w', encoding='utf-8') as f:
            f.write(metadata_file_text(document))
        tmp.replace(target)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise RecordingError(f'cannot write {target}: {err.strerror}') from err
    return target


def load_yaml(text: str, source: str) -> Any:
    """The YAML document ``text``; RecordingError with a one-line reason (line and column
    of the problem) naming ``source``."""
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as err:
        raise RecordingError(f'{source} is not valid YAML: {yaml_problem(err)}') from None
    except RecursionError:
        raise RecordingError(f'{source} is not valid YAML: it nests too deeply') from None


def read_metadata_file(folder: Path) -> dict[str, Any]:
    """The BagMetadata mapping of ``folder/metadata.yaml``.

    Any version is read (as rosbag2 reads older and newer ones): only the storage and
    the file list are used.

    Raises:
        RecordingError: missing, not YAML, not a rosbag2 metadata file (no whole-number
            version), or not MCAP.
    """
    path = folder / METADATA_FILE
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise RecordingError(f'{folder} has no {METADATA_FILE}: not a bag folder') from None
    except OSError as err:
        raise RecordingError(f'cannot read {path}: {err.strerror}') from None
    except UnicodeDecodeError as err:
        raise RecordingError(f'cannot read {path}: {err}') from None
    data = load_yaml(text, str(path))
    info = data.get(TOP_KEY) if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise RecordingError(f'{path} has no {TOP_KEY} mapping: not rosbag2 metadata')
    version = info.get('version')
    if version is None:
        raise RecordingError(f'{path} has no version: not rosbag2 metadata')
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise RecordingError(f'{path}: version {version!r} is not a BagMetadata version (a '
                             f'whole number, {BAG_METADATA_VERSION} for Jazzy)')
    storage = info.get('storage_identifier')
    if storage != 'mcap':
        raise RecordingError(f"{path}: storage '{storage}' is not supported (only mcap)")
    paths = info.get('relative_file_paths')
    if not isinstance(paths, list) or not all(isinstance(p, str) for p in paths):
        raise RecordingError(f'{path}: relative_file_paths is not a list of file names')
    if info.get('compression_mode') not in (None, '', 'none', 'NONE'):
        raise RecordingError(f"{path}: compression mode '{info['compression_mode']}' is not "
                             'supported (MCAP chunk compression is)')
    return info
