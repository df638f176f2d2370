"""Prescribed kinematics of the two jaws and the lift, and their controllers.

The jaws close symmetrically about the gripper centre x. In position mode the gap moves
towards a target at a rate limit, but never closes further than where the grip force
(mean normal force of the two jaws on the fruit) reaches the maximum effort; in force
mode the gap moves so that the grip force meets its target, through the drive's damping
(grip force - target = damping x gap rate, ``jaw_drive.damping_rate``).
``GripperKinematics.advance`` predicts the step's gap from the last measured force and
the contact stiffness; the facade (``core.facade.SimulationFacade``) then solves the
step and, if the force it measures misses the target, re-solves the step at a
corrected gap (``_drive_jaws``), so the force holds whatever dt. The lift moves the jaw centre height towards a target with
a trapezoidal speed profile, and the transport moves the gripper centre sideways (x)
the same way. The arithmetic of each rule is a compiled function of ``core.jaw_drive``,
which the 2D multi-step advance (``core.advance_kernels``) calls too.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from gripper_sim.core import jaw_drive


#: m, how far the lift and the transport may move where no table or wall bounds them
FREE_TRAVEL = 10.0
#: m, how far above its lowest height (jaws on the table) the lift may go
LIFT_TRAVEL = 2.0


def lift_range(config) -> tuple[float, float]:
    """(lowest, highest) jaw centre height (m) a lift command may ask for, from the flat
    configuration: from the jaws' lower edge on the table to ``LIFT_TRAVEL`` above it,
    or +-``FREE_TRAVEL`` without a table."""
    if not config['world.table']:
        return -FREE_TRAVEL, FREE_TRAVEL
    low = config['world.table_height'] + 0.5 * config['gripper.jaw_height']
    return low, low + LIFT_TRAVEL


def transport_range(config) -> tuple[float, float]:
    """(lowest, highest) gripper centre x (m) a transport command may ask for: between
    the walls, or +-``FREE_TRAVEL`` without them."""
    limit = config['world.wall_half_width'] if config['world.walls'] else FREE_TRAVEL
    return -limit, limit


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
        stiffness: N/m, -d grip force / d gap of the contact, as last measured within a
            step (the facade's gap correction); the prediction's slope.
        measured_force, measured_gap: N and m at the previous advance.
        x: m, gripper centre along x (the transport axis).  x_rate: m/s.
        target_x: m.  x_speed: m/s, transport speed limit.
        max_effort: N, position mode's grip force limit (the servo stops closing there).
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
    max_effort: float = math.inf


class GripperKinematics:
    """Advances the jaws and lift by one step given the last measured grip force.

    Args:
        max_gap: m.  lift_acceleration: m/s^2.
        initial_stiffness: N/m, first guess of -d grip force / d gap.
        hertz_modulus: N/m^1.5, K of Hertz's law F = K delta^(3/2) at each jaw
            (``jaw_drive.hertz_stiffness``) where the fruit's contact follows it (a solid
            3D fruit), else 0: the first guess at a force (``first_stiffness``).
        transport_acceleration: m/s^2, of the sideways transport.
        max_speed: m/s, the drive's top gap rate (see ``gap_bounds``).
        damping: N s/m, the force-mode drive's damping (``jaw_drive.damping_rate``).
        min_gap: m, the jaws' stop: the gap at which the fingers' rigid parts meet (0 for
            rigid fingers; ``SimulationFacade.smallest_gap``). No drive closes past it.
    """

    def __init__(self, max_gap: float, lift_acceleration: float, initial_stiffness: float,
                 transport_acceleration: float = 1.0, max_speed: float = math.inf,
                 damping: float = 0.0, min_gap: float = 0.0, hertz_modulus: float = 0.0):
        self.max_gap = max_gap
        self.hertz_modulus = hertz_modulus
        self.min_gap = min_gap
        self.max_speed = max_speed
        self.damping = damping
        self.lift_acceleration = lift_acceleration
        self.initial_stiffness = initial_stiffness
        self.transport_acceleration = transport_acceleration

    def first_stiffness(self, force: float) -> float:
        """N/m, the first guess of -d grip force / d gap for a grip at ``force`` (N): the
        Hertz law's tangent there (``hertz_modulus``) if there is one, else
        ``initial_stiffness``."""
        if self.hertz_modulus > 0.0:
            return jaw_drive.hertz_stiffness(self.hertz_modulus, force)
        return self.initial_stiffness

    def advance(self, state: GripperState, dt: float, grip_force: float,
                both_in_contact: bool, clearance: float = math.inf) -> GripperState:
        """The state after ``dt`` (s); ``grip_force`` (N) measured at the current state.

        The gap is a prediction: the gap at which the grip force would meet the target
        (force mode) or the effort limit (position mode) at the present stiffness, within
        the speed limits; the facade corrects it after the solve (``_drive_jaws``).
        ``clearance`` (m): how far a jaw that does not yet touch the fruit is from it (inf
        when both touch or unknown). Under force control the jaws close at the commanded
        speed until both touch, but never further in one step than that clearance plus
        the travel that gives the target force at the present stiffness: a large step
        then lands the jaw on the fruit instead of driving it through the surface.
        """
        lo, hi = self.gap_bounds(state, dt)
        gap = jaw_drive.predicted_gap(
            state.mode == 'force', state.gap, state.target_gap, state.target_force,
            state.speed, state.stiffness, state.max_effort, grip_force, both_in_contact,
            clearance, lo, hi, self.min_gap, self.max_gap, dt, self.damping_rate(state, dt))
        return self.moved(state, dt, gap, grip_force)

    def damping_rate(self, state: GripperState, dt: float) -> float:
        """N/m, the drive's damping per metre of gap change in a step of ``dt`` (s) from
        ``state`` (``jaw_drive.damping_rate``)."""
        return jaw_drive.damping_rate(state.mode == 'force', state.measured_force,
                                      self.damping, dt)

    def moved(self, state: GripperState, dt: float, gap: float,
              grip_force: float) -> GripperState:
        """The state after ``dt`` (s) with the jaws at ``gap`` (m) and the lift and the
        transport advanced; ``grip_force`` (N) the force measured at ``state``."""
        rate, lift, lift_rate, x, x_rate = jaw_drive.moved(
            state.gap, gap, state.lift, state.lift_rate, state.target_lift, state.lift_speed,
            self.lift_acceleration, state.x, state.x_rate, state.target_x, state.x_speed,
            self.transport_acceleration, dt)
        return GripperState(gap, rate, lift, lift_rate, state.mode, state.target_gap,
                            state.target_force, state.speed, state.target_lift,
                            state.lift_speed, state.stiffness, grip_force, state.gap, x,
                            x_rate, state.target_x, state.x_speed, state.max_effort)

    def servo_gap(self, state: GripperState, dt: float) -> float:
        """m, the gap after ``dt`` (s) of the position servo's move towards its target at
        the commanded speed, before any force limit."""
        return jaw_drive.servo_gap(state.gap, state.target_gap, state.speed, self.min_gap,
                                   self.max_gap, dt)

    def gap_bounds(self, state: GripperState, dt: float) -> tuple[float, float]:
        """(smallest, largest) gap (m) the drive can reach from ``state`` in ``dt`` (s):
        it closes at the commanded speed until it grips; holding a grip force (force
        mode, a force measured) it closes and opens at up to its own top speed
        ``max_speed``, as a force-controlled drive does (a soft plum lifted off the table
        lost 10-12 % of its grip force while the drive re-closed at the approach speed)."""
        return jaw_drive.gap_bounds(state.gap, state.speed, self.max_speed,
                                    state.mode == 'force' and state.measured_force > 0.0,
                                    self.min_gap, self.max_gap, dt)

