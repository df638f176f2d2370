"""Study files: a base set-up, axes (grids over keys) and a fruit population, validated.

A study file (``config/studies/*.yaml``) is YAML with these top-level keys:

    name, description       text
    base                    fruit, finger (presets), scenario (a name in config/scenarios
                            or a file), scenario_set (scenario keys), set (configuration
                            keys): the set-up every evaluation starts from
    axes                    {key: [values, ...]}: the design points are every
                            combination. A key is 'fruit' or 'finger' (presets), a
                            scenario key spelled 'scenario.KEY', a configuration key,
                            or 'force' (grip forces in N: the study then evaluates
                            this grid instead of searching each fruit's window)
    population              samples, seed, distributions (``population.py``)
    window                  fraction (default 0.99), confidence (0.95), tolerance (0.03)

Everything is checked before any simulation runs: unknown keys, empty axes, values out
of range (every design point and every sample is built), negative standard
deviations and distributions that yield non-physical values are ``ConfigError``s
naming the key.
"""
from __future__ import annotations

import hashlib
import itertools
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from gripper_sim.configuration import (SCHEMA, key_suggestion, load_config, package_config_dir,
                                       read_yaml)
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.population import Population, as_number, parse_population
from gripper_sim.workflows.scenario import (SCENARIO_SCHEMA, Scenario, load_scenario,
                                            scenario_config)
from gripper_sim.workflows.window import TOLERANCE, estimates, trial_setup

TOP_KEYS = ('name', 'description', 'base', 'axes', 'population', 'window')
BASE_KEYS = ('fruit', 'finger', 'scenario', 'scenario_set', 'set')
WINDOW_KEYS = ('fraction', 'confidence', 'tolerance')
#: axis keys that are not configuration keys
PRESET_AXES = ('fruit', 'finger')
FORCE_AXIS = 'force'
SCENARIO_PREFIX = 'scenario.'


@dataclass(frozen=True)
class DesignPoint:
    """One combination of the axes (without 'force'): index and ``{axis key: value}``."""

    index: int
    values: Mapping[str, Any]

    def label(self) -> str:
        return ', '.join(f'{key}={value}' for key, value in self.values.items()) or 'base'


@dataclass(frozen=True)
class FruitSetup:
    """The set-up of one (design point, sample): its trial configuration and scenario
    (``workflows.window.trial_setup``) and the sample's drawn values."""

    point: int
    sample: int
    config: Mapping[str, Any]
    scenario: Scenario
    drawn: Mapping[str, float]


@dataclass(frozen=True)
class Study:
    """A validated study file (see the module docstring)."""

    name: str
    description: str
    source: str
    base: Mapping[str, Any]
    axes: Mapping[str, tuple]
    population: Population
    fraction: float = 0.99
    confidence: float = 0.95
    tolerance: float = TOLERANCE
    points: tuple[DesignPoint, ...] = field(default=())

    @property
    def forces(self) -> tuple[float, ...]:
        """The grip-force grid (N), empty when each fruit's window is searched."""
        return tuple(self.axes.get(FORCE_AXIS, ()))

    @property
    def method(self) -> str:
        return 'grid' if self.forces else 'bisection'

    def definition_hash(self) -> str:
        """16 hex digits of what decides the study's rows: its name, base set-up (the
        scenario's values), axes, population and tolerance. Not its description, file
        path, fraction or confidence (they change the summary, not the rows)."""
        scenario = self.base['scenario']
        definition = dict(
            name=self.name,
            base=dict(self.base, scenario=dict(values=dict(scenario.values),
                                               overrides=dict(scenario.overrides))),
            axes={key: list(values) for key, values in self.axes.items()},
            population=dict(samples=self.population.samples, seed=self.population.seed,
                            distributions=[[d.key, d.kind, dict(d.params)]
                                           for d in self.population.distributions]),
            tolerance=self.tolerance)
        text = json.dumps(definition, sort_keys=True, default=repr)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def trial(self, point: DesignPoint, sample: int,
              drawn: Mapping[str, float]) -> FruitSetup:
        """The trial set-up of ``point`` for the fruit ``drawn`` (ConfigError if invalid)."""
        fruit = point.values.get('fruit', self.base['fruit'])
        finger = point.values.get('finger', self.base['finger'])
        scenario = self.base['scenario']
        overrides = dict(self.base['set'])
        scenario_values = {}
        for key, value in point.values.items():
            if key.startswith(SCENARIO_PREFIX):
                scenario_values[key[len(SCENARIO_PREFIX):].replace('.', '__')] = value
            elif key not in PRESET_AXES:
                overrides[key] = value
        if scenario_values:
            scenario = scenario.with_values(**scenario_values)
        sampled = {k: v for k, v in drawn.items() if k != 'mass'}
        overrides.update(sampled)
        static, kinetic = 'contact.jaw.static_friction', 'contact.jaw.kinetic_friction'
        if static in overrides and static not in self.base['set'] \
                and kinetic not in overrides:
            # a varied static friction keeps the configured kinetic/static ratio
            plain = load_config(fruit=fruit, finger=finger, overrides={
                k: v for k, v in overrides.items() if k != static})
            overrides[kinetic] = overrides[static] * plain[kinetic] / plain[static]
        config = _config(scenario, fruit, finger, overrides, point, sample)
        if 'mass' in drawn:
            mass = estimates(config)[2]
            overrides['fruit.density'] = config['fruit.density'] * drawn['mass'] / mass
            config = _config(scenario, fruit, finger, overrides, point, sample,
                             f"population key 'mass' = {drawn['mass']:.4g} kg sets "
                             f'fruit.density: ')
        trial_config, trial_scenario = trial_setup(config, scenario)
        return FruitSetup(point=point.index, sample=sample, config=trial_config,
                          scenario=trial_scenario, drawn=dict(drawn))

    def setups(self, samples: list[Mapping[str, float]]) -> list[FruitSetup]:
        """The set-up of every (design point, fruit) of ``samples`` (``Population.draw``),
        point by point: all of them built, so that a sample no configuration takes, or
        a window search that cannot start, is a ConfigError before any cluster starts
        or any file is written."""
        setups = [self.trial(point, index, drawn) for point in self.points
                  for index, drawn in enumerate(samples)]
        if not self.forces:
            for setup in setups:
                _check_searchable(setup, self.points[setup.point])
        return setups


