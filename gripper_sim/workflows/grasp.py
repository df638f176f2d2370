"""A grasp as a step-driven state machine: close to a force, settle, lift, hold, release;
and ``evaluate``, the one function that runs a grasp and measures it.

Used by the offline ``pick`` command and by the node's Grasp action alike: after every
``sim.step()`` call ``update(result)``; it issues the simulation's commands itself.
``evaluate`` drives any such machine (``GraspSequence`` for ``pick``, the scenario's
``PickAndPlace`` for the grasp window and for studies) to its end - the steps at which
the machine decides nothing in one compiled call where it can (``Simulation.advance``,
``core.multistep``) when no ``on_step`` watches every step - and returns a
``GraspEvaluation``: the outcome, the peaks of force, compression and pressure, the
damage, and the solver's error if it failed.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Protocol

from gripper_sim.core.multistep import Skipped, StopRules, next_result
from gripper_sim.core.peaks import RunPeaks
from gripper_sim.core.results import StepResult
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.slip import ContactSlide, grasp_slipped
from gripper_sim.core.vocabulary import DROP_SLIP, damage_fields
from gripper_sim.errors import CommandError, ConvergenceError, FingersClosed

CLOSING, SQUEEZING, LIFTING, HOLDING, RELEASING, DONE = (
    'closing', 'squeezing', 'lifting', 'holding', 'releasing', 'done')

#: fraction of the target force at which closing ends
FORCE_REACHED = 0.97
#: time (s) the grip force is held on the table before lifting
SETTLE_TIME = 0.2
#: s of simulation a grasp may take beyond its phases' planned durations
#: (``GraspSequence.time_needed``) before ``evaluate`` stops it
TIME_MARGIN = 10.0
#: s, ``evaluate``'s time limit for a machine that does not say how long it needs
DEFAULT_TIME_LIMIT = 120.0


#: the phases in which the fruit's slide along the jaws is integrated (``contact``)
SLIDING_PHASES = (LIFTING, HOLDING)


class GraspSequence:
    """Close, settle, lift, hold (and release) the fruit.

    It slipped when it slid more than ``core.slip.SLIP_TOLERANCE`` down the jaws at its
    contacts between the lift-off (the grip when there is no lift) and the end of the
    hold (``core.slip.ContactSlide``, the pick-and-place's measure too). The drop of its
    centroid relative to the jaws, which also grows as a squeezed fruit relaxes once
    lifted off the table, is reported apart (``centroid_drop``) and decides only a drop
    (more than ``DROP_SLIP``), as in the pick-and-place.

    Args:
        sim: the simulation to drive.
        target_force: N, grip force to close to (> 0).
        close_speed: m/s gap closing rate (None or 0 = configured default).
        lift_height: m to lift after closing (>= 0).
        hold_time: s to hold after lifting (>= 0).
        release: lower back and open the jaws at the end.

    Raises:
        CommandError: a goal value is NaN, negative or out of range.
    """

    def __init__(self, sim: Simulation, target_force: float, close_speed: float | None = None,
                 lift_height: float = 0.0, hold_time: float = 0.0, release: bool = False):
        for name, value in (('lift_height', lift_height), ('hold_time', hold_time)):
            if not math.isfinite(value) or value < 0:
                raise CommandError(f'{name} must be finite and >= 0, got {value}')
        self.sim = sim
        self.start_lift = sim.gripper_state.lift
        self.lift_height = float(lift_height)
        self.hold_time = float(hold_time)
        self.release = bool(release)
        self.target_force = float(target_force)
        sim.command_force(target_force, close_speed)
        if lift_height > 0:
            sim.command_lift(self.start_lift + lift_height)  # validates the range
            sim.command_lift(self.start_lift)
        self.phase = CLOSING
        self.phase_start = sim.time
        speed = sim.gripper_state.speed
        self.closing_deadline = sim.time + 2.0 + 2.0 * sim.gripper_state.gap / speed
        self.outcome: str | None = None
        self.message = ''
        self.dropped_at: float | None = None
        self.peaks = RunPeaks()
        #: the fruit's slide along the jaws and its centroid's drop, from the lift-off
        self.contact = ContactSlide(sim.last.time)
        self.bruised = False
        self.damage = sim.last.damage
        self.final_gap = sim.gripper_state.gap

    @property
    def done(self) -> bool:
        return self.phase == DONE

    def time_needed(self) -> float:
        """s of simulation the whole sequence may take from now: the close (up to its
        deadline), the settling, the lift, the hold and, with ``release``, the lowering
        and opening, each at its commanded or configured speed; plus ``TIME_MARGIN``."""
        sim, grip = self.sim, self.sim.gripper_state
        lift = 0.0
        if self.lift_height > 0:
            speed = grip.lift_speed
            lift = self.lift_height / speed + speed / sim.config['gripper.lift_acceleration']
        release = 0.0
        if self.release:
            release = lift + sim.initial_gap / sim.config['gripper.close_speed']
        return (max(self.closing_deadline - sim.time, 0.0) + SETTLE_TIME + lift
                + self.hold_time + release + TIME_MARGIN)

    def _enter(self, phase: str) -> None:
        self.phase = phase
        self.phase_start = self.sim.time

    def _finish(self, outcome: str, message: str) -> None:
        if self.outcome is None:
            self.outcome, self.message = outcome, message
        if self.release and self.phase != RELEASING and outcome != 'failed':
            self.sim.command_lift(self.start_lift)
            self._enter(RELEASING)
        else:
            self.sim.hold()
            self._enter(DONE)

    def update(self, result: StepResult) -> str:
        """Advance the state machine after a step; returns the phase."""
        sim = self.sim
        self.contact.update(result, self.phase in SLIDING_PHASES)
        self.peaks(result)
        if result.damage is not None:  # the Hertz estimate of gripper_sim.core.damage
            self.damage = result.damage
            self.bruised = result.damage.bruised
        else:
            self.bruised = self.peaks.jaw_pressure > sim.config['fruit.bruise_pressure']
        self.final_gap = result.gap
        elapsed = sim.time - self.phase_start
        if self.phase in SLIDING_PHASES:
            gripped = result.in_contact_with('left_jaw') or result.in_contact_with('right_jaw')
            if not gripped or result.slip_distance > DROP_SLIP:
                self.dropped_at = sim.time
                why = ('' if not gripped else ' (its centroid fell '
                       f'{result.slip_distance * 1e3:.1f} mm behind the jaws)')
                self._finish('dropped', f'the fruit dropped at t = {sim.time:.3f} s{why}')
                return self.phase
        if self.phase == CLOSING:
            # both jaws: a single jaw's force (an impact, or pushing the fruit along the
            # table) is not a grip
            both = result.in_contact_with('left_jaw') and result.in_contact_with('right_jaw')
            if both and result.grip_force >= FORCE_REACHED * self.target_force:
                self._enter(SQUEEZING)
            elif sim.time > self.closing_deadline or result.gap <= sim.smallest_gap:
                self._finish('failed', f'the grip force did not reach {self.target_force} N '
                             f'(reached {self.peaks.grip_force:.3g} N)'
                             f'{stop_reached(sim, result.gap)}')
        elif self.phase == SQUEEZING:
            if elapsed >= SETTLE_TIME:
                if self.lift_height > 0:
                    sim.mark_slip_reference()
                    sim.command_lift(self.start_lift + self.lift_height)
                    self._enter(LIFTING)
                else:
                    self._enter(HOLDING)
        elif self.phase == LIFTING:
            grip = sim.gripper_state
            if grip.lift == grip.target_lift and grip.lift_rate == 0.0:
                self._enter(HOLDING)
        elif self.phase == HOLDING:
            if elapsed >= self.hold_time - 0.5 * sim.dt:
                if grasp_slipped(self.contact.largest):
                    self._finish('slipped', 'the fruit slipped '
                                 f'{self.contact.largest * 1e3:.2f} mm in the jaws')
                else:
                    self._finish('held', 'the fruit was held')
        elif self.phase == RELEASING:
            grip = sim.gripper_state
            if grip.lift == grip.target_lift and grip.lift_rate == 0.0:
                if grip.mode != 'position' or grip.target_gap != sim.initial_gap:
                    sim.command_open()
                elif abs(grip.gap - sim.initial_gap) < 1e-9:
                    self._enter(DONE)
        return self.phase

    def stop_rules(self, end: float) -> StopRules | None:
        """When ``Simulation.advance`` must hand the next step back to ``update``: the
        first step at which this phase could end (or a drop, a bruise, the time ``end``
        s); None when every step must be seen (releasing at the lift's end, done)."""
        sim = self.sim
        rules = StopRules(bruise=self.peaks.bruised_at is None, end=end)
        if self.phase in SLIDING_PHASES:
            rules.drop, rules.drop_slip = True, DROP_SLIP
            rules.slide, rules.slide_from = True, self.contact.state()
        if self.phase == CLOSING:
            rules.grip_force = FORCE_REACHED * self.target_force
            rules.deadline, rules.gap_closed = self.closing_deadline, True
        elif self.phase == SQUEEZING:
            rules.phase_start, rules.elapsed = self.phase_start, SETTLE_TIME
        elif self.phase == LIFTING:
            rules.lifted = True
        elif self.phase == HOLDING:
            rules.phase_start, rules.elapsed = self.phase_start, self.hold_time - 0.5 * sim.dt
        elif self.phase == RELEASING:
            grip = sim.gripper_state
            if grip.lift == grip.target_lift and grip.lift_rate == 0.0:
                return None
            rules.lifted = True
        else:
            return None
        return rules

    def include(self, skipped: Skipped) -> None:
        """What the steps ``Simulation.advance`` ran without showing them leave: their
        peaks, the slide along the jaws, the time of the step before the last."""
        self.peaks.include(skipped.peaks)
        self.contact.include(skipped, self.phase in SLIDING_PHASES)

    def summary(self) -> dict:
        """The grasp's result under the vocabulary's keys (``core.vocabulary``; the
        Grasp action's result maps its fields onto them)."""
        success = self.outcome == 'held'
        message = self.message
        damage = self.damage
        if damage is not None:
            damage_keys = damage_fields(damage)
        else:
            damage_keys = dict(bruised=self.bruised, crushed=False, bruised_length=0.0,
                               bruised_fraction=0.0,
                               peak_damage_pressure=self.peaks.jaw_pressure,
                               peak_flesh_stress=0.0)
        damage_keys['bruised'] = bool(self.bruised)
        if self.bruised:
            peak = damage_keys['peak_damage_pressure']
            message += (f'; bruised: peak damage pressure {peak:.4g} Pa above '
                        f"{self.sim.config['fruit.bruise_pressure']:.4g} Pa")
        if damage_keys['crushed']:
            message += '; crushed: the flesh failed'
        return dict(success=success, outcome=self.outcome or 'running',
                    slipped=self.outcome is not None and grasp_slipped(
                        self.contact.largest, self.dropped_at is not None),
                    dropped=self.dropped_at is not None,
                    message=message, final_gap=self.final_gap,
                    slip_distance=self.contact.largest,
                    centroid_drop=self.contact.centroid_drop, dropped_at=self.dropped_at,
                    **self.peaks.as_dict(), **damage_keys)


class GraspMachine(Protocol):
    """What ``evaluate`` needs of a state machine (``GraspSequence``, ``PickAndPlace``).

    A machine that also has ``stop_rules(end)`` (``core.multistep.StopRules`` or None)
    and ``include(skipped)`` (``core.multistep.Skipped``) lets ``evaluate`` run the steps
    at which it decides nothing in one compiled call (``Simulation.advance``) when nothing
    watches every step; one that has ``time_needed()`` (s) sets ``evaluate``'s time limit.
    """

    phase: str

    @property
    def done(self) -> bool: ...

    def update(self, result: StepResult) -> str: ...

    def summary(self) -> dict: ...


#: outcomes after which the fruit was still in the jaws (``held`` needs more: see below)
CARRIED = ('held', 'slipped', 'bruised', 'crushed', 'placed')


#: ``GraspEvaluation.outcome`` of a run whose solver failed (``ConvergenceError``)
SOLVER_FAILED = 'solver failed'
#: ``GraspEvaluation.outcome`` of a run whose deformable fingers closed on each other over
#: the fruit (``FingersClosed``): crushed where they pinch it (``bruised_at`` PINCH)
PINCHED = 'pinched'
#: ``GraspEvaluation.bruised_at`` of a pinched run
PINCH = 'pinch'


def stop_reached(sim, gap: float) -> str:
    """The end of a message on a close that ended at ``gap`` (m): why, if the jaws are at
    their stop (``Simulation.smallest_gap``), else ''."""
    if gap > sim.smallest_gap:
        return ''
    if sim.smallest_gap <= 0.0:
        return '; the jaws closed fully'
    return (f': the jaws are at their stop, a {sim.smallest_gap * 1e3:.4g} mm gap, where '
            'the two fingers meet')


@dataclass
class GraspEvaluation:
    """One grasp run to its end, measured (``evaluate``).

    Attributes:
        force: N, the commanded grip force.
        outcome: the machine's one-word outcome, 'solver failed', or 'pinched' (the
            fingers closed on each other over the fruit).
        held: the fruit was carried to the end, not dropped, and slid less than
            ``window.max_slip`` in the jaws.
        dropped, slipped, bruised, crushed: the run's flags.
        slip_distance: m, how far the fruit slid in the jaws at its contacts (the
            largest ``core.slip.ContactSlide``; not the centroid's drop).
        peak_grip_force: N, largest measured grip force (mean jaw normal force).
        peak_compression: m, largest loss of width along the closing axis.
        peak_jaw_pressure, peak_table_pressure: Pa, largest contact pressure at the jaws,
            on the table (``core.peaks.contact_pressures``).
        peak_damage_pressure: Pa, the damage model's peak pressure (Hertz in 2D).
        bruised_at: where it first bruised, 'jaws', 'table' or 'pinch' (between the
            fingers closed on each other) ('': not bruised; a study's rows are a table of
            one type per column).
        bruised_fraction: fraction of the outline (2D) or surface (3D) bruised.
        error: '' or the solver's message when it failed.
        sim_time: s simulated; steps: time steps taken.
        message: the machine's text.
        summary: the machine's own summary (JSON-ready; empty when the solver failed).
        failure: the ConvergenceError when the solver failed or the fingers closed
            (``FingersClosed``) (not compared, not pickled into rows).
    """

    force: float
    outcome: str
    held: bool
    dropped: bool
    slipped: bool
    bruised: bool
    crushed: bool
    slip_distance: float
    peak_grip_force: float
    peak_compression: float
    peak_jaw_pressure: float
    peak_table_pressure: float
    peak_damage_pressure: float
    bruised_at: str
    bruised_fraction: float
    error: str
    sim_time: float
    steps: int
    message: str
    summary: dict = field(default_factory=dict, repr=False)
    failure: ConvergenceError | None = field(default=None, repr=False, compare=False)

    def row(self) -> dict[str, Any]:
        """The scalar fields (no summary, no exception object)."""
        values = asdict(self)
        values.pop('summary')
        values.pop('failure')
        return values


def evaluate(sim, machine: GraspMachine, force: float,
             on_step: Callable[[StepResult, str], None] | None = None,
             time_limit: float | None = None) -> GraspEvaluation:
    """Step ``sim`` until ``machine`` is done (or ``time_limit`` s of simulation; None:
    what the machine says it needs, ``time_needed()``, else ``DEFAULT_TIME_LIMIT``). A
    machine stopped at the limit keeps its outcome ('running') with a message saying so.

    A ``ConvergenceError`` of the solver ends the run: the evaluation then has outcome
    'solver failed', ``error`` set and counts as neither held nor undamaged (dropped
    and crushed flags set), so that a force the solver cannot follow stays out of any
    window. Where the solver stopped because the fingers closed on each other over the
    fruit (``FingersClosed``) the outcome is 'pinched': crushed at the pinch, not dropped.
    A run holds when it carried the fruit to the end (``CARRIED``, not dropped)
    with less than ``window.max_slip`` of slip.
    """
    peaks = RunPeaks()
    start_step = sim.last.step
    if time_limit is None:
        time_needed = getattr(machine, 'time_needed', None)
        time_limit = time_needed() if time_needed is not None else DEFAULT_TIME_LIMIT
    end = sim.time + time_limit
    try:
        while not machine.done and sim.time < end:
            result, skipped = next_result(sim, machine, end, on_step is not None)
            if skipped is not None:
                peaks.include(skipped.peaks)
            peaks(result)
            machine.update(result)
            if on_step is not None:
                on_step(result, machine.phase)
    except ConvergenceError as err:
        pinched = isinstance(err, FingersClosed)  # stopped by the fruit, not the solver
        damage = sim.last.damage if pinched else None
        return GraspEvaluation(
            force=float(force), outcome=PINCHED if pinched else SOLVER_FAILED, held=False,
            dropped=not pinched, slipped=False, bruised=True, crushed=True,
            slip_distance=0.0, peak_grip_force=peaks.grip_force,
            peak_compression=peaks.compression, peak_jaw_pressure=peaks.jaw_pressure,
            peak_table_pressure=peaks.table_pressure,
            peak_damage_pressure=float(damage.peak_pressure) if damage is not None else 0.0,
            bruised_at=peaks.bruised_at or (PINCH if pinched else ''), bruised_fraction=0.0,
            error='' if pinched else str(err) or type(err).__name__,
            sim_time=float(sim.time), steps=int(sim.last.step - start_step),
            message=str(err), failure=err)
    summary = machine.summary()
    if not machine.done:
        stopped = (f'stopped at the time limit ({time_limit:.4g} s simulated) while '
                   f'{machine.phase}')
        summary['message'] = '; '.join(filter(None, (summary.get('message'), stopped)))
    damage = sim.last.damage
    outcome = str(summary['outcome'])
    dropped = bool(summary.get('dropped', outcome == 'dropped'))
    slip = float(summary.get('slip_distance', 0.0))
    held = outcome in CARRIED and not dropped and slip < sim.config['window.max_slip']
    return GraspEvaluation(
        force=float(force), outcome=outcome, held=bool(held), dropped=dropped,
        slipped=bool(summary.get('slipped', outcome == 'slipped')),
        bruised=bool(summary.get('bruised', False)),
        crushed=bool(summary.get('crushed', False)),
        slip_distance=slip,
        peak_grip_force=peaks.grip_force, peak_compression=peaks.compression,
        peak_jaw_pressure=peaks.jaw_pressure, peak_table_pressure=peaks.table_pressure,
        peak_damage_pressure=float(damage.peak_pressure) if damage is not None else 0.0,
        bruised_at=peaks.bruised_at or '',
        bruised_fraction=float(damage.bruised_fraction) if damage is not None else 0.0,
        error='', sim_time=float(sim.time), steps=int(sim.last.step - start_step),
        message=str(summary.get('message', '')), summary=summary)


def run_grasp(sim: Simulation, sequence: GraspSequence, on_step=None,
              time_limit: float | None = None) -> dict:
    """Step until the sequence is done (or ``time_limit`` s of simulation; None: the
    sequence's ``time_needed``); its summary.

    Raises:
        ConvergenceError: the solver failed (``evaluate``'s failure, raised again).
    """
    evaluation = evaluate(sim, sequence, sequence.target_force, on_step, time_limit)
    if evaluation.failure is not None:
        raise evaluation.failure
    return evaluation.summary
