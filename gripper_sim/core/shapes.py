"""Rest outlines of the fruit, counter-clockwise in the x-z plane, centred at the origin.

An outline is sampled at ``n`` nodes evenly spaced in arc length. Only the circle is
configurable for now; the fruit model takes any closed counter-clockwise outline.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.errors import ConfigError


def circle(diameter: float, n: int) -> np.ndarray:
    """(n, 2) m, nodes on a circle, node 0 at +x (on the right jaw's axis)."""
    theta = 2 * np.pi * np.arange(n) / n
    return 0.5 * diameter * np.stack([np.cos(theta), np.sin(theta)], axis=1)


def outline_from_config(config) -> np.ndarray:
    """The rest outline (n, 2) m that the configuration asks for."""
    kind = config['fruit.shape.type']
    if kind == 'circle':
        return circle(config['fruit.shape.diameter'], config['fruit.nodes'])
    raise ConfigError(f"config key 'fruit.shape.type': unknown shape '{kind}'")


def polygon_area(points: np.ndarray) -> float:
    """Signed shoelace area (m^2) of a closed polygon (n, 2); > 0 if counter-clockwise."""
    nxt = np.roll(points, -1, axis=0)
    return float(0.5 * np.sum(points[:, 0] * nxt[:, 1] - nxt[:, 0] * points[:, 1]))
