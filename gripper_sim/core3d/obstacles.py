"""Rigid flat obstacles in 3D: jaw plates, the table, walls.

A plate is a point ``origin`` on it, a unit ``normal`` towards the fruit side and two
unit ``tangents`` spanning it, half-extents along the tangents (``inf`` for the table
and walls) and a thickness behind the face beyond which a node is not in contact.
Plates translate with a prescribed ``velocity``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Plate:
    """Attributes:
        name: e.g. 'left_jaw', 'table'.
        origin: (3,) m, centre of the face.
        normal: (3,) unit normal pointing towards the fruit.
        tangents: (2, 3) orthonormal tangents, both perpendicular to the normal.
        half_extents: (2,) m, half sizes along the tangents.
        thickness: m, depth behind the face that still counts as contact.
        velocity: (3,) m/s.
        static_friction, kinetic_friction: Coulomb coefficients.
        restitution: normal restitution coefficient of impacts.
    """

    name: str
    origin: np.ndarray
    normal: np.ndarray
    tangents: np.ndarray
    half_extents: np.ndarray = field(default_factory=lambda: np.full(2, np.inf))
    thickness: float = np.inf
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    static_friction: float = 0.0
    kinetic_friction: float = 0.0
    restitution: float = 0.0

    def gap(self, points: np.ndarray) -> np.ndarray:
        """(n,) m, signed distance of points (n, 3) from the face plane; < 0 inside."""
        return (points - self.origin) @ self.normal

    def covers(self, points: np.ndarray) -> np.ndarray:
        """(n,) bool, points within the face's extent and not beyond its back."""
        rel = points - self.origin
        along = np.abs(rel @ self.tangents.T)
        return np.all(along <= self.half_extents, axis=1) & (rel @ self.normal > -self.thickness)

    def may_touch(self, low: np.ndarray, high: np.ndarray) -> bool:
        """Broad phase: can any point of the box [low, high] (3,) be inside the plate?"""
        corners = np.array([[[low[0], high[0]][i], [low[1], high[1]][j], [low[2], high[2]][k]]
                            for i in (0, 1) for j in (0, 1) for k in (0, 1)])
        return bool(np.min(self.gap(corners)) < 0)
