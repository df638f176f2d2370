"""The numbers of one recorded run: peaks, stiffness, held/slipped, damage; and its CSV.

Stiffness is fitted on the loading part only: from the grip (both jaws touching) to the
first row at which the grip force reaches ``FORCE_REACHED`` of its largest value before
the lift-off (or the release, or the end). The plateau that follows, the dip and rise
at lift-off and any unloading stay out of the fit. Tangent: least-squares slope over
the loading rows above ``FIT_FROM`` of that force; secant: the chord of the loading
curve, from the grip to the end of loading (compression is measured from the rest
width, and a fruit sagging on the table starts the grip below zero). The rows and
ranges used are in the summary. A stiffness that cannot be estimated is None, and
``stiffness_note`` says why in words. Both need a loading recorded in ``FIT_MIN_ROWS``
samples or more, and the tangent as many above ``FIT_FROM`` of its end force. A
force-mode close (a Grasp goal's) loads the apple within ~8 ms, one or two samples at
the node's default 100 Hz publish_rate; the first sample at ``FORCE_REACHED`` then lies
up to a sample interval after the loading, in the fruit's ringing, and a secant to it
varies with the sampling phase (1.35-2.61 N/mm over the ten phases of one 100 Hz
pick, 2.15 N/mm at 1 kHz): neither is given.

Held and slipped use ``gripper_sim.core.slip.grasp_slipped``, the rule of the node's
Grasp result, but on another measure: a recording has no contact slide (how far the
jaw-contact nodes slid, ``core.slip.ContactSlide``, what ``pick``, ``run`` and the
Grasp action judge on), so a recording is judged on the centroid's drop relative to the
jaws at the end of the hold (``FruitState.slip_distance``, before the release; its
elastic sag included), or a drop. They judge a lifted fruit: a run without a lift-off (a squeeze, or a recording without
``/joint_states``) has no hold, and both are None (n/a, 'not lifted').
"""
from __future__ import annotations

import csv
import math
import textwrap
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from gripper_sim.core.slip import SLIP_TOLERANCE, grasp_slipped
from gripper_sim.recording.analysis.events import Events, both_jaws, find_events
from gripper_sim.recording.analysis.series import (COLUMNS, DAMAGE_PRESSURE_FIELD,
                                                   TimeSeries)
from gripper_sim.recording.errors import RecordingError

#: fraction of the pre-lift peak force at which loading ends (as the grasp's closing)
FORCE_REACHED = 0.97
#: the tangent fit starts at this fraction of the loading's end force
FIT_FROM = 0.2
#: samples a tangent fit needs (a least-squares line through two would be a chord)
FIT_MIN_ROWS = 3
#: the indent of a printed line's continuation lines (under its value)
NOTE_INDENT = ' ' * 23


@dataclass(frozen=True)
class StiffnessFit:
    """The stiffness fit of the loading part.

    Attributes:
        tangent: N/m, least-squares slope of force over compression (None: fewer than
            ``FIT_MIN_ROWS`` rows, or no compression change over them).
        secant: N/m, (force, compression) chord from the grip to the end of loading
            (None: no grip, a loading of fewer than ``FIT_MIN_ROWS`` rows, or no
            compression gained).
        intercept: N, of the tangent line.
        rows: (k,) row indices of the series used by the tangent fit (none without one).
        start, end: rows of the grip and of the end of loading (None: the jaws never
            both touched).
        note: why the tangent or the secant is None, in words (None: both estimated).
    """

    tangent: float | None
    secant: float | None
    intercept: float
    rows: np.ndarray
    start: int | None
    end: int | None
    note: str | None = None

    def ranges(self, series: TimeSeries) -> dict[str, list[float] | None]:
        """[low, high] of force (N), compression (m) and time (s) over the fitted rows."""
        if self.rows.size == 0:
            return {'force_n': None, 'compression_m': None, 'time_s': None}

        def span(name: str) -> list[float]:
            values = series[name][self.rows]
            return [float(values.min()), float(values.max())]
        return {'force_n': span('grip_force_n'), 'compression_m': span('compression_m'),
                'time_s': span('time_s')}


