"""The compiled multi-step advance of the 2D kernel route: many steps in one numba call.

``advance`` runs steps of the whole-step kernel (``kernels.substep``) with the jaw drive
around each one, as ``SimulationFacade._drive_jaws`` does (the prediction of
``GripperKinematics.advance``, then the gap search on the force goal, with the rules of
``core.jaw_drive``), keeps what the per-step route's measures keep from step to step (the
slip reference, the damage tracker's cover and peaks) and the run's peaks
(``core.peaks.RunPeaks``), and stops after the first step at which a stop rule fires
(``core.multistep.StopRules``: a grasp machine has something to decide) or before a step
it cannot do itself (a solve the kernel cannot do, or whose first solve fails: the
per-step route then halves it). The caller (``core.multistep``) builds the StepResult
of the last step only.

State arrays (updated in place): the grip (G_SIZE,) [the ``GripperState`` fields in the
G_* order; mode 1.0 = force, 0.0 = position] and ``run`` (R_SIZE,) [time s, each jaw's
closing force N at the last step, slip reference m (NaN: none yet), held slip m, the
damage tracker's peak pressure Pa, peak flesh stress Pa, crushed (1.0/0.0), then the
counts of the call: steps, Newton iterations of its last step, gap solves, Newton
iterations of all its steps; then a pick-and-place's slide along the jaws m, its largest,
the largest slip distance m, each as it was before the last step, and the time of the
step before the last s (see ``S_SLIDE``)].
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gripper_sim.core import jaw_drive
from gripper_sim.core.damage import TRESCA_OVER_P0
from gripper_sim.core.kernels import (KI_SURFACE, M_ANY_LEFT, M_ANY_RIGHT, M_CZ, M_LEFT_FX,
                                      M_LEFT_N, M_RIGHT_FX, M_RIGHT_N, M_WIDTH, OK, UNSUPPORTED,
                                      _packed1, borrowed, substep)
from gripper_sim.core.measures import numpy_sum

#: the grip's slots (``GripperState``'s fields)
(G_GAP, G_GAP_RATE, G_LIFT, G_LIFT_RATE, G_MODE, G_TARGET_GAP, G_TARGET_FORCE, G_SPEED,
 G_TARGET_LIFT, G_LIFT_SPEED, G_STIFFNESS, G_MEASURED_FORCE, G_MEASURED_GAP, G_X, G_X_RATE,
 G_TARGET_X, G_X_SPEED, G_MAX_EFFORT, G_SIZE) = range(19)
#: ``kin`` (K_SIZE,): the kinematics' constants [max gap m, max speed m/s, lift and
#: transport accelerations m/s^2, dt s, fruit rest width m, plain jaws (1/0), the flat
#: jaws' clearance applies (1/0), the fruit has flesh in the kernel (1/0), bruise
#: pressure Pa, failure stress Pa, failure strain (NaN: none), the force-mode drive's
#: damping N s/m, the jaws' stop (their smallest gap) m]
(K_MAX_GAP, K_MAX_SPEED, K_LIFT_ACC, K_X_ACC, K_DT, K_REST_WIDTH, K_PLAIN, K_CLEARANCE,
 K_FLESH, K_BRUISE, K_FAILURE_STRESS, K_FAILURE_STRAIN, K_DAMPING, K_MIN_GAP,
 K_SIZE) = range(15)
#: ``run`` slots (module doc)
(R_TIME, R_JAW_LEFT, R_JAW_RIGHT, R_SLIP_REF, R_HELD_SLIP, R_PEAK_PRESSURE, R_PEAK_STRESS,
 R_CRUSHED, R_STEPS, R_ITERATIONS, R_SOLVES, R_NEWTON, R_SLIDE, R_MAX_SLIP, R_MAX_DROP,
 R_PREVIOUS_TIME, R_SIZE) = range(17)
#: ``rules`` slots (``multistep.StopRules``): stop after a step where both jaws touch
#: and the grip force is at least S_FORCE N; the time is past S_DEADLINE s; S_GAP_CLOSED
#: (1/0) and the jaws are at their stop (K_MIN_GAP); the time since S_PHASE_START is at
#: least S_ELAPSED s; S_LIFTED and S_MOVED (1/0) and the lift, the transport (each asked
#: for) reached its target at rest; the gap is within 1e-9 m of S_GAP_AT (NaN: off);
#: S_DROP (1/0) and no jaw touches or the slip exceeds S_DROP_SLIP m; S_BRUISE (1/0) and
#: the fruit is bruised where a jaw or the table presses; S_DAMAGED (1/0) and it is
#: bruised or crushed; the time reached S_END s; S_MAX_STEPS steps run; the slide
#: exceeds S_SLIDE_LIMIT m. S_SLIDE (1/0): the slide of the fruit along the jaws is
#: integrated (``scenario.PickAndPlace._slide``) and the largest slip distance kept
(S_FORCE, S_DEADLINE, S_GAP_CLOSED, S_PHASE_START, S_ELAPSED, S_LIFTED, S_MOVED, S_GAP_AT,
 S_DROP, S_DROP_SLIP, S_BRUISE, S_DAMAGED, S_END, S_MAX_STEPS, S_SLIDE, S_SLIDE_LIMIT,
 S_SIZE) = range(17)
#: ``peaks`` (P_SIZE,): the run's largest grip force N, compression m, jaw and table
#: contact pressure Pa over the steps of the call
PEAK_GRIP, PEAK_COMPRESSION, PEAK_JAW, PEAK_TABLE, PEAK_SIZE = range(5)

#: ``advance`` status: a stop rule fired after the last step; the next step needs the
#: per-step route (no step of it was kept)
STOPPED, NEEDS_STEP = 0, 1


@njit(cache=True)
def _moved(grip, dt, gap, grip_force, kin, new):
    """``GripperKinematics.moved``: ``new`` (G_SIZE,) the grip after ``dt`` with the jaws
    at ``gap`` (m), the lift and transport advanced; ``grip_force`` N measured at ``grip``."""
    new[:] = grip
    new[G_GAP] = gap
    (new[G_GAP_RATE], new[G_LIFT], new[G_LIFT_RATE], new[G_X],
     new[G_X_RATE]) = jaw_drive.moved(
        grip[G_GAP], gap, grip[G_LIFT], grip[G_LIFT_RATE], grip[G_TARGET_LIFT],
        grip[G_LIFT_SPEED], kin[K_LIFT_ACC], grip[G_X], grip[G_X_RATE], grip[G_TARGET_X],
        grip[G_X_SPEED], kin[K_X_ACC], dt)
    new[G_MEASURED_FORCE] = grip_force
    new[G_MEASURED_GAP] = grip[G_GAP]


@njit(cache=True)
def _bounds(grip, kin, dt):
    """``GripperKinematics.gap_bounds``."""
    return jaw_drive.gap_bounds(grip[G_GAP], grip[G_SPEED], kin[K_MAX_SPEED],
                                grip[G_MODE] > 0 and grip[G_MEASURED_FORCE] > 0.0,
                                kin[K_MIN_GAP], kin[K_MAX_GAP], dt)


@njit(cache=True)
def _damping_rate(grip, kin, dt):
    """``GripperKinematics.damping_rate``."""
    return jaw_drive.damping_rate(grip[G_MODE] > 0, grip[G_MEASURED_FORCE], kin[K_DAMPING],
                                  dt)


@njit(cache=True)
def _clearance(x, grip, left_n, right_n, kin):
    """``SimulationFacade._jaw_clearance`` of positions x (n, 2) m, the grip and the jaw
    forces N."""
    if (left_n > 0 and right_n > 0) or kin[K_CLEARANCE] == 0.0:
        return math.inf
    return jaw_drive.clearance(np.min(x[:, 0]), np.max(x[:, 0]), grip[G_X], grip[G_GAP],
                               left_n > 0, right_n > 0)


@njit(cache=True)
def _solve(x, v, c_int, c_float, grip, new, gap, jaw_left, jaw_right, kin, x_out, v_out,
           forces_out, fixed, outs, dmg, pad, scratch):
    """One solve of the step from x, v (n, 2) and the contact set (c_int (3, n) [obstacle,
    mode, secondary], c_float (3, n) [normal force, bounce speed, secondary bounce],
    updated in place) with the jaws at ``gap`` (m; NaN: the kinematics' prediction), as
    ``SimulationFacade._solve_at``; ``new`` receives the grip at the end. Returns the
    substep's status."""
    dt = kin[K_DT]
    force = 0.5 * (jaw_left + jaw_right)
    if math.isnan(gap):
        lo, hi = _bounds(grip, kin, dt)
        gap = jaw_drive.predicted_gap(
            grip[G_MODE] > 0, grip[G_GAP], grip[G_TARGET_GAP], grip[G_TARGET_FORCE],
            grip[G_SPEED], grip[G_STIFFNESS], grip[G_MAX_EFFORT], force,
            jaw_left > 0 and jaw_right > 0, _clearance(x, grip, jaw_left, jaw_right, kin),
            lo, hi, kin[K_MIN_GAP], kin[K_MAX_GAP], dt, _damping_rate(grip, kin, dt))
    _moved(grip, dt, gap, force, kin, new)
    face_par, face_dyn, fconst, iconst, layout, fpar, ipar = fixed
    history, out, normal_out, pressure_out, meas_out, counts = outs
    d_face, d_rest, d_par, covered_in, covered_out, d_pressure, patches, d_out = dmg
    pad_k, pad_scalars, pad_forces, pad_normal, pad_holder, pad_side = pad
    work, iwork, bwork, storage, stress = scratch
    return substep(
        x, v, c_int[0], c_int[1], c_float[0], c_float[1], c_int[2], c_float[2], face_par,
        face_dyn, (grip[G_GAP], grip[G_LIFT], grip[G_X], new[G_GAP], new[G_LIFT], new[G_X],
                   new[G_GAP_RATE], new[G_LIFT_RATE], new[G_X_RATE]),
        fconst, iconst, layout, fpar, ipar, x_out, v_out, forces_out, history, out,
        normal_out, pressure_out, meas_out, counts, d_face, d_rest, d_par, covered_in,
        covered_out, d_pressure, patches, d_out, pad_k, pad_scalars, pad_forces, pad_normal,
        pad_holder, pad_side, work, iwork, bwork, storage, stress)


@njit(cache=True)
def _holder(c_int, pad_holder, padded, i):
    """The obstacle holding node i: its hard contact's, else its pad's face (-1: none), as
    ``Simulation.contact_forces_and_holders``."""
    if c_int[0, i] >= 0 or not padded:
        return c_int[0, i]
    return pad_holder[i]


@njit(cache=True)
def _drive_jaws(x, v, start_int, start_float, c_int, c_float, ends_int, ends_float, grip, new,
                jaw, kin, x_out, v_out, forces_out, fixed, outs, dmg, pad, scratch, tried):
    """One step whose end meets the jaw drive's force goal, as
    ``SimulationFacade._drive_jaws``, from x, v and the contact set ``start_*`` at the
    step's start (left alone); the end contact set in ``c_*``, the end grip in ``new``,
    the outputs in the substep's. Returns (status, Newton iterations, solves): status OK,
    or not OK when the step must go to the per-step route."""
    dt = kin[K_DT]
    out = outs[1]
    if grip[G_MODE] > 0:
        lo, hi = _bounds(grip, kin, dt)
        goal = grip[G_TARGET_FORCE]
    else:
        lo, hi = _bounds(grip, kin, dt)
        servo = jaw_drive.servo_gap(grip[G_GAP], grip[G_TARGET_GAP], grip[G_SPEED],
                                    kin[K_MIN_GAP], kin[K_MAX_GAP], dt)
        goal, lo, hi = grip[G_MAX_EFFORT], servo, max(servo, hi)
    start_gap = grip[G_GAP]
    damped = _damping_rate(grip, kin, dt)
    stiffness = grip[G_STIFFNESS] + damped
    iterations = 0
    solves = 0
    count = 0
    gap = math.nan
    for _ in range(jaw_drive.MAX_GAP_SOLVES):
        near = jaw_drive.nearest_solve(tried, count, gap)
        if near < 0:
            c_int[:] = start_int
            c_float[:] = start_float
        else:
            c_int[:] = ends_int[near]
            c_float[:] = ends_float[near]
        solves += 1
        status = _solve(x, v, c_int, c_float, grip, new, gap, jaw[0], jaw[1], kin, x_out,
                        v_out, forces_out, fixed, outs, dmg, pad, scratch)
        if status != OK:
            if count == 0 or status == UNSUPPORTED:
                return status, iterations, solves
            gap = jaw_drive.halfway(tried, count, gap)
            continue
        iterations += np.int64(out[0])
        left_n, right_n = out[2], out[3]
        both = left_n > 0 and right_n > 0
        gap = new[G_GAP]
        miss = jaw_drive.grip_miss(left_n, right_n, goal, gap, start_gap, damped)
        ends_int[count] = c_int
        ends_float[count] = c_float
        count, stiffness, action = jaw_drive.record_solve(tried, count, gap, miss, both,
                                                          stiffness, goal, lo, hi)
        if action == jaw_drive.DONE:
            new[G_STIFFNESS] = jaw_drive.contact_stiffness(stiffness, damped,
                                                           grip[G_STIFFNESS])
            return OK, iterations, solves
        if action == jaw_drive.SETTLE:
            break
        clearance = math.inf if both else _clearance(x_out, new, left_n, right_n, kin)
        gap = jaw_drive.next_gap(tried, count, stiffness, goal, lo, hi, clearance)
        if math.isnan(gap):
            break
    best = jaw_drive.settle_on(tried, count, gap)
    if best >= 0:
        c_int[:] = ends_int[best]
        c_float[:] = ends_float[best]
        solves += 1
        status = _solve(x, v, c_int, c_float, grip, new, tried[best, 0], jaw[0], jaw[1], kin,
                        x_out, v_out, forces_out, fixed, outs, dmg, pad, scratch)
        if status != OK:
            return status, iterations, solves
        iterations += np.int64(out[0])
    new[G_STIFFNESS] = jaw_drive.contact_stiffness(stiffness, damped, grip[G_STIFFNESS])
    return OK, iterations, solves


@njit(cache=True)
def advance(x, v, c_int, c_float, forces, grip, run, kin, rules, peaks, site, fixed, outs,
            dmg, pad, scratch, work_int, work_float, ends_int, ends_float, x_out, v_out):
    """Steps until a stop rule fires after one (STOPPED) or the next step needs the
    per-step route (NEEDS_STEP).

    Args:
        x, v: (n, 2) positions m and velocities m/s; c_int (3, n) int64 [obstacle, mode,
            secondary] and c_float (3, n) [normal force, bounce speed, secondary bounce]
            the contact set; forces (n, 2) N the contact forces: the state, updated at
            every step kept.
        grip, run: the grip and the run's numbers (module doc), updated likewise.
        kin: (K_SIZE,) the constants (K_*).  rules: (S_SIZE,) the stop rules (S_*).
        peaks: (PEAK_SIZE,) raised to the peaks of the steps kept.
        site: (n_obstacles + 1,) int64, per obstacle + 1 (0: none) 1 a jaw's face, 2 the
            table, else 0 (``peaks.contact_pressures``).
        fixed, outs, dmg, pad, scratch: ``kernels.substep``'s other arguments: (face_par,
            face_dyn, fconst, iconst, layout, fpar, ipar), (history, out, normal_out,
            pressure_out, meas_out, counts), its damage arguments (covered_in is the
            tracker's cover, updated at every step kept), its pad arguments and its
            scratch space; after the call they hold the last solve's outputs.
        work_int, work_float, ends_int, ends_float, x_out, v_out: scratch: the contact set
            of a solve (3, n), those at the end of each solve of a step
            (MAX_GAP_SOLVES, 3, n), the solve's end state (n, 2).

    Returns:
        STOPPED or NEEDS_STEP; ``run`` counts the steps kept, the last one's Newton
        iterations and the gap solves of all.
    """
    b = borrowed  # the caller keeps every array alive for the call
    fixed = (b(fixed[0]), b(fixed[1]), b(fixed[2]), b(fixed[3]), b(fixed[4]), b(fixed[5]),
             b(fixed[6]))
    outs = (b(outs[0]), b(outs[1]), b(outs[2]), b(outs[3]), b(outs[4]), b(outs[5]))
    dmg = (b(dmg[0]), b(dmg[1]), b(dmg[2]), b(dmg[3]), b(dmg[4]), b(dmg[5]), b(dmg[6]),
           b(dmg[7]))
    pad = (b(pad[0]), b(pad[1]), b(pad[2]), b(pad[3]), b(pad[4]), b(pad[5]))
    storage = scratch[3]
    scratch = (b(scratch[0]), b(scratch[1]), b(scratch[2]),
               (b(storage[0]), b(storage[1]), b(storage[2]), b(storage[3]), b(storage[4])),
               b(scratch[4]))
    x, v, c_int, c_float, forces = b(x), b(v), b(c_int), b(c_float), b(forces)
    grip, run, kin, rules, peaks, site = b(grip), b(run), b(kin), b(rules), b(peaks), b(site)
    work_int, work_float, ends_int, ends_float = (b(work_int), b(work_float), b(ends_int),
                                                  b(ends_float))
    x_out, v_out = b(x_out), b(v_out)
    dt = kin[K_DT]
    out, normal_out, pressure_out, meas_out = outs[1], outs[2], outs[3], outs[4]
    covered_in, covered_out, d_pressure, d_out = dmg[3], dmg[4], dmg[5], dmg[7]
    pad_holder = pad[4]
    padded = pad[0].shape[0] > 0
    surface_nodes = _packed1(fixed[3], fixed[4], KI_SURFACE)
    new = np.empty(G_SIZE)
    lifts = np.empty(x.shape[0])
    tried = np.zeros((jaw_drive.MAX_GAP_SOLVES, 3))
    jaw = np.empty(2)
    n_steps = 0
    run[R_STEPS] = 0.0
    run[R_SOLVES] = 0.0
    run[R_NEWTON] = 0.0
    while True:
        jaw[0], jaw[1] = run[R_JAW_LEFT], run[R_JAW_RIGHT]
        status, iterations, solves = _drive_jaws(
            x, v, c_int, c_float, work_int, work_float, ends_int, ends_float, grip, new, jaw,
            kin, x_out, v_out, forces, fixed, outs, dmg, pad, scratch, tried)
        if status != OK:
            return NEEDS_STEP
        # the step is kept
        x[:] = x_out
        v[:] = v_out
        c_int[:] = work_int
        c_float[:] = work_float
        grip[:] = new
        run[R_PREVIOUS_TIME] = run[R_TIME]
        run[R_TIME] += dt
        run[R_JAW_LEFT], run[R_JAW_RIGHT] = out[2], out[3]
        n_steps += 1
        run[R_STEPS] = n_steps
        run[R_ITERATIONS] = iterations
        run[R_SOLVES] += solves
        run[R_NEWTON] += iterations
        time = run[R_TIME]
        # the measures the per-step route keeps (FastPath.measure)
        left_n, right_n = meas_out[M_LEFT_N], meas_out[M_RIGHT_N]
        if kin[K_PLAIN] == 0.0:
            left_n, right_n = -meas_out[M_LEFT_FX], meas_out[M_RIGHT_FX]
        any_left, any_right = meas_out[M_ANY_LEFT] > 0, meas_out[M_ANY_RIGHT] > 0
        both = any_left and any_right
        touching = any_left or any_right
        relative_z = meas_out[M_CZ] - grip[G_LIFT]
        if both and math.isnan(run[R_SLIP_REF]):
            run[R_SLIP_REF] = relative_z
        if not math.isnan(run[R_SLIP_REF]) and touching:
            run[R_HELD_SLIP] = abs(run[R_SLIP_REF] - relative_z)
        slip = run[R_HELD_SLIP] if not math.isnan(run[R_SLIP_REF]) else 0.0
        grip_force = 0.5 * (left_n + right_n)
        rest_width = kin[K_REST_WIDTH]
        compression = rest_width - meas_out[M_WIDTH]
        ratio = compression / rest_width if rest_width > 0 else 0.0
        # the damage tracker (FastPath._damage)
        bruised = False
        damage_site = 0
        if dmg[1].shape[0] > 0:
            covered_in[:] = covered_out
            flesh_stress = out[8] if kin[K_FLESH] > 0 else 0.0
            stress = max(TRESCA_OVER_P0 * d_out[1], flesh_stress)
            run[R_PEAK_PRESSURE] = max(run[R_PEAK_PRESSURE], d_out[1])
            run[R_PEAK_STRESS] = max(run[R_PEAK_STRESS], stress)
            if run[R_PEAK_STRESS] > kin[K_FAILURE_STRESS]:
                run[R_CRUSHED] = 1.0
            if not math.isnan(kin[K_FAILURE_STRAIN]) and ratio > kin[K_FAILURE_STRAIN]:
                run[R_CRUSHED] = 1.0
            bruised = run[R_PEAK_PRESSURE] > kin[K_BRUISE]
            if bruised and rules[S_BRUISE] > 0 and d_pressure.shape[0] > 0:
                node = np.argmax(d_pressure)
                if d_pressure[node] > 0:
                    damage_site = site[_holder(c_int, pad_holder, padded,
                                               surface_nodes[node]) + 1]
        # the run's peaks (RunPeaks)
        peaks[PEAK_GRIP] = max(peaks[PEAK_GRIP], grip_force)
        peaks[PEAK_COMPRESSION] = max(peaks[PEAK_COMPRESSION], compression)
        for s in range(surface_nodes.shape[0]):
            where = site[_holder(c_int, pad_holder, padded, surface_nodes[s]) + 1]
            if where == 1:
                peaks[PEAK_JAW] = max(peaks[PEAK_JAW], pressure_out[s])
            elif where == 2:
                peaks[PEAK_TABLE] = max(peaks[PEAK_TABLE], pressure_out[s])
        # a pick-and-place's slide along the jaws (PickAndPlace._slide) and largest slip
        slide, max_slip, max_drop = run[R_SLIDE], run[R_MAX_SLIP], run[R_MAX_DROP]
        if rules[S_SLIDE] > 0:
            max_drop = max(max_drop, slip)
            step_dt = time - run[R_PREVIOUS_TIME]
            count = 0
            for i in range(x.shape[0]):
                if site[_holder(c_int, pad_holder, padded, i) + 1] == 1:
                    lifts[count] = v[i, 1]
                    count += 1
            if step_dt > 0 and count > 0:
                relative = numpy_sum(lifts, count) / count - grip[G_LIFT_RATE]
                slide = max(0.0, slide - relative * step_dt)
                max_slip = max(max_slip, slide)
        # the stop rules
        if _stops(rules, grip, time, n_steps, both, touching, grip_force, slip, max_slip,
                  damage_site, bruised or run[R_CRUSHED] > 0, kin[K_MIN_GAP]):
            return STOPPED
        run[R_SLIDE], run[R_MAX_SLIP], run[R_MAX_DROP] = slide, max_slip, max_drop
    return STOPPED  # not reached: the loop returns


@njit(cache=True)
def _stops(rules, grip, time, n_steps, both, touching, grip_force, slip, max_slip,
           damage_site, damaged, min_gap):
    """Whether a stop rule (S_*) fires after a step with these measures (``min_gap`` m:
    the jaws' stop)."""
    if both and grip_force >= rules[S_FORCE]:
        return True
    if time > rules[S_DEADLINE]:
        return True
    if rules[S_GAP_CLOSED] > 0 and grip[G_GAP] <= min_gap:
        return True
    if time - rules[S_PHASE_START] >= rules[S_ELAPSED]:
        return True
    lifted = grip[G_LIFT] == grip[G_TARGET_LIFT] and grip[G_LIFT_RATE] == 0.0
    moved = grip[G_X] == grip[G_TARGET_X] and grip[G_X_RATE] == 0.0
    if ((rules[S_LIFTED] > 0 or rules[S_MOVED] > 0) and (lifted or rules[S_LIFTED] == 0)
            and (moved or rules[S_MOVED] == 0)):
        return True
    if abs(grip[G_GAP] - rules[S_GAP_AT]) < 1e-9:
        return True
    if rules[S_DROP] > 0 and (not touching or slip > rules[S_DROP_SLIP]):
        return True
    if max_slip > rules[S_SLIDE_LIMIT]:
        return True
    if damage_site == 1 or damage_site == 2:
        return True
    if rules[S_DAMAGED] > 0 and damaged:
        return True
    return time >= rules[S_END] or n_steps >= rules[S_MAX_STEPS]
