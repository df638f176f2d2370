"""What the 2D and the 3D simulation facades share: commands, state, observers, stepping.

A facade keeps the gripper command state ``_grip`` (``GripperState``), the time, the
last ``StepResult`` and its observers, and steps: the jaw faces follow the gripper, the
soft pads (if any) are set up around the step, and one implicit step with contact
(``core.contact_passes``) advances the fruit, whatever the dimension ``dimension``
(d = 2 or 3). The subclasses (``core.simulation.Simulation``,
``core3d.simulation.Simulation3D``) build the fruit, the gravity, pads and kinematics,
and provide ``_make_faces()`` (which also sets ``_face_side`` and ``_face_offsets``),
``_make_damage()`` and ``_measure(iterations, substeps)``.
The facade owns its state: a step's end is taken in one place, ``commit_step`` (the
generic, soft and compiled routes all commit there), a compiled multi-step run's in
``commit_advance``; the compiled routes (``core.fast``, ``core.multistep``) read what
they need through public read-only properties (``faces_template``, ``face_sides``,
``face_offsets``, ``pad``, ``damage_tracker``, ``jaw_forces``, ...) and methods
(``faces_at``, ``gripper_after``, ``measure_slip``, ``contact_forces_and_holders``).
Commands validate their values (``CommandError``, the simulation unchanged) and take
effect on the next step.

The jaw drive (``_drive_jaws``): in force mode the grip force (the mean of the contact
forces the fruit exerts on the two jaws) meets its command at the end of every step,
within ``FORCE_TOLERANCE``, unless the speed limit keeps the jaws from getting there; in
position mode the servo moves the gap towards its target but stops where the grip force
reaches the maximum effort. After a step is solved at the gap ``GripperKinematics``
predicts (with deformable fingers in force mode, at ``jaw_drive.first_gap``: the gap it
starts from while the grip holds still, else moved on at its last rate), a force that
misses its goal restores the step's start and solves it again at a gap corrected by
secant steps on force(gap) (bracketed, at most ``MAX_GAP_SOLVES`` solves), so the force
does not depend on dt. The drive's rules (prediction, bounds, secant and bracket steps)
are the compiled functions of ``core.jaw_drive``; the 2D multi-step advance
(``core.advance_kernels``) runs this same loop on them in numba.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Callable

import numpy as np

from gripper_sim.configuration import RUNTIME_KEYS
from gripper_sim.core import contact as cm
from gripper_sim.core import jaw_drive
from gripper_sim.core import soft_step_kernels as ssk
from gripper_sim.core.barrier import (BarrierContact, NoCollisionFreeStart, barrier_step,
                                      soft_body_step)
from gripper_sim.core.barrier_kernels import (held_normal_forces, mark_sticking,
                                              split_partners)
from gripper_sim.core.contact_passes import ContactSettings, contact_step
from gripper_sim.core.deferred import build
from gripper_sim.core.energies import Gravity
from gripper_sim.core.fast_solver import PatternCachingSolver
from gripper_sim.core.gripper import GripperState, lift_range, transport_range
from gripper_sim.core.jaw_drive import FORCE_TOLERANCE, MAX_GAP_SOLVES
from gripper_sim.core.measures import jaw_normal_forces, outline_at_rest
from gripper_sim.core.results import Energies, JawWrench, StepResult
from gripper_sim.core.soft_fingers import FingerState, SoftFingers, base_pushes
from gripper_sim.core.slip import jaw_contacts_sliding, patches_sliding, surface_motion
from gripper_sim.core.stepper import NewtonFailure
from gripper_sim.errors import (CommandError, ConfigError, ConvergenceError,
                                FingersClosed)

LEFT, RIGHT = 0, 1


#: configuration keys that may change while the simulation runs (the schema's runtime keys)
DYNAMIC_KEYS = RUNTIME_KEYS

#: m, deformable fingers whose outlines come this close while their step finds no
#: collision-free start have closed on each other over the fruit (``FingersClosed``): far
#: less than any fruit's skin is thick (tens of um and more)
FINGERS_MEET = 1e-5

#: with deformable fingers, the first of the faces' obstacle indices (0 and 1 are the
#: fingers, ``obstacle_names``: left_jaw, right_jaw)
FIRST_FACE = 2

#: m, how far a starting gap may lie below the fruit's width across the jaws and still
#: count as touching it (a mesh's width differs from its diameter by rounding)
TOUCHING_TOLERANCE = 1e-9

#: the settle on the table (``_settle``): its first step is the simulation's time step and
#: each next one this factor longer, up to ``settle_longest_step`` s (here
#: ``SETTLE_LONGEST_STEP``); it ends at the first step in which no node of the fruit moves
#: further than ``SETTLE_TOLERANCE`` m, and fails after ``SETTLE_MAX_STEPS`` steps
SETTLE_GROWTH = 2.0
SETTLE_LONGEST_STEP = 0.04
SETTLE_TOLERANCE = 1e-7
SETTLE_MAX_STEPS = 60


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

    #: the barrier contact model (``contact.model: ipc``, ``core.barrier``), or None for
    #: the modified mass method's contact passes
    _barrier: BarrierContact | None = None
    #: the deformable fingers (``core.soft_fingers``), None for rigid ones
    _soft: SoftFingers | None = None
    #: the deformable fingers' state, None for rigid fingers
    _finger: FingerState | None = None
    #: the obstacles' normals and sides, kept per face set (``_obstacles``)
    _obstacles_kept: tuple | None = None
    #: ``_finger_bases``, built on first use
    _jaw_bases: tuple | None = None
    #: ``faces_at``'s last three faces made: (the jaws' placement: the gripper's x, gap,
    #: lift and their rates, the faces template, the faces), the newest first
    _faces_kept: tuple = ()
    #: the obstacles' velocities (``_obstacles``): (the ``_obstacles_kept`` they are of,
    #: the gripper's (x, gap, lift) rates m/s, (k, d) m/s read only), or None
    _moving_kept: tuple | None = None
    #: ``obstacle_names``: (the faces template they are of, the names), or None
    _names_kept: tuple | None = None
    #: ``_total_mass``: (the masses array, their sum kg), or None
    _mass_kept: tuple | None = None
    #: whether ``_settle`` steps: a subclass's compiled routes stand aside, so that every
    #: route of a configuration starts from the same settled state
    _settling = False
    #: the solver's energies that act only in the settle (``_settle_energies``)
    _settle_terms: tuple = ()
    #: s, the settle's longest step (``_settle``)
    settle_longest_step = SETTLE_LONGEST_STEP
    #: ``_joined``'s arrays of the last deformable fingers' solve: per quantity (the
    #: positions, the velocities) (the fruit's rows, the fingers' rows, the whole array)
    _joined_kept: tuple = ()

    # ------------------------------------------------------------------ construction
    def _place_fruit(self) -> None:
        """``initial_positions`` (n, d) m (the fruit on the table, or at its configured
        height), ``initial_gap`` and ``initial_lift`` (m) from the configuration."""
        c = self.config
        rest = self.fruit.rest_positions
        if c['fruit.initial_height'] is not None:
            centre_z = c['fruit.initial_height']
        elif c['world.table']:
            centre_z = c['world.table_height'] - rest[:, -1].min()
        else:
            centre_z = 0.0
        self.initial_positions = rest + self._in_plane(0.0, centre_z)
        self.initial_lift = (c['gripper.initial_lift'] if c['gripper.initial_lift'] is not None
                             else centre_z)
        # deformable fingers: the gap is between their backings, which they stand in front
        # of: the jaws touch the fruit at a wider gap (m)
        self.touching_gap = (self.fruit.rest_width if self._soft is None else
                             self._soft.touching_gap(self.initial_positions
                                                     - self._in_plane(0.0, self.initial_lift)))
        # (a fruit below or above the fingers: they close on nothing down to their stop)
        self.initial_gap = (c['gripper.initial_gap'] if c['gripper.initial_gap'] is not None
                            else min(max(self.touching_gap, self.smallest_gap) + 0.01,
                                     c['gripper.max_gap']))
        if self.initial_gap > c['gripper.max_gap']:
            raise ConfigError("config key 'gripper.initial_gap' exceeds 'gripper.max_gap'")

    def jaws_start_inside(self) -> bool:
        """Whether the jaws start inside the fruit: ``initial_gap`` narrower than
        ``touching_gap`` (by more than ``TOUCHING_TOLERANCE``)."""
        return self.initial_gap < self.touching_gap - TOUCHING_TOLERANCE

    def _starts_on_table(self) -> bool:
        """Whether ``_place_fruit`` put the fruit on the table (no ``fruit.initial_height``,
        a table)."""
        return self.config['fruit.initial_height'] is None and bool(self.config['world.table'])

    def _settles(self) -> bool:
        """Whether the fruit settles on the table before t = 0 (``_settle``): it starts on
        the table, between the jaws (a simulation whose jaws start inside it is refused,
        ``workflows.factory.check_start_gap``)."""
        return self._starts_on_table() and not self.jaws_start_inside()

    def _settle(self) -> None:
        """Let the fruit that ``_place_fruit`` put undeformed on the table come to rest on
        it under its weight, then ``reset``: ``initial_positions`` (n, d) m become its
        resting positions. Without this it would start weightless and land on the table
        with up to 1.7 times its weight, the peak pressure of every gentle grasp.

        Implicit Euler steps from rest (each starts with every velocity 0; the jaws, open,
        stand still) have the static equilibrium as their fixed point, and longer steps
        reach it in fewer (``SETTLE_GROWTH``, ``settle_longest_step``): 8 steps for the
        default 2D apple. A step that fails is tried again shorter (not below the time
        step). A round fruit's rest on a flat table is neutral in rolling: a step that
        moves it more than the one before of the same length rolls it, and it stays where
        that step started. Deformable fingers take part and start again at rest.

        Raises:
            ConfigError: a step of the time step's length failed, or the fruit still moved
                more than ``SETTLE_TOLERANCE`` in its ``SETTLE_MAX_STEPS``-th step.
        """
        self._settling = True
        try:
            self._settle_steps()
        finally:
            self._settling = False
            for energy in self._settle_terms:
                energy.hold(None)
        self.initial_positions = self.q.copy()
        self.reset()

    def _settle_steps(self) -> None:
        """``_settle``'s steps: the fruit at rest (``q``) at their end."""
        dt, last_dt, moved = self.dt, math.nan, math.inf
        for _ in range(SETTLE_MAX_STEPS):
            saved = self._saved_state()
            for energy in self._settle_terms:
                energy.hold(self.q, dt)
            try:
                self._advance(dt, 0)
            except ConvergenceError as failure:
                self._restore(saved)
                if dt <= self.dt:
                    raise ConfigError(
                        f'the fruit does not come to rest on the table under its weight '
                        f"({failure}); set 'fruit.initial_height' to start it above the "
                        f'table') from failure
                last_dt, dt = math.nan, max(dt / SETTLE_GROWTH, self.dt)
                continue
            self.v = np.zeros_like(self.v)
            last, moved = moved, float(np.abs(self.q - saved[0]).max())
            if moved <= SETTLE_TOLERANCE:
                break
            if moved >= last and dt == last_dt:
                # a round fruit on a flat table rolls (its rest is neutral or unstable):
                # the step before came nearest to rest
                self.q = saved[0]
                break
            last_dt, dt = dt, min(SETTLE_GROWTH * dt, self.settle_longest_step)
        else:
            raise ConfigError(
                f'the fruit does not come to rest on the table under its weight: it still '
                f'moved {moved:.3g} m in its {SETTLE_MAX_STEPS}th settling step; set '
                f"'fruit.initial_height' to start it above the table")

    def _settle_energies(self) -> list:
        """Energies of the solver that act only while the fruit settles, each with
        ``hold(start, dt)``: active in the settling step of ``dt`` s from the fruit's
        positions ``start`` (n, d) m, inactive after ``hold(None)``. None here: the 2D
        fruit rolls or tips to its rest (see ``_settle``); ``Simulation3D`` holds it."""
        return []

    def _make_solver(self) -> PatternCachingSolver:
        """The Newton solver of the fruit's energies, gravity, the pads and the
        deformable fingers (if any)."""
        c = self.config
        masses, gravity, fingers = self.fruit.masses, self.gravity, []
        if self._soft is not None:
            masses = np.concatenate([masses, self._soft.masses])
            gravity = Gravity(masses, c['world.gravity'], self.dimension)
            fingers = self._soft.energies
        self._settle_terms = tuple(self._settle_energies())
        solver = PatternCachingSolver(
            masses, list(self.fruit.energies) + [gravity] + fingers + list(self._settle_terms)
            + ([self._pad] if self._pad is not None else [])
            + ([self._barrier] if self._barrier is not None else []),
            damping_mass=c['fruit.damping.mass'], damping_stiffness=c['fruit.damping.stiffness'],
            tolerance=c['sim.newton_tolerance'], max_iterations=c['sim.max_newton_iterations'],
            dim=self.dimension, carry_newton_matrix=self._soft is not None)
        return solver

    def _forget_factor(self) -> None:
        """Drop the Newton factorisations kept by a compiled step (none here)."""

    def reset(self) -> None:
        """Back to the initial state and commands, time 0."""
        n = self.fruit.n_nodes
        if any([barrier.restore_pattern() for barrier in self._patterned_barriers()]):
            self.solver = self._make_solver()
        self.solver.reset()
        self._forget_factor()
        self.q = self.initial_positions.copy()
        self.v = np.tile(self._in_plane(self.config['fruit.initial_velocity.x'],
                                        self.config['fruit.initial_velocity.z']), (n, 1))
        self.contacts = cm.ContactState.empty(n)
        self.contact_forces = np.zeros((n, self.dimension))
        self._time = 0.0
        self._step = 0
        self._slip_reference: float | None = None
        self._held_slip = 0.0
        self._faces_template = self._make_faces()
        self._grip = GripperState(
            gap=self.initial_gap, gap_rate=0.0, lift=self.initial_lift, lift_rate=0.0,
            mode='position', target_gap=self.initial_gap, target_force=0.0,
            speed=self.config['gripper.close_speed'], target_lift=self.initial_lift,
            lift_speed=self.config['gripper.lift_speed'],
            stiffness=self.kinematics.initial_stiffness,
            x_speed=self.config['gripper.transport_speed'],
            max_effort=self.config['gripper.max_force'])
        if self._soft is not None:
            self._finger = self._soft.at_rest(self._jaw_origin(self._grip, LEFT),
                                              self._jaw_origin(self._grip, RIGHT))
            faces = self.faces_at(self._grip)
            self._barrier.begin_step(np.vstack([self.q, self._finger.positions]), faces,
                                     faces, self.dt)
        self._jaw_force = (0.0, 0.0)
        self._gap_override: float | None = None
        #: solves of the steps so far, gap corrections included (``_drive_jaws``)
        self.gap_solves = 0
        #: Newton iterations of the steps so far
        self.newton_iterations = 0
        self._damage = self._make_damage()
        if self._pad is not None:
            self._pad.begin_step(self.q, self._pad_faces(self._grip),
                                 self._pad_faces(self._grip), self.dt)
            self._pad.finish_step(self.q.ravel())
        self._last = self._measure(0, 1)

    # ------------------------------------------------------------------ commands
    def command_gap(self, gap: float, speed: float | None = None,
                    max_effort: float | None = None) -> None:
        """Position mode: move the jaws to gap ``gap`` (m) at gap rate ``speed`` (m/s),
        closing no further than where the grip force reaches ``max_effort`` (N; None =
        ``gripper.max_force``); there the jaws hold that force."""
        gap = finite('gap', gap)
        if gap < 0 or gap > self.config['gripper.max_gap']:
            raise CommandError(f"gap {gap} m is out of range [0, "
                               f"{self.config['gripper.max_gap']}] m")
        if gap < self.smallest_gap:
            raise CommandError(f'gap {gap} m would press the two deformable fingers into each '
                               f'other (each reaches {self._soft.thickness:g} m in front of '
                               f'its jaw): the smallest gap is {self.smallest_gap:g} m')
        speed = self._speed(speed, self.config['gripper.close_speed'])
        limit = self.config['gripper.max_force']
        if max_effort is None:
            max_effort = limit
        max_effort = finite('max_effort', max_effort)
        if max_effort <= 0 or max_effort > limit:
            raise CommandError(f'max_effort {max_effort} N is out of range (0, {limit}] N')
        self._grip = replace(self._grip, mode='position', target_gap=gap, speed=speed,
                             max_effort=max_effort)

    @property
    def smallest_gap(self) -> float:
        """m, the jaws' stop (``GripperKinematics.min_gap``): the smallest gap a command
        may ask for and a force-mode drive closes to, 0 or, with deformable fingers, the
        gap at which their fronts at rest would meet (a Fin Ray's rigid base reaches that
        far: there the two bases collide)."""
        return 2.0 * self._soft.thickness if self._soft is not None else 0.0

    def command_force(self, force: float, speed: float | None = None) -> None:
        """Force mode: close until the mean jaw normal force is ``force`` (N), hold it. Not
        yet gripping, the drive starts from its first stiffness guess at that force."""
        force = finite('force', force)
        limit = self.config['gripper.max_force']
        if force <= 0 or force > limit:
            raise CommandError(f'force {force} N is out of range (0, {limit}] N')
        speed = self._speed(speed, self.config['gripper.close_speed'])
        stiffness = (self._grip.stiffness if self._grip_force() > 0.0
                     else self.kinematics.first_stiffness(force))
        self._grip = replace(self._grip, mode='force', target_force=force, speed=speed,
                             stiffness=stiffness)

    def command_open(self, speed: float | None = None) -> None:
        """Position mode back to the initial gap."""
        self.command_gap(self.initial_gap, speed)
        self._slip_reference = None

    def command_lift(self, height: float, speed: float | None = None) -> None:
        """Move the gripper (jaw centre) to height ``height`` (m)."""
        height = finite('lift height', height)
        low, high = lift_range(self.config)
        if height < low - 1e-12 or height > high:
            below = (' (the jaws may not go below the table)'
                     if self.config['world.table'] else '')
            raise CommandError(f'lift height {height} m is out of range [{low:.4g}, '
                               f'{high:.4g}] m{below}')
        speed = self._speed(speed, self.config['gripper.lift_speed'])
        self._grip = replace(self._grip, target_lift=height, lift_speed=speed)

    def command_transport(self, x: float, speed: float | None = None) -> None:
        """Move the gripper centre (both jaws) sideways to ``x`` (m) at ``speed`` (m/s)."""
        x = finite('transport x', x)
        low, high = transport_range(self.config)
        if not low <= x <= high:
            raise CommandError(f'transport x {x} m is out of range [{low:g}, {high:g}] m')
        speed = self._speed(speed, self.config['gripper.transport_speed'])
        self._grip = replace(self._grip, target_x=x, x_speed=speed)

    def hold(self) -> None:
        """Stop the jaws where they are (position mode at the current gap)."""
        self._grip = replace(self._grip, mode='position', target_gap=self._grip.gap)

    def mark_slip_reference(self) -> None:
        """Measure slip from the fruit's present position relative to the jaws."""
        self._slip_reference = float(self._last.centroid[-1] - self._grip.lift)
        self._held_slip = 0.0

    def measure_slip(self, relative_z: float, both: bool, touching: bool) -> float:
        """m, the fruit's vertical motion relative to the jaws since both jaws first held
        it (or since ``mark_slip_reference``), from ``relative_z`` (m, centroid height over
        the jaw centre). While no jaw touches the fruit (released, or dropped) it stays at
        its last value: the fruit is then no longer moving in the jaws. A step's measure:
        it sets the slip reference when both jaws first hold (``both``) and keeps the slip
        while a jaw touches (``touching``)."""
        if both and self._slip_reference is None:
            self._slip_reference = relative_z
        if self._slip_reference is None:
            return 0.0
        if touching:
            self._held_slip = abs(self._slip_reference - relative_z)
        return self._held_slip

    def set_parameter(self, key: str, value: Any) -> None:
        """Change a dynamic configuration key while running (see DYNAMIC_KEYS)."""
        if key not in DYNAMIC_KEYS:
            raise ConfigError(f"config key '{key}' cannot change while running")
        self.config = self.config.replaced({key: value})
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
        """s, the simulated time since ``reset``."""
        return self._time

    @property
    def step_count(self) -> int:
        """The steps taken since ``reset`` (``StepResult.step`` of the last one)."""
        return self._step

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

    @property
    def has_observers(self) -> bool:
        """Whether a callback sees every step (``add_observer``)."""
        return bool(self._observers)

    # ------------------------------------------------------------------ what a step reads
    # Read-only views for the compiled routes (``core.fast``, ``core.multistep``), which
    # step this simulation and hand back what they computed (``commit_step``,
    # ``commit_advance``).
    @property
    def faces_template(self) -> list:
        """The obstacles as configured (``_make_faces``): the jaw faces first, each at
        its jaw's origin offset by ``face_offsets``, then the fixed ones (table, walls).
        A new list after ``reset`` and ``set_parameter``: compare it by identity to know
        when it changed. Read only."""
        return self._faces_template

    @property
    def face_sides(self) -> list[int]:
        """The jaw (LEFT 0, RIGHT 1) of each of the first ``len(face_sides)`` obstacles
        of ``faces_template``, the jaw faces."""
        return self._face_side

    @property
    def face_offsets(self) -> list[np.ndarray]:
        """(d,) m, each jaw face's origin relative to its jaw's origin
        (``_jaw_origin``)."""
        return self._face_offsets

    @property
    def plain_jaws(self) -> bool:
        """Whether the jaws are one flat rigid face each (no shaped finger, pad or
        deformable finger): a jaw's force is then the normal force on its face."""
        return self._plain_jaws

    @property
    def pad(self):
        """The soft pad layer on the jaw faces (``core.pad.PadLayer``, 3D
        ``core3d.fingers_pad.PadLayer3D``), None without pads."""
        return self._pad

    @property
    def damage_tracker(self):
        """The damage tracker of this run (``core.damage.DamageTracker``, 3D
        ``core3d.damage.DamageTracker3D``; a new one after ``reset``)."""
        return self._damage

    @property
    def jaw_forces(self) -> tuple[float, float]:
        """(left, right) N, each jaw's force on the fruit along its closing axis at the
        end of the last solve (the pads' push included): what the jaw drive reads."""
        return self._jaw_force

    @property
    def slip_reference(self) -> float | None:
        """m, the centroid's height over the jaw centre when slip began to be measured
        (``measure_slip``), None before both jaws held the fruit."""
        return self._slip_reference

    @property
    def held_slip(self) -> float:
        """m, the slip distance at the last step a jaw touched the fruit."""
        return self._held_slip

    # ------------------------------------------------------------------ committing
    def commit_step(self, positions: np.ndarray, velocities: np.ndarray,
                    contacts: cm.ContactState, contact_forces: np.ndarray,
                    grip: GripperState, jaw_forces: tuple[float, float], dt: float) -> None:
        """Take the end of one solved step of ``dt`` s as the state: the fruit's
        positions (n, d) m and velocities (n, d) m/s, its contact set and contact forces
        (n, d) N, the gripper state ``grip`` and the jaw forces (left, right) N
        (``jaw_forces``). Every route of a step (generic, soft, compiled) commits here."""
        self.q, self.v, self.contacts = positions, velocities, contacts
        self.contact_forces = contact_forces
        self._grip = grip
        self._time += dt
        self._jaw_force = jaw_forces

    def commit_advance(self, positions: np.ndarray, velocities: np.ndarray,
                       contacts: cm.ContactState, contact_forces: np.ndarray, *,
                       grip: GripperState, jaw_forces: tuple[float, float], time: float,
                       steps: int, solves: int, newton_iterations: int,
                       slip_reference: float | None, held_slip: float,
                       last_iterations: int) -> StepResult:
        """Take the end of ``steps`` steps run at once (``core.multistep``) as the
        state, as ``commit_step`` and ``step`` would have left it: the fruit's positions,
        velocities, contact set and contact forces, the gripper state, the jaw forces (N),
        the time (s), the ``gap_solves`` (``solves``) and ``newton_iterations`` they took,
        the slip reference and held slip (m, ``slip_reference``, ``held_slip``). Measures
        the last step (``last_iterations``: its Newton iterations) and returns its result
        (``last``); no observer is called (a run with observers steps with ``step``)."""
        self.q, self.v, self.contacts = positions, velocities, contacts
        self.contact_forces = contact_forces
        self._grip = grip
        self._time = time
        self._jaw_force = jaw_forces
        self._slip_reference = slip_reference
        self._held_slip = held_slip
        self._step += steps
        self.gap_solves += solves
        self.newton_iterations += newton_iterations
        self._last = self._measure(last_iterations, 1)
        return self._last

    # ------------------------------------------------------------------ stepping
    def step(self) -> StepResult:
        """Advance one step of ``dt``.

        Raises:
            ConvergenceError: the step failed even after halving; the state is unchanged.
        """
        saved = self._saved_state()
        try:
            iterations, substeps = self._advance(self.dt, 0)
        except ConvergenceError:
            self._restore(saved)
            raise
        self._step += 1
        self.newton_iterations += iterations
        self._last = self._measure(iterations, substeps)
        for callback in self._observers:
            callback(self._last)
        return self._last

    def advance(self, rules) -> 'tuple[StepResult, Any] | None':
        """Many steps at once until ``rules`` (``core.multistep.StopRules``) stop: (the last
        step's result, ``core.multistep.Skipped``), or None where only ``step`` applies
        (here: always; the 2D kernel route has it, see ``core.multistep``)."""
        return None

    def run(self, duration: float) -> StepResult:
        """Step for ``duration`` seconds; returns the last result."""
        for _ in range(max(1, int(round(duration / self.dt)))):
            self.step()
        return self._last

    def gripper_after(self, dt: float) -> GripperState:
        """The gripper state after a step of ``dt`` (s) from the present one, from the
        last step's jaw forces; the jaws at the drive's corrected gap while
        ``_drive_jaws`` re-solves a step. Changes nothing."""
        left_n, right_n = self._jaw_force
        force = 0.5 * (left_n + right_n)
        if self._gap_override is not None:
            return self.kinematics.moved(self._grip, dt, self._gap_override, force)
        return self.kinematics.advance(self._grip, dt, force, left_n > 0 and right_n > 0,
                                       self._jaw_clearance())

    def _grip_force_goal(self, grip: GripperState, dt: float):
        """(goal N, lowest gap m, highest gap m) the drive meets in the step from ``grip``:
        force mode its command anywhere the speed allows; position mode the maximum
        effort, the gap no smaller than the servo's own step."""
        lo, hi = self.kinematics.gap_bounds(grip, dt)
        if grip.mode == 'force':
            return grip.target_force, lo, hi
        servo = self.kinematics.servo_gap(grip, dt)
        return grip.max_effort, servo, max(servo, hi)

    def _drive_jaws(self, dt: float) -> int:
        """One step of ``dt`` (``_substep``) whose end meets the jaw drive's force goal
        (see the module docstring); returns the Newton iterations of every solve.

        Raises:
            NewtonFailure: the first solve failed (the state is back at the step's start).
        """
        if self._barrier is not None and self._soft is None:
            # the barrier's contact force is not monotone in the gap within a step (the
            # solve starts from a feasible, pushed-ahead outline): the prediction only
            goal = self._grip_force_goal(self._grip, dt)[0]
            gap, force = self._grip.gap, self._grip_force()
            self.gap_solves += 1
            iterations = self._substep(dt)
            return self._kept_stiffness(jaw_drive.adapted_stiffness(
                self._grip.stiffness, goal, gap, force, self._grip.gap, self._grip_force()),
                iterations)
        saved = self._saved_state()
        goal, lo, hi = self._grip_force_goal(self._grip, dt)
        start_gap = self._grip.gap
        damped = self.kinematics.damping_rate(self._grip, dt)
        stiffness = self._grip.stiffness + damped   # the slope of the miss in the gap
        iterations = 0
        tried = np.empty((MAX_GAP_SOLVES, 3))   # the solves' rows, see ``jaw_drive``
        count = 0
        ends: list = []   # the contact set at the end of each solve in ``tried``
        gap = math.nan    # the first solve: at the predicted gap
        force = self._grip_force()
        if (self._soft is not None and self._grip.mode == 'force' and lo <= start_gap <= hi
                and force > 0.0):
            gap = jaw_drive.first_gap(start_gap, self._grip.gap_rate, force, goal, stiffness,
                                      lo, hi, dt)
        try:
            for _ in range(MAX_GAP_SOLVES):
                near = jaw_drive.nearest_solve(tried, count, gap)
                try:
                    iterations += self._solve_at(None if math.isnan(gap) else gap, dt,
                                                 ends[near] if near >= 0 else None)
                except NewtonFailure:
                    if count == 0:
                        raise
                    self._restore(saved)
                    gap = jaw_drive.halfway(tried, count, gap)
                    continue
                left_n, right_n = self._jaw_force
                both = left_n > 0 and right_n > 0
                gap = self._grip.gap
                miss = jaw_drive.grip_miss(left_n, right_n, goal, gap, start_gap, damped)
                ends.append(self.contacts)
                count, stiffness, action = jaw_drive.record_solve(
                    tried, count, gap, miss, both, stiffness, goal, lo, hi)
                if action == jaw_drive.DONE:
                    return self._kept_stiffness(
                        jaw_drive.contact_stiffness(stiffness, damped, self._grip.stiffness),
                        iterations)
                if action == jaw_drive.SETTLE:
                    break
                gap = jaw_drive.next_gap(tried, count, stiffness, goal, lo, hi,
                                         math.inf if both else self._jaw_clearance())
                self._restore(saved)
                if math.isnan(gap):
                    break
            best = jaw_drive.settle_on(tried, count, gap)
            if best >= 0:
                self._restore(saved)
                iterations += self._solve_at(tried[best, 0], dt, ends[best])
        finally:
            self._gap_override = None
        return self._kept_stiffness(
            jaw_drive.contact_stiffness(stiffness, damped, self._grip.stiffness), iterations)

    def _grip_force(self) -> float:
        """N, the mean of the jaws' forces if both touch the fruit, else 0."""
        left_n, right_n = self._jaw_force
        return 0.5 * (left_n + right_n) if left_n > 0 and right_n > 0 else 0.0

    def _kept_stiffness(self, stiffness: float, iterations: int) -> int:
        """Keep ``stiffness`` (N/m, the contact's) in the gripper state for the next
        step's prediction; returns ``iterations``."""
        if stiffness != self._grip.stiffness:
            self._grip = replace(self._grip, stiffness=stiffness)
        return iterations

    def _solve_at(self, gap: float | None, dt: float, contacts=None) -> int:
        """``_substep(dt)`` with the jaws at ``gap`` (m; None: where the kinematics put
        them), its contact passes starting from the contact set ``contacts`` (an earlier
        solve's of this step, at a nearby gap: it is mostly the right one, and the passes
        only correct it) or from the step's start (None); Newton iterations."""
        if contacts is not None:
            self.contacts = contacts
        self._gap_override = gap
        self.gap_solves += 1
        return self._substep(dt)

    def _saved_state(self) -> tuple:
        """What a step changes (the state ``_restore`` returns to)."""
        return (self.q, self.v, self.contacts, self.contact_forces, self._grip, self._time,
                self._jaw_force, self._finger)

    def _restore(self, saved: tuple) -> None:
        """Back to a ``_saved_state``."""
        (self.q, self.v, self.contacts, self.contact_forces, self._grip, self._time,
         self._jaw_force, self._finger) = saved

    def _jaw_clearance(self) -> float:
        """m, the distance along x from the fruit to the nearest flat jaw face that does
        not touch it (``jaw_drive.clearance``); inf when both jaws touch, and where no
        plane gives it (``clearance_is_planar``)."""
        left_n, right_n = self._jaw_force
        if (left_n > 0 and right_n > 0) or not self.clearance_is_planar:
            return math.inf
        x = self.q[:, 0]
        return jaw_drive.clearance(float(x.min()), float(x.max()), self._grip.x,
                                   self._grip.gap, left_n > 0, right_n > 0)

    @property
    def clearance_is_planar(self) -> bool:
        """Whether a jaw's clearance is a flat face's: not for arc and V-groove fingers
        and soft pads (the fruit enters their recess or layer)."""
        return (self.config.get('gripper.finger.type', 'flat') == 'flat' and self._soft is None
                and not self.config.get('gripper.finger.pad.enabled', False))

    # ------------------------------------------------------------------ jaws
    def _jaw_origin(self, grip: GripperState, side: int) -> np.ndarray:
        """(d,) m, centre of the jaw's front face (where the gap is measured)."""
        sign = -1.0 if side == LEFT else 1.0
        return self._in_plane(grip.x + sign * 0.5 * grip.gap, grip.lift)

    def _in_plane(self, x: float, z: float) -> np.ndarray:
        """(d,) the point (x, z) of the gripper's plane (y = 0 in 3D)."""
        return np.array([x, z]) if self.dimension == 2 else np.array([x, 0.0, z])

    def faces_at(self, grip: GripperState) -> list:
        """The obstacles (``faces_template``) with the jaw faces where the gripper state
        ``grip`` puts them, moving with it: copies of the template's (the fixed faces,
        table and walls, the template's own), read only. The faces of the last three jaw
        placements made are kept: a step's end faces are its measures' and the next step's
        start faces, and the jaw drive's second solve at another gap starts from the same
        faces as its first."""
        template = self._faces_template
        placement = (grip.x, grip.gap, grip.lift, grip.x_rate, grip.gap_rate, grip.lift_rate)
        for kept_placement, kept_template, faces in self._faces_kept:
            if kept_placement == placement and kept_template is template:
                return faces
        faces = list(template)
        for index, side in enumerate(self._face_side):
            sign = -1.0 if side == LEFT else 1.0
            faces[index] = template[index].moved(
                self._jaw_origin(grip, side) + self._face_offsets[index],
                self._in_plane(grip.x_rate + sign * 0.5 * grip.gap_rate, grip.lift_rate))
        self._faces_kept = ((placement, template, faces),) + self._faces_kept[:2]
        return faces

    def _jaw_faces(self, side: int) -> list[int]:
        """Obstacle indices of the faces of jaw ``side`` (LEFT or RIGHT)."""
        return [i for i, s in enumerate(self._face_side) if s == side]

    def _pad_faces(self, grip: GripperState) -> list:
        """(face, jaw side, obstacle index) of every jaw face, for the pads."""
        faces = self.faces_at(grip)
        return [(faces[i], side, i) for i, side in enumerate(self._face_side)]

    @property
    def obstacle_names(self) -> tuple:
        """The obstacles' names (``StepResult.obstacle_names``), kept per face set."""
        kept = self._names_kept
        if kept is None or kept[0] is not self._faces_template:
            names = tuple(f.name for f in self._faces_template)
            names = ('left_jaw', 'right_jaw') + names if self._soft is not None else names
            kept = self._names_kept = (self._faces_template, names)
        return kept[1]

    def _held_measures(self, x: np.ndarray, obstacle: np.ndarray) -> tuple | None:
        """With deformable fingers, where the fruit's barrier kept its forces at the
        present state, the fruit's positions ``x`` (n, 2) m and the body holding each node
        ``obstacle`` (n,): (each node's normal force (n,) N, the nodes each jaw holds
        (left, right) (n,) bool, whether the left and the right jaw hold any, the held
        outline's length m, (the width m, the largest skin strain, the peak line
        pressure Pa, each outline node's pressure (n_s,) Pa)), in one compiled call
        (``soft_step_kernels.held_measures``); else None."""
        n = len(obstacle)
        surface, skin, rest_segments = outline_at_rest(self.fruit)
        self._obstacles(self._grip)  # (keeps each obstacle's jaw side)
        side_of_obstacle = self._obstacles_kept[-1]
        normal, lengths, pressure = np.empty(n), np.empty(len(surface)), np.empty(len(surface))
        left, right, held = np.empty(n, bool), np.empty(n, bool), np.empty(n, bool)
        kept, any_left, any_right, length, width, max_strain, peak = ssk.held_measures(
            self._barrier.part, self._joined(x, self._finger.positions).ravel(), x, obstacle,
            side_of_obstacle, surface, skin, rest_segments, float(self.fruit.depth), normal,
            left, right, held, lengths, pressure)
        if not kept:
            return None
        return (normal, (left, right), bool(any_left), bool(any_right), float(length),
                (float(width), float(max_strain), float(peak), pressure))

    def _obstacles(self, grip: GripperState):
        """(normals (k, d), jaw side (k,) or -1, velocities (k, d) m/s) of the k obstacles
        (``obstacle_names``) where ``grip`` puts them; a deformable finger counts as a face
        along its backing. The normals and sides are kept per face set, the velocities
        while the gripper's rates stay (all read only)."""
        template = self._faces_template
        kept = self._obstacles_kept
        if kept is None or kept[0] is not template:
            faces = list(template)
            normals = [f.normal for f in faces]
            velocities = [f.velocity for f in faces]
            sides = list(self._face_side) + [-1] * (len(faces) - len(self._face_side))
            if self._soft is not None:
                normals = [self._in_plane(1.0, 0.0), self._in_plane(-1.0, 0.0)] + normals
                velocities = [self._in_plane(0.0, 0.0)] * 2 + velocities
                sides = [LEFT, RIGHT] + sides
            normals, sides = np.array(normals, float), np.array(sides, np.int64)
            normals.flags.writeable = sides.flags.writeable = False
            # (obstacle, -1.0 left or 1.0 right) of the jaws' obstacles
            jaw_signs = tuple((int(k), -1.0 if sides[k] == LEFT else 1.0)
                              for k in np.flatnonzero(sides >= 0))
            # the jaw side of each obstacle, and last -1: an obstacle index's (-1: none)
            side_of_obstacle = np.append(sides, -1)
            kept = self._obstacles_kept = (template, normals, sides, np.array(velocities, float),
                                           jaw_signs, side_of_obstacle)
        _, normals, sides, velocities, jaw_signs, _ = kept
        rates = (grip.x_rate, grip.gap_rate, grip.lift_rate)
        moving = self._moving_kept
        if moving is None or moving[0] is not kept or moving[1] != rates:
            velocities = velocities.copy()  # the jaws' faces (and fingers) move with the gripper
            half_gap_rate = 0.5 * grip.gap_rate
            for k, sign in jaw_signs:
                velocities[k] = 0.0
                velocities[k, 0] = grip.x_rate + half_gap_rate * sign
                velocities[k, -1] = grip.lift_rate
            velocities.flags.writeable = False
            moving = self._moving_kept = (kept, rates, velocities)
        return normals, sides, moving[2]

    def _closing_forces(self, forces, obstacle) -> tuple:
        """(left, right) N, each jaw's hard-contact force on the fruit along its closing
        axis (the face normal for flat jaws: ``jaw_normal_forces``), summed over its faces.
        ``forces`` (n, d) N the contact force on each node, ``obstacle`` (n,) the
        obstacle holding it."""
        if self._plain_jaws:
            return self._jaw_normal_forces(forces, obstacle)[2]
        return tuple(sign * float(forces[np.isin(obstacle, self._jaw_faces(side)), 0].sum())
                     for side, sign in ((LEFT, 1.0), (RIGHT, -1.0)))

    # ------------------------------------------------------------------ measures
    def _common_measures(self, x: np.ndarray, v: np.ndarray, forces: np.ndarray,
                         obstacle: np.ndarray, iterations: int, substeps: int):
        """``_step_measures`` with every field built at once: (StepResult fields (dict),
        normal (n,) N, (on_left, on_right) (n,) bool)."""
        fields, rarely_read, normal, sides = self._step_measures(x, v, forces, obstacle,
                                                                 iterations, substeps)
        fields.update(rarely_read())
        return fields, normal, sides

    #: the StepResult fields ``_step_measures`` leaves to first read
    DEFERRED_MEASURES = ('left_wrench', 'right_wrench', 'slipping', 'contact_sticking',
                         'energies', 'fingers')

    def _step_measures(self, x: np.ndarray, v: np.ndarray, forces: np.ndarray,
                       obstacle: np.ndarray, iterations: int, substeps: int,
                       held: tuple | None = None):
        """What the 2D and 3D step results share, at the present gripper state.

        Args:
            x, v: (n, d) positions (m) and velocities (m/s).  forces: (n, d) N, every
            contact force on the fruit (pads included).  obstacle: (n,) the obstacle
            holding each node (pads included), -1 if none.  held: the deformable
            fingers' ``_held_measures`` of this state, if made.

        Returns:
            (StepResult fields (dict) but ``DEFERRED_MEASURES``, a callable giving those
            (dict; of this step's state, whenever called), normal (n,) N each node's
            normal contact force, (on_left, on_right) (n,) bool the nodes each jaw holds).
        """
        grip, fruit, finger, soft = self._grip, self.fruit, self._finger, self._soft
        normals, face_sides, face_velocities = self._obstacles(grip)
        if held is not None:
            normal, sides, on_left, on_right = held[:4]
        elif soft is not None:  # the barrier's force is normal to the finger's outline
            normal = np.empty(len(obstacle))
            held_normal_forces(self._barrier.normal_forces(
                self._joined(x, finger.positions).ravel()), obstacle, normal)
            sides = (np.empty(len(obstacle), bool), np.empty(len(obstacle), bool))
            on_left, on_right = cm.jaw_sides(obstacle, self._obstacles_kept[-1], *sides)
        else:
            on_left, on_right, jaw_forces, normal, sides = self._jaw_normal_forces(
                forces, obstacle)

        def jaw_origins() -> tuple:
            return self._jaw_origin(grip, LEFT), self._jaw_origin(grip, RIGHT)

        def jaw_wrenches(origins: tuple) -> list:
            if soft is not None:
                return self._finger_wrenches(finger, origins)
            return [_wrench(x[sides[side]] - origins[side], -forces[sides[side]])
                    for side in (LEFT, RIGHT)]
        wrenches = None  # built on first read where the grip force needs none
        if self._plain_jaws:
            left_n, right_n = jaw_forces
        elif soft is not None:  # what the step committed: its fingers' base reactions
            left_n, right_n = self._jaw_force
        else:  # each jaw's force along the closing axis
            wrenches = jaw_wrenches(jaw_origins())
            left_n, right_n = -float(wrenches[LEFT].force[0]), float(wrenches[RIGHT].force[0])
        masses = fruit.masses
        centroid = masses @ x / self._total_mass(masses)
        slip = self.measure_slip(float(centroid[-1] - grip.lift), on_left and on_right,
                                 on_left or on_right)
        x, v, forces, obstacle = x.copy(), v.copy(), forces.copy(), obstacle.copy()
        sticking = self.contacts.mode == cm.STICK if soft is None else None
        fields = dict(
            time=self._time, step=self._step, positions=x, velocities=v,
            contact_forces=forces, contact_obstacle=obstacle,
            obstacle_names=self.obstacle_names, surface=fruit.surface,
            left_jaw_x=grip.x - 0.5 * grip.gap, right_jaw_x=grip.x + 0.5 * grip.gap,
            jaw_velocity=-0.5 * grip.gap_rate, lift=grip.lift, lift_velocity=grip.lift_rate,
            gap=grip.gap, grip_force=0.5 * (left_n + right_n), slip_distance=slip,
            centroid=centroid, newton_iterations=iterations, substeps=substeps,
            gripper_x=grip.x, gripper_x_velocity=grip.x_rate)

        def rarely_read() -> dict:
            origins = jaw_origins()
            jaws = wrenches if wrenches is not None else jaw_wrenches(origins)
            on_fingers = self._on_fingers(x, v, obstacle, finger) if soft is not None else None
            return dict(
                left_wrench=jaws[LEFT], right_wrench=jaws[RIGHT],
                slipping=(self._fingers_sliding(x, on_fingers) if soft is not None
                          else jaw_contacts_sliding(  # 3D: the patches' rigid motion
                              v, obstacle, face_sides, normals, face_velocities,
                              x if self.dimension == 3 else None)),
                contact_sticking=(sticking if soft is None else self._fingers_sticking(
                    v, obstacle, on_fingers, normals, face_velocities)),
                energies=Energies(
                    kinetic=float(0.5 * np.sum(masses * np.sum(v * v, axis=1))),
                    elastic=float(sum(e.value(x.ravel()) for e in fruit.energies)),
                    gravitational=float(self.gravity.value(x.ravel()))),
                fingers=soft.result(finger, *origins) if soft is not None else None)
        return fields, rarely_read, normal, sides

    def _fingers_sliding(self, x: np.ndarray, on_fingers: tuple) -> bool:
        """``StepResult.slipping`` with deformable fingers (``slip.patches_sliding``): the
        fruit's nodes held by a finger, at positions ``x`` (n, d) m, moving against the
        finger's surface where they lie on it as ``on_fingers`` (``_on_fingers``) gives."""
        held, relative, normals = on_fingers
        jaw = np.repeat([LEFT, RIGHT], [held[LEFT].size, held[RIGHT].size])
        return patches_sliding(relative, normals, jaw,
                               x[np.concatenate(held)] if self.dimension == 3 else None)

    def _fingers_sticking(self, v: np.ndarray, obstacle: np.ndarray, on_fingers: tuple,
                          normals: np.ndarray, velocities: np.ndarray) -> np.ndarray:
        """``StepResult.contact_sticking`` (n,) bool with deformable fingers: each node
        sticks where it moves along its obstacle slower than the barrier's friction
        smoothing speed (``barrier_kernels.mark_sticking``): one held by a finger
        (``obstacle`` (n,) 0 left, 1 right) along the finger's surface where it lies on it
        (``on_fingers``, ``_on_fingers``), one held by a face (the table) along that face
        (the obstacles' ``normals`` and ``velocities`` (k, d)); velocities ``v`` (n, d)."""
        smoothing = self._barrier.settings.friction_smoothing
        mode = np.zeros(len(obstacle), np.int64)
        mark_sticking(v, np.where(obstacle >= FIRST_FACE, obstacle, -1), normals, velocities,
                      smoothing, cm.STICK, cm.SLIP, mode)
        held, relative, surface_normals = on_fingers
        held = np.concatenate(held)
        on_surface = np.zeros(held.size, np.int64)   # each against its own surface point
        mark_sticking(relative, np.arange(held.size), surface_normals,
                      np.zeros_like(relative), smoothing, cm.STICK, cm.SLIP, on_surface)
        mode[held] = on_surface
        return mode == cm.STICK

    def _on_fingers(self, x: np.ndarray, v: np.ndarray, obstacle: np.ndarray,
                    finger: FingerState) -> tuple:
        """The fruit's nodes held by each finger (``obstacle`` (n,) 0 left, 1 right) and
        their motion against the finger's surface where they lie on it
        (``slip.surface_motion``), not against its backing (a finger that bends under the
        fruit carries the nodes stuck to it): ((the left finger's nodes, the right's),
        their velocities relative to the surface (k, d) m/s, its unit normals there (k,
        d)); positions ``x``, velocities ``v`` (n, d), the fingers' state ``finger``."""
        held = [np.flatnonzero(obstacle == side) for side in (LEFT, RIGHT)]
        relative, normals = [], []
        for nodes, elements in zip(held, self._soft.surface_elements):
            velocity, normal = surface_motion(x[nodes], elements, finger.positions,
                                              finger.velocities)
            relative.append(v[nodes] - velocity)
            normals.append(normal)
        return held, np.concatenate(relative), np.concatenate(normals)

    def _jaw_normal_forces(self, forces: np.ndarray, obstacle: np.ndarray) -> tuple:
        """(whether the left jaw holds any node, whether the right does, (the left jaw's
        summed normal force, the right's) N, each node's normal force (n,) N, (the nodes
        the left jaw holds, the right's) (n,) bool) of the contact forces ``forces``
        (n, d) N on nodes held by ``obstacle`` (n,) (``measures.jaw_normal_forces``)."""
        n = len(obstacle)
        normal, sides = np.empty(n), (np.empty(n, bool), np.empty(n, bool))  # LEFT, RIGHT
        normals = self._obstacles(self._grip)[0]
        any_left, any_right, left, right = jaw_normal_forces(
            obstacle, np.ascontiguousarray(forces), normals, self._obstacles_kept[-1],
            *sides, normal, np.empty(n))
        return any_left, any_right, (float(left), float(right)), normal, sides

    def _total_mass(self, masses: np.ndarray) -> float:
        """kg, the sum of ``masses`` (n,) kg (``masses.sum()``), kept for the same array."""
        kept = self._mass_kept
        if kept is None or kept[0] is not masses:
            kept = self._mass_kept = (masses, masses.sum())
        return kept[1]

    def contact_forces_and_holders(self) -> tuple[np.ndarray, np.ndarray]:
        """(n, d) N every contact force on the fruit and (n,) the obstacle holding each
        node: the hard contacts' reactions, plus the pads' forces on the nodes that press
        a pad (held by the pad's face) if there are pads."""
        obstacle = self.contacts.obstacle.copy()
        if self._pad is None:
            return self.contact_forces, obstacle
        on_pad = (obstacle < 0) & (self._pad.holder >= 0)
        obstacle[on_pad] = self._pad.holder[on_pad]
        return self.contact_forces + self._pad.forces, obstacle

    # ------------------------------------------------------------------ stepping
    #: the contact passes' ``ContactSettings.deepest_first`` (0: every penetrating node
    #: is held at once)
    deepest_first = 0.0

    def _substep(self, dt: float) -> int:
        """One implicit step of ``dt``, the soft pads (if any) set up around it; returns
        Newton iterations. Raises NewtonFailure (the caller halves the step)."""
        if self._pad is None:
            return self._substep_hard(dt)
        grip_new = self.gripper_after(dt)
        self._pad.begin_step(self.q, self._pad_faces(self._grip), self._pad_faces(grip_new), dt)
        iterations = self._substep_hard(dt)
        self._pad.finish_step(self.q.ravel())
        hard = self._jaw_force
        self._jaw_force = (hard[0] + float(self._pad.side_force[0]),
                           hard[1] + float(self._pad.side_force[1]))
        return iterations

    def _substep_hard(self, dt: float) -> int:
        """One step with the hard contacts (the pads, if any, set up by the caller)."""
        grip_new = self.gripper_after(dt)
        new_faces = self.faces_at(grip_new)
        if self._soft is not None:
            return self._substep_soft(dt, grip_new, new_faces)
        if self._barrier is not None:
            outcome = barrier_step(self.solver, self._barrier, self.q, self.v,
                                   self.faces_at(self._grip), new_faces, dt,
                                   self._predicted_velocities(grip_new, self.v))
        else:
            outcome = contact_step(self.solver, self.fruit.surface, self.contacts, self.q,
                                   self.v, self.faces_at(self._grip), new_faces, dt,
                                   ContactSettings.from_config(self.config,
                                                               self.deepest_first))
        self.commit_step(outcome.x, outcome.v, outcome.contacts, outcome.forces, grip_new,
                         self._closing_forces(outcome.forces, outcome.contacts.obstacle), dt)
        return outcome.iterations

    def _predicted_velocities(self, grip_new: GripperState, v: np.ndarray,
                              while_on_faces: bool = True) -> np.ndarray | None:
        """(k, d) m/s, where both jaws held the fruit in the last step and the gripper
        moves (lifts or transports) in the step to ``grip_new``, the velocities of a
        barrier step's predicted start (``barrier_step``, ``soft_body_step``): ``v``
        (k, d) m/s (the fruit's, then any deformable fingers'), each plus the change of
        the gripper's own velocity (not the jaws' closing): a held fruit, and the fingers
        holding it, are carried. None elsewhere, and, unless ``while_on_faces``, where a
        face (the table) touches the fruit.

        With rigid fingers, from its velocities alone (2D), a lift's or a transport's
        start and stop left every node of a held fruit 5 times the friction smoothing
        speed behind its jaws, and Newton crossed the friction law's kink: 6 to 10
        iterations a step instead of 3; from x_n (3D), 9 a step while lifting
        (``docs/performance.md``). A Fin Ray finger bends under the fruit's weight while
        the table still bears it: the fruit is not carried yet. Its grasp's lift of 1 cm
        took 640 Newton iterations at 4 N (649 at 8 N) carried once off the table, 663
        (765) from v_n, 697 (735) carried from the lift's start on and 1806 (1485) with
        the fingers carried alone.
        """
        left, right = self._jaw_force
        grip = self._grip
        if (left <= 0.0 or right <= 0.0
                or not (grip.x_rate or grip.lift_rate or grip_new.x_rate or grip_new.lift_rate)):
            return None
        if not while_on_faces and bool((self.contacts.obstacle >= FIRST_FACE).any()):
            return None
        return v + self._in_plane(grip_new.x_rate - grip.x_rate,
                                  grip_new.lift_rate - grip.lift_rate)

    def _substep_soft(self, dt: float, grip_new: GripperState, new_faces: list) -> int:
        """One step of the fruit and the deformable fingers (``barrier.soft_body_step``),
        the fingers' bases on the jaws where ``grip_new`` puts them; Newton iterations."""
        soft, n, finger = self._soft, self.fruit.n_nodes, self._finger
        targets = soft.base_targets(self._jaw_origin(grip_new, LEFT),
                                    self._jaw_origin(grip_new, RIGHT))
        m_both = soft.n_nodes

        def carried():  # each finger's nodes and its base's shift (``soft_body_step``)
            m = m_both // 2
            return [(n + side * m + np.arange(m),
                     self._jaw_origin(grip_new, side) - self._jaw_origin(self._grip, side))
                    for side in (LEFT, RIGHT)]
        v_n = self._joined(self.v, finger.velocities)
        outcome = soft_body_step(self.solver, self._barrier,
                                 self._joined(self.q, finger.positions), v_n, soft.base,
                                 targets, self.faces_at(self._grip), new_faces, dt,
                                 self_contact=soft.self_contact, carried=carried,
                                 v_predicted=self._predicted_velocities(grip_new, v_n,
                                                                         while_on_faces=False))
        x, v = outcome.x[:n], outcome.v[:n]
        # the fruit's partners 1 + finger, 1 + 2 + face: the obstacles left_jaw,
        # right_jaw (the fingers), then the faces
        obstacle, touching = np.empty(n, np.int64), np.empty(m_both, bool)
        split_partners(outcome.contacts.obstacle, obstacle, touching)
        # held by ``obstacle``, the rest of the outcome's fresh contact set (all FREE, no
        # forces, no second obstacle: ``ContactState.held_by``) cut to the fruit's nodes
        _, mode, normal_force, bounce_speed, secondary, secondary_bounce = (
            outcome.contacts.arrays())
        contacts = cm.ContactState(obstacle, mode[:n], normal_force[:n], bounce_speed[:n],
                                   secondary[:n], secondary_bounce[:n])
        self._finger = finger = build(FingerState, dict(
            positions=outcome.x[n:], velocities=outcome.v[n:], contact_forces=outcome.forces[n:],
            reaction=outcome.reaction[n:], touching=touching))
        self._joined_kept = ((x, finger.positions, outcome.x),
                             (v, finger.velocities, outcome.v))
        self.commit_step(x, v, contacts, outcome.forces[:n], grip_new,
                         self._finger_jaw_forces(), dt)
        return outcome.iterations

    def _joined(self, fruit: np.ndarray, fingers: np.ndarray) -> np.ndarray:
        """``np.concatenate([fruit, fingers])``: the fruit's rows (n, d) of a quantity
        and the deformable fingers' (m, d) as one array (n + m, d); where both are the
        views of one array a solve gave (``_substep_soft``), that array (read only)."""
        for fruit_rows, finger_rows, whole in self._joined_kept:
            if fruit_rows is fruit and finger_rows is fingers:
                return whole
        return np.concatenate([fruit, fingers])

    def _finger_wrenches(self, finger: FingerState, origins: tuple) -> list[JawWrench]:
        """What each jaw feels at its deformable finger's base nodes (the reaction that
        holds them on it) in the fingers' state ``finger``, about the backings' centres
        ``origins`` (left, right) (d,) m; zero for a finger that does not touch the fruit
        (its inertia and weight are no grip)."""
        wrenches = []
        for (nodes, own), origin in zip(self._finger_bases(), origins):
            if not finger.touching[own].any():
                nodes = nodes[:0]
            wrenches.append(_wrench(finger.positions[nodes] - origin, -finger.reaction[nodes]))
        return wrenches

    def _finger_jaw_forces(self) -> tuple[float, float]:
        """(left, right) N, each jaw's force on the fruit along its closing axis through
        its deformable finger: the x part of its ``_finger_wrenches`` force (the same
        sum), without the rest of the wrench."""
        finger = self._finger
        (left, _), (right, _) = self._finger_bases()
        return base_pushes(finger.reaction, finger.touching, left, right,
                           self._soft.body.n_nodes)

    def _finger_bases(self) -> tuple:
        """Per jaw (LEFT, RIGHT): (its finger's base nodes, the slice of its finger's
        nodes), as indices into the fingers' state."""
        if self._jaw_bases is None:
            soft = self._soft
            base, m = soft.base - soft.first, soft.body.n_nodes
            self._jaw_bases = tuple((base[mine], slice(side * m, (side + 1) * m))
                                    for side, mine in zip((LEFT, RIGHT), soft.sides_of_base()))
        return self._jaw_bases

    def _advance(self, dt: float, depth: int) -> tuple[int, int]:
        """Step ``dt``, halving it (recursively) while Newton fails; (iterations, substeps)."""
        try:
            return self._drive_jaws(dt), 1
        except NewtonFailure as failure:
            if self._pattern_grown():  # the step again, every coupling in the matrix
                return self._advance(dt, depth)
            if depth >= self.config['sim.max_halvings']:
                self._check_fingers_open(failure)
                msg = (f'the solver did not converge at t = {self._time:.6g} s even in '
                       f'sub-steps of {dt:.3g} s (the step halved {depth} times: '
                       f'{failure}); {self._convergence_advice(failure)}')
                raise ConvergenceError(msg, failure.history, self._time) from failure
        it1, s1 = self._advance(0.5 * dt, depth + 1)
        it2, s2 = self._advance(0.5 * dt, depth + 1)
        return it1 + it2, s1 + s2

    def _check_fingers_open(self, failure: NewtonFailure) -> None:
        """FingersClosed if the deformable fingers' step ``failure`` (in its smallest
        sub-step) found no collision-free start because the fingers' outlines have come
        within ``FINGERS_MEET`` of each other over the fruit: the jaws close them on each
        other (the model has no finger-to-finger contact) with the fruit's outline pinched
        between them."""
        if not isinstance(failure, NoCollisionFreeStart):
            return
        gap = self._barrier.bodies_gap(self._joined(self.q, self._finger.positions))
        if gap < FINGERS_MEET:
            raise FingersClosed(
                f'the fingers closed on each other over the fruit at t = {self._time:.6g} s '
                f'(their outlines {gap * 1e6:.2g} um apart): its outline is pinched between '
                f'them (crushed there; the model has no contact between the fingers) and the '
                f'jaws close no further; a smaller grip force avoids it, or fingers whose '
                f'rigid parts meet at a smaller jaw gap',
                failure.history, self._time, gap) from failure

    def _pattern_grown(self) -> bool:
        """Whether a barrier's Hessian pattern (the fruit's, the fingers' self-contact)
        grew to hold the pairs near contact after a failed step left couplings out of the
        Newton matrix (``BarrierContact.grow_pattern``); the solver is then made anew
        over it."""
        if self._soft is None:
            return False
        x = self._joined(self.q, self._finger.positions)
        grown = [barrier.grow_pattern(x) for barrier in self._patterned_barriers()]
        if not any(grown):
            return False
        self.solver = self._make_solver()
        return True

    def _patterned_barriers(self) -> list:
        """The barriers whose Hessian pattern may grow: the fruit's, the fingers'
        self-contact (those present)."""
        soft = self._soft
        return [b for b in (self._barrier, soft.self_contact if soft else None)
                if b is not None]

    def _convergence_advice(self, failure: NewtonFailure) -> str:
        """What may help a step that failed in its smallest sub-steps (a smaller sim.dt
        would only repeat them)."""
        c = self.config
        if 'infeasible' in str(failure):  # an element inverted: crushed
            body = ('the fruit' if self._soft is None
                    else f"the fruit or of a {c['gripper.finger.type']} finger")
            return (f'an element of {body} inverted (it is crushed): a smaller grip force, '
                    'gap command or closing speed helps; a smaller sim.dt would only repeat '
                    'these sub-steps')
        return (f"raise sim.max_newton_iterations (now {c['sim.max_newton_iterations']}) "
                f"or sim.max_halvings (now {c['sim.max_halvings']}); a smaller sim.dt would "
                f'only repeat these sub-steps')


def _wrench(r: np.ndarray, f: np.ndarray) -> JawWrench:
    """The net force (3,) N and torque (3,) N m of forces f (k, d) applied at r (k, d) m
    from the reference point; planar (x, z) vectors have y = 0."""
    if r.shape[1] == 2:
        return JawWrench(np.array([f[:, 0].sum(), 0.0, f[:, 1].sum()]),
                         np.array([0.0, float(np.sum(r[:, 1] * f[:, 0] - r[:, 0] * f[:, 1])),
                                   0.0]))
    torque = np.array([np.sum(r[:, 1] * f[:, 2] - r[:, 2] * f[:, 1]),
                       np.sum(r[:, 2] * f[:, 0] - r[:, 0] * f[:, 2]),
                       np.sum(r[:, 0] * f[:, 1] - r[:, 1] * f[:, 0])])
    return JawWrench(f.sum(axis=0), torque)
