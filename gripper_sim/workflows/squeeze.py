"""The plate compression test (ASAE S368 style): flat jaws close at a constant gap rate
on the fruit until a grip force or a gap is reached.

Used by ``gripper-sim squeeze`` and by the calibration (``workflows.calibrate_model``):
one implementation of the test. Gravity and the table are off unless the configuration
sets them (``SQUEEZE_DEFAULTS``, applied by the callers under the user's overrides).
"""
from __future__ import annotations

from typing import Mapping

from gripper_sim.core.facade import FORCE_TOLERANCE
from gripper_sim.core.results import StepResult
from gripper_sim.errors import GripperSimError

#: longest simulated time (s) a squeeze may take before it is called off
SQUEEZE_TIME_LIMIT = 600.0
#: configuration a squeeze runs with unless the user sets these keys
SQUEEZE_DEFAULTS = {'world.gravity': 0.0, 'world.table': False}


def check_squeeze(config: Mapping, speed: float, to_force: float | None = None) -> None:
    """GripperSimError when the gap rate ``speed`` (m/s) or the force target ``to_force``
    (N) exceed what the configured gripper may do."""
    if to_force is not None and to_force > config['gripper.max_force']:
        raise GripperSimError(f"--to-force {to_force} N exceeds gripper.max_force "
                              f"{config['gripper.max_force']} N")
    if speed > config['gripper.max_speed']:
        raise GripperSimError(f"--speed {speed} m/s exceeds gripper.max_speed "
                              f"{config['gripper.max_speed']} m/s")


def stopped_at_max_effort(sim, result: StepResult) -> bool:
    """Whether the position servo of ``sim`` holds the jaws at its maximum effort (the
    grip force within ``FORCE_TOLERANCE`` of it) short of its gap target."""
    grip = sim.gripper_state
    return (grip.mode == 'position' and result.gap > grip.target_gap + 1e-12
            and result.grip_force >= (1 - FORCE_TOLERANCE) * grip.max_effort)


def squeeze(sim, speed: float, to_force: float | None = None,
            to_gap: float | None = None) -> StepResult:
    """Close the jaws of ``sim`` at ``speed`` (m/s) until the grip force reaches
    ``to_force`` (N) or the gap reaches ``to_gap`` (m), or the jaws stop at their maximum
    effort (``gripper.max_force``, see ``stopped_at_max_effort``); returns the last step's
    result.

    Observers added to ``sim`` beforehand see every step.

    Raises:
        GripperSimError: ``to_gap`` is not below the initial gap, or the target was not
            reached (the gap closed, or ``SQUEEZE_TIME_LIMIT`` s passed).
        ConvergenceError: a step failed.
    """
    if (to_force is None) == (to_gap is None):
        raise GripperSimError('a squeeze needs exactly one of a force or a gap target')
    if to_gap is not None and to_gap >= sim.initial_gap:
        raise GripperSimError(f'--to-gap {to_gap} m is not below the initial gap '
                              f'{sim.initial_gap:.4g} m')
    sim.command_gap(to_gap if to_gap is not None else sim.smallest_gap, speed)
    peak_force = 0.0
    while sim.time < SQUEEZE_TIME_LIMIT:
        result = sim.step()
        peak_force = max(peak_force, result.grip_force)
        if to_force is not None and result.grip_force >= to_force:
            return result
        if to_gap is not None and result.gap <= to_gap + 1e-12:
            return result
        if stopped_at_max_effort(sim, result):
            return result
        if result.gap <= sim.smallest_gap:
            break
    raise GripperSimError(f'the squeeze did not reach the target (peak force '
                          f'{peak_force:.4g} N, final gap {sim.last.gap:.4g} m)')