def loading_end(series: TimeSeries, events: Events) -> int | None:
    """Row at which loading ends (module docstring), or None without a grip."""
    if events.grip is None:
        return None
    stop = next((row for row in (events.lift_off, events.release) if row is not None),
                len(series))
    force = series['grip_force_n'][events.grip:max(stop, events.grip + 1)]
    reached = np.flatnonzero(force >= FORCE_REACHED * float(force.max()))
    return int(events.grip + reached[0])


def fit_stiffness(series: TimeSeries, events: Events | None = None) -> StiffnessFit:
    """The tangent and secant stiffness of the loading part (module docstring)."""
    events = find_events(series) if events is None else events
    end = loading_end(series, events)
    empty = np.zeros(0, dtype=int)
    if end is None:
        return StiffnessFit(None, None, 0.0, empty, None, None,
                            'no stiffness: the jaws never both touched the fruit')
    grip = events.grip
    if end - grip + 1 < FIT_MIN_ROWS:
        return StiffnessFit(None, None, 0.0, empty, grip, end,
                            _unresolved_note(series, grip, end))
    force = series['grip_force_n']
    compression = series['compression_m']
    gained = float(compression[end] - compression[grip])
    secant = float(force[end] - force[grip]) / gained if gained > 0 else None
    secant_note = None if secant is not None else \
        'no secant: the fruit gained no compression from the grip to the end of loading'
    span = np.arange(grip, end + 1)
    span = span[both_jaws(series)[span] & (force[span] >= FIT_FROM * force[end])]
    tangent_note = None
    if span.size < FIT_MIN_ROWS:
        tangent_note = (f'no tangent: {span.size} sample(s) of the loading above '
                        f'{FIT_FROM * 100:g} % of its end force, {FIT_MIN_ROWS} needed')
    elif float(np.ptp(compression[span])) <= 0:
        tangent_note = 'no tangent: the compression did not change over the loading'
    note = '; '.join(n for n in (tangent_note, secant_note) if n) or None
    if tangent_note is not None:
        return StiffnessFit(None, secant, 0.0, empty, grip, end, note)
    slope, intercept = np.polyfit(compression[span], force[span], 1)
    return StiffnessFit(float(slope), secant, float(intercept), span, grip, end, note)


def _unresolved_note(series: TimeSeries, grip: int, end: int) -> str:
    """Why a loading recorded in fewer than ``FIT_MIN_ROWS`` samples, rows ``grip`` to
    ``end``, gives no stiffness: it was over within about a sample interval."""
    t = series['time_s']
    interval = float(np.median(np.diff(t))) if len(t) > 1 else float('nan')
    count = end - grip + 1
    when = f't = {t[grip]:.3f} s' if count == 1 else f't = {t[grip]:.3f}-{t[end]:.3f} s'
    return (f'no stiffness: the loading (grip to {FORCE_REACHED * 100:g} % of its force) '
            f'spans {count} sample{"" if count == 1 else "s"}, {when}, one every '
            f'{interval * 1e3:.3g} ms; {FIT_MIN_ROWS} needed, and a loading over within a '
            "sample interval ends in the fruit's ringing: record at a higher publish_rate "
            'or in-node, or load in position mode (a gap command)')


def _finite_or_none(value: float) -> float | None:
    value = float(value)
    return value if math.isfinite(value) else None


def _time_at(series: TimeSeries, row: int | None) -> float | None:
    return None if row is None else float(series['time_s'][row])


def grasp_outcome(summary: dict) -> str:
    """The run's grasp in words: 'held', 'slipped', 'not lifted' (gripped, no lift-off
    recorded: held and slipped are None) or 'not gripped'."""
    if not summary['gripped']:
        return 'not gripped'
    if summary['held'] is None:
        return 'not lifted'
    return 'slipped' if summary['slipped'] else 'held'


