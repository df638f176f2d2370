"""Prescribed kinematics of the two jaws and the lift, and their controllers.

The jaws close symmetrically about the gripper centre x. In position mode the gap moves
towards a target at a rate limit; in force mode a regulator moves it so that the grip
force (mean normal force of the two jaws) reaches a target and stays there. The lift
moves the jaw centre height towards a target with a trapezoidal speed profile, and the
transport moves the gripper centre sideways (x) the same way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(slots=True)
class GripperState:
    """The gripper's kinematic state; treated as immutable (new states come from
    ``dataclasses.replace`` or the constructor), but not frozen: a frozen dataclass
    costs several microseconds to build, on every physics step.

    Attributes:
        gap: m, jaw separation.  gap_rate: m/s (negative while closing).
        lift: m, jaw centre height.  lift_rate: m/s.
        mode: 'position' or 'force'.
        target_gap: m.  target_force: N.  speed: m/s gap rate limit.
        target_lift: m.  lift_speed: m/s.
        stiffness: N/m, the force regulator's running estimate of d force / d gap.
        measured_force, measured_gap: N and m at the previous advance (for the estimate).
        x: m, gripper centre along x (the transport axis).  x_rate: m/s.
        target_x: m.  x_speed: m/s, transport speed limit.
    """

    gap: float
    gap_rate: float
    lift: float
    lift_rate: float
    mode: str
    target_gap: float
    target_force: float
    speed: float
    target_lift: float
    lift_speed: float
    stiffness: float
    measured_force: float = 0.0
    measured_gap: float = float('nan')
    x: float = 0.0
    x_rate: float = 0.0
    target_x: float = 0.0
    x_speed: float = 0.1


class GripperKinematics:
    """Advances the jaws and lift by one step given the last measured grip force.

    Args:
        max_gap: m.  lift_acceleration: m/s^2.  force_time_constant: s.
        initial_stiffness: N/m, first guess of the contact stiffness.
        transport_acceleration: m/s^2, of the sideways transport.
    """

    def __init__(self, max_gap: float, lift_acceleration: float, force_time_constant: float,
                 initial_stiffness: float, transport_acceleration: float = 1.0):
        self.max_gap = max_gap
        self.lift_acceleration = lift_acceleration
        self.tau = force_time_constant
        self.initial_stiffness = initial_stiffness
        self.transport_acceleration = transport_acceleration

    def advance(self, state: GripperState, dt: float, grip_force: float,
                both_in_contact: bool, clearance: float = math.inf) -> GripperState:
        """The state after ``dt`` (s); ``grip_force`` (N) measured at the current state.

        ``clearance`` (m): how far a jaw that does not yet touch the fruit is from it (inf
        when both touch or unknown). Under force control the jaws close at the commanded
        speed until both touch, but never further in one step than that clearance plus
        the travel the force regulator allows from zero force: a large step then lands
        the jaw on the fruit instead of driving it through the surface (at dt 20 ms
        the impact overshot a 2 N target by 150 %).
        """
        stiffness = state.stiffness
        if state.mode == 'force':
            if both_in_contact and abs(state.gap - state.measured_gap) > 1e-9:
                measured = -(grip_force - state.measured_force) / (state.gap - state.measured_gap)
                if measured > 0:
                    stiffness = min(max(0.7 * stiffness + 0.3 * measured,
                                        1e-3 * self.initial_stiffness),
                                    1e3 * self.initial_stiffness)
            if grip_force <= 0.0 or not both_in_contact:
                # one jaw alone only pushes the fruit (e.g. across the table): that force
                # is no grip, so close at the commanded speed until both jaws touch
                landing = (max(clearance, 0.0) / dt
                           + state.target_force / (stiffness * max(self.tau, dt)))
                rate = -min(state.speed, landing)
            else:
                rate = -(state.target_force - grip_force) / (stiffness * max(self.tau, dt))
                rate = min(max(rate, -state.speed), state.speed)
        else:
            rate = (state.target_gap - state.gap) / dt
            rate = min(max(rate, -state.speed), state.speed)
        gap = min(max(state.gap + rate * dt, 0.0), self.max_gap)
        rate = (gap - state.gap) / dt
        lift, lift_rate = self._advance_lift(state, dt)
        if state.x != state.target_x or state.x_rate != 0.0:
            x, x_rate = trapezoid(state.x, state.x_rate, state.target_x, state.x_speed,
                                  self.transport_acceleration, dt)
        else:
            x, x_rate = state.x, 0.0
        return GripperState(gap, rate, lift, lift_rate, state.mode, state.target_gap,
                            state.target_force, state.speed, state.target_lift,
                            state.lift_speed, stiffness, grip_force, state.gap, x, x_rate,
                            state.target_x, state.x_speed)

    def _advance_lift(self, state: GripperState, dt: float) -> tuple[float, float]:
        distance = state.target_lift - state.lift
        a = self.lift_acceleration
        # fastest speed from which we can still stop at the target
        v_stop = math.copysign(min(state.lift_speed, math.sqrt(2 * a * abs(distance))),
                               distance)
        rate = state.lift_rate + min(max(v_stop - state.lift_rate, -a * dt), a * dt)
        if abs(distance) <= max(abs(rate) * dt, 1e-12):
            return state.target_lift, 0.0
        return state.lift + rate * dt, rate


def trapezoid(position: float, rate: float, target: float, speed: float,
              acceleration: float, dt: float) -> tuple[float, float]:
    """One step of a move to ``target`` at speed and acceleration limits (as the lift).

    Returns the new position (m) and rate (m/s).
    """
    distance = target - position
    v_stop = math.copysign(min(speed, math.sqrt(2 * acceleration * abs(distance))), distance)
    rate = rate + min(max(v_stop - rate, -acceleration * dt), acceleration * dt)
    if abs(distance) <= max(abs(rate) * dt, 1e-12):
        return target, 0.0
    return position + rate * dt, rate
