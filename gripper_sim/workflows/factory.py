"""The simulation a configuration asks for, 2D or 3D: the one place that knows both."""
from __future__ import annotations

from typing import Any, Mapping

from gripper_sim.core.simulation import Simulation
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.errors import ConfigError


def make_simulation(config: Mapping[str, Any], **kwargs) -> Simulation | Simulation3D:
    """The simulation the configuration asks for: 2D (``Simulation``) or, with
    ``dimension: 3``, 3D (``gripper_sim.core3d.simulation.Simulation3D``).

    ``kwargs`` go to the 2D ``Simulation`` (e.g. ``fast``); the 3D one takes none.
    """
    if int(config.get('dimension', 2)) == 3:
        if kwargs.get('fast'):
            raise ConfigError("the fast path is 2D only (config key 'dimension' is 3)")
        return Simulation3D(config)
    return Simulation(config, **kwargs)
