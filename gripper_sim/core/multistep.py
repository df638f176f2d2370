"""Many steps in one compiled call, for runs that nobody watches step by step.

``Simulation.advance(rules)`` steps until the first step after which a grasp machine has
something to decide (``StopRules``) and returns that step's ``StepResult`` only, with what
the steps before it leave to the machine (``Skipped``: their peaks, which
``core.peaks.RunPeaks.include`` takes, a pick-and-place's slide). The steps are
those of ``Simulation.step`` - the same jaw drive (``core.jaw_drive``), whole-step kernel,
measures and damage - run by ``core.advance_kernels.advance`` on the 2D kernel route
(``core.fast``) when nothing observes every step. Where it does not apply (no kernel
route, observers, a damage model the kernel does not have) or the next step needs the
per-step route (a step whose first solve fails and is halved, one the kernel cannot
solve) ``advance`` returns None and the caller steps with ``Simulation.step``.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from gripper_sim.core import advance_kernels as ak
from gripper_sim.core import contact as cm
from gripper_sim.core import jaw_drive
from gripper_sim.core.fast import record_pad
from gripper_sim.core.gripper import GripperState
from gripper_sim.core.peaks import site_codes

if TYPE_CHECKING:
    from gripper_sim.core.results import StepResult


@dataclass
class StopRules:
    """When ``Simulation.advance`` stops: after the first step at which any of these holds
    (each off at its default).

    Attributes:
        grip_force: N; both jaws touch the fruit and the grip force is at least this.
        deadline: s; the time is past it.
        gap_closed: the jaws are at their stop (``GripperKinematics.min_gap``).
        phase_start, elapsed: s; the time since ``phase_start`` is at least ``elapsed``.
        lifted, moved: the lift, the transport (each one asked for) reached its target
            and stopped.
        gap_at: m; the gap is within 1e-9 m of it (NaN: off).
        drop: no jaw touches the fruit, or its slip exceeds ``drop_slip`` (m).
        bruise: the fruit is bruised where a jaw or the table presses (the step a run's
            ``RunPeaks.bruised_at`` is taken from).
        damaged: the fruit is bruised or crushed.
        end: s; the time reached it.
        max_steps: steps run.
        slide: integrate the fruit's slide along the jaws from ``slide_from`` (m: slide,
            largest slide, largest slip distance: ``core.slip.ContactSlide.state``);
            stop when the largest slide exceeds ``slide_limit`` (m).
    """

    grip_force: float = math.inf
    deadline: float = math.inf
    gap_closed: bool = False
    phase_start: float = 0.0
    elapsed: float = math.inf
    lifted: bool = False
    moved: bool = False
    gap_at: float = math.nan
    drop: bool = False
    drop_slip: float = math.inf
    bruise: bool = False
    damaged: bool = False
    end: float = math.inf
    max_steps: int = 1 << 40
    slide: bool = False
    slide_from: tuple = (0.0, 0.0, 0.0)
    slide_limit: float = math.inf

    def array(self) -> np.ndarray:
        """The rules as ``advance_kernels.advance`` takes them (S_SIZE,)."""
        values = np.empty(ak.S_SIZE)
        values[ak.S_FORCE] = self.grip_force
        values[ak.S_DEADLINE] = self.deadline
        values[ak.S_GAP_CLOSED] = float(self.gap_closed)
        values[ak.S_PHASE_START] = self.phase_start
        values[ak.S_ELAPSED] = self.elapsed
        values[ak.S_LIFTED] = float(self.lifted)
        values[ak.S_MOVED] = float(self.moved)
        values[ak.S_GAP_AT] = self.gap_at
        values[ak.S_DROP] = float(self.drop)
        values[ak.S_DROP_SLIP] = self.drop_slip
        values[ak.S_BRUISE] = float(self.bruise)
        values[ak.S_DAMAGED] = float(self.damaged)
        values[ak.S_END] = self.end
        values[ak.S_MAX_STEPS] = float(self.max_steps)
        values[ak.S_SLIDE] = float(self.slide)
        values[ak.S_SLIDE_LIMIT] = self.slide_limit
        return values


@dataclass
class Skipped:
    """What the steps before the last of a ``Simulation.advance`` call leave to a grasp
    machine that did not see them.

    Attributes:
        peaks: the largest (grip force N, compression m, jaw pressure Pa, table pressure
            Pa) of the steps run, the last included (``RunPeaks.include``).
        slide: (slide m, largest slide m, largest slip distance m) before the last step
            (``StopRules.slide``).
        previous_time: s, the time of the step before the last.
    """

    peaks: tuple
    slide: tuple
    previous_time: float


def grip_array(grip: GripperState) -> np.ndarray:
    """``grip`` as the kernel's (G_SIZE,) array (``advance_kernels``)."""
    return np.array([grip.gap, grip.gap_rate, grip.lift, grip.lift_rate,
                     1.0 if grip.mode == 'force' else 0.0, grip.target_gap, grip.target_force,
                     grip.speed, grip.target_lift, grip.lift_speed, grip.stiffness,
                     grip.measured_force, grip.measured_gap, grip.x, grip.x_rate,
                     grip.target_x, grip.x_speed, grip.max_effort], dtype=float)


