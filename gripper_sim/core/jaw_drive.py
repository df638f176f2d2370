"""The jaw drive's scalar rules, compiled once and used by both routes that step a grasp.

``GripperKinematics`` (the per-step route, every set-up) and the compiled multi-step
advance (``core.advance_kernels``, the 2D kernel route) call these same functions, so a
grasp driven either way moves its jaws by the same arithmetic:

- ``trapezoid``, ``moved``: one step of the lift and the transport at their speed and
  acceleration limits;
- ``servo_gap``, ``gap_bounds``, ``predicted_gap``: the gap a step starts its solve at;
  ``hertz_stiffness``: the first guess of the stiffness it predicts with (a solid 3D fruit);
- ``damping_rate``, ``grip_miss``, ``contact_stiffness``: the force-mode drive's damping
  (grip force - command = damping x gap rate) in the equation a step's gap meets;
- the gap search when a solved step misses its force goal: ``record_solve`` (keep a
  solve, update the stiffness, decide: done, settle, or search on), ``next_gap`` (with
  ``contact_measure``, ``secant_stiffness``, ``chord_stiffness``), ``nearest_solve``
  (whose end contact set a solve starts from), ``halfway`` (after a failed solve) and
  ``settle_on`` (which solve stands when none met the goal), ``clearance`` (how far a
  jaw that does not touch is from the fruit), ``adapted_stiffness`` (the barrier
  model's steps, which have no search), ``first_gap`` and ``steady`` (with deformable
  fingers, where a step is first solved: the jaws kept where a grip holds still, else
  moved on at their last rate). Both loops that run the search -
  ``core.facade.SimulationFacade._drive_jaws`` and ``core.advance_kernels._drive_jaws`` -
  only solve and call these.

The gap search's solves so far are rows of ``tried`` (MAX_GAP_SOLVES, 3) [gap m, force -
goal N, both jaws touch (1.0/0.0)], the first ``count`` of them filled.
"""
from __future__ import annotations

import math

from numba import njit

#: relative miss of the grip force (of its command, or of the maximum effort) a step
#: accepts before it is solved again at a corrected gap
FORCE_TOLERANCE = 0.005
#: solves of one step at most, the first included (then the best one is solved again)
MAX_GAP_SOLVES = 8
#: what the gap search does after a solve (``record_solve``): solve again at
#: ``next_gap``; the solve met the goal; no gap of this step does better (``settle_on``)
SEARCH, DONE, SETTLE = 0, 1, 2
#: a step solved once at its predicted gap (the barrier model's) whose grip force passes
#: its goal by more than this share of what the step aimed to change raises the drive's
#: stiffness (``adapted_stiffness``)
OVERSHOOT_SHARE = 0.5
#: a step whose grip force changed (either way) by less than this share of what the
#: drive's stiffness predicts for its gap change lowers the stiffness by
#: ``UNDERSHOOT_FACTOR`` (``adapted_stiffness``)
STIFF_SHARE = 0.1
UNDERSHOOT_FACTOR = 0.5
#: N/m, the least stiffness the drive lowers to (a newton over a metre of gap: far below
#: any fruit's contact; it keeps the predicted gap finite)
LOWEST_STIFFNESS = 1.0
#: a held grip force within this share of ``FORCE_TOLERANCE`` of its goal is steady
#: (``steady``): with deformable fingers the step is first solved with the jaws where
#: they are
STEADY_SHARE = 0.5


@njit(cache=True)
def trapezoid(position, rate, target, speed, acceleration, dt):
    """One step of ``dt`` (s) of a move to ``target`` at speed and acceleration limits.

    The rate is the fastest from which the move can still stop at the target decelerating
    at ``acceleration`` after this step (v dt + v^2 / (2 a) = distance), so the move ends
    at a rate of about ``acceleration`` dt whatever dt. Returns the new position (m) and
    the rate over the step (m/s): the step that reaches the target moves at the distance
    left over dt (the jaws' faces move with that velocity).
    """
    distance = target - position
    a = acceleration
    v_stop = math.copysign(
        min(speed, -a * dt + math.sqrt((a * dt) * (a * dt) + 2 * a * abs(distance))), distance)
    rate = rate + min(max(v_stop - rate, -a * dt), a * dt)
    if abs(distance) <= max(abs(rate) * dt, 1e-12):
        return target, distance / dt
    return position + rate * dt, rate