def summarize(series: TimeSeries, *, bruise_pressure: float) -> dict[str, Any]:
    """The numbers a person looks at first, from the time series of one run."""
    t = series['time_s']
    force = series['grip_force_n']
    peak = int(np.argmax(force))
    dt = np.diff(t, append=t[-1])
    # the damage estimate's pressure (2D: Hertz, 3D: resolved); older recordings: the
    # peak contact pressure
    pressure = series['damage_pressure_pa'] if series.has_damage_pressure \
        else series['peak_contact_pressure_pa']
    over = pressure > bruise_pressure
    events = find_events(series)
    fit = fit_stiffness(series, events)
    both = both_jaws(series)
    slip = np.abs(series['slip_distance_m'])
    judged = events.held_until(len(series))
    dropped = events.drop is not None
    lifted = events.grip is not None and events.lift_off is not None
    held_slip = float(slip[judged]) if lifted else None
    slipped = grasp_slipped(held_slip, dropped) if lifted else None
    window = np.zeros(len(series), dtype=bool)
    if events.grip is not None:
        window[events.grip:judged + 1] = True
    sliding = window & both & (series['slipping'] > 0)
    left = series['left_force_n']
    right = series['right_force_n']
    bruised_flag = bool(np.any(series['bruised'] > 0))
    if series.has_damage_pressure:
        damage_pressure = _finite_or_none(np.max(series['peak_damage_pressure_pa']))
        bruised = bruised_flag
        note = None
    else:
        damage_pressure = None
        bruised = bruised_flag or bool(np.any(over))
        note = (f'the FruitState messages of this recording have no '
                f"'{DAMAGE_PRESSURE_FIELD}' field (recorded before it was added): the peak "
                'damage pressure is not available; bruised is the recorded flag or the '
                'peak contact pressure above the threshold')
    ranges = fit.ranges(series)
    return {
        'dimension': series.dimension,
        'samples': len(series),
        'duration_s': float(t[-1] - t[0]),
        'start_time_s': float(t[0]),
        'peak_grip_force_n': float(force[peak]),
        'time_of_peak_force_s': float(t[peak]),
        'peak_left_force_n': _finite_or_none(np.nanmax(left)) if np.any(np.isfinite(left))
        else None,
        'peak_right_force_n': _finite_or_none(np.nanmax(right))
        if np.any(np.isfinite(right)) else None,
        'peak_compression_m': float(np.max(series['compression_m'])),
        'peak_compression_ratio': float(np.max(series['compression_ratio'])),
        'compression_at_peak_force_m': float(series['compression_m'][peak]),
        'stiffness_n_per_m': fit.tangent,
        'secant_stiffness_n_per_m': fit.secant,
        'stiffness_fit_force_range_n': ranges['force_n'],
        'stiffness_fit_compression_range_m': ranges['compression_m'],
        'stiffness_fit_time_range_s': ranges['time_s'],
        'stiffness_note': fit.note,
        'peak_contact_pressure_pa': float(np.max(series['peak_contact_pressure_pa'])),
        'peak_max_skin_strain': float(series['max_skin_strain'][
            int(np.argmax(np.abs(series['max_skin_strain'])))]),
        'gripped': events.grip is not None,
        'held': None if slipped is None else not slipped,
        'slipped': slipped,
        'dropped': dropped,
        'held_slip_distance_m': held_slip,
        'max_slip_distance_m': float(np.max(slip)),
        'final_slip_distance_m': float(slip[-1]),
        'slipping_time_s': float(np.sum(dt[sliding])),
        'peak_contact_length_m': float(np.max(series['contact_length_m'])),
        'contact_length_at_peak_force_m': float(series['contact_length_m'][peak]),
        'peak_contact_area_m2': float(np.max(series['contact_area_m2'])),
        'contact_area_at_peak_force_m2': float(series['contact_area_m2'][peak]),
        'bruised': bruised,
        'bruised_fraction': float(np.max(series['bruised_fraction'])),
        'final_bruised_fraction': float(series['bruised_fraction'][-1]),
        'peak_damage_pressure_pa': damage_pressure,
        'peak_flesh_stress_pa': _finite_or_none(np.max(series['peak_flesh_stress_pa']))
        if series.has_damage_pressure else None,
        'crushed': bool(np.any(series['crushed'] > 0)),
        'damage_note': note,
        'bruise_threshold_pa': float(bruise_pressure),
        'time_above_bruise_threshold_s': float(np.sum(dt[over])),
        'first_contact_time_s': _time_at(series, events.grip),
        'event_times_s': {label: float(t[row]) for label, row in events.marked()},
        'slip_threshold_m': SLIP_TOLERANCE,
    }


