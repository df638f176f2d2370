"""The simulated counterpart of a measured plate compression test.

``CompressionTest`` holds what every simulation of one calibration shares: the base
configuration (fruit preset + ``--set``), the plate speed, the largest deformation and
the fruit's rest width. ``simulate`` runs the squeeze workflow (``workflows.squeeze``)
for a set of parameter values and returns the force (and the damage pressure) against
the plate travel since first contact, ``deformation = rest width - gap``.

Simulation settings chosen here unless ``--set`` gives them: the jaws start
``CLEARANCE_RATIO`` of the largest deformation (at least ``MIN_CLEARANCE``) from the
fruit, so no time goes into the approach, and the step is chosen so that the whole
test takes ``TEST_STEPS`` steps (never below the built-in 2D ``sim.dt``, whatever the
dimension's default step): a plate test
is quasi-static, and the implicit step damps what inertia there is.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np

from gripper_sim.configuration import SCHEMA, load_config, no_effect_reason
from gripper_sim.workflows.calibrate_data import CalibrationError, CompressionCurve
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.squeeze import SQUEEZE_DEFAULTS, check_squeeze, squeeze

#: steps a simulated test takes (sets sim.dt unless the user sets it)
TEST_STEPS = 200
#: initial jaw clearance over the largest deformation
CLEARANCE_RATIO = 0.02
#: m, smallest initial jaw clearance
MIN_CLEARANCE = 1e-5
#: the model's range: largest deformation over the fruit's rest width
MAX_DEFORMATION_RATIO = 0.3
#: the smallest largest deformation a fit is attempted on, over the fruit's rest width
#: (0.13 mm of a 63.5 mm apple): below it the curve is a deformation column in m read
#: as mm, not a test a fruit model can be fitted to
MIN_DEFORMATION_RATIO = 0.002
#: m/s, plate speed when neither the file nor the command line gives one (squeeze's)
DEFAULT_SPEED = 0.005

#: keys a calibration may fit (fruit material keys; the geometry stays as configured)
FITTABLE_KEYS = ('fruit.flesh.youngs_modulus', 'fruit.flesh.poisson_ratio',
                 'fruit.skin.youngs_modulus', 'fruit.skin.thickness',
                 'fruit.pressure.turgor', 'fruit.pressure.bulk_modulus',
                 'fruit.damping.mass', 'fruit.damping.stiffness')
#: keys fitted when none are named, per fruit model
DEFAULT_FIT = {'shell': ('fruit.flesh.youngs_modulus', 'fruit.pressure.turgor'),
               'solid': ('fruit.flesh.youngs_modulus',)}


@dataclass(frozen=True)
class SimulatedCurve:
    """One simulated test.

    Attributes:
        deformation: (m,) m, plate travel since first contact at each step (may start < 0).
        force: (m,) N, grip force (mean normal force of the two plates) at each step.
        damage_pressure: (m,) Pa, largest damage pressure so far (``Damage.peak_pressure``).
        bruised: (m,) bool, the fruit is bruised at that step.
    """

    deformation: np.ndarray
    force: np.ndarray
    damage_pressure: np.ndarray
    bruised: np.ndarray

    def force_at(self, deformation: np.ndarray) -> np.ndarray:
        """N, the simulated force interpolated at ``deformation`` (m, within the test)."""
        return np.interp(deformation, self.deformation, self.force)


def fit_keys(names: str | None, model: str) -> tuple[str, ...]:
    """The keys to fit: ``'flesh.youngs_modulus,pressure.turgor'`` (``fruit.`` may be
    left out) or, for None, the model's default; CalibrationError for a key that cannot
    be fitted, and for no key or an empty one ('', 'a,,b')."""
    if names is None:
        if model not in DEFAULT_FIT:
            raise CalibrationError(f"the {model} model cannot be calibrated (use --model "
                                   'shell or solid)')
        return DEFAULT_FIT[model]
    keys = []
    for name in (n.strip() for n in names.split(',')):
        if not name:
            raise CalibrationError(f"--fit '{names}' names an empty key: give KEY,KEY, or "
                                   "leave --fit out for the model's default keys")
        key = name if name.startswith('fruit.') else f'fruit.{name}'
        if key not in FITTABLE_KEYS:
            known = ', '.join(k.removeprefix('fruit.') for k in FITTABLE_KEYS)
            raise CalibrationError(f"--fit: '{name}' cannot be fitted (keys: {known})")
        if key in keys:
            raise CalibrationError(f"--fit: '{name}' is named twice")
        keys.append(key)
    return tuple(keys)


def check_fit_keys(keys: tuple[str, ...], config: Mapping) -> None:
    """Refuse to fit a key that has no effect in ``config``'s set-up
    (``configuration.no_effect_reason``: e.g. the turgor of a solid): the fit could not
    move the force with it, and the preset would record a meaningless value.

    Raises:
        CalibrationError: naming the key and why it has no effect.
    """
    for key in keys:
        reason = no_effect_reason(key, config)
        if reason is not None:
            raise CalibrationError(f"--fit: '{key}' has no effect in this set-up: {reason}")


class CompressionTest:
    """The simulated test of ``curve`` for configurations built from ``base_overrides``.

    Args:
        curve: the measured curve (its largest deformation and speed set the test).
        fruit: fruit preset name or preset file (None: the default fruit).
        config_file: a configuration file (``--config``), as ``load_config`` takes it.
        overrides: ``{key: value}`` from ``--set`` (they win over the test's settings).
        speed: m/s, plate speed; None = the curve's, else ``DEFAULT_SPEED``.

    Raises:
        CalibrationError: the deformation is beyond the model's range or too small to
            fit (a unit mistake), the speed beyond
            the gripper's, or the fruit model cannot be calibrated.
        ConfigError: a bad fruit or override.
    """

    def __init__(self, curve: CompressionCurve, fruit: str | None = None,
                 overrides: Mapping | None = None, speed: float | None = None,
                 config_file: str | None = None):
        self.curve = curve
        self.config_file = config_file
        self.user = dict(overrides or {})
        self.speed = speed or curve.speed or DEFAULT_SPEED
        probe = load_config(fruit=fruit, config_file=config_file,
                            overrides={**SQUEEZE_DEFAULTS, **self.user})
        self.fruit = fruit
        self.dimension = int(probe['dimension'])
        self.model = probe['fruit.model']
        if self.model not in DEFAULT_FIT:
            raise CalibrationError(f"the {self.model} model cannot be calibrated (use "
                                   '--model shell or solid)')
        check_squeeze(probe, self.speed)
        rest = make_simulation(probe).last.positions[:, 0]
        self.rest_width = float(np.ptp(rest))
        limit = MAX_DEFORMATION_RATIO * self.rest_width
        if curve.max_deformation > limit:
            raise CalibrationError(
                f'the largest deformation {curve.max_deformation * 1e3:.4g} mm is beyond the '
                f'model\'s range: at most {MAX_DEFORMATION_RATIO:.0%} of the fruit\'s width '
                f'({self.rest_width * 1e3:.4g} mm), i.e. {limit * 1e3:.4g} mm; set '
                "fruit.shape.diameter to the tested fruit's size")
        smallest = MIN_DEFORMATION_RATIO * self.rest_width
        if curve.max_deformation < smallest:
            raise CalibrationError(
                f'the largest deformation {curve.max_deformation * 1e3:.4g} mm is '
                f"{curve.max_deformation / self.rest_width:.2%} of the fruit's width "
                f'({self.rest_width * 1e3:.4g} mm), below the {smallest * 1e3:.2g} mm a fit '
                'needs: is the deformation column in m rather than mm?')
        self.clearance = max(CLEARANCE_RATIO * curve.max_deformation, MIN_CLEARANCE)
        duration = (self.clearance + curve.max_deformation) / self.speed
        settings = {'gripper.initial_gap': self.rest_width + self.clearance,
                    'sim.dt': min(max(duration / TEST_STEPS, SCHEMA['sim.dt'].default),
                                  SCHEMA['sim.dt'].high)}
        self.settings = {key: value for key, value in settings.items()
                         if key not in self.user}
        self.base = self.config()

    def config(self, values: Mapping[str, float] | None = None) -> dict:
        """The validated configuration with ``values`` ({key: value}) set."""
        return load_config(fruit=self.fruit, config_file=self.config_file,
                           overrides={**SQUEEZE_DEFAULTS, **self.settings, **self.user,
                                      **(values or {})})

    def simulate(self, values: Mapping[str, float] | None = None,
                 config: Mapping | None = None) -> SimulatedCurve:
        """Run the test with ``values`` set (or with the whole ``config``).

        Raises:
            ConvergenceError, GripperSimError: from the squeeze.
        """
        sim = make_simulation(config if config is not None else self.config(values))
        rows: list[tuple[float, float, float, bool]] = []

        def record(result):
            damage = result.damage
            rows.append((self.rest_width - result.gap, result.grip_force,
                         damage.peak_pressure if damage is not None else 0.0,
                         bool(damage.bruised) if damage is not None else False))

        sim.add_observer(record)
        squeeze(sim, self.speed, to_gap=self.rest_width - self.curve.max_deformation)
        table = np.array(rows, dtype=float)
        return SimulatedCurve(deformation=table[:, 0], force=table[:, 1],
                              damage_pressure=table[:, 2], bruised=table[:, 3] > 0.5)


def synthetic_curve(fruit: str | None, overrides: Mapping, values: Mapping[str, float],
                    deformation: np.ndarray, speed: float, noise: float = 0.0,
                    seed: int = 0, step_ratio: float = 1.0) -> CompressionCurve:
    """A test measured on the model itself: the simulated force of ``values`` at
    ``deformation`` ((n,) m, increasing) times ``1 + noise * N(0, 1)`` (fixed ``seed``),
    simulated with ``step_ratio`` times the step a calibration of it would take. For
    checking a calibration, or whether a planned test can determine a key."""
    deformation = np.asarray(deformation, dtype=float)
    placeholder = CompressionCurve(deformation, np.ones_like(deformation), speed,
                                   'synthetic', '')
    step = CompressionTest(placeholder, fruit, overrides).base['sim.dt'] * step_ratio
    generator = CompressionTest(placeholder, fruit, {**overrides, 'sim.dt': step})
    force = generator.simulate(values).force_at(deformation)
    force = force * (1.0 + noise * np.random.default_rng(seed).standard_normal(len(force)))
    return CompressionCurve(deformation, np.maximum(force, 0.0), speed, 'synthetic', '')
