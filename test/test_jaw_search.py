"""The jaw drive's gap search (``core.jaw_drive``: ``record_solve``, ``secant_stiffness``,
``next_gap``) on force-gap laws with a known answer: the search that both ``_drive_jaws``
loops run, each solve replaced by the law."""
import math

import numpy as np
import pytest

from gripper_sim.core import jaw_drive
from gripper_sim.core.jaw_drive import FORCE_TOLERANCE, MAX_GAP_SOLVES

#: the fruit's width (m): both jaws touch below this gap
TOUCH = 0.0635


def hertz(scale: float):
    """force(gap) N of two jaws pressing a sphere: F = scale (TOUCH - gap)^1.5."""
    return lambda gap: scale * max(TOUCH - gap, 0.0) ** 1.5


def linear(stiffness: float):
    """force(gap) N of a fruit that is a linear spring once touched."""
    return lambda gap: stiffness * max(TOUCH - gap, 0.0)


def search(force, first_gap: float, stiffness: float, goal: float, lo: float = 0.05,
           hi: float = 0.08, one_jaw_until: float = TOUCH) -> list[float]:
    """The gaps (m) the drive solves at, from ``first_gap`` with the kept ``stiffness``
    (N/m), until the force is within the tolerance of ``goal`` (N). Above
    ``one_jaw_until`` only one jaw touches; the other's clearance is known."""
    tried, count, gaps = np.empty((MAX_GAP_SOLVES, 3)), 0, []
    gap = first_gap
    for _ in range(MAX_GAP_SOLVES):
        gaps.append(gap)
        both = gap < one_jaw_until
        miss = (force(gap) if both else 0.0) - goal
        count, stiffness, action = jaw_drive.record_solve(tried, count, gap, miss, both,
                                                          stiffness, goal, lo, hi)
        if action == jaw_drive.DONE:
            return gaps
        assert action == jaw_drive.SEARCH
        gap = jaw_drive.next_gap(tried, count, stiffness, goal, lo, hi,
                                 math.inf if both else gap - one_jaw_until)
        assert lo <= gap <= hi
    pytest.fail(f'no gap within the tolerance in {MAX_GAP_SOLVES} solves: {gaps}')


def rows(tried: list) -> tuple[np.ndarray, int]:
    """Solves (gap m, force - goal N, both touch) as ``jaw_drive``'s rows and count."""
    table = np.zeros((MAX_GAP_SOLVES, 3))
    for k, (gap, miss, both) in enumerate(tried):
        table[k] = gap, miss, 1.0 if both else 0.0
    return table, len(tried)


def test_secant_stiffness_is_the_hertz_stiffness_at_the_goal():
    """Two solves on a Hertz law, both far below the goal force: the stiffness kept for
    the next step is -dF/d gap at the goal force itself (a chord of F would be about
    half of it, and a step from it would overshoot)."""
    force = hertz(2.0 / 0.001 ** 1.5)   # 2 N at 1 mm
    goal = 2.0
    g1, g2 = TOUCH - 0.0001, TOUCH - 0.00015
    tried = [(g1, force(g1) - goal, True), (g2, force(g2) - goal, True)]
    stiffness = jaw_drive.secant_stiffness(*rows(tried), 1.0, goal)
    assert stiffness == pytest.approx(1.5 * goal / 0.001, rel=1e-9)
    chord = (force(g2) - force(g1)) / (g1 - g2)
    assert chord < 0.4 * stiffness


def test_secant_stiffness_needs_two_solves_with_both_jaws():
    assert jaw_drive.secant_stiffness(*rows([(0.063, -1.0, True)]), 123.0, 2.0) == 123.0
    assert jaw_drive.secant_stiffness(*rows([(0.064, -2.0, False), (0.063, -1.0, True)]),
                                      123.0, 2.0) == 123.0


@pytest.mark.parametrize('factor', [0.5, 1.0, 2.0])
@pytest.mark.parametrize('first', [TOUCH - 0.0001, TOUCH - 0.001])
@pytest.mark.parametrize('law, stiffness_at_goal, most', [
    # Hertz (2 N at 2 mm): with the exact stiffness one secant step, else a bracket
    (hertz(2.0 / 0.002 ** 1.5), 1.5 * 2.0 / 0.002, 3),
    # a linear (membrane-like) fruit, 1000 N/m, which the F^(2/3) secant does not model
    (linear(1000.0), 1000.0, 5)], ids=['hertz', 'linear'])
def test_the_search_meets_the_goal_in_a_few_solves(law, stiffness_at_goal, most, first,
                                                    factor):
    """From a light touch or a firm one, the kept stiffness exact or off by a factor 2:
    the goal within the tolerance in a few solves (``MAX_GAP_SOLVES`` = 8)."""
    gaps = search(law, first, factor * stiffness_at_goal, 2.0)
    assert abs(law(gaps[-1]) - 2.0) <= FORCE_TOLERANCE * 2.0
    assert len(gaps) <= most
    if factor == 1.0 and most == 3:
        assert len(gaps) == 2


def test_a_jaw_that_does_not_touch_closes_by_its_clearance():
    """One jaw 0.4 mm short of the fruit: the next solve closes that clearance plus the
    approach of the goal force; with the right stiffness that lands on the goal."""
    scale = 2.0 / 0.001 ** 1.5
    goal = 2.0
    stiffness_at_goal = 1.5 * goal / 0.001
    gaps = search(hertz(scale), TOUCH + 0.0004, stiffness_at_goal, goal)
    assert len(gaps) == 2
    assert gaps[1] == pytest.approx(TOUCH - 0.001, abs=1e-9)


def test_the_search_stays_in_the_speed_range_and_stops_at_its_end():
    """A goal the jaws cannot reach within the step's range: the search ends at the
    range's end (the drive keeps the best solve) instead of leaving it."""
    force = linear(1000.0)
    lo = TOUCH - 0.0005        # at most 0.5 N
    tried, count = np.empty((MAX_GAP_SOLVES, 3)), 0
    gap = TOUCH - 0.0002
    for _ in range(MAX_GAP_SOLVES):
        count, stiffness, action = jaw_drive.record_solve(tried, count, gap, force(gap) - 2.0,
                                                          True, 1000.0, 2.0, lo, 0.08)
        if action == jaw_drive.SETTLE:
            break
        gap = jaw_drive.next_gap(tried, count, stiffness, 2.0, lo, 0.08, math.inf)
        if math.isnan(gap) or gap <= lo:
            break
    assert gap == lo