@njit(cache=True)
def moved(gap0, gap, lift, lift_rate, target_lift, lift_speed, lift_acceleration, x, x_rate,
          target_x, x_speed, x_acceleration, dt):
    """The gripper after ``dt`` (s) with the jaws moved from ``gap0`` to ``gap`` (m) and
    the lift and the transport advanced by their ``trapezoid`` moves (m, m/s, m/s^2):
    (gap rate m/s, lift m, lift rate m/s, x m, x rate m/s)."""
    rate = (gap - gap0) / dt
    lift, lift_rate = trapezoid(lift, lift_rate, target_lift, lift_speed, lift_acceleration,
                                dt)
    if x != target_x or x_rate != 0.0:
        x, x_rate = trapezoid(x, x_rate, target_x, x_speed, x_acceleration, dt)
    else:
        x_rate = 0.0
    return rate, lift, lift_rate, x, x_rate


@njit(cache=True)
def servo_gap(gap, target_gap, speed, min_gap, max_gap, dt):
    """m, the gap after ``dt`` (s) of the position servo's move from ``gap`` towards
    ``target_gap`` at ``speed`` (m/s), before any force limit, within the jaws' stroke
    [``min_gap``, ``max_gap``] (m)."""
    travel = speed * dt
    return min(max(target_gap, gap - travel, min_gap), gap + travel, max_gap)


@njit(cache=True)
def gap_bounds(gap, speed, max_speed, gripping, min_gap, max_gap, dt):
    """(smallest, largest) gap (m) the drive can reach from ``gap`` in ``dt`` (s): it
    closes at the commanded ``speed`` until it grips (``gripping``: force mode with a
    force measured); then it closes and opens at up to its own top speed ``max_speed``
    (m/s), as a force-controlled drive does. Never past the jaws' stroke [``min_gap``,
    ``max_gap``] (m): ``min_gap`` is the stop where the fingers' rigid parts meet."""
    fastest = max(speed, max_speed)
    closing = fastest if gripping else speed
    return max(gap - closing * dt, min_gap), min(gap + fastest * dt, max_gap)


@njit(cache=True)
def damping_rate(force_mode, measured_force, damping, dt):
    """N/m, the drive's damping per metre of gap change within a step of ``dt`` (s):
    ``damping`` / dt (``damping`` N s/m) while it holds a grip in force mode (a force
    measured, as in ``gap_bounds``), else 0 (it closes at the commanded speed, or it is a
    position servo).

    A force-controlled jaw is a motor with a force limit and damping (MuJoCo's slide
    joint with a motor and damping): grip force - command = damping x gap rate, solved
    at the step's end (implicit Euler). An ideal force source (damping 0) follows every
    vibration of the fruit without taking energy out of it: an undamped fruit rings for as
    long as the integrator lets it, and the slip after a lift moves with dt (README, Jaw
    drive).
    """
    return damping / dt if force_mode and measured_force > 0.0 else 0.0


@njit(cache=True)
def grip_miss(left_n, right_n, goal, gap, start_gap, rate):
    """N, how far a solve at ``gap`` (m) misses the drive's equation: the grip force (the
    mean of the jaws' normal forces ``left_n``, ``right_n`` N if both touch, else 0) - the
    ``goal`` (N) - ``rate`` (``damping_rate``, N/m) x (gap - ``start_gap``, m)."""
    force = 0.5 * (left_n + right_n) if left_n > 0 and right_n > 0 else 0.0
    return force - goal - rate * (gap - start_gap)


@njit(cache=True)
def steady(force, goal):
    """Whether a grip force (N, 0 unless both jaws touch) holds within ``STEADY_SHARE`` x
    ``FORCE_TOLERANCE`` of its ``goal`` (N). A gap search meets the goal within
    ``FORCE_TOLERANCE`` at every step; a first solve predicted to close even that miss
    (``predicted_gap``) moves the jaws on what is mostly the fingers' own ringing: with
    deformable fingers, whose light nodes carry each step's motion into the next, the
    gap then flips direction every other step within the tolerance (the 2D Fin Ray held
    at 4 N: 140 of 199 steps, 0.9 um a step) and each solve starts from a worse
    prediction (2.6 Newton iterations a step instead of 1.3)."""
    return force > 0.0 and abs(force - goal) <= STEADY_SHARE * FORCE_TOLERANCE * goal


