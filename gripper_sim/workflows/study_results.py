"""A study's rows on disk: Parquet part files written as rows arrive, read back to resume.

The rows live in ``DIR/rows/`` as ``part-*.parquet`` files (one Parquet dataset:
``pandas.read_parquet('DIR/rows')`` or ``pyarrow.dataset.dataset('DIR/rows')`` read it).
Rows are buffered and written as a new part at least every ``FLUSH_SECONDS`` or
``FLUSH_ROWS`` rows, each part written to a temporary name and renamed, so that a
killed study loses at most the last buffer and never leaves a half-written file.
``compact`` rewrites all parts as one, sorted, and drops the rows a complete run did
not use (those of earlier code: changed code computes its own). Each row is keyed by ``case_key`` (the
case's effective configuration, scenario, force, kind and code version): a row already
stored is never computed again.

``DIR/study.json`` names the study whose rows the directory holds (``identity``: its
name and ``definition`` hash), so that a run of another study, or of a changed
definition, into the directory is refused instead of mixing its rows in
(``held_study``; ``workflows.study.run_study`` checks it).
"""
from __future__ import annotations

import csv
import json
import os
import time
from pathlib import Path
from typing import Any, Iterable

import pyarrow as pa
import pyarrow.parquet as pq

from gripper_sim.errors import GripperSimError

FLUSH_SECONDS = 2.0
FLUSH_ROWS = 200
#: the order rows are sorted in (then by case_key)
SORT_KEYS = ('point', 'sample', 'kind', 'force')
#: the file in a results directory naming the study it holds (see the module docstring)
IDENTITY_FILE = 'study.json'


class StudyResultsError(GripperSimError):
    """The results directory cannot be read or written."""


class RowStore:
    """The rows of one study in ``directory/rows`` (see the module docstring)."""

    def __init__(self, directory: str | os.PathLike):
        self.directory = Path(directory)
        self.parts = self.directory / 'rows'
        try:
            self.parts.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise StudyResultsError(f"cannot create '{self.parts}': {err.strerror}") from err
        self.rows: dict[str, dict[str, Any]] = {}
        self._buffer: list[dict[str, Any]] = []
        self._last_flush = time.monotonic()
        self._counter = 0
        for part in sorted(self.parts.glob('part-*.parquet')):
            try:
                table = pq.read_table(part)
            except (OSError, pa.ArrowException) as err:
                raise StudyResultsError(f"cannot read '{part}': {err}") from err
            for row in table.to_pylist():
                self.rows[row['case_key']] = row

    def __contains__(self, key: str) -> bool:
        return key in self.rows

    def __len__(self) -> int:
        return len(self.rows)

    def get(self, key: str) -> dict[str, Any] | None:
        return self.rows.get(key)

    def add(self, row: dict[str, Any]) -> None:
        """Keep ``row`` and write the buffer out when it is due."""
        self.rows[row['case_key']] = row
        self._buffer.append(row)
        if (len(self._buffer) >= FLUSH_ROWS
                or time.monotonic() - self._last_flush >= FLUSH_SECONDS):
            self.flush()

    def flush(self) -> None:
        """Write the buffered rows as a new part file."""
        self._last_flush = time.monotonic()
        if not self._buffer:
            return
        self._write(self._buffer, f'part-{time.time_ns():020d}-{os.getpid()}-'
                                  f'{self._counter:05d}.parquet')
        self._counter += 1
        self._buffer = []

    def sorted_rows(self) -> list[dict[str, Any]]:
        """Every row, sorted by design point, sample, kind, force, case_key."""
        return sorted(self.rows.values(),
                      key=lambda r: tuple(r[k] for k in SORT_KEYS) + (r['case_key'],))

    def compact(self, keep: set[str] | None = None) -> int:
        """Rewrite all parts as one sorted part (the old parts removed after), with only
        the rows whose ``case_key`` is in ``keep`` if given (a complete run's: rows of
        earlier code are superseded); how many rows were dropped."""
        self.flush()
        dropped = [key for key in self.rows if keep is not None and key not in keep]
        for key in dropped:
            del self.rows[key]
        old = sorted(self.parts.glob('part-*.parquet'))
        if len(old) <= 1 and not dropped:
            return 0
        name = f'part-{time.time_ns():020d}-{os.getpid()}-compact.parquet'
        self._write(self.sorted_rows(), name)
        for part in old:
            part.unlink()
        return len(dropped)

    def claim(self, identity: dict[str, str]) -> None:
        """Write ``identity`` ({'study': name, 'definition': hash}) as the directory's
        ``IDENTITY_FILE``."""
        path = self.directory / IDENTITY_FILE
        tmp = self.directory / f'.{IDENTITY_FILE}.tmp'
        try:
            tmp.write_text(json.dumps(identity, indent=1) + '\n', encoding='utf-8')
            os.replace(tmp, path)
        except OSError as err:
            raise StudyResultsError(f"cannot write '{path}': {err.strerror}") from err

    def write_csv(self, path: str | os.PathLike) -> None:
        """Every row as CSV (columns in the order of the first row)."""
        rows = self.sorted_rows()
        columns = _columns(rows)
        with open(path, 'w', newline='', encoding='utf-8') as stream:
            writer = csv.DictWriter(stream, fieldnames=columns)
            writer.writeheader()
            writer.writerows(rows)

    def _write(self, rows: list[dict[str, Any]], name: str) -> None:
        columns = _columns(rows)
        table = pa.Table.from_pylist([{c: row.get(c) for c in columns} for row in rows])
        tmp = self.parts / f'.{name}.tmp'
        try:
            pq.write_table(table, tmp)
            os.replace(tmp, self.parts / name)
        except OSError as err:
            raise StudyResultsError(f"cannot write '{self.parts / name}': "
                                    f'{err.strerror}') from err


def held_study(directory: str | os.PathLike) -> dict[str, str | None] | None:
    """The identity of the study whose results ``directory`` holds, without changing
    it: its ``IDENTITY_FILE``, else (results written before there was one) the
    ``study`` names of its rows with ``definition`` None; None if it holds no results.

    Raises:
        StudyResultsError: the identity file or a part cannot be read.
    """
    directory = Path(directory)
    path = directory / IDENTITY_FILE
    if path.is_file():
        try:
            identity = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError) as err:
            raise StudyResultsError(f"cannot read '{path}': {err}") from err
        if not isinstance(identity, dict) or not isinstance(identity.get('study'), str):
            raise StudyResultsError(f"'{path}' does not name a study")
        return identity
    names: set[str] = set()
    for part in sorted((directory / 'rows').glob('part-*.parquet')):
        try:
            names.update(pq.read_table(part, columns=['study']).column('study').to_pylist())
        except (OSError, KeyError, pa.ArrowException) as err:
            raise StudyResultsError(f"cannot read '{part}': {err}") from err
    if not names:
        return None
    return dict(study=', '.join(sorted(map(str, names))), definition=None)


def _columns(rows: Iterable[dict[str, Any]]) -> list[str]:
    columns: dict[str, None] = {}
    for row in rows:
        for key in row:
            columns.setdefault(key, None)
    return list(columns)
