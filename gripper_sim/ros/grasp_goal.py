"""What a ``~/grasp`` goal means: its validation, the state machine that runs it, its result.

A plain goal runs ``gripper_sim.workflows.grasp.GraspSequence`` (close, squeeze, lift, hold,
release); a goal with ``place`` runs ``gripper_sim.workflows.scenario.PickAndPlace`` on a
scenario built from the goal and the node's configuration (``place_scenario``). Both
are wrapped in a ``GoalRun``: ``update(result)`` after every step, ``phase`` (the
feedback's -ing name), ``done``, and ``result()`` the filled ``Grasp.Result``.

The outcome word follows the scenario's precedence: crushed, dropped, bruised, slipped,
then held (grasp) or placed (place), else failed. ``success`` means held or placed:
a grasp that bruised or crushed the fruit, or let it slip, is not a success.
"""
from __future__ import annotations

import math
from typing import Any, Mapping

from gripper_sim_interfaces.action import Grasp

from gripper_sim.workflows.grasp import SETTLE_TIME as SQUEEZE_TIME, GraspSequence
from gripper_sim.workflows.scenario import PickAndPlace, scenario_from_mapping

MAX_LIFT_HEIGHT = 1.0       # m
MAX_HOLD_TIME = 3600.0      # s
MAX_TRANSPORT = 5.0         # m, |transport_distance| (the scenario's range)
MAX_RETREAT = 1.0           # m

#: scenario phase -> feedback phase
PLACE_PHASES = {'approach': 'approaching', 'close': 'closing', 'squeeze': 'squeezing',
                'lift': 'lifting', 'transport': 'transporting', 'lower': 'lowering',
                'open': 'opening', 'retreat': 'retreating', 'settle': 'settling',
                'hold': 'holding', 'done': 'done'}
#: a place goal waits this long (s) after retreating before judging where the fruit is
SETTLE_TIME = 0.2


def goal_problem(goal, config: Mapping[str, Any]) -> str | None:
    """Why a Grasp goal is invalid, or None. ``config`` is the flat configuration."""
    fields = {'target_force': goal.target_force, 'close_speed': goal.close_speed,
              'lift_height': goal.lift_height, 'hold_time': goal.hold_time,
              'transport_distance': goal.transport_distance,
              'retreat_height': goal.retreat_height}
    for name, value in fields.items():
        if not math.isfinite(value):
            return f'{name} must be finite, got {value}'
    max_force = config['gripper.max_force']
    if not 0.0 < goal.target_force <= max_force:
        return f'target_force must be in (0, {max_force:g}] N, got {goal.target_force:g} N'
    max_speed = config['gripper.max_speed']
    if not 0.0 <= goal.close_speed <= max_speed:
        return (f'close_speed must be in [0, {max_speed:g}] m/s (0 = default), got '
                f'{goal.close_speed:g} m/s')
    if not 0.0 <= goal.lift_height <= MAX_LIFT_HEIGHT:
        return (f'lift_height must be in [0, {MAX_LIFT_HEIGHT:g}] m, got '
                f'{goal.lift_height:g} m')
    if not 0.0 <= goal.hold_time <= MAX_HOLD_TIME:
        return f'hold_time must be in [0, {MAX_HOLD_TIME:g}] s, got {goal.hold_time:g} s'
    if not goal.place:
        if goal.transport_distance != 0.0 or goal.retreat_height != 0.0:
            return ('transport_distance and retreat_height are place options: set place '
                    'true, or leave them 0')
        return None
    if not goal.release:
        return ('a place goal always opens the jaws on the table: release must be true '
                '(release false with place is contradictory)')
    if goal.lift_height <= 0.0:
        return 'a place goal needs lift_height > 0 (the fruit is carried, not dragged)'
    if goal.hold_time != 0.0:
        return ('hold_time is not used by a place goal (it holds only while carrying): '
                f'set it to 0, got {goal.hold_time:g} s')
    if abs(goal.transport_distance) > MAX_TRANSPORT:
        return (f'transport_distance must be in [-{MAX_TRANSPORT:g}, {MAX_TRANSPORT:g}] m, '
                f'got {goal.transport_distance:g} m')
    if not 0.0 <= goal.retreat_height <= MAX_RETREAT:
        return (f'retreat_height must be in [0, {MAX_RETREAT:g}] m, got '
                f'{goal.retreat_height:g} m')
    return None


