"""A fruit population: distributions over configuration keys, drawn reproducibly.

A study file's ``population`` names, per key, one distribution:

    normal      mean, std                    (std >= 0)
    lognormal   mean, std of the values      (the log's sigma^2 = ln(1 + (std/mean)^2))
    uniform     low, high                    (low <= high)
    list        values: measured values      (drawn without replacement while there
                                              are enough, else with replacement)

Keys are numeric configuration keys (``fruit.shape.diameter``, ``fruit.density``,
``fruit.flesh.youngs_modulus``, ``fruit.pressure.turgor``, ``contact.jaw.static_friction``,
...) or ``mass`` (kg: the fruit's density is scaled so that the fruit weighs that
much; ``study_spec`` applies it). Every drawn value
must lie in its key's range: a distribution that yields a non-physical value (a
negative diameter, a friction above 5) is a ``ConfigError`` naming the key and the
sample.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from gripper_sim.configuration import SCHEMA, key_suggestion
from gripper_sim.errors import ConfigError

#: the parameters of each distribution
DISTRIBUTIONS = {'normal': ('mean', 'std'), 'lognormal': ('mean', 'std'),
                 'uniform': ('low', 'high'), 'list': ('values',)}
#: population keys that are not configuration keys: unit and meaning
DERIVED_KEYS = {'mass': ('kg', 'fruit mass; sets fruit.density')}
#: most samples a population may have
MAX_SAMPLES = 100_000


@dataclass(frozen=True)
class Distribution:
    """One key's distribution: ``kind`` (see ``DISTRIBUTIONS``) and its parameters."""

    key: str
    kind: str
    params: Mapping[str, Any]

    def describe(self) -> str:
        """e.g. 'normal(mean=0.0635, std=0.004)'."""
        if self.kind == 'list':
            return f"list of {len(self.params['values'])} values"
        inner = ', '.join(f'{name}={self.params[name]:g}' for name in DISTRIBUTIONS[self.kind])
        return f'{self.kind}({inner})'

    def draw(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` values, shape (count,)."""
        p = self.params
        if self.kind == 'normal':
            return rng.normal(p['mean'], p['std'], count)
        if self.kind == 'lognormal':
            sigma2 = math.log1p((p['std'] / p['mean']) ** 2)
            return rng.lognormal(math.log(p['mean']) - 0.5 * sigma2, math.sqrt(sigma2), count)
        if self.kind == 'uniform':
            return rng.uniform(p['low'], p['high'], count)
        values = np.asarray(p['values'], dtype=float)
        return rng.choice(values, count, replace=count > len(values))


@dataclass(frozen=True)
class Population:
    """``samples`` fruits drawn with ``seed`` from ``distributions`` (sorted by key)."""

    samples: int
    seed: int
    distributions: tuple[Distribution, ...]

    @property
    def keys(self) -> list[str]:
        return [d.key for d in self.distributions]

    def draw(self) -> list[dict[str, float]]:
        """The samples: one ``{key: value}`` per fruit, the same for the same seed.

        Raises:
            ConfigError: a drawn value is outside its key's range.
        """
        rng = np.random.default_rng(self.seed)
        columns = {}
        for dist in self.distributions:
            values = dist.draw(rng, self.samples)
            _check_range(dist, values)
            columns[dist.key] = values
        return [{key: float(values[i]) for key, values in columns.items()}
                for i in range(self.samples)]


def parse_population(data: Any, where: str = 'population') -> Population:
    """A ``Population`` from a study file's ``population`` mapping.

    Raises:
        ConfigError: unknown key or distribution, missing or bad parameter, a negative
            standard deviation, an empty list (the message names the key).
    """
    if not isinstance(data, Mapping):
        raise ConfigError(f"study key '{where}' must be a mapping (samples, seed, "
                          'distributions)')
    unknown = set(data) - {'samples', 'seed', 'distributions'}
    if unknown:
        raise ConfigError(f"unknown study key '{where}.{sorted(unknown)[0]}' (known: "
                          'samples, seed, distributions)')
    samples = _integer(data.get('samples', 1), f'{where}.samples', 1, MAX_SAMPLES)
    seed = _integer(data.get('seed', 0), f'{where}.seed', 0, 2 ** 63 - 1)
    raw = data.get('distributions') or {}
    if not isinstance(raw, Mapping):
        raise ConfigError(f"study key '{where}.distributions' must map keys to "
                          'distributions')
    dists = tuple(_distribution(str(key), spec, f'{where}.distributions.{key}')
                  for key, spec in sorted(raw.items()))
    return Population(samples=samples, seed=seed, distributions=dists)


def _integer(value: Any, where: str, low: int, high: int) -> int:
    number = as_number(value)
    if not math.isfinite(number) or not number.is_integer() or not low <= number <= high:
        raise ConfigError(f"study key '{where}' must be an integer in [{low}, {high}], "
                          f'got {value!r}')
    return int(number)


def _distribution(key: str, spec: Any, where: str) -> Distribution:
    if key not in DERIVED_KEYS:
        if key not in SCHEMA:
            raise ConfigError(f"unknown population key '{key}'{key_suggestion(key)}")
        if SCHEMA[key].kind not in ('float', 'int'):
            raise ConfigError(f"population key '{key}' is not numeric: put it in 'axes'")
    if not isinstance(spec, Mapping) or 'distribution' not in spec:
        raise ConfigError(f"study key '{where}' must be a mapping with 'distribution' "
                          f"({', '.join(DISTRIBUTIONS)}) and its parameters")
    kind = str(spec['distribution'])
    if kind not in DISTRIBUTIONS:
        raise ConfigError(f"study key '{where}.distribution': unknown distribution "
                          f"'{kind}' (known: {', '.join(DISTRIBUTIONS)})")
    names = DISTRIBUTIONS[kind]
    extra = set(spec) - set(names) - {'distribution'}
    if extra:
        raise ConfigError(f"unknown study key '{where}.{sorted(extra)[0]}' ({kind} takes "
                          f"{', '.join(names)})")
    missing = [name for name in names if name not in spec]
    if missing:
        raise ConfigError(f"study key '{where}' ({kind}) needs '{missing[0]}'")
    params: dict[str, Any] = {}
    if kind == 'list':
        values = spec['values']
        if not isinstance(values, (list, tuple)) or not values:
            raise ConfigError(f"study key '{where}.values' must be a non-empty list")
        params['values'] = tuple(_number(v, f'{where}.values') for v in values)
    else:
        for name in names:
            params[name] = _number(spec[name], f'{where}.{name}')
    if kind in ('normal', 'lognormal') and params['std'] < 0:
        raise ConfigError(f"study key '{where}.std' must not be negative, got "
                          f"{params['std']:g}")
    if kind == 'lognormal' and params['mean'] <= 0:
        raise ConfigError(f"study key '{where}.mean' of a lognormal must be > 0, got "
                          f"{params['mean']:g}")
    if kind == 'uniform' and params['low'] > params['high']:
        raise ConfigError(f"study key '{where}': low {params['low']:g} is above high "
                          f"{params['high']:g}")
    return Distribution(key=key, kind=kind, params=params)


def as_number(value: Any) -> float:
    """``value`` as a float, NaN if it is no number: the one reading of every numeric
    field of a study file. Text such as '1e6' or '1.5e6' is a number (YAML 1.1 reads a
    number written without a dot, or without a sign after the 'e', as a string), as
    the configuration keys take it; true and false are not."""
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _number(value: Any, where: str) -> float:
    """A finite float (``as_number``), else ConfigError naming ``where``."""
    number = as_number(value)
    if not math.isfinite(number):
        raise ConfigError(f"study key '{where}' must be a finite number, got {value!r}")
    return number


def _check_range(dist: Distribution, values: np.ndarray) -> None:
    """Every value inside the key's range (mass: > 0), else ConfigError naming it."""
    key = dist.key
    if key in DERIVED_KEYS:
        low, high, open_low, unit = 0.0, None, True, DERIVED_KEYS[key][0]
    else:
        spec = SCHEMA[key]
        low, high, open_low, unit = spec.low, spec.high, spec.open_low, spec.unit
    unit = f' {unit}' if unit not in ('', '-') else ''
    bad = np.zeros(len(values), dtype=bool)
    if low is not None:
        bad |= (values <= low) if open_low else (values < low)
    if high is not None:
        bad |= values > high
    if np.any(bad):
        i = int(np.argmax(bad))
        limits = []
        if low is not None:
            limits.append(f"{'>' if open_low else '>='} {low:g}{unit}")
        if high is not None:
            limits.append(f'<= {high:g}{unit}')
        raise ConfigError(
            f"population key '{key}' ({dist.describe()}) yields non-physical values: "
            f'sample {i} is {values[i]:.4g}{unit} ({int(bad.sum())} of {len(values)} out of '
            f"the key's range: {', '.join(limits)}); narrow the distribution")
