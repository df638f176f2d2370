"""Rigid obstacles the fruit nodes can touch: jaw faces, the table, walls.

Each obstacle is a flat face: a point ``origin`` on it, a unit ``normal`` pointing to
the side where the fruit is, a half-length along the face (``inf`` for the table and
walls) and a thickness behind the face beyond which a node is not in contact (it
passed the jaw). Obstacles translate with a prescribed ``velocity``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class FlatFace:
    """Attributes:
        name: e.g. 'left_jaw', 'table'.
        origin: (2,) m, centre of the face.
        normal: (2,) unit normal pointing towards the fruit.
        half_length: m, half the face length along its tangent.
        thickness: m, depth behind the face that still counts as contact.
        velocity: (2,) m/s.
        static_friction, kinetic_friction: Coulomb coefficients.
        restitution: normal restitution coefficient of impacts.
    """

    name: str
    origin: np.ndarray
    normal: np.ndarray
    half_length: float = np.inf
    thickness: float = np.inf
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(2))
    static_friction: float = 0.0
    kinetic_friction: float = 0.0
    restitution: float = 0.0

    @property
    def tangent(self) -> np.ndarray:
        """(2,) unit tangent, the normal turned by +90 degrees."""
        return np.array([-self.normal[1], self.normal[0]])

    @property
    def tangents(self) -> np.ndarray:
        """(1, 2) the tangent as the one row spanning the face's tangent space (the
        dimension-generic contact code reads ``tangents`` (d - 1, d))."""
        return np.array([[-self.normal[1], self.normal[0]]])

    @property
    def half_extents(self) -> np.ndarray:
        """(1,) m, the half length as the half-extents along ``tangents`` (as a 3D plate's)."""
        return np.array([self.half_length])

    def may_touch(self, low: np.ndarray, high: np.ndarray) -> bool:
        """Broad phase: can any point of the box [low, high] (2,) be inside the face?"""
        corners = np.array([[low[0], low[1]], [low[0], high[1]], [high[0], low[1]],
                            [high[0], high[1]]])
        return bool(np.min(self.gap(corners)) < 0)

    def gap(self, points: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
        """(n,) m, signed distance of points (n, 2) from the face; < 0 inside."""
        o = self.origin if origin is None else origin
        return (points - o) @ self.normal

    def covers(self, points: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
        """(n,) bool, points within the face's extent and not beyond its back."""
        o = self.origin if origin is None else origin
        along = np.abs((points - o) @ self.tangent)
        return (along <= self.half_length) & ((points - o) @ self.normal > -self.thickness)