def _check_searchable(setup: FruitSetup, point: DesignPoint) -> None:
    """A window search starts from the force that holds the fruit by friction, m g /
    (2 mu): without friction (mu = 0, of the jaws or of the pads) there is none.

    Raises:
        ConfigError: naming the design point, the sample and the friction key.
    """
    config = setup.config
    key = ('contact.pad.friction' if config['gripper.finger.pad.enabled']
           else 'contact.jaw.static_friction')
    if config[key] <= 0:
        raise ConfigError(f'design point {point.index} ({point.label()}), sample '
                          f"{setup.sample}: {key} is 0, so no grip force holds the fruit "
                          "and its window search cannot start; give a 'force' axis to "
                          'evaluate grip forces without friction')


def _config(scenario, fruit, finger, overrides, point, sample, cause: str = '') -> dict:
    """The scenario's configuration; a ConfigError names the design point, the sample
    and ``cause`` (what set the offending key, if not the study file itself)."""
    try:
        return scenario_config(scenario, fruit=fruit, finger=finger, overrides=overrides)
    except ConfigError as err:
        raise ConfigError(f'design point {point.index} ({point.label()}), sample {sample}: '
                          f'{cause}{err}') from err


def load_study(path: str | Path) -> Study:
    """Read and validate a study file (a path, or the name of one in config/studies).

    Raises:
        ConfigError: see the module docstring.
    """
    file = Path(path)
    if not file.is_file() and not file.suffix:
        candidate = package_config_dir() / 'studies' / f'{path}.yaml'
        if candidate.is_file():
            file = candidate
    if not file.is_file():
        installed = sorted(p.stem for p in (package_config_dir() / 'studies').glob('*.yaml'))
        raise ConfigError(f"no study file '{path}': no such file, and not one of the "
                          f"installed studies ({', '.join(installed) or 'none installed'})")
    data = read_yaml(file)
    _known(data, TOP_KEYS, '')
    base = _base(data.get('base') or {})
    axes = _axes(data.get('axes') or {}, base['scenario'])
    population = parse_population(data.get('population') or {})
    overlap = set(axes) & set(population.keys)
    if overlap:
        raise ConfigError(f"key '{sorted(overlap)[0]}' is both an axis and a population key")
    if 'mass' in population.keys and 'fruit.density' in population.keys + list(axes):
        raise ConfigError("population key 'mass' sets fruit.density: do not vary both")
    window = data.get('window') or {}
    _known(window, WINDOW_KEYS, 'window.')
    fraction = _fraction(window.get('fraction', 0.99), 'window.fraction')
    confidence = _fraction(window.get('confidence', 0.95), 'window.confidence')
    tolerance = _fraction(window.get('tolerance', TOLERANCE), 'window.tolerance')
    grid_keys = [key for key in axes if key != FORCE_AXIS]
    points = tuple(DesignPoint(i, dict(zip(grid_keys, combo))) for i, combo in enumerate(
        itertools.product(*(axes[key] for key in grid_keys))))
    study = Study(name=str(data.get('name') or file.stem),
                  description=str(data.get('description') or ''), source=str(file),
                  base=base, axes=axes, population=population, fraction=fraction,
                  confidence=confidence, tolerance=tolerance, points=points)
    forces = study.forces
    for point in points:  # every design point's set-up builds (values in range)
        config = study.trial(point, 0, {}).config
        for force in forces:
            if force > config['gripper.max_force']:
                raise ConfigError(f"axis 'force': {force:g} N exceeds gripper.max_force "
                                  f"{config['gripper.max_force']:g} N")
    return study


