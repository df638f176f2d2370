"""The simulation facade: fruit + gripper + world, stepped in time. (API stub, being implemented.)"""
from __future__ import annotations

from typing import Any, Callable, Mapping

from gripper_sim.core.results import StepResult


class Simulation:
    """A parallel-jaw gripper and a deformable fruit.

    Args:
        config: validated flat configuration from ``gripper_sim.configuration.load_config``.

    Commands take effect on the next step. Invalid commands raise ``CommandError``
    and leave the simulation unchanged.
    """

    def __init__(self, config: Mapping[str, Any]):
        raise NotImplementedError

    dt: float            # s, physics step
    time: float          # s, simulation time
    config: dict         # the flat configuration in use

    def command_gap(self, gap: float, speed: float | None = None) -> None:
        """Position mode: move the jaws to gap ``gap`` (m) at gap rate ``speed`` (m/s)."""

    def command_force(self, force: float, speed: float | None = None) -> None:
        """Force mode: close until the mean jaw normal force is ``force`` (N), hold it."""

    def command_open(self, speed: float | None = None) -> None:
        """Position mode to the initial gap."""

    def command_lift(self, height: float, speed: float | None = None) -> None:
        """Move the gripper (jaw centre) to height ``height`` (m)."""

    def step(self) -> StepResult:
        """Advance one step of ``dt``; raises ConvergenceError (state unchanged) on failure."""

    @property
    def last(self) -> StepResult:
        """The most recent step result (a result of the initial state before any step)."""

    def reset(self) -> None:
        """Back to the initial state and commands, time 0."""

    def add_observer(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(result)`` after every step."""
