"""Deformation measures of the fruit from its node positions and contact forces."""
from __future__ import annotations

import numpy as np

from gripper_sim.core.fruit import FruitModel
from gripper_sim.core.results import Deformation


def tributary_lengths(fruit: FruitModel, x: np.ndarray) -> np.ndarray:
    """(n_surface,) m, half the length of the two skin segments at each surface node."""
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    seg = np.hypot(e[:, 0], e[:, 1])
    return 0.5 * (seg + np.roll(seg, 1))


def skin_strains(fruit: FruitModel, x: np.ndarray) -> np.ndarray:
    """(n_surface,) engineering strains of the skin segments."""
    rest = fruit.rest_positions
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    e0 = rest[fruit.skin_edges[:, 1]] - rest[fruit.skin_edges[:, 0]]
    return np.hypot(e[:, 0], e[:, 1]) / np.hypot(e0[:, 0], e0[:, 1]) - 1.0


def deformation(fruit: FruitModel, x: np.ndarray, normal_force: np.ndarray,
                jaw_contact: np.ndarray) -> Deformation:
    """Measures at positions ``x`` (n_nodes, 2).

    Args:
        normal_force: (n_nodes,) N, normal contact reaction at each node (0 if free).
        jaw_contact: (n_nodes,) bool, node held by a jaw.
    """
    surface = fruit.surface
    xs = x[surface]
    width = float(np.ptp(xs[:, 0]))
    compression = fruit.rest_width - width
    strains = skin_strains(fruit, x)
    max_strain = float(strains[np.argmax(np.abs(strains))])
    trib = tributary_lengths(fruit, x)
    contact_length = float(np.sum(trib[jaw_contact[surface]]))
    pressure = np.maximum(normal_force[surface], 0.0) / (trib * fruit.depth)
    return Deformation(compression=compression,
                       compression_ratio=compression / fruit.rest_width,
                       max_skin_strain=max_strain, contact_length=contact_length,
                       peak_contact_pressure=float(pressure.max(initial=0.0)),
                       node_pressure=pressure)