@njit(cache=True)
def first_gap(start_gap, gap_rate, force, goal, stiffness, lo, hi, dt):
    """m, the gap a force-mode step with deformable fingers is first solved at, from
    the gap it starts at ``start_gap`` (m), the last step's gap rate ``gap_rate`` (m/s),
    the grip force ``force`` (N, > 0: both jaws touch) and its ``goal`` (N), the slope
    of the force's miss in the gap ``stiffness`` (N/m, the drive's damping included),
    within [lo, hi] (m) and a step ``dt`` (s):

    - ``start_gap`` where the grip holds still: its force ``steady`` and the last step's
      gap change worth no more than that same band of force at ``stiffness``;
    - else the gap moved on at the last step's rate, corrected by the force's miss at
      ``stiffness``: where the fruit and the fingers ring (a squeeze, the start of a
      lift), the force at a fixed gap moves from step to step, and the gap a search
      settled on moves smoothly with it (the 2D Fin Ray at 4 N: a search of two solves at
      nearly every squeeze step before, from the gap where it started or predicted from
      the force alone).
    """
    band = STEADY_SHARE * FORCE_TOLERANCE * goal
    move = gap_rate * dt
    if steady(force, goal) and abs(move) * stiffness <= band:
        return start_gap
    return min(max(start_gap + move + (force - goal) / stiffness, lo), hi)


@njit(cache=True)
def contact_stiffness(step_stiffness, rate, previous):
    """N/m, the contact's -d force / d gap from a gap search's ``step_stiffness`` (the
    slope of ``grip_miss`` in the gap, N/m) less the drive's ``rate`` (N/m); ``previous``
    when the difference is not positive (the damping dominates the secant)."""
    stiffness = step_stiffness - rate
    return stiffness if stiffness > 0.0 else previous


@njit(cache=True)
def predicted_gap(force_mode, gap, target_gap, target_force, speed, stiffness, max_effort,
                  grip_force, both_in_contact, clearance, lo, hi, min_gap, max_gap, dt,
                  damped=0.0):
    """m, the gap a step is first solved at (``GripperKinematics.advance``): where the
    grip force (N, measured at the step's start) would meet its target (force mode, with
    the drive's damping ``damped`` N/m, ``damping_rate``) or the effort limit (position
    mode) at ``stiffness`` (N/m), within [lo, hi]."""
    if force_mode:
        if grip_force <= 0.0 or not both_in_contact:
            landing = (max(clearance, 0.0) + target_force / stiffness) / dt
            rate = -min(speed, landing)
        else:
            rate = -(target_force - grip_force) / ((stiffness + damped) * dt)
    else:
        rate = (servo_gap(gap, target_gap, speed, min_gap, max_gap, dt) - gap) / dt
        if rate < 0 and both_in_contact and grip_force > 0:
            rate = max(rate, -(max_effort - grip_force) / (stiffness * dt))
    return min(max(gap + rate * dt, lo), hi)


@njit(cache=True)
def hertz_stiffness(modulus, force):
    """N/m, -d grip force / d gap of a fruit held at ``force`` (N) between two flat jaws,
    each contact Hertz's F = K delta^(3/2) with K = ``modulus`` (N/m^1.5; a sphere of
    radius R: 4/3 E / (1 - nu^2) sqrt(R), Johnson 1985, Contact Mechanics, eq. 4.22) and
    the gap closing by twice delta: 3/4 K^(2/3) F^(1/3)."""
    return 0.75 * modulus ** (2.0 / 3.0) * max(force, 0.0) ** (1.0 / 3.0)


@njit(cache=True)
def contact_measure(force):
    """N^(2/3), the grip force in the variable that the jaw search treats as linear in
    the gap: Hertz's law F ~ delta^(3/2) (Johnson 1985, Contact Mechanics, eq. 4.22)
    makes F^(2/3) linear in the approach delta. Secant steps on it neither overshoot
    from a first light touch (a chord of F there is far too soft) nor undershoot much on
    a membrane-dominated fruit (F closer to linear in delta)."""
    return max(force, 0.0) ** (2.0 / 3.0)


@njit(cache=True)
def measure_slope(stiffness, goal):
    """N^(2/3)/m, d F^(2/3) / d(-gap) of the Hertz law whose stiffness -dF/d gap at the
    force ``goal`` (N) is ``stiffness`` (N/m)."""
    return stiffness / (1.5 * max(goal, 1e-12) ** (1.0 / 3.0))