def grip_state(values: np.ndarray) -> GripperState:
    """The ``GripperState`` of a kernel's grip array."""
    v = values.tolist()
    return GripperState(v[0], v[1], v[2], v[3], 'force' if v[4] > 0 else 'position', *v[5:])


class MultiStep:
    """The compiled multi-step advance of one ``FastPath`` (its scratch kept)."""

    def __init__(self, path: 'FastPath'):
        self.path = path
        n = path.n
        self._work_int = np.empty((3, n), np.int64)
        self._work_float = np.empty((3, n))
        self._ends_int = np.empty((jaw_drive.MAX_GAP_SOLVES, 3, n), np.int64)
        self._ends_float = np.empty((jaw_drive.MAX_GAP_SOLVES, 3, n))
        self._x_out, self._v_out = np.empty((n, 2)), np.empty((n, 2))
        self._site_of = None
        self._site = np.zeros(1, np.int64)

    def applies(self) -> bool:
        """Whether the simulation's steps can run here now: its kernel models the
        obstacles and the damage tracker, and nothing observes every step. (A
        ``FastPath`` exists only for the modified mass method's contact and rigid
        fingers: no barrier, no deformable fingers.)"""
        path = self.path
        return (not path.sim.has_observers and path.applies() and path.damage_supported())

    def _sites(self) -> np.ndarray:
        template = self.path.sim.faces_template
        if self._site_of is not template:
            self._site = site_codes(self.path.obstacle_names())
            self._site_of = template
        return self._site

    def advance(self, rules: StopRules) -> 'tuple[StepResult, Skipped] | None':
        """Steps until ``rules`` stop (see the module doc): (the last step's result, what
        the steps before it leave), or None when no step could be run here."""
        if not self.applies():
            return None
        path = self.path
        sim = path.sim
        n = path.n
        dt = sim.dt
        path.prepare(dt)
        face_par, face_dyn = path.face_arrays()
        c = sim.contacts
        x = np.array(sim.q, dtype=float, order='C')
        v = np.array(sim.v, dtype=float, order='C')
        c_int = np.array([c.obstacle, c.mode, c.secondary], dtype=np.int64)
        c_float = np.array([c.normal_force, c.bounce_speed, c.secondary_bounce], dtype=float)
        forces = np.empty((n, 2))
        grip = grip_array(sim.gripper_state)
        tracker = sim.damage_tracker
        reference = sim.slip_reference
        run = np.zeros(ak.R_SIZE)
        run[ak.R_TIME] = sim.time
        run[ak.R_JAW_LEFT], run[ak.R_JAW_RIGHT] = sim.jaw_forces
        run[ak.R_SLIP_REF] = math.nan if reference is None else reference
        run[ak.R_HELD_SLIP] = sim.held_slip
        run[ak.R_PEAK_PRESSURE] = tracker.peak_pressure
        run[ak.R_PEAK_STRESS] = tracker.peak_flesh_stress
        run[ak.R_CRUSHED] = float(tracker.crushed)
        run[ak.R_SLIDE], run[ak.R_MAX_SLIP], run[ak.R_MAX_DROP] = rules.slide_from
        kinematics = sim.kinematics
        failure_strain = tracker.failure_strain
        kin = np.array([kinematics.max_gap, kinematics.max_speed,
                        kinematics.lift_acceleration, kinematics.transport_acceleration, dt,
                        sim.fruit.rest_width, float(sim.plain_jaws),
                        float(sim.clearance_is_planar), float(path.flesh_in_kernel),
                        tracker.bruise_pressure, tracker.failure_stress,
                        math.nan if failure_strain is None else failure_strain,
                        kinematics.damping, kinematics.min_gap], dtype=float)
        peaks = np.zeros(ak.PEAK_SIZE)
        normal, pressure = np.empty(n), np.empty(len(path.surface))
        damage = list(path.damage_inputs())
        damage[3] = damage[3].copy()  # the cover before each step, kept by the kernel
        damage = tuple(damage)
        pad = sim.pad
        pad_k, pad_scalars, pad_out = path.pad_arguments(pad)
        timing = path.timing
        if timing:
            t0 = time.perf_counter()
        ak.advance(x, v, c_int, c_float, forces, grip, run, kin, rules.array(), peaks,
                   self._sites(), (face_par, face_dyn, *path.constants, path.fpar, path.ipar),
                   (path.history, path.out, normal, pressure, path.measures, path.counts),
                   damage, (pad_k, pad_scalars, *pad_out), path.scratch, self._work_int,
                   self._work_float, self._ends_int, self._ends_float, self._x_out, self._v_out)
        if timing:
            path.timers['kernel'] += time.perf_counter() - t0
        steps = int(run[ak.R_STEPS])
        if steps == 0:
            path.forget_end_measures()
            return None
        # the last step's measure takes its cover from damage[3]
        tracker.take_run(damage[3], float(run[ak.R_PEAK_PRESSURE]),
                         float(run[ak.R_PEAK_STRESS]), bool(run[ak.R_CRUSHED]))
        record_pad(pad, pad_out)
        path.keep_end_measures(x, normal, pressure, damage)
        slip_reference = float(run[ak.R_SLIP_REF])
        contacts = cm.ContactState(obstacle=c_int[0].copy(), mode=c_int[1].copy(),
                                   normal_force=c_float[0].copy(),
                                   bounce_speed=c_float[1].copy(), secondary=c_int[2].copy(),
                                   secondary_bounce=c_float[2].copy())
        last = sim.commit_advance(
            x, v, contacts, forces, grip=grip_state(grip),
            jaw_forces=(float(run[ak.R_JAW_LEFT]), float(run[ak.R_JAW_RIGHT])),
            time=float(run[ak.R_TIME]), steps=steps, solves=int(run[ak.R_SOLVES]),
            newton_iterations=int(run[ak.R_NEWTON]),
            slip_reference=None if math.isnan(slip_reference) else slip_reference,
            held_slip=float(run[ak.R_HELD_SLIP]), last_iterations=int(run[ak.R_ITERATIONS]))
        return last, Skipped(
            tuple(peaks.tolist()),
            (float(run[ak.R_SLIDE]), float(run[ak.R_MAX_SLIP]), float(run[ak.R_MAX_DROP])),
            float(run[ak.R_PREVIOUS_TIME]))


def next_result(sim, machine, end: float, watched: bool) -> 'tuple[StepResult, Skipped | None]':
    """The next result a grasp machine (``workflows.grasp.GraspMachine``) is to see: of
    one ``sim.step()``, or - when nothing ``watched`` every step and the machine gives
    ``stop_rules(end)`` (``StopRules``, None: the next step) - of the last step of a
    ``sim.advance`` call, whose skipped steps the machine then ``include``s; (the
    result, the ``Skipped`` or None)."""
    if not watched and hasattr(machine, 'stop_rules'):
        rules = machine.stop_rules(end)
        if rules is not None:
            ran = sim.advance(rules)
            if ran is not None:
                machine.include(ran[1])
                return ran
    return sim.step(), None