def place_scenario(goal, config: Mapping[str, Any]):
    """The ``Scenario`` of a place goal: no approach (the gripper grasps at its present
    height, first moving sideways over the fruit's middle), close to ``target_force``,
    squeeze ``grasp.SETTLE_TIME``, lift ``lift_height``, transport
    ``transport_distance`` along x, lower back onto the table, open to the initial gap,
    retreat ``retreat_height``, settle ``SETTLE_TIME``; speeds from the configuration
    (``gripper.lift_speed`` up and down, ``gripper.transport_speed``,
    ``gripper.close_speed`` to open, ``close_speed`` or ``gripper.close_speed`` to close).

    Raises:
        ConfigError: a value outside the scenario's ranges.
    """
    lift_speed = float(config['gripper.lift_speed'])
    close_speed = float(goal.close_speed or config['gripper.close_speed'])
    return scenario_from_mapping({
        'name': 'grasp_action_place',
        'approach': {'height': 0.0, 'speed': float(config['gripper.transport_speed'])},
        'close': {'mode': 'force', 'force': float(goal.target_force), 'speed': close_speed},
        'squeeze': {'time': SQUEEZE_TIME},
        'lift': {'height': float(goal.lift_height), 'speed': lift_speed},
        'transport': {'distance': float(goal.transport_distance),
                      'speed': float(config['gripper.transport_speed'])},
        'lower': {'speed': lift_speed},
        'open': {'speed': float(config['gripper.close_speed'])},
        'retreat': {'height': float(goal.retreat_height), 'speed': lift_speed},
        'settle': {'time': SETTLE_TIME},
    }, source='the Grasp goal')


def outcome_of(summary: Mapping[str, Any]) -> str:
    """One word for a run (precedence: crushed, dropped, bruised, slipped, held/placed)."""
    outcome = str(summary.get('outcome', 'failed'))
    if summary.get('crushed'):
        return 'crushed'
    if outcome == 'dropped':
        return 'dropped'
    if summary.get('bruised'):
        return 'bruised'
    if summary.get('slipped') and outcome in ('held', 'placed', 'slipped'):
        return 'slipped'
    return outcome


class GoalRun:
    """A Grasp goal's state machine and the measures its result reports.

    Args:
        sim: the node's simulation (call under the node's lock).
        goal: a validated ``Grasp.Goal`` (``goal_problem`` is None).
        config: the node's flat configuration.

    Raises:
        GripperSimError: the simulation refuses a command of the goal.
    """

    def __init__(self, sim, goal, config: Mapping[str, Any]):
        self.sim = sim
        self.place = bool(goal.place)
        self.max_compression = 0.0
        self.max_contact_pressure = 0.0
        self.last = sim.last
        if self.place:
            self.machine = PickAndPlace(sim, place_scenario(goal, config))
        else:
            close_speed = goal.close_speed or config['gripper.close_speed']
            self.machine = GraspSequence(sim, goal.target_force, close_speed,
                                         goal.lift_height, goal.hold_time, goal.release)

    @property
    def phase(self) -> str:
        """The feedback phase name."""
        phase = self.machine.phase
        return PLACE_PHASES.get(phase, phase) if self.place else phase

    @property
    def done(self) -> bool:
        return self.machine.done

    def update(self, result) -> None:
        """After every physics step."""
        self.last = result
        self.max_compression = max(self.max_compression, float(result.deformation.compression))
        self.max_contact_pressure = max(self.max_contact_pressure,
                                        float(result.deformation.peak_contact_pressure))
        self.machine.update(result)

    def summary(self) -> dict:
        return dict(self.machine.summary())

    def result(self, summary: Mapping[str, Any] | None = None) -> Grasp.Result:
        """The action result of the run so far (``summary``: an earlier ``summary()``)."""
        summary = self.summary() if summary is None else summary
        damage = self.last.damage
        result = Grasp.Result()
        result.outcome = outcome_of(summary)
        result.success = result.outcome == ('placed' if self.place else 'held')
        result.slipped = bool(summary.get('slipped', False))
        result.bruised = bool(summary.get('bruised', False))
        result.crushed = bool(summary.get('crushed', False))
        result.message = str(summary.get('message', ''))
        dropped_at = summary.get('dropped_at')
        values = {
            'max_grip_force': summary.get('max_grip_force', 0.0),
            'final_gap': self.last.gap,
            'max_compression': self.max_compression,
            'max_contact_pressure': self.max_contact_pressure,
            'peak_damage_pressure': damage.peak_pressure if damage is not None
            else self.max_contact_pressure,
            'bruised_fraction': damage.bruised_fraction if damage is not None else 0.0,
            'slip_distance': summary.get('slip_distance', 0.0),
            'dropped_at': -1.0 if dropped_at is None else dropped_at,
        }
        for name, value in values.items():
            value = float(value)
            setattr(result, name, value if math.isfinite(value) else 0.0)
        return result