def held_line(s: dict, fmt: Callable[..., str]) -> str:
    """The printed line on held and slipped, judged on the centroid drop (module
    docstring): n/a, with the reason, for a run not lifted."""
    largest = fmt(s['max_slip_distance_m'], 'mm', 1e3)
    dropped = ', dropped' if s.get('dropped') else ''
    if s.get('held') is None:
        return (f"held: n/a   slipped: n/a ({grasp_outcome(s)}: no lift-off in the "
                f"recording; largest centroid drop {largest}{dropped})")
    return (f"held: {s['held']}   slipped: {s['slipped']} (centroid drop at the end of "
            f"the hold {fmt(s['held_slip_distance_m'], 'mm', 1e3)}, largest {largest}"
            f"{dropped})\n{NOTE_INDENT}judged on the centroid's drop relative to the jaws "
            f"(elastic sag\n{NOTE_INDENT}included): a recording has no contact slide, which "
            f"pick and run judge on")


def describe(summary: dict) -> list[str]:
    """The summary as text lines, as ``analyze`` prints them."""
    s = summary

    def fmt(value: Any, unit: str, scale: float = 1.0, digits: int = 3) -> str:
        if value is None:
            return 'n/a'
        return f'{value * scale:.{digits}f} {unit}'

    three_d = s.get('dimension') == 3
    if three_d:
        area = fmt(s['contact_area_at_peak_force_m2'], 'mm^2', 1e6, 1)
        largest = fmt(s['peak_contact_area_m2'], 'mm^2', 1e6, 1)
        contact = f'contact area:          {area} at peak force (largest {largest})'
    else:
        length = fmt(s['contact_length_at_peak_force_m'], 'mm', 1e3)
        contact = f'contact length:        {length} at peak force'
    damage = (f"damage:                bruised {s['bruised']} "
              f"({100 * s['bruised_fraction']:.1f} % of the "
              f"{'surface' if three_d else 'outline'}), peak damage pressure "
              f"{fmt(s['peak_damage_pressure_pa'], 'kPa', 1e-3, 1)}, crushed {s['crushed']}")
    fit_range = s.get('stiffness_fit_force_range_n')
    fitted = ''
    if fit_range is not None:
        c_lo, c_hi = s['stiffness_fit_compression_range_m']
        t_lo, t_hi = s['stiffness_fit_time_range_s']
        fitted = (f'\n                       fitted on the loading only: {fit_range[0]:.2f}-'
                  f'{fit_range[1]:.2f} N, {c_lo * 1e3:.2f}-{c_hi * 1e3:.2f} mm, '
                  f't = {t_lo:.3f}-{t_hi:.3f} s')
    if s.get('stiffness_note'):
        fitted += ''.join(f'\n{NOTE_INDENT}{line}'
                          for line in textwrap.wrap(s['stiffness_note'], 66))
    events = ', '.join(f'{label} {time:.3f}' for label, time in
                       s.get('event_times_s', {}).items()) or 'no grip'
    return [
        f"analysed {s['samples']} FruitState messages on {s['fruit_state_topic']} "
        f"({s['duration_s']:.3f} s of sim time, {s.get('dimension', 2)}D model)",
        f'phases (s):            {events}',
        f"peak grip force:       {fmt(s['peak_grip_force_n'], 'N')} at "
        f"{fmt(s['time_of_peak_force_s'], 's')}",
        f"peak compression:      {fmt(s['peak_compression_m'], 'mm', 1e3)}",
        f"stiffness:             {fmt(s['stiffness_n_per_m'], 'N/mm', 1e-3)} (tangent), "
        f"{fmt(s['secant_stiffness_n_per_m'], 'N/mm', 1e-3)} (secant){fitted}",
        f"peak contact pressure: {fmt(s['peak_contact_pressure_pa'], 'kPa', 1e-3, 1)}",
        held_line(s, fmt),
        contact,
        damage,
        f"time above bruise threshold (damage pressure): "
        f"{fmt(s['time_above_bruise_threshold_s'], 's')}",
    ] + ([f"note: {s['damage_note']}"] if s.get('damage_note') else [])


def write_csv(series: TimeSeries, path: Path) -> None:
    """``timeseries.csv``: a header of ``COLUMNS`` and one row per sample (empty: NaN).

    Raises:
        RecordingError: the file cannot be written.
    """
    data = np.column_stack([series[c] for c in COLUMNS])
    try:
        with open(path, 'w', newline='', encoding='utf-8') as f:
            writer = csv.writer(f)
            writer.writerow(COLUMNS)
            for row in data:
                writer.writerow([repr(float(v)) if math.isfinite(v) else '' for v in row])
    except OSError as err:
        raise RecordingError(f'cannot write {path}: {err.strerror}') from err
