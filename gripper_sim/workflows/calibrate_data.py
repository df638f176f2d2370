"""A measured plate compression curve: read from CSV, checked, in SI units.

The file (one test, loading part only)::

    # any comment lines; these two are read when present:
    # plate_speed: 20 mm/min
    # source: ...
    deformation_mm,force_N
    0.0,0.0
    0.5,3.1
    ...

The header names the two columns ``deformation`` and ``force`` with their units as a
suffix (``deformation_mm``, ``deformation [m]``, ``force (N)``); where it has none, the
caller passes them (``deformation_unit``/``force_unit``), and a file with no header row
at all is read as two columns in that order. Deformation is the plate travel since
first contact. Every problem is a ``CalibrationError`` with a one-line message naming
it (and the row, for a bad value).
"""
from __future__ import annotations

import csv
import hashlib
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gripper_sim.errors import GripperSimError

#: length units of the deformation column, in m
LENGTH_UNITS = {'mm': 1e-3, 'm': 1.0}
#: force units of the force column, in N
FORCE_UNITS = {'N': 1.0}
#: plate speed units, in m/s
SPEED_UNITS = {'m/s': 1.0, 'mm/s': 1e-3, 'mm/min': 1e-3 / 60.0, 'm/min': 1.0 / 60.0}
#: fewest data points a fit is attempted with
MIN_POINTS = 5

_COLUMN = re.compile(r'^\s*(?P<name>[A-Za-z]+)\s*(?:[_\s]\s*(?P<u1>[^\s\[\]()]+)|'
                     r'[\[(]\s*(?P<u2>[^\])]+?)\s*[\])])?\s*$')
_QUANTITY = re.compile(r'^\s*(?P<value>[-+0-9.eE]+|nan|inf)\s*(?P<unit>\S*)\s*$', re.I)
_SPEED_LINE = re.compile(r'^\s*#\s*plate[_ ]speed\s*[:=]\s*(?P<text>.+?)\s*$', re.I)


class CalibrationError(GripperSimError):
    """Bad measured data or calibration request; the message names the problem."""


@dataclass(frozen=True)
class CompressionCurve:
    """A loading curve of a plate compression test.

    Attributes:
        deformation: (n,) m, plate travel since first contact, strictly increasing, >= 0.
        force: (n,) N, plate force at each deformation, >= 0.
        speed: m/s, plate (gap closing) speed, None when the file does not give it.
        path: the file it was read from.  sha256: hex digest of the file's bytes.
    """

    deformation: np.ndarray
    force: np.ndarray
    speed: float | None
    path: str
    sha256: str

    @property
    def max_deformation(self) -> float:
        """m, the largest deformation of the test."""
        return float(self.deformation[-1])


def parse_quantity(text: str, units: dict[str, float], what: str) -> float:
    """``'20 mm/min'`` to SI with ``units`` ({unit: factor}); a finite value > 0."""
    match = _QUANTITY.match(text)
    if not match:
        raise CalibrationError(f"{what} '{text}' is not a number with a unit "
                               f"({', '.join(units)})")
    unit = match['unit']
    if unit not in units:
        known = ', '.join(units)
        if not unit:
            raise CalibrationError(f"{what} '{text}' has no unit (give one of: {known})")
        raise CalibrationError(f"{what} '{text}': unknown unit '{unit}' (known: {known})")
    value = float(match['value'])
    if not math.isfinite(value) or value <= 0:
        raise CalibrationError(f"{what} '{text}' must be a finite number > 0")
    return value * units[unit]


def _column(cell: str, expected: str) -> str | None:
    """The unit named in header cell ``cell`` for column ``expected`` ('' if none)."""
    match = _COLUMN.match(cell)
    if not match or match['name'].lower() != expected:
        return None
    return (match['u1'] or match['u2'] or '').strip()


def _unit_factor(column: str, unit: str | None, flag: str | None, units: dict,
                 option: str) -> float:
    """SI factor of a column's unit: from the header, else from the flag."""
    chosen = unit or flag
    known = ', '.join(units)
    if not chosen:
        raise CalibrationError(f"the {column} unit is missing: name it in the header "
                               f"({column}_{next(iter(units))}) or with {option} "
                               f'(known: {known})')
    if unit and flag and unit != flag:
        raise CalibrationError(f"the header gives the {column} unit '{unit}' but "
                               f"{option} says '{flag}'")
    if chosen not in units:
        raise CalibrationError(f"unknown {column} unit '{chosen}' (known: {known})")
    return units[chosen]


def _number(cell: str, column: str, line: int) -> float:
    try:
        value = float(cell)
    except ValueError:
        raise CalibrationError(f"row {line}: {column} '{cell.strip()}' is not a "
                               'number') from None
    if not math.isfinite(value):
        raise CalibrationError(f"row {line}: {column} is not a finite number "
                               f"('{cell.strip()}')")
    return value


