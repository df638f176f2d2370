"""What the 2D and the 3D simulation facades share: commands, state, observers, stepping.

A facade keeps the gripper command state ``_grip`` (``GripperState``), the time, the
last ``StepResult`` and its observers; the subclasses (``core.simulation.Simulation``,
``core3d.simulation.Simulation3D``) build the fruit and the jaws and provide
``reset()``, ``_make_faces()``, ``_substep(dt)`` (one implicit step, raising
``NewtonFailure`` when it does not converge) and ``_measure(iterations, substeps)``.
Commands validate their values (``CommandError``, the simulation unchanged) and take
effect on the next step.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable

from gripper_sim.core.gripper import GripperState
from gripper_sim.core.results import StepResult
from gripper_sim.core.stepper import NewtonFailure
from gripper_sim.errors import CommandError, ConfigError, ConvergenceError

#: configuration keys that may change while the simulation runs
DYNAMIC_KEYS = ('contact.jaw.static_friction', 'contact.jaw.kinetic_friction',
                'contact.table.static_friction', 'contact.table.kinetic_friction',
                'contact.restitution', 'gripper.close_speed', 'gripper.lift_speed')


def finite(name: str, value: Any) -> float:
    """``value`` as a finite float, else CommandError naming ``name``."""
    try:
        number = float(value)
    except (TypeError, ValueError) as err:
        raise CommandError(f'{name} must be a number, got {value!r}') from err
    if not math.isfinite(number):
        raise CommandError(f'{name} must be finite, got {number}')
    return number


class SimulationFacade:
    """Base of the simulation facades (see the module docstring)."""

    # ------------------------------------------------------------------ commands
    def command_gap(self, gap: float, speed: float | None = None) -> None:
        """Position mode: move the jaws to gap ``gap`` (m) at gap rate ``speed`` (m/s)."""
        gap = finite('gap', gap)
        if gap < 0 or gap > self.config['gripper.max_gap']:
            raise CommandError(f"gap {gap} m is out of range [0, "
                               f"{self.config['gripper.max_gap']}] m")
        speed = self._speed(speed, self.config['gripper.close_speed'])
        self._grip = replace(self._grip, mode='position', target_gap=gap, speed=speed)

    def command_force(self, force: float, speed: float | None = None) -> None:
        """Force mode: close until the mean jaw normal force is ``force`` (N), hold it."""
        force = finite('force', force)
        limit = self.config['gripper.max_force']
        if force <= 0 or force > limit:
            raise CommandError(f'force {force} N is out of range (0, {limit}] N')
        speed = self._speed(speed, self.config['gripper.close_speed'])
        self._grip = replace(self._grip, mode='force', target_force=force, speed=speed)

    def command_open(self, speed: float | None = None) -> None:
        """Position mode back to the initial gap."""
        self.command_gap(self.initial_gap, speed)
        self._slip_reference = None

    def command_lift(self, height: float, speed: float | None = None) -> None:
        """Move the gripper (jaw centre) to height ``height`` (m)."""
        height = finite('lift height', height)
        low = (self.config['world.table_height'] + 0.5 * self.config['gripper.jaw_height']
               if self.config['world.table'] else -10.0)
        high = low + 10.0 if not self.config['world.table'] else low + 2.0
        if height < low - 1e-12 or height > high:
            raise CommandError(f'lift height {height} m is out of range [{low:.4g}, '
                               f'{high:.4g}] m (the jaws may not go below the table)')
        speed = self._speed(speed, self.config['gripper.lift_speed'])
        self._grip = replace(self._grip, target_lift=height, lift_speed=speed)

    def command_transport(self, x: float, speed: float | None = None) -> None:
        """Move the gripper centre (both jaws) sideways to ``x`` (m) at ``speed`` (m/s)."""
        x = finite('transport x', x)
        limit = (self.config['world.wall_half_width'] if self.config['world.walls'] else 10.0)
        if abs(x) > limit:
            raise CommandError(f'transport x {x} m is out of range [-{limit:g}, {limit:g}] m')
        speed = self._speed(speed, self.config['gripper.transport_speed'])
        self._grip = replace(self._grip, target_x=x, x_speed=speed)

    def hold(self) -> None:
        """Stop the jaws where they are (position mode at the current gap)."""
        self._grip = replace(self._grip, mode='position', target_gap=self._grip.gap)

    def mark_slip_reference(self) -> None:
        """Measure slip from the fruit's present position relative to the jaws."""
        self._slip_reference = float(self._last.centroid[-1] - self._grip.lift)
        self._held_slip = 0.0

    def _slip_distance(self, relative_z: float, both: bool, touching: bool) -> float:
        """m, the fruit's vertical motion relative to the jaws since both jaws first held
        it (or since ``mark_slip_reference``), from ``relative_z`` (m, centroid height over
        the jaw centre). While no jaw touches the fruit (released, or dropped) it stays at
        its last value: the fruit is then no longer moving in the jaws."""
        if both and self._slip_reference is None:
            self._slip_reference = relative_z
        if self._slip_reference is None:
            return 0.0
        if touching:
            self._held_slip = abs(self._slip_reference - relative_z)
        return self._held_slip

    def set_parameter(self, key: str, value: Any) -> None:
        """Change a dynamic configuration key while running (see DYNAMIC_KEYS)."""
        from gripper_sim.configuration import validate
        if key not in DYNAMIC_KEYS:
            raise ConfigError(f"config key '{key}' cannot change while running")
        trial = dict(self.config)
        trial[key] = value
        self.config = validate(trial)
        self._faces_template = self._make_faces()

    def _speed(self, speed, default: float) -> float:
        if speed is None or speed == 0:
            return default
        speed = finite('speed', speed)
        limit = self.config['gripper.max_speed']
        if speed <= 0 or speed > limit:
            raise CommandError(f'speed {speed} m/s is out of range (0, {limit}] m/s')
        return speed

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        return self._time

    @property
    def gripper_state(self) -> GripperState:
        return self._grip

    @property
    def last(self) -> StepResult:
        """The most recent step result (the initial state before any step)."""
        return self._last

    def add_observer(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(result)`` after every step."""
        self._observers.append(callback)

    # ------------------------------------------------------------------ stepping
    def step(self) -> StepResult:
        """Advance one step of ``dt``.

        Raises:
            ConvergenceError: the step failed even after halving; the state is unchanged.
        """
        saved = (self.q, self.v, self.contacts, self.contact_forces, self._grip, self._time,
                 self._jaw_force)
        try:
            iterations, substeps = self._advance(self.dt, 0)
        except ConvergenceError:
            (self.q, self.v, self.contacts, self.contact_forces, self._grip, self._time,
             self._jaw_force) = saved
            raise
        self._step += 1
        self._last = self._measure(iterations, substeps)
        for callback in self._observers:
            callback(self._last)
        return self._last

    def run(self, duration: float) -> StepResult:
        """Step for ``duration`` seconds; returns the last result."""
        for _ in range(max(1, int(round(duration / self.dt)))):
            self.step()
        return self._last

    def _advance_gripper(self, dt: float) -> GripperState:
        """The gripper state after ``dt`` (s), from the last step's jaw forces."""
        left_n, right_n = self._jaw_force
        return self.kinematics.advance(self._grip, dt, 0.5 * (left_n + right_n),
                                       left_n > 0 and right_n > 0, self._jaw_clearance())

    def _jaw_clearance(self) -> float:
        """m, the distance along x from the fruit to the nearest flat jaw face that does
        not touch it; inf when both jaws touch, and for arc and V-groove fingers and soft
        pads (the fruit enters their recess or layer: no plane gives their clearance)."""
        left_n, right_n = self._jaw_force
        if left_n > 0 and right_n > 0:
            return math.inf
        if (self.config.get('gripper.finger.type', 'flat') != 'flat'
                or self.config.get('gripper.finger.pad.enabled', False)):
            return math.inf
        grip = self._grip
        x = self.q[:, 0]
        gaps = []
        if not left_n > 0:
            gaps.append(float(x.min()) - (grip.x - 0.5 * grip.gap))
        if not right_n > 0:
            gaps.append((grip.x + 0.5 * grip.gap) - float(x.max()))
        return min(gaps)

    def _advance(self, dt: float, depth: int) -> tuple[int, int]:
        """Step ``dt``, halving it (recursively) while Newton fails; (iterations, substeps)."""
        try:
            return self._substep(dt), 1
        except NewtonFailure as failure:
            if depth >= self.config['sim.max_halvings']:
                msg = (f'the solver did not converge at t = {self._time:.6g} s even with the '
                       f'step halved {depth} times ({failure}); try a smaller sim.dt or '
                       f'slower jaws')
                raise ConvergenceError(msg, failure.history, self._time) from failure
        it1, s1 = self._advance(0.5 * dt, depth + 1)
        it2, s2 = self._advance(0.5 * dt, depth + 1)
        return it1 + it2, s1 + s2
