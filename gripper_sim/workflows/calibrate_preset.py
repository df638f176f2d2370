"""The fruit preset a calibration writes: the fitted fruit as YAML, with its provenance.

The file holds every ``fruit.*`` key of the fitted configuration and the fruit's friction
keys (as the built-in presets in ``config/fruits`` do), so ``--fruit FILE.yaml``,
``--config`` (``fruit: FILE.yaml``), the node's ``fruit`` parameter and a study load it
like a built-in fruit; the simulation settings of the test (step, initial gap, ``dimension``)
are not part of it. Its ``calibration:`` section (``configuration.PROVENANCE_KEY``, not
configuration) records the data file's SHA-256, the date, the fitted keys with their
standard errors and the fit quality.
"""
from __future__ import annotations

import datetime
from pathlib import Path

import yaml

from gripper_sim.configuration import DEFAULT_FRUIT, PROVENANCE_KEY, load_config, unflatten
from gripper_sim.workflows.calibrate_bruise import BruiseCalibration
from gripper_sim.workflows.calibrate_data import CalibrationError
from gripper_sim.workflows.calibrate_fit import FitResult
from gripper_sim.workflows.calibrate_model import CompressionTest

#: the keys a preset holds besides ``fruit.*``: the fruit's friction against jaws and table
FRICTION_KEYS = ('contact.jaw.static_friction', 'contact.jaw.kinetic_friction',
                 'contact.pad.friction', 'contact.table.static_friction',
                 'contact.table.kinetic_friction')


def _plain(value):
    """numpy scalars to Python numbers (YAML writes only plain types)."""
    return value.item() if hasattr(value, 'item') else value


def provenance(test: CompressionTest, result: FitResult, bruise: BruiseCalibration | None,
               today: datetime.date | None = None) -> dict:
    """The ``calibration:`` record of the preset."""
    curve = test.curve
    record = {
        'data_file': Path(curve.path).name,
        'data_sha256': curve.sha256,
        'date': (today or datetime.date.today()).isoformat(),
        'base_fruit': test.fruit or (f'config file {Path(test.config_file).name}'
                                     if test.config_file else DEFAULT_FRUIT),
        'model': test.model,
        'dimension': test.dimension,
        'points': int(len(curve.force)),
        'max_deformation_m': float(curve.max_deformation),
        'plate_speed_m_per_s': float(test.speed),
        'sim_dt_s': float(result.config['sim.dt']),
        'fitted_keys': {k.key: {'value': float(k.value), 'std_error': float(k.std_error),
                                'start': float(k.start)} for k in result.keys},
        'rms_error_N': float(result.rms_error),
        'max_error_N': float(result.max_error),
        'rms_error_over_peak_force': float(result.relative_rms_error),
        'warnings': list(result.warnings),
    }
    if bruise is not None:
        record['bruise'] = {
            'observed_deformation_m': float(bruise.observed_deformation),
            'observed_force_N': float(bruise.observed_force),
            'bruise_pressure_Pa': float(bruise.bruise_pressure),
            'simulated_onset_deformation_m': (None if bruise.simulated_deformation is None
                                              else float(bruise.simulated_deformation))}
    return record


def preset_text(test: CompressionTest, result: FitResult, name: str,
                bruise: BruiseCalibration | None = None,
                today: datetime.date | None = None) -> str:
    """The preset file's text (comment header, keys, ``calibration:`` record)."""
    config = {**result.config, 'fruit.name': name}
    if bruise is not None:
        config['fruit.bruise_pressure'] = bruise.bruise_pressure
    keys = {k: _plain(v) for k, v in config.items()
            if k.startswith('fruit.') or k in FRICTION_KEYS}
    record = provenance(test, result, bruise, today)
    fitted = ', '.join(f'{k.key.removeprefix("fruit.")} = {k.value:.4g} +/- {k.std_error:.2g}'
                       for k in result.keys)
    header = [
        f'# Fruit preset {name}: written by gripper-sim calibrate on {record["date"]}',
        f'# from {record["data_file"]} (sha256 {test.curve.sha256[:16]}...), starting from '
        f'{record["base_fruit"]}, {test.model} model, {test.dimension}D.',
        f'# Fitted: {fitted}.',
        f'# Fit: RMS force error {result.rms_error:.3g} N '
        f'({result.relative_rms_error:.1%} of the largest force), largest '
        f'{result.max_error:.3g} N. Use with --fruit {name}.yaml'
        + (' --set dimension=3' if test.dimension == 3 else '') + '.',
    ]
    header += [f'# warning: {w}' for w in result.warnings]
    body = yaml.safe_dump(unflatten(keys), sort_keys=True)
    tail = yaml.safe_dump({PROVENANCE_KEY: record}, sort_keys=False)
    return '\n'.join(header) + '\n' + body + tail


def write_preset(path: str | Path, text: str, dimension: int) -> None:
    """Write the preset and check that it loads as a fruit (strict validation) in the
    ``dimension`` it was calibrated in (as its header says to use it: in another one its
    ``calibration:`` record would make loading it warn).

    Raises:
        CalibrationError: the file cannot be written.
        ConfigError: it does not load (a bug, never left silently).
    """
    path = Path(path)
    try:
        path.write_text(text, encoding='utf-8')
    except OSError as err:
        raise CalibrationError(f"cannot write the preset '{path}': {err.strerror}") from err
    load_config(fruit=str(path), overrides={'dimension': dimension})
