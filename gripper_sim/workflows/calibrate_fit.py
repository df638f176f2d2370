"""Fit configuration keys to a measured compression curve by bounded least squares.

The residuals are the simulated minus the measured force at each measured
deformation, over the largest measured force. Each key is fitted in a scaled variable
``x``: ``x = ln(value / start)`` for a key whose range starts above zero (moduli),
``x = value / scale`` otherwise (turgor, Poisson ratio; scale = the starting value), so a
step of ``x`` is a relative change either way; the bounds are the configuration schema's
range in that variable. ``scipy.optimize.least_squares`` (trust-region reflective,
variables scaled by the Jacobian's columns) with forward differences of ``DIFF_STEP`` in
``x``. Before the fit the stiffness keys are scaled together by the factor that best
matches the starting curve to the data.

Uncertainty: the covariance of ``x`` at the optimum is ``s^2 (J^T J)^-1`` with
``s^2`` the residual variance (sum of squares over n - p), J the Jacobian; a key's
standard error follows through the transform. Identifiability warnings: a key whose
column of J is (nearly) zero, a near-singular J^T J (condition number above
``MAX_CONDITION``: a flat direction), a correlation above ``MAX_CORRELATION`` between
two keys, a relative standard error above ``MAX_RELATIVE_ERROR``, a key at a bound.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.optimize import least_squares

from gripper_sim.configuration import SCHEMA
from gripper_sim.errors import ConvergenceError
from gripper_sim.workflows.calibrate_data import CalibrationError, CompressionCurve
from gripper_sim.workflows.calibrate_model import CompressionTest, SimulatedCurve

#: forward-difference step of the Jacobian, in the scaled variables (2 % of a modulus)
DIFF_STEP = 0.02
#: condition number of J^T J above which a direction is called flat
MAX_CONDITION = 1e6
#: |correlation| above which two keys are called strongly correlated
MAX_CORRELATION = 0.95
#: relative standard error above which a key is called poorly determined
MAX_RELATIVE_ERROR = 0.25
#: simulations a fit may take at most
MAX_EVALUATIONS = 60
#: keys that scale the stiffness of the fruit (scaled together for the starting point)
STIFFNESS_KEYS = ('fruit.flesh.youngs_modulus', 'fruit.skin.youngs_modulus',
                  'fruit.pressure.turgor', 'fruit.pressure.bulk_modulus')


@dataclass(frozen=True)
class Parameter:
    """One fitted key and its scaled variable (see the module docstring).

    Attributes:
        key: configuration key.  start: its value at x = 0.
        log: x = ln(value / start), else x = value / scale.  scale: see ``log``.
        low, high: the schema's range of the value.
    """

    key: str
    start: float
    log: bool
    scale: float
    low: float
    high: float

    @classmethod
    def for_key(cls, key: str, start: float) -> 'Parameter':
        spec = SCHEMA[key]
        low, high = float(spec.low), float(spec.high)
        start = min(max(start, low), high)
        if low > 0 and start > 0:
            return cls(key, start, True, 1.0, low, high)
        scale = abs(start) if start != 0 else 1e-3 * (high - low)
        return cls(key, start, False, scale, low, high)

    def value(self, x: float) -> float:
        value = self.start * math.exp(x) if self.log else x * self.scale
        return min(max(value, self.low), self.high)

    def variable(self, value: float) -> float:
        return math.log(value / self.start) if self.log else value / self.scale

    def bounds(self) -> tuple[float, float]:
        return self.variable(self.low), self.variable(self.high)


@dataclass(frozen=True)
class FittedKey:
    """Attributes: key; value (fitted); std_error (absolute, same unit); start (the
    preset's value); at_bound (the fit stopped at the end of the key's range)."""

    key: str
    value: float
    std_error: float
    start: float
    at_bound: bool

    @property
    def relative_error(self) -> float:
        return self.std_error / abs(self.value) if self.value else math.inf


@dataclass(frozen=True)
class FitResult:
    """What a calibration found.

    Attributes:
        keys: the fitted keys.  values: {key: fitted value}.
        config: the configuration with the fitted values (validated).
        fitted: the simulated curve at the optimum.  start: at the preset's values.
        measured: the data.
        rms_error, max_error: N, RMS and largest |simulated - measured| force.
        correlation: (p, p) correlation matrix of the fitted keys.
        warnings: identifiability warnings (one line each).
        evaluations: simulations run by the fit.
    """

    keys: tuple[FittedKey, ...]
    config: dict
    fitted: SimulatedCurve
    start: SimulatedCurve
    measured: CompressionCurve
    rms_error: float
    max_error: float
    correlation: np.ndarray
    warnings: tuple[str, ...]
    evaluations: int

    @property
    def values(self) -> dict[str, float]:
        return {k.key: k.value for k in self.keys}

    @property
    def relative_rms_error(self) -> float:
        """RMS force error over the largest measured force."""
        return self.rms_error / float(np.max(self.measured.force))


def _start_value(config: dict, key: str) -> float:
    value = config[key]
    if value is None and key == 'fruit.pressure.bulk_modulus':
        e, nu = config['fruit.flesh.youngs_modulus'], config['fruit.flesh.poisson_ratio']
        return e / (2 * (1 + nu) * (1 - 2 * nu))
    return float(value)


def fit(test: CompressionTest, keys: tuple[str, ...],
        progress: Callable[[dict, float], None] | None = None) -> FitResult:
    """Fit ``keys`` so that ``test`` reproduces its measured curve.

    Args:
        progress: called after each simulation with ({key: value}, RMS force error N).

    Raises:
        CalibrationError: a simulation failed to converge during the fit.
    """
    measured = test.curve
    peak = float(np.max(measured.force))
    parameters = [Parameter.for_key(k, _start_value(test.base, k)) for k in keys]
    evaluations = 0

    def simulate(values: dict) -> SimulatedCurve:
        nonlocal evaluations
        try:
            curve = test.simulate(values)
        except ConvergenceError as err:
            shown = ', '.join(f'{k}={v:.4g}' for k, v in values.items())
            raise CalibrationError(f'the simulated test did not converge at {shown} '
                                   f'({err}); try a smaller sim.dt') from err
        evaluations += 1
        if progress is not None:
            error = curve.force_at(measured.deformation) - measured.force
            progress(values, float(np.sqrt(np.mean(error ** 2))))
        return curve

    start_curve = simulate({p.key: p.start for p in parameters})
    parameters = _scaled_start(parameters, start_curve, measured)

    computed: dict[bytes, np.ndarray] = {}

    def residuals(x: np.ndarray) -> np.ndarray:
        key = np.asarray(x, dtype=float).tobytes()
        if key not in computed:
            values = {p.key: p.value(xi) for p, xi in zip(parameters, x)}
            computed[key] = (simulate(values).force_at(measured.deformation)
                             - measured.force) / peak
        return computed[key]

    lower, upper = (np.array(b) for b in zip(*(p.bounds() for p in parameters)))

    def jacobian(x: np.ndarray) -> np.ndarray:
        """Forward differences of ``DIFF_STEP`` in each scaled variable (backward at
        the upper bound): steps large enough to see past the small jumps of the force
        as contact nodes engage."""
        base = residuals(x)
        columns = []
        for i in range(len(x)):
            step = DIFF_STEP if x[i] + DIFF_STEP <= upper[i] else -DIFF_STEP
            shifted = np.array(x, dtype=float)
            shifted[i] += step
            columns.append((residuals(shifted) - base) / step)
        return np.column_stack(columns)

    start_x = np.array([p.variable(p.start) for p in parameters])
    solution = least_squares(residuals, start_x, jac=jacobian, bounds=(lower, upper),
                             method='trf', x_scale='jac', ftol=1e-8, xtol=1e-6, gtol=1e-10,
                             max_nfev=MAX_EVALUATIONS)
    values = {p.key: p.value(xi) for p, xi in zip(parameters, solution.x)}
    config = test.config(values)
    fitted = test.simulate(config=config)
    error = fitted.force_at(measured.deformation) - measured.force
    sigma_x, correlation, warnings = _uncertainty(parameters, solution, len(error))
    fitted_keys = []
    for p, xi, sx in zip(parameters, solution.x, sigma_x):
        value = p.value(xi)
        std = value * sx if p.log else p.scale * sx
        low, high = p.bounds()
        at_bound = bool(min(xi - low, high - xi) < 1e-6 * max(1.0, abs(xi)))
        if at_bound:
            warnings.append(f'{p.key} = {value:.4g} stopped at the end of its range '
                            f'[{p.low:g}, {p.high:g}]: the data want a value outside it')
        fitted_keys.append(FittedKey(p.key, value, float(std), _start_value(test.base, p.key),
                                     at_bound))
    for k in fitted_keys:
        if math.isfinite(k.relative_error) and k.relative_error > MAX_RELATIVE_ERROR:
            size = (f'{k.relative_error:.0%} of its value' if k.relative_error < 10
                    else 'more than 10 times its value')
            warnings.append(f'{k.key} is poorly determined by these data (standard error '
                            f'{size})')
    return FitResult(keys=tuple(fitted_keys), config=config, fitted=fitted,
                     start=start_curve, measured=measured,
                     rms_error=float(np.sqrt(np.mean(error ** 2))),
                     max_error=float(np.max(np.abs(error))), correlation=correlation,
                     warnings=tuple(dict.fromkeys(warnings)), evaluations=evaluations)


def _scaled_start(parameters: list[Parameter], start: SimulatedCurve,
                  measured: CompressionCurve) -> list[Parameter]:
    """The parameters with the stiffness keys scaled by the factor that best matches
    the starting curve to the data (least squares), within their ranges."""
    simulated = start.force_at(measured.deformation)
    denominator = float(simulated @ simulated)
    if denominator <= 0:
        return parameters
    factor = float(simulated @ measured.force) / denominator
    scaled = []
    for p in parameters:
        if p.key in STIFFNESS_KEYS and p.start > 0:
            p = Parameter.for_key(p.key, min(max(p.start * factor, p.low), p.high))
        scaled.append(p)
    return scaled


def _uncertainty(parameters: list[Parameter], solution,
                 n_points: int) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(standard errors of x, correlation matrix, warnings) from the Jacobian."""
    jac = np.atleast_2d(solution.jac)
    p = len(parameters)
    names = [q.key for q in parameters]
    warnings: list[str] = []
    dof = max(n_points - p, 1)
    variance = float(solution.fun @ solution.fun) / dof
    norms = np.linalg.norm(jac, axis=0)
    largest = float(norms.max())
    dead = norms <= 1e-9 * largest if largest > 0 else np.ones(p, dtype=bool)
    for name, flat in zip(names, dead):
        if flat:
            warnings.append(f'{name} is not identifiable: it does not change the simulated '
                            'force in this test')
    normal = jac.T @ jac
    singular = np.linalg.svd(jac, compute_uv=False) if p else np.zeros(0)
    if p > 1 and singular[-1] <= singular[0] / math.sqrt(MAX_CONDITION):
        _, _, vt = np.linalg.svd(jac)
        direction = vt[-1]
        involved = [names[i] for i in np.argsort(-np.abs(direction))
                    if abs(direction[i]) > 0.3]
        if len(involved) > 1:
            warnings.append('flat direction: the data do not determine '
                            + ' and '.join(involved) + ' separately (the force barely '
                            'changes along a combination of them)')
        else:
            warnings.append(f'flat direction: the data barely determine {involved[0]} '
                            '(the force hardly changes with it)')
    covariance = variance * np.linalg.pinv(normal)
    sigma = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    sigma = np.where(dead, np.inf, sigma)
    with np.errstate(divide='ignore', invalid='ignore'):
        correlation = covariance / np.outer(sigma, sigma)
    correlation = np.where(np.isfinite(correlation), correlation, 0.0)
    np.fill_diagonal(correlation, 1.0)
    for i in range(p):
        for j in range(i + 1, p):
            if abs(correlation[i, j]) > MAX_CORRELATION:
                warnings.append(f'{names[i]} and {names[j]} are strongly correlated '
                                f'(correlation {correlation[i, j]:+.3f}): the data fix a '
                                'combination of them better than each')
    return sigma, correlation, warnings
