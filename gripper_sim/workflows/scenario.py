"""The whole pick-and-place as a scenario file and a step-driven state machine.

A scenario (``config/scenarios/*.yaml``) names a fruit and a finger preset, optional
configuration overrides (``set``), and the parameters of each phase:

    approach   the open gripper descends from ``approach.height`` above the grasp height
    close      to a grip force (``close.mode: force``) or a gap (``close.mode: position``)
    squeeze    hold the grip for ``squeeze.time`` on the table
    lift       up by ``lift.height``
    transport  sideways (x) by ``transport.distance``
    lower      back down until the fruit is ``PLACE_CLEARANCE`` above the table
    open       the jaws back to their initial gap
    retreat    up by ``retreat.height``
    settle     wait ``settle.time`` and look where the fruit is

Outcomes: ``placed`` (on the table, clear of the jaws, within a quarter of its width of
the target, at rest), ``dropped`` (the fruit left both jaws or fell more than
``DROP_SLIP`` behind them between lift and open; ``dropped_at`` says when, the run then
ends), ``slipped`` (placed, but it slid more than ``SLIP_TOLERANCE`` at its contacts
with the jaws: ``slip_distance``, the largest ``core.slip.ContactSlide``, the jaw-contact
nodes' downward velocity relative to the jaws integrated, which leaves out the fruit's
elastic sag; the centroid's largest drop relative to the jaws is ``centroid_drop``),
``bruised``, ``crushed`` (``gripper_sim.core.damage``), or ``failed`` (the grip never
reached its target, or the fruit was not found on the table at the end). One word
summarises a run, in this order of precedence: crushed, dropped, bruised, slipped,
placed, failed; the flags are all reported.

The grasp height is the fruit's centre height on the table, raised where needed so
that the jaws stay above the table (``gripper.jaw_height`` / 2 + 1 mm).

The same machine drives the 2D ``Simulation`` and the 3D ``Simulation3D`` (``dimension:
3``; ``gripper_sim.core.make_simulation`` picks one): it uses only their common commands
and results, whose last coordinate column is the height.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from gripper_sim.configuration import (Key, flatten, load_config, package_config_dir,
                                       parse_override, read_yaml)
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.multistep import Skipped, StopRules, next_result
from gripper_sim.core.peaks import RunPeaks
from gripper_sim.core.slip import SLIP_TOLERANCE, ContactSlide
from gripper_sim.core.vocabulary import DROP_SLIP, damage_fields
from gripper_sim.core3d.fruit import build_fruit3d
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.grasp import FORCE_REACHED, stop_reached

#: height (m) above the table at which the lowered fruit is let go
PLACE_CLEARANCE = 5e-4

#: m, a fruit whose middle lies this near the gripper's x needs no centring (a settled
#: 3D mesh's middle lies ~0.05 um off its placement; moving there takes steps)
AIM_TOLERANCE = 1e-6

PHASES = ('approach', 'close', 'squeeze', 'lift', 'transport', 'lower', 'open', 'retreat',
          'settle', 'done')
#: the phases in which the fruit's slide along the jaws is integrated (``contact``)
SLIDING_PHASES = ('lift', 'transport', 'lower', 'hold')

#: every scenario key: unit, range, meaning (Key of gripper_sim.configuration)
SCENARIO_SCHEMA: dict[str, Key] = {
    'name': Key('scenario', '-', 'name shown in outputs', 'str'),
    'description': Key('', '-', 'free text', 'str'),
    'fruit': Key(None, '-', 'fruit preset (config/fruits); null = the default fruit',
                 'str', nullable=True),
    'finger': Key(None, '-', 'finger preset (config/fingers); null = the configured finger',
                  'str', nullable=True),
    'approach.height': Key(0.02, 'm', 'start this far above the grasp height', low=0.0,
                           high=1.0),
    'approach.speed': Key(0.1, 'm/s', 'descent speed', low=0.0, high=2.0, open_low=True),
    'close.mode': Key('force', '-', 'close to a grip force or to a gap', 'str',
                      choices=('force', 'position')),
    'close.force': Key(5.0, 'N', 'force mode: grip force', low=0.0, high=1e5, open_low=True),
    'close.gap': Key(None, 'm', 'position mode: gap to close to', low=0.0, high=2.0,
                     nullable=True),
    'close.speed': Key(0.05, 'm/s', 'gap closing rate', low=0.0, high=5.0, open_low=True),
    'squeeze.time': Key(0.2, 's', 'hold on the table before lifting', low=0.0, high=60.0),
    'lift.height': Key(0.03, 'm', 'lift height', low=0.0, high=2.0),
    'lift.speed': Key(0.1, 'm/s', 'lift speed', low=0.0, high=2.0, open_low=True),
    'transport.distance': Key(0.08, 'm', 'sideways (x) travel, signed', low=-5.0, high=5.0),
    'transport.speed': Key(0.2, 'm/s', 'transport speed', low=0.0, high=5.0, open_low=True),
    'lower.speed': Key(0.1, 'm/s', 'lowering speed', low=0.0, high=2.0, open_low=True),
    'open.speed': Key(0.05, 'm/s', 'opening gap rate', low=0.0, high=5.0, open_low=True),
    'retreat.height': Key(0.02, 'm', 'rise after opening', low=0.0, high=2.0),
    'retreat.speed': Key(0.1, 'm/s', 'retreat speed', low=0.0, high=2.0, open_low=True),
    'settle.time': Key(0.2, 's', 'wait before judging where the fruit is', low=0.0,
                       high=60.0),
}


@dataclass(frozen=True)
class Scenario:
    """A validated scenario: ``values`` {dotted key: value} and configuration ``overrides``."""

    values: Mapping[str, Any]
    overrides: Mapping[str, Any] = field(default_factory=dict)
    source: str = ''

    def __getitem__(self, key: str) -> Any:
        return self.values[key]

    def with_values(self, **changes) -> 'Scenario':
        """A copy with some keys changed (dotted keys spelled with '__' for '.')."""
        values = dict(self.values)
        for name, value in changes.items():
            key = name.replace('__', '.')
            values[key] = _coerce(key, value, 'argument')
        return Scenario(values, dict(self.overrides), self.source)


def available_scenarios() -> list[str]:
    """Names of the scenarios in ``config/scenarios``."""
    return sorted(p.stem for p in (package_config_dir() / 'scenarios').glob('*.yaml'))


def _coerce(key: str, value: Any, source: str) -> Any:
    spec = SCENARIO_SCHEMA[key]
    where = f"scenario key '{key}'"
    origin = f' (in {source})' if source else ''
    if value is None:
        if spec.nullable:
            return None
        raise ConfigError(f'{where} must not be null ({spec.description}){origin}')
    if spec.kind == 'str':
        text = str(value)
        if spec.choices and text not in spec.choices:
            raise ConfigError(f"{where} must be one of {', '.join(spec.choices)}, got "
                              f"'{text}'{origin}")
        return text
    if isinstance(value, bool):
        raise ConfigError(f'{where} must be a number, got {value!r}{origin}')
    try:
        number = float(value)
    except (TypeError, ValueError) as err:
        raise ConfigError(f'{where} must be a number, got {value!r}{origin}') from err
    unit = f' {spec.unit}' if spec.unit not in ('', '-') else ''
    if not math.isfinite(number) or number < spec.low or number > spec.high or (
            spec.open_low and number <= spec.low):
        relation = '>' if spec.open_low else '>='
        raise ConfigError(f'{where} = {value!r}{unit} is out of range: it must be '
                          f'{relation} {spec.low:g}{unit} and <= {spec.high:g}{unit}{origin}')
    return number


def scenario_path(name_or_path: str) -> Path:
    """A scenario file: an existing path, or a name in ``config/scenarios``."""
    path = Path(name_or_path)
    if path.is_file():
        return path
    named = package_config_dir() / 'scenarios' / f'{name_or_path}.yaml'
    if named.is_file():
        return named
    known = ', '.join(available_scenarios()) or 'none installed'
    raise ConfigError(f"unknown scenario '{name_or_path}': no such file, and not one of "
                      f'the installed scenarios ({known})')


def load_scenario(name_or_path: str) -> Scenario:
    """Read and validate a scenario file.

    Raises:
        ConfigError: no such scenario, bad YAML, an unknown or out-of-range key, a
            position close without a gap, or a bad ``set`` override.
    """
    path = scenario_path(name_or_path)
    data = read_yaml(path)
    return scenario_from_mapping(data, str(path))


def scenario_from_mapping(data: Mapping[str, Any], source: str = '') -> Scenario:
    """Validate a scenario given as a (nested) mapping."""
    data = dict(data)
    overrides = data.pop('set', None) or {}
    if not isinstance(overrides, Mapping):
        raise ConfigError(f"scenario key 'set' in {source} must be a mapping of "
                          'configuration keys')
    flat = flatten(data)
    values = {key: spec.default for key, spec in SCENARIO_SCHEMA.items()}
    for key, value in flat.items():
        if key not in SCENARIO_SCHEMA:
            import difflib
            close = difflib.get_close_matches(key, SCENARIO_SCHEMA.keys(), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ''
            raise ConfigError(f"unknown scenario key '{key}' in {source}{hint}")
        values[key] = _coerce(key, value, source)
    if values['close.mode'] == 'position' and values['close.gap'] is None:
        raise ConfigError(f"scenario key 'close.gap' in {source} is needed when "
                          "'close.mode' is position")
    flat_overrides = {}
    for key, value in flatten(overrides).items():
        flat_overrides[key] = value
    return Scenario(values, flat_overrides, source)


def rest_shape(config: Mapping[str, Any]):
    """The fruit model of ``config`` (2D ``FruitModel`` or 3D ``FruitModel3D``, as
    ``dimension`` says): its ``rest_positions`` are (n, 2) (x, z) or (n, 3) (x, y, z),
    the last column always the height (m)."""
    if int(config.get('dimension', 2)) == 3:
        return build_fruit3d(config)
    return build_fruit(config)


def grasp_height(config: Mapping[str, Any]) -> float:
    """m: height of the jaw centre that grasps the fruit resting on the table."""
    rest = rest_shape(config).rest_positions
    if config['fruit.initial_height'] is not None:
        centre = float(config['fruit.initial_height'])
    elif config['world.table']:
        centre = float(config['world.table_height'] - rest[:, -1].min())
    else:
        centre = 0.0
    if config['world.table']:
        centre = max(centre, config['world.table_height'] + 0.5 * config['gripper.jaw_height']
                     + 1e-3)
    return centre


def scenario_config(scenario: Scenario, fruit: str | None = None, finger: str | None = None,
                    config_file: str | None = None,
                    overrides: Iterable[str] | Mapping[str, Any] = ()) -> dict[str, Any]:
    """The simulation configuration of a scenario run.

    Command-line choices (``fruit``, ``finger``, ``config_file``, ``overrides``) win over
    the scenario's (its ``fruit``, ``finger`` and ``set``); the configuration file layers
    over the fruit preset (``configuration.load_config``). The gripper starts
    ``approach.height`` above the grasp height.
    """
    if isinstance(overrides, Mapping):
        user = dict(overrides)
    else:
        user = dict(parse_override(text) for text in overrides)
    merged = dict(scenario.overrides)
    merged.update(user)
    choice = dict(fruit=fruit, finger=finger, config_file=config_file,
                  fallback_fruit=scenario['fruit'], fallback_finger=scenario['finger'])
    with warnings.catch_warnings(record=True) as first:   # warned once, by the second load
        warnings.simplefilter('always')
        config = load_config(overrides=merged, **choice)
    if 'gripper.initial_lift' not in merged:
        merged['gripper.initial_lift'] = grasp_height(config) + scenario['approach.height']
        config = load_config(overrides=merged, **choice)
    else:
        for warning in first:
            warnings.warn_explicit(warning.message, warning.category, warning.filename,
                                   warning.lineno)
    return config


class PickAndPlace:
    """Drives a simulation through a scenario; call ``update(result)`` after every step.

    Args:
        sim: the simulation (built from ``scenario_config``).
        scenario: the scenario.
        until: last phase to run ('settle' = the whole scenario; e.g. 'transport' ends
            after the transport and a ``hold`` of ``squeeze.time``, for the grasp window).
        stop_on_slip: end as soon as the fruit slips more than ``SLIP_TOLERANCE``.
        stop_on_bruise: end as soon as the fruit is bruised.

    Raises:
        CommandError: a phase's command is out of the simulation's range.
    """

    def __init__(self, sim, scenario: Scenario, until: str = 'settle',
                 stop_on_slip: bool = False, stop_on_bruise: bool = False):
        if until not in PHASES:
            raise ValueError(f'unknown phase {until!r}')
        self.sim = sim
        self.scenario = scenario
        self.until = until
        self.stop_on_slip = stop_on_slip
        self.stop_on_bruise = stop_on_bruise
        # aim at the middle of the fruit's extent along the closing axis (where a camera
        # would put the gripper), which for an uneven outline is not its centroid
        surface = sim.last.positions[sim.fruit.surface]
        self.start_x = 0.5 * float(surface[:, 0].min() + surface[:, 0].max())
        if abs(self.start_x - sim.gripper_state.x) <= AIM_TOLERANCE:
            self.start_x = sim.gripper_state.x
        self.start_lift = sim.gripper_state.lift
        self.grasp_lift = self.start_lift - scenario['approach.height']
        self.phase = 'approach'
        self.phase_start = sim.time
        self.phase_times: dict[str, float] = {'approach': sim.time}
        self.outcome: str | None = None
        self.message = ''
        self.dropped_at: float | None = None
        self.dropped_phase: str | None = None
        #: the fruit's slide along the jaws and its centroid's drop, from the lift-off
        self.contact = ContactSlide(sim.last.time)
        self.peaks = RunPeaks()
        self.placed = False
        self.reached_grip = False
        self.last = sim.last
        self.closing_deadline = math.inf
        sim.command_lift(self.grasp_lift, scenario['approach.speed'])
        if self.start_x != sim.gripper_state.x:
            sim.command_transport(self.start_x, scenario['approach.speed'])
        if scenario['approach.height'] <= 0 and self._x_reached():
            self._start_close()

    @property
    def done(self) -> bool:
        return self.phase == 'done'

    def _enter(self, phase: str) -> None:
        self.phase = phase
        self.phase_start = self.sim.time
        self.phase_times[phase] = self.sim.time

    def _x_reached(self) -> bool:
        grip = self.sim.gripper_state
        return grip.x == grip.target_x and grip.x_rate == 0.0

    def _lift_reached(self) -> bool:
        grip = self.sim.gripper_state
        return grip.lift == grip.target_lift and grip.lift_rate == 0.0

    def _start_close(self) -> None:
        sc, sim = self.scenario, self.sim
        self._enter('close')
        if sc['close.mode'] == 'force':
            sim.command_force(sc['close.force'], sc['close.speed'])
        else:
            sim.command_gap(sc['close.gap'], sc['close.speed'])
        gap = sim.gripper_state.gap
        self.closing_deadline = sim.time + 1.0 + 2.0 * gap / sc['close.speed']

    def _end(self, outcome: str | None, message: str) -> None:
        if outcome is not None and self.outcome is None:
            self.outcome, self.message = outcome, message
        self.sim.hold()
        self.sim.command_lift(self.sim.gripper_state.lift)
        self._enter('done')

    def _past_until(self, phase: str) -> bool:
        return PHASES.index(phase) > PHASES.index(self.until)

    def update(self, result) -> str:
        """Advance after a step; returns the phase."""
        sim, sc = self.sim, self.scenario
        self.contact.update(result, self.phase in SLIDING_PHASES)
        self.last = result
        self.peaks(result)
        elapsed = sim.time - self.phase_start
        gripped = result.in_contact_with('left_jaw') or result.in_contact_with('right_jaw')
        if self.phase in ('lift', 'transport', 'lower'):
            if not gripped or result.slip_distance > DROP_SLIP:
                self.dropped_at = sim.time
                self.dropped_phase = self.phase
                self._end('dropped', f'the fruit dropped at t = {sim.time:.3f} s during '
                          f'the {self.phase}')
                return self.phase
            if self.stop_on_slip and self.contact.largest > SLIP_TOLERANCE:
                self._end('slipped', f'the fruit slipped {self.contact.largest * 1e3:.2f} '
                          f'mm in the jaws during the {self.phase}')
                return self.phase
        if self.stop_on_bruise and result.damage is not None and (
                result.damage.bruised or result.damage.crushed):
            self._end('bruised', f'the fruit was damaged at t = {sim.time:.3f} s')
            return self.phase
        if self.phase == 'approach':
            if self._lift_reached() and self._x_reached():
                self._start_close()
        elif self.phase == 'close':
            if sc['close.mode'] == 'force':
                # both jaws: one jaw's force (an impact, a push) is not a grip
                reached = (result.in_contact_with('left_jaw')
                           and result.in_contact_with('right_jaw')
                           and result.grip_force >= FORCE_REACHED * sc['close.force'])
            else:
                reached = abs(sim.gripper_state.gap - sc['close.gap']) < 1e-9
            if reached:
                self.reached_grip = True
                self._enter('squeeze')
            elif sim.time > self.closing_deadline or result.gap <= sim.smallest_gap:
                what = (f"{sc['close.force']} N" if sc['close.mode'] == 'force'
                        else f"the gap {sc['close.gap']} m")
                self._end('failed', f'the grip did not reach {what} (peak force '
                          f'{self.peaks.grip_force:.3g} N){stop_reached(sim, result.gap)}')
        elif self.phase == 'squeeze':
            if elapsed >= sc['squeeze.time'] - 0.5 * sim.dt:
                if self._past_until('lift'):
                    self._end(None, '')
                else:
                    sim.mark_slip_reference()
                    sim.command_lift(self.grasp_lift + sc['lift.height'], sc['lift.speed'])
                    self._enter('lift')
        elif self.phase == 'lift':
            if self._lift_reached():
                if self._past_until('transport'):
                    self._enter('hold')
                else:
                    sim.command_transport(self.start_x + sc['transport.distance'],
                                          sc['transport.speed'])
                    self._enter('transport')
        elif self.phase == 'transport':
            grip = sim.gripper_state
            if grip.x == grip.target_x and grip.x_rate == 0.0:
                if self._past_until('lower'):
                    self._enter('hold')
                else:
                    # down to where the fruit (which may have slid in the jaws) just meets
                    # the table again, plus PLACE_CLEARANCE: never pressed into the table
                    sim.command_lift(self.grasp_lift + result.slip_distance + PLACE_CLEARANCE,
                                     sc['lower.speed'])
                    self._enter('lower')
        elif self.phase == 'hold':
            if not gripped or result.slip_distance > DROP_SLIP:
                self.dropped_at = sim.time
                self.dropped_phase = 'hold'
                self._end('dropped', f'the fruit dropped at t = {sim.time:.3f} s')
            elif elapsed >= sc['squeeze.time'] - 0.5 * sim.dt:
                self._end(None, '')
        elif self.phase == 'lower':
            if self._lift_reached():
                sim.command_gap(sim.initial_gap, sc['open.speed'])
                self._enter('open')
        elif self.phase == 'open':
            if abs(sim.gripper_state.gap - sim.initial_gap) < 1e-9:
                sim.command_lift(self.grasp_lift + sc['retreat.height'], sc['retreat.speed'])
                self._enter('retreat')
        elif self.phase == 'retreat':
            if self._lift_reached():
                self._enter('settle')
        elif self.phase == 'settle':
            if elapsed >= sc['settle.time'] - 0.5 * sim.dt:
                self._judge_placement(result)
                self._enter('done')
        return self.phase

    def stop_rules(self, end: float) -> StopRules | None:
        """When ``Simulation.advance`` must hand the next step back to ``update``: the
        first step at which this phase could end (or a drop, a slip or damage it stops
        on, a bruise, the time ``end`` s); None when every step must be seen (done)."""
        sc, sim = self.scenario, self.sim
        phase = self.phase
        rules = StopRules(bruise=self.peaks.bruised_at is None, damaged=self.stop_on_bruise,
                          end=end)
        if phase in SLIDING_PHASES:
            rules.slide, rules.slide_from = True, self.contact.state()
            rules.drop, rules.drop_slip = True, DROP_SLIP
            if self.stop_on_slip and phase != 'hold':
                rules.slide_limit = SLIP_TOLERANCE
        settle = 0.5 * sim.dt
        if phase == 'approach':
            rules.lifted = rules.moved = True
        elif phase == 'close':
            if sc['close.mode'] == 'force':
                rules.grip_force = FORCE_REACHED * sc['close.force']
            else:
                rules.gap_at = sc['close.gap']
            rules.deadline, rules.gap_closed = self.closing_deadline, True
        elif phase in ('squeeze', 'hold', 'settle'):
            wait = sc['settle.time'] if phase == 'settle' else sc['squeeze.time']
            rules.phase_start, rules.elapsed = self.phase_start, wait - settle
        elif phase in ('lift', 'lower', 'retreat'):
            rules.lifted = True
        elif phase == 'transport':
            rules.moved = True
        elif phase == 'open':
            rules.gap_at = sim.initial_gap
        else:
            return None
        return rules

    def include(self, skipped: Skipped) -> None:
        """What the steps ``Simulation.advance`` ran without showing them leave: their
        peaks, the slide along the jaws, the time of the step before the last."""
        self.peaks.include(skipped.peaks)
        self.contact.include(skipped, self.phase in SLIDING_PHASES)

    def _judge_placement(self, result) -> None:
        sc = self.scenario
        target = self.start_x + sc['transport.distance']
        width = self.sim.fruit.rest_width
        on_table = result.in_contact_with('table') or not self.sim.config['world.table']
        gripped = result.in_contact_with('left_jaw') or result.in_contact_with('right_jaw')
        speed = float(np.linalg.norm(result.velocities.mean(axis=0)))
        off = abs(float(result.centroid[0]) - target)
        self.placed = bool(on_table and not gripped and off < 0.25 * width and speed < 0.05)
        if self.placed:
            self.message = (f'placed {off * 1e3:.1f} mm from the target at t = '
                            f'{self.sim.time:.3f} s')
        elif self.outcome is None:
            why = ('still in the jaws' if gripped else 'not on the table' if not on_table
                   else f'{off * 1e3:.0f} mm from the target' if off >= 0.25 * width
                   else 'still moving')
            self.outcome, self.message = 'failed', f'the fruit was not placed: {why}'

    def summary(self) -> dict:
        """The run's outcome and measures (JSON-ready), under the vocabulary's keys
        (``gripper_sim.core.vocabulary``)."""
        damage = self.last.damage
        bruised = bool(damage is not None and damage.bruised)
        crushed = bool(damage is not None and damage.crushed)
        slipped = self.contact.largest > SLIP_TOLERANCE
        dropped = self.dropped_at is not None
        if crushed:
            outcome = 'crushed'
        elif dropped:
            outcome = 'dropped'
        elif bruised:
            outcome = 'bruised'
        elif slipped and (self.placed or self.outcome == 'slipped'):
            outcome = 'slipped'
        elif self.placed:
            outcome = 'placed'
        elif slipped and self.until != 'settle' and self.reached_grip:
            outcome = 'slipped'
        elif self.outcome is None and self.until != 'settle' and self.reached_grip:
            outcome = 'held'
        else:
            outcome = self.outcome or 'running'
        messages = [self.message] if self.message else []
        if bruised:
            messages.append(f'bruised: peak damage pressure {damage.peak_pressure:.4g} Pa '
                            f"above {self.sim.config['fruit.bruise_pressure']:.4g} Pa, "
                            f'{damage.bruised_fraction * 100:.1f} % of the '
                            + ('surface' if getattr(self.sim, 'dimension', 2) == 3
                               else 'outline'))
        if crushed:
            messages.append(f'crushed: flesh stress {damage.peak_flesh_stress:.4g} Pa')
        summary = dict(outcome=outcome, placed=bool(self.placed), dropped=dropped,
                       dropped_at=None if self.dropped_at is None else float(self.dropped_at),
                       dropped_phase=self.dropped_phase, slipped=bool(slipped),
                       slip_distance=float(self.contact.largest),
                       centroid_drop=float(self.contact.centroid_drop),
                       message='; '.join(messages), sliding=bool(self.last.slipping),
                       **self.peaks.as_dict())
        if damage is not None:
            summary.update(damage_fields(damage))
        summary.update(bruised=bruised, crushed=crushed,
                       final_centroid=[float(v) for v in self.last.centroid],
                       phase_times=dict(self.phase_times), duration=self.sim.time)
        return summary


def run_scenario(sim, scenario: Scenario, on_step=None, time_limit: float = 120.0,
                 **options) -> dict:
    """Run ``scenario`` on ``sim`` to the end (or ``time_limit`` s); its summary.

    ``options`` go to ``PickAndPlace`` (``until``, ``stop_on_slip``, ``stop_on_bruise``).
    """
    machine = PickAndPlace(sim, scenario, **options)
    end = sim.time + time_limit
    while not machine.done and sim.time < end:
        result, _skipped = next_result(sim, machine, end, on_step is not None)
        machine.update(result)
        if on_step is not None:
            on_step(result, machine.phase)
    return machine.summary()
