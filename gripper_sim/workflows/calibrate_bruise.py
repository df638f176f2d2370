"""Bruise calibration: the bruise pressure at which the simulated test bruises where the
real one did.

The simulation calls a fruit bruised once its damage pressure (``Damage.peak_pressure``:
the Hertz peak pressure in 2D, the resolved one in 3D; ``gripper_sim.core.damage``)
exceeds ``fruit.bruise_pressure``. Given the force or the plate travel at which bruising
was observed in the test, the bruise pressure is the simulated damage pressure at that
point of the fitted curve; the test is then run again with it to find the simulated onset.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.configuration import SCHEMA, validate
from gripper_sim.workflows.calibrate_data import CalibrationError
from gripper_sim.workflows.calibrate_model import CompressionTest, SimulatedCurve


@dataclass(frozen=True)
class BruiseCalibration:
    """Attributes:
        bruise_pressure: Pa, the calibrated ``fruit.bruise_pressure``.
        observed_deformation: m, plate travel at the observed onset.
        observed_force: N, simulated force there (the observed force when one was given).
        simulated_deformation: m, plate travel at which the re-run simulation first
            reports the fruit bruised (None if it never does).
        step_travel: m, plate travel per simulation step (the onset's resolution).
    """

    bruise_pressure: float
    observed_deformation: float
    observed_force: float
    simulated_deformation: float | None
    step_travel: float


def onset_deformation(curve: SimulatedCurve, at_force: float) -> float:
    """m, the first plate travel at which the simulated force reaches ``at_force`` (N)."""
    above = np.flatnonzero(curve.force >= at_force)
    if not len(above):
        raise CalibrationError(f'--bruise-force {at_force:g} N is beyond the largest force '
                               f'of the test ({curve.force.max():.4g} N)')
    i = int(above[0])
    if i == 0:
        return float(curve.deformation[0])
    f0, f1 = curve.force[i - 1], curve.force[i]
    d0, d1 = curve.deformation[i - 1], curve.deformation[i]
    return float(d0 + (at_force - f0) / (f1 - f0) * (d1 - d0))


def calibrate_bruise(test: CompressionTest, config: dict, fitted: SimulatedCurve,
                     at_force: float | None = None,
                     at_deformation: float | None = None) -> BruiseCalibration:
    """The bruise pressure for an onset at ``at_force`` (N) or ``at_deformation`` (m).

    Args:
        config: the fitted configuration.  fitted: its simulated test.

    Raises:
        CalibrationError: the onset lies outside the test or before any contact.
    """
    if (at_force is None) == (at_deformation is None):
        raise CalibrationError('give the bruise onset as a force or a deformation, not both')
    if at_force is not None:
        deformation = onset_deformation(fitted, at_force)
    else:
        deformation = float(at_deformation)
        if not 0 < deformation <= test.curve.max_deformation:
            raise CalibrationError(f'--bruise-deformation {deformation * 1e3:g} mm is outside '
                                   f'the test (0, {test.curve.max_deformation * 1e3:.4g}] mm')
    pressure = float(np.interp(deformation, fitted.deformation, fitted.damage_pressure))
    if pressure <= 0:
        raise CalibrationError('the simulated fruit is not yet in contact at the observed '
                               'bruise onset: give a later onset')
    high = SCHEMA['fruit.bruise_pressure'].high
    if pressure > high:
        raise CalibrationError(f'the bruise pressure {pressure:.4g} Pa is beyond the range '
                               f'of fruit.bruise_pressure (<= {high:g} Pa)')
    rerun = test.simulate(config=validate({**config, 'fruit.bruise_pressure': pressure}))
    bruised = np.flatnonzero(rerun.bruised)
    force = at_force if at_force is not None else float(fitted.force_at(deformation))
    return BruiseCalibration(
        bruise_pressure=pressure, observed_deformation=deformation, observed_force=force,
        simulated_deformation=float(rerun.deformation[bruised[0]]) if len(bruised) else None,
        step_travel=test.speed * float(config['sim.dt']))