@njit(cache=True)
def secant_stiffness(tried, count, stiffness, goal):
    """N/m, -d force / d gap at the force ``goal`` (N), from the last two solves of a
    step if both jaws held the fruit in each (the secant of F^(2/3),
    ``contact_measure``), else ``stiffness``."""
    if count < 2:
        return stiffness
    g1, m1, both1 = tried[count - 2, 0], tried[count - 2, 1], tried[count - 2, 2]
    g2, m2, both2 = tried[count - 1, 0], tried[count - 1, 1], tried[count - 1, 2]
    if not (both1 > 0 and both2 > 0 and g1 != g2):
        return stiffness
    return chord_stiffness(g1, goal + m1, g2, goal + m2, goal, stiffness)


@njit(cache=True)
def chord_stiffness(gap_a, force_a, gap_b, force_b, goal, otherwise):
    """N/m, -d force / d gap at the force ``goal`` (N) from the chord of F^(2/3)
    (``contact_measure``) between two solves (gap m, grip force N, gaps unequal);
    ``otherwise`` where the force does not fall as the gap grows."""
    slope = (contact_measure(force_a) - contact_measure(force_b)) / (gap_b - gap_a)
    return 1.5 * goal ** (1.0 / 3.0) * slope if slope > 0 else otherwise


@njit(cache=True)
def adapted_stiffness(stiffness, goal, gap_before, force_before, gap_after, force_after):
    """N/m, the drive's stiffness after a step solved once at its predicted gap (the
    barrier model's: no gap search corrects it within the step, ``predicted_gap``), from
    the step's start and end (gap m, grip force N, 0 unless both jaws touched) and its
    force ``goal`` (N). Only steps that aimed to change the force by more than the
    drive's ``FORCE_TOLERANCE`` of the goal teach it anything (smaller aims are the size
    of the fruit's own ringing):

    - a step that passed the goal by more than ``OVERSHOOT_SHARE`` of its aim (``goal -
      force_before``) raises it to the secant of F^(2/3) (``contact_measure``) between the
      step's start and end: a prediction at less than half the contact's stiffness swings
      wider at every step;
    - a step whose secant of F^(2/3) at the goal (``chord_stiffness``'s) is within
      ``STIFF_SHARE`` of the stiffness either way (the force barely moved with the gap)
      lowers it by ``UNDERSHOOT_FACTOR``. A stiffness too high only closes a miss over
      more steps, but one many times too high barely moves the jaws: single steps in
      which the fruit's own motion, not the gap, changed the force by more than the
      step aimed at raised the 3D apple's to 2500 times its contact's and left its grip
      5 % low for seconds. Only a far miss lowers it: closed towards 60 N, the 2D apple
      answers at a third of its stiffness at 60 N while the jaws still move in, and
      lowered there its drive passed 63 N. A force that moved the other way by more
      (the fruit's own motion: a lift starting) does not lower it either: lowered there,
      the 2D shell apple held at 20 N swung between 17.1 and 21.6 N in its lift (19.0 to
      20.2 N now).
    """
    aim = goal - force_before
    if (force_before <= 0.0 or force_after <= 0.0 or gap_after == gap_before
            or abs(aim) <= FORCE_TOLERANCE * goal):
        return stiffness
    over = force_after - goal
    if aim * over > 0.0 and abs(over) > OVERSHOOT_SHARE * abs(aim):
        return max(stiffness, chord_stiffness(gap_before, force_before, gap_after,
                                              force_after, goal, stiffness))
    slope = (contact_measure(force_after) - contact_measure(force_before)) / (gap_before
                                                                             - gap_after)
    if 1.5 * goal ** (1.0 / 3.0) * abs(slope) < STIFF_SHARE * stiffness:
        return max(UNDERSHOOT_FACTOR * stiffness, LOWEST_STIFFNESS)
    return stiffness


@njit(cache=True)
def _row_before(tried, a, b):
    """Whether row a of ``tried`` sorts before row b (gap, then miss, then both)."""
    for c in range(3):
        if tried[a, c] != tried[b, c]:
            return tried[a, c] < tried[b, c]
    return False


