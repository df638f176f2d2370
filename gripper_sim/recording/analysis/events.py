"""The phases of one recorded run, found from its time series (rows of ``TimeSeries``).

    grip        both jaws touch the fruit for the first time
    lift-off    the gripper starts to rise after the grip (needs the lift joint)
    hold        the lift has reached its top
    release     the gripper comes down again after the hold, or the jaws open
                (the gap grows by more than ``OPENING`` over its smallest value)
    let go      no jaw touches the fruit any more after the release
    drop        between the lift-off (or the grip) and the release, no jaw touches the
                fruit or it slid more than ``DROP_SLIP`` behind them

These are the moments at which the grasp state machine (``gripper_sim.workflows.grasp``)
changes phase, seen from outside: the analysis has only what was recorded.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.vocabulary import DROP_SLIP
from gripper_sim.recording.analysis.series import TimeSeries

#: m the jaws must open beyond their smallest gap to count as a release (a force
#: controller breathes by far less; a release opens them by centimetres)
OPENING = 1e-3
#: m the lift must change by to count as moving (a held lift joint does not move at all;
#: the first step of a ramped start may move it by less than a micrometre)
LIFT_MOVE = 1e-9


@dataclass(frozen=True)
class Events:
    """Row indices (into the run's series) of its phases; None when it did not happen."""

    grip: int | None
    lift_off: int | None
    hold: int | None
    release: int | None
    let_go: int | None
    drop: int | None

    def marked(self) -> list[tuple[str, int]]:
        """(label, row) of the events that happened, in time order (for figures)."""
        named = (('grip', self.grip), ('lift-off', self.lift_off), ('hold', self.hold),
                 ('drop', self.drop), ('release', self.release), ('let go', self.let_go))
        return sorted(((label, row) for label, row in named if row is not None),
                      key=lambda item: item[1])

    def held_until(self, n_rows: int) -> int:
        """The last row at which the grasp is judged: before the release, else the end."""
        end = self.release if self.release is not None else n_rows
        return max(0, end - 1)


def both_jaws(series: TimeSeries) -> np.ndarray:
    """(n,) bool: both jaws touch the fruit."""
    return (series['left_jaw_contact'] > 0) & (series['right_jaw_contact'] > 0)


def any_jaw(series: TimeSeries) -> np.ndarray:
    """(n,) bool: at least one jaw touches the fruit."""
    return (series['left_jaw_contact'] > 0) | (series['right_jaw_contact'] > 0)


def _first(mask: np.ndarray, start: int = 0) -> int | None:
    hits = np.flatnonzero(mask[start:])
    return int(start + hits[0]) if hits.size else None


def find_events(series: TimeSeries) -> Events:
    """The phases of one run (see the module docstring)."""
    n = len(series)
    grip = _first(both_jaws(series))
    if grip is None:
        return Events(None, None, None, None, None, None)
    lift = series['lift_m']
    lift_off = hold = lowering = None
    if series.has_lift:
        lift_off = _first(lift > lift[grip] + LIFT_MOVE, grip)
        if lift_off is not None:
            top = float(np.nanmax(lift[lift_off:]))
            hold = _first(lift >= top - LIFT_MOVE, lift_off)
            lowering = _first(lift < top - LIFT_MOVE, hold) if hold is not None else None
    gap = series['gap_m']
    smallest = np.minimum.accumulate(gap[grip:])
    opening = _first(gap[grip:] > smallest + OPENING)
    opening = None if opening is None else grip + opening
    candidates = [row for row in (lowering, opening) if row is not None]
    release = min(candidates) if candidates else None
    touching = any_jaw(series)
    let_go = _first(~touching, release) if release is not None else None
    judged_from = lift_off if lift_off is not None else grip
    # lost: no jaw touches it, or it slid more than DROP_SLIP behind them (left on the
    # table as the jaws rose): the grasp state machine's 'dropped'
    lost = ~touching | (np.abs(series['slip_distance_m']) > DROP_SLIP)
    drop = _first(lost[:release if release is not None else n], judged_from)
    return Events(grip, lift_off, hold, release, let_go, drop)


def lift_never_moved(series: TimeSeries) -> bool:
    """Whether the run recorded its lift joint and the gripper never rose or sank (by
    more than ``LIFT_MOVE``): a squeeze, not a grasp (a run without the joint: False)."""
    if not series.has_lift:
        return False
    lift = series['lift_m'][np.isfinite(series['lift_m'])]
    return bool(np.ptp(lift) <= LIFT_MOVE)


def key_moments(series: TimeSeries, events: Events) -> list[tuple[str, int]]:
    """(label, row) of the snapshots: start, grip, peak force, and then the hold's end
    (or the drop) and the end of the run; no row twice."""
    moments = [('start', 0)]
    if events.grip is not None:
        moments.append(('grip', events.grip))
    moments.append(('peak force', int(np.argmax(series['grip_force_n']))))
    if events.drop is not None:
        moments.append(('drop', events.drop))
    elif events.release is not None:
        moments.append(('end of hold', events.held_until(len(series))))
    moments.append(('end', len(series) - 1))
    seen: set[int] = set()
    unique = []
    for label, row in sorted(moments, key=lambda item: item[1]):
        if row not in seen:
            seen.add(row)
            unique.append((label, row))
    return unique


def phase_at(events: Events, row: int) -> str:
    """The phase the run is in at ``row``, in words."""
    if events.grip is None or row < events.grip:
        return 'closing'
    if events.drop is not None and row >= events.drop and (
            events.release is None or events.drop < events.release):
        return 'dropped'
    if events.release is not None and row >= events.release:
        return 'released' if events.let_go is not None and row >= events.let_go \
            else 'releasing'
    if events.hold is not None and row >= events.hold:
        return 'holding'
    if events.lift_off is not None and row >= events.lift_off:
        return 'lifting'
    return 'gripping'
