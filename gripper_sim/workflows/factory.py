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

    Raises:
        ConfigError: an invalid configuration, or jaws that would start inside the
            fruit (``check_start_gap``).
    """
    if int(config.get('dimension', 2)) == 3:
        if kwargs.get('fast'):
            raise ConfigError("the fast path is 2D only (config key 'dimension' is 3)")
        sim = Simulation3D(config)
    else:
        sim = Simulation(config, **kwargs)
    check_start_gap(sim)
    return sim


def check_start_gap(sim: Simulation | Simulation3D) -> None:
    """ConfigError when the jaws of ``sim`` start inside its fruit: the fruit is wider
    across the jaws than ``gripper.max_gap``, or ``gripper.initial_gap`` is narrower
    than the gap at which the fingers touch it (``sim.touching_gap``, m: the fruit's
    width for rigid faces and pads, more for deformable fingers standing in front of
    their jaws)."""
    config = sim.config
    touching, gap = sim.touching_gap, sim.initial_gap
    if not sim.jaws_start_inside():
        return
    max_gap = config['gripper.max_gap']
    if touching > max_gap:
        raise ConfigError(f'the fruit does not fit between the jaws: the fingers touch it '
                          f'at a gap of {touching * 1e3:.4g} mm (its width across them), '
                          f"more than they open ('gripper.max_gap' = {max_gap * 1e3:.4g} "
                          "mm); make the fruit smaller or 'gripper.max_gap' larger")
    raise ConfigError(f"config key 'gripper.initial_gap' = {gap * 1e3:.4g} mm puts the jaws "
                      f'inside the fruit: the fingers touch it at a gap of '
                      f'{touching * 1e3:.4g} mm (its width across them); open them at least '
                      'that far, or leave the key null (that gap + 10 mm)')