@njit(cache=True)
def next_gap(tried, count, stiffness, goal, lo, hi, clearance):
    """m, the next gap to solve a step at so that the force meets ``goal`` (N), from the
    solves so far (the force falls as the gap grows), within [lo, hi]: a secant step on
    F^(2/3) (``contact_measure``; its slope from ``stiffness``, N/m at the goal) from the
    last solve if it stays inside the bracket the solves so far leave, else the end of
    the range not yet tried, else the bracket's interpolation (F^(2/3) linear between its
    ends) or middle; NaN when the bracket has closed. After a solve in which a jaw did
    not touch, the step closes the gap by ``clearance`` (m, how far that jaw is from the
    fruit; inf if unknown) plus the approach that gives the goal."""
    low = -1    # the widest solve with too much force: the gap must grow from it
    high = -1   # the narrowest solve with too little force
    for k in range(count):
        if tried[k, 1] > 0:
            if low < 0 or _row_before(tried, low, k):
                low = k
        elif high < 0 or _row_before(tried, k, high):
            high = k
    low_gap = tried[low, 0] if low >= 0 else lo
    high_gap = tried[high, 0] if high >= 0 else hi
    if high_gap - low_gap <= 1e-12:
        return math.nan
    slope = measure_slope(stiffness, goal)
    target = contact_measure(goal)
    gap, miss, both = tried[count - 1, 0], tried[count - 1, 1], tried[count - 1, 2] > 0
    if both:
        guess = gap + (contact_measure(goal + miss) - target) / slope
    elif math.isfinite(clearance):
        guess = gap - clearance - target / slope
    else:
        guess = gap + miss / stiffness
    if low_gap < guess < high_gap:
        return guess
    if guess <= low_gap and low < 0:
        return lo
    if guess >= high_gap and high < 0:
        return hi
    if low >= 0 and high >= 0 and tried[low, 2] > 0 and tried[high, 2] > 0:
        h_low = contact_measure(goal + tried[low, 1])
        h_high = contact_measure(goal + tried[high, 1])
        fraction = (h_low - target) / (h_low - h_high)
        if 0.05 < fraction < 0.95:
            return low_gap + fraction * (high_gap - low_gap)
    return 0.5 * (low_gap + high_gap)


@njit(cache=True)
def record_solve(tried, count, gap, miss, both, stiffness, goal, lo, hi):
    """Keep a solve as row ``count`` of ``tried`` and decide what the search does next.

    Args:
        gap: m, the gap the step was solved at.  miss: N, its grip force - ``goal``.
        both: whether both jaws held the fruit.  stiffness: N/m, the search's so far.
        goal: N.  lo, hi: m, the gaps this step's speed limit allows.

    Returns:
        (count + 1, the stiffness after this solve (``secant_stiffness``), SEARCH, DONE
        or SETTLE: at a limit of the range with the force on the wrong side).
    """
    tried[count, 0] = gap
    tried[count, 1] = miss
    tried[count, 2] = 1.0 if both else 0.0
    count += 1
    stiffness = secant_stiffness(tried, count, stiffness, goal)
    if abs(miss) <= FORCE_TOLERANCE * goal:
        return count, stiffness, DONE
    if (miss < 0 and gap <= lo + 1e-12) or (miss > 0 and gap >= hi - 1e-12):
        return count, stiffness, SETTLE
    return count, stiffness, SEARCH


@njit(cache=True)
def nearest_solve(tried, count, gap):
    """Index of the solve in ``tried`` whose gap is nearest to ``gap`` (m; the first of
    equals): the next solve starts from its end contact set; -1 if none (or ``gap`` is
    NaN: the step's first solve starts from the step's start)."""
    if math.isnan(gap) or count == 0:
        return -1
    best = 0
    for k in range(1, count):
        if abs(tried[k, 0] - gap) < abs(tried[best, 0] - gap):
            best = k
    return best


@njit(cache=True)
def halfway(tried, count, gap):
    """m, the gap to try after a solve at ``gap`` failed (a corrected gap the solver
    cannot follow): halfway back to the last solve that worked (``count`` > 0)."""
    return 0.5 * (gap + tried[count - 1, 0])


@njit(cache=True)
def settle_on(tried, count, gap):
    """When no solve met the goal: the index of the solve with the smallest miss (the
    first of equals) to solve again at, or -1 if the state is already that solve's (it
    was the last, at ``gap``, m; NaN after the state was put back)."""
    best = 0
    for k in range(1, count):
        if abs(tried[k, 1]) < abs(tried[best, 1]):
            best = k
    return best if best != count - 1 or gap != tried[best, 0] else -1


@njit(cache=True)
def clearance(x_min, x_max, centre, gap, left_touches, right_touches):
    """m, the distance along x from the fruit, which spans [x_min, x_max] (m), to the
    nearest flat jaw face that does not touch it, the faces at ``centre`` -/+ ``gap`` / 2
    (m); inf when both touch."""
    result = math.inf
    if not left_touches:
        result = min(result, x_min - (centre - 0.5 * gap))
    if not right_touches:
        result = min(result, (centre + 0.5 * gap) - x_max)
    return result
