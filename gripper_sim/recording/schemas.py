"""Message definitions (``ros2msg`` schema text) and type hashes, from installed .msg files.

rosbag2 stores, for every message type, the type's .msg text followed, for each type it
depends on (depth first, each once), by a separator line of 80 ``=``, a line
``MSG: pkg/Type`` and that type's .msg text. Readers such as Foxglove, ``mcap-ros2-support``
and ``ros2 bag play`` decode CDR with it, so it must hold every nested definition.

The .msg files ship with the interface packages under ``<prefix>/share/<pkg>/msg/``; the
prefixes searched are those of ``AMENT_PREFIX_PATH`` and the running interpreter's prefix.
The ``<Type>.json`` type description beside each .msg file carries its RIHS01 type hash.
"""
from __future__ import annotations

import functools
import json
import os
import re
import sys
from pathlib import Path
from typing import Iterable

from gripper_sim.recording.errors import RecordingError

SEPARATOR = '=' * 80

PRIMITIVE_TYPES = frozenset({
    'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
    'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring',
})

_ARRAY_SUFFIX = re.compile(r'\[[^\]]*\]$')
_STRING_BOUND = re.compile(r'^(w?string)<=\d+$')


def split_type_name(type_name: str) -> tuple[str, str]:
    """``'pkg/msg/Type'`` or ``'pkg/Type'`` -> ``('pkg', 'Type')``.

    Raises:
        RecordingError: the name is not of one of those two forms.
    """
    parts = type_name.strip().split('/')
    if len(parts) == 3 and parts[1] == 'msg' and all(parts):
        return parts[0], parts[2]
    if len(parts) == 2 and all(parts):
        return parts[0], parts[1]
    msg = (f"'{type_name}' is not a message type name: expected 'package/msg/Type' "
           "(e.g. 'std_msgs/msg/String')")
    raise RecordingError(msg)


def full_type_name(type_name: str) -> str:
    """``'pkg/Type'`` or ``'pkg/msg/Type'`` -> ``'pkg/msg/Type'``."""
    pkg, name = split_type_name(type_name)
    return f'{pkg}/msg/{name}'


def search_prefixes() -> list[Path]:
    """Install prefixes searched for ``share/<pkg>/msg`` files, in order."""
    prefixes: list[Path] = []
    for entry in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if entry:
            prefixes.append(Path(entry))
    prefixes.append(Path(sys.prefix))
    seen: set[Path] = set()
    unique = []
    for prefix in prefixes:
        if prefix not in seen:
            seen.add(prefix)
            unique.append(prefix)
    return unique


def _field_dependency(line: str, package: str) -> tuple[str, str] | None:
    """The (package, Type) a field line of a .msg file depends on, or None."""
    line = line.split('#', 1)[0].strip()
    if not line:
        return None
    tokens = line.split()
    if len(tokens) < 2:
        return None
    if '=' in line and re.match(r'^\S+\s+[A-Za-z0-9_]+\s*=', line):
        return None  # constant: always of a primitive type
    base = _ARRAY_SUFFIX.sub('', tokens[0])
    base = _STRING_BOUND.sub(r'\1', base)
    if base in PRIMITIVE_TYPES:
        return None
    if base == 'Header':
        return 'std_msgs', 'Header'
    if '/' in base:
        return split_type_name(base)
    return package, base


def dependencies(text: str, package: str) -> list[tuple[str, str]]:
    """Types a .msg text uses directly, in order of first use, each once."""
    found: list[tuple[str, str]] = []
    for line in text.splitlines():
        dep = _field_dependency(line, package)
        if dep is not None and dep not in found:
            found.append(dep)
    return found


@functools.lru_cache(maxsize=None)
def _find_msg_file(package: str, name: str, prefixes: tuple[Path, ...]) -> Path | None:
    for prefix in prefixes:
        candidate = prefix / 'share' / package / 'msg' / f'{name}.msg'
        if candidate.is_file():
            return candidate
    return None


def find_msg_file(type_name: str, prefixes: Iterable[Path] | None = None) -> Path | None:
    """Path of the installed .msg file of ``type_name``, or None."""
    package, name = split_type_name(type_name)
    return _find_msg_file(package, name, tuple(prefixes or search_prefixes()))


@functools.lru_cache(maxsize=None)
def _definition(package: str, name: str, prefixes: tuple[Path, ...]) -> str:
    root = _find_msg_file(package, name, prefixes)
    if root is None:
        where = ', '.join(str(p / 'share' / package / 'msg') for p in prefixes)
        msg = (f"no message definition for '{package}/msg/{name}': {name}.msg not found "
               f'in {where}; install the interface package or set AMENT_PREFIX_PATH')
        raise RecordingError(msg)
    root_text = root.read_text(encoding='utf-8')
    parts = [root_text]
    seen = {(package, name)}

    def visit(text: str, pkg: str) -> None:
        for dep in dependencies(text, pkg):
            if dep in seen:
                continue
            seen.add(dep)
            path = _find_msg_file(dep[0], dep[1], prefixes)
            if path is None:
                msg = (f"message definition of '{package}/msg/{name}' needs "
                       f"'{dep[0]}/msg/{dep[1]}', whose .msg file was not found; install "
                       'that interface package or set AMENT_PREFIX_PATH')
                raise RecordingError(msg)
            dep_text = path.read_text(encoding='utf-8')
            parts.append(f'{SEPARATOR}\nMSG: {dep[0]}/{dep[1]}\n{dep_text}')
            visit(dep_text, dep[0])

    visit(root_text, package)
    joined = parts[0]
    for part in parts[1:]:
        if not joined.endswith('\n'):
            joined += '\n'
        joined += part
    return joined


def message_definition(type_name: str, prefixes: Iterable[Path] | None = None) -> str:
    """The full ``ros2msg`` schema text of ``type_name`` with all nested definitions.

    Raises:
        RecordingError: the .msg file of the type or of a type it uses is not installed.
    """
    package, name = split_type_name(type_name)
    return _definition(package, name, tuple(prefixes or search_prefixes()))


@functools.lru_cache(maxsize=None)
def _type_hash(package: str, name: str, prefixes: tuple[Path, ...]) -> str | None:
    for prefix in prefixes:
        path = prefix / 'share' / package / 'msg' / f'{name}.json'
        if not path.is_file():
            continue
        try:
            data = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError):
            return None
        for entry in data.get('type_hashes', ()):
            if entry.get('type_name') == f'{package}/msg/{name}':
                value = entry.get('hash_string')
                return value if isinstance(value, str) and value else None
        return None
    return None


def type_hash(type_name: str, prefixes: Iterable[Path] | None = None) -> str | None:
    """The ``RIHS01_...`` hash of ``type_name`` from its installed type description, or None."""
    package, name = split_type_name(type_name)
    return _type_hash(package, name, tuple(prefixes or search_prefixes()))