def read_curve(path: str | Path, deformation_unit: str | None = None,
               force_unit: str | None = None, speed: float | None = None) -> CompressionCurve:
    """Read and check a compression curve (see the module docstring).

    Args:
        deformation_unit, force_unit: units where the header gives none (or to confirm it).
        speed: m/s, plate speed; overrides a ``# plate_speed:`` line of the file.

    Raises:
        CalibrationError: unreadable file, missing/unknown unit, a single column, a
            value that is not a finite number, negative force or deformation, a
            deformation that does not increase, fewer than ``MIN_POINTS`` rows.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise CalibrationError(f"cannot read data file '{path}': {err.strerror}") from err
    try:
        text = raw.decode('utf-8-sig')
    except UnicodeDecodeError:
        raise CalibrationError(f"data file '{path}' is not a text (UTF-8) file") from None
    rows: list[tuple[int, list[str]]] = []
    file_speed = None
    for number, line in enumerate(text.splitlines(), start=1):
        if line.lstrip().startswith('#'):
            found = _SPEED_LINE.match(line)
            if found:
                file_speed = parse_quantity(found['text'], SPEED_UNITS,
                                            f'plate speed (row {number})')
            continue
        if line.strip():
            rows.append((number, next(csv.reader([line]))))
    if not rows:
        raise CalibrationError(f"data file '{path}' holds no data rows")
    header_line, first = rows[0]
    widths = {len(cells) for _, cells in rows}
    if widths == {1}:
        raise CalibrationError(f"data file '{path}' has a single column; it needs two: "
                               'deformation and force')
    has_header = any(_is_text(cell) for cell in first)
    if has_header:
        rows = rows[1:]
        if len(first) != 2:
            raise CalibrationError(f'the header (row {header_line}) has {len(first)} '
                                   'columns; it needs two: deformation and force')
        units = [_column(first[0], 'deformation'), _column(first[1], 'force')]
        if units[0] is None or units[1] is None:
            raise CalibrationError(f'the header (row {header_line}) must name the columns '
                                   f"deformation and force, e.g. 'deformation_mm,force_N'; "
                                   f"got '{','.join(first)}'")
    else:
        units = ['', '']
    length_factor = _unit_factor('deformation', units[0], deformation_unit, LENGTH_UNITS,
                                 '--deformation-unit')
    force_factor = _unit_factor('force', units[1], force_unit, FORCE_UNITS, '--force-unit')
    deformation, force = [], []
    for line, cells in rows:
        if len(cells) != 2:
            raise CalibrationError(f'row {line} has {len(cells)} value(s); it needs two: '
                                   'deformation and force')
        d = _number(cells[0], 'deformation', line)
        f = _number(cells[1], 'force', line)
        if d < 0:
            raise CalibrationError(f'row {line}: negative deformation {cells[0].strip()}')
        if f < 0:
            raise CalibrationError(f'row {line}: negative force {cells[1].strip()}')
        if deformation and d * length_factor <= deformation[-1]:
            raise CalibrationError(f'row {line}: the deformation does not increase '
                                   f'({cells[0].strip()} after a larger or equal one); '
                                   'give the loading part of the test only, in order')
        deformation.append(d * length_factor)
        force.append(f * force_factor)
    if len(deformation) < MIN_POINTS:
        raise CalibrationError(f'only {len(deformation)} data point(s); a fit needs at '
                               f'least {MIN_POINTS}')
    if max(force) <= 0:
        raise CalibrationError('every force is zero: nothing to fit')
    return CompressionCurve(deformation=np.array(deformation), force=np.array(force),
                            speed=speed if speed is not None else file_speed,
                            path=str(path), sha256=hashlib.sha256(raw).hexdigest())


def write_curve(path: str | Path, curve: CompressionCurve, comment: str = '') -> None:
    """Write ``curve`` as a CSV that ``read_curve`` reads back (mm, N, plate speed in
    mm/s); ``comment`` lines go first, each prefixed with '# '."""
    lines = [f'# {line}' for line in comment.splitlines()]
    if curve.speed is not None:
        lines.append(f'# plate_speed: {curve.speed * 1e3:.9g} mm/s')
    lines.append('deformation_mm,force_N')
    lines += [f'{d * 1e3:.6g},{f:.6g}' for d, f in zip(curve.deformation, curve.force)]
    Path(path).write_text('\n'.join(lines) + '\n', encoding='utf-8')


def _is_text(cell: str) -> bool:
    """A header cell: not a number (not even NaN or inf written out)."""
    try:
        float(cell)
    except ValueError:
        return True
    return False