def _known(data: Mapping, known: tuple, prefix: str) -> None:
    if not isinstance(data, Mapping):
        raise ConfigError(f"study key '{prefix.rstrip('.') or 'study'}' must be a mapping")
    for key in data:
        if key not in known:
            raise ConfigError(f"unknown study key '{prefix}{key}' (known: {', '.join(known)})")


def _base(data: Mapping) -> dict[str, Any]:
    _known(data, BASE_KEYS, 'base.')
    scenario = load_scenario(str(data.get('scenario') or 'pick_and_place'))
    changes = data.get('scenario_set') or {}
    _known(changes, tuple(SCENARIO_SCHEMA), 'base.scenario_set.')
    if changes:
        scenario = scenario.with_values(**{k.replace('.', '__'): v for k, v in changes.items()})
    overrides = data.get('set') or {}
    if not isinstance(overrides, Mapping):
        raise ConfigError("study key 'base.set' must map configuration keys to values")
    for key in overrides:
        if key not in SCHEMA:
            raise ConfigError(f"unknown config key '{key}' in base.set{key_suggestion(key)}")
    return dict(fruit=data.get('fruit') or scenario['fruit'],
                finger=data.get('finger') or scenario['finger'], scenario=scenario,
                set={key: _read_number(value, SCHEMA[key].kind)
                     for key, value in overrides.items()})


def _axes(data: Mapping, scenario: Scenario) -> dict[str, tuple]:
    if not isinstance(data, Mapping):
        raise ConfigError("study key 'axes' must map keys to lists of values")
    axes: dict[str, tuple] = {}
    for key, values in data.items():
        key = str(key)
        if not isinstance(values, (list, tuple)):
            raise ConfigError(f"axis '{key}' must be a list of values, got {values!r}")
        if not values:
            raise ConfigError(f"axis '{key}' is empty: give it at least one value")
        if key == FORCE_AXIS:
            forces = [as_number(value) for value in values]
            for value, force in zip(values, forces):
                if not math.isfinite(force) or force <= 0:
                    raise ConfigError(f"axis 'force' values must be positive grip forces "
                                      f'(N), got {value!r}')
            values = sorted(forces)
        elif key.startswith(SCENARIO_PREFIX):
            name = key[len(SCENARIO_PREFIX):]
            if name not in SCENARIO_SCHEMA:
                raise ConfigError(f"unknown scenario key '{name}' in axis '{key}'")
            values = [_read_number(value, SCENARIO_SCHEMA[name].kind) for value in values]
            for value in values:  # validates each value
                scenario.with_values(**{name.replace('.', '__'): value})
        elif key in SCHEMA:
            values = [_read_number(value, SCHEMA[key].kind) for value in values]
        elif key not in PRESET_AXES:
            raise ConfigError(f"unknown axis key '{key}'{key_suggestion(key)} (an axis is "
                              "'fruit', 'finger', 'force', 'scenario.KEY' or a configuration "
                              'key)')
        if len(set(map(repr, values))) != len(values):
            raise ConfigError(f"axis '{key}' repeats a value")
        axes[key] = tuple(values)
    return axes


def _read_number(value: Any, kind: str) -> Any:
    """An axis or ``base.set`` value of a key of ``kind`` ('float', 'int', ...): text
    that is a number (``as_number``: '1e6') as that number, so that rows, labels and
    the definition's hash hold numbers; any other value as given (the key's validation
    judges it)."""
    number = as_number(value)
    if not isinstance(value, str) or not math.isfinite(number):
        return value
    if kind == 'float':
        return number
    if kind == 'int' and number.is_integer():
        return int(number)
    return value


def _fraction(value: Any, where: str) -> float:
    number = as_number(value)
    if not 0 < number < 1:
        raise ConfigError(f"study key '{where}' must be a number in (0, 1), got {value!r}")
    return number
