"""Rigid flat obstacles the fruit nodes can touch: jaw faces, the table, walls, in 2D
(``FlatFace``, a segment) and 3D (``Plate``, a rectangle).

Each obstacle is a flat face: a point ``origin`` on it, a unit ``normal`` pointing to
the side where the fruit is, unit ``tangents`` (d - 1, d) spanning it with half-extents
along them (``inf`` for the table and walls) and a thickness behind the face beyond
which a node is not in contact (it passed the jaw). Obstacles translate with a
prescribed ``velocity``. The geometry (gap, cover, broad phase) is one implementation
for both dimensions (``FaceGeometry``).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np


class FaceGeometry:
    """Gap, cover and broad phase of a flat face in d dimensions, from its ``origin`` (d,),
    ``normal`` (d,), ``tangents`` (d - 1, d), ``half_extents`` (d - 1,) m and
    ``thickness`` m."""

    origin: np.ndarray
    normal: np.ndarray
    thickness: float
    tangents: np.ndarray
    half_extents: np.ndarray

    def gap(self, points: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
        """(n,) m, signed distance of points (n, d) from the face's plane; < 0 inside.
        ``origin`` (d,) replaces the face's own (a face moved without copying it)."""
        o = self.origin if origin is None else origin
        return (points - o) @ self.normal

    def covers(self, points: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
        """(n,) bool, points (n, d) within the face's extent and not beyond its back."""
        rel = points - (self.origin if origin is None else origin)
        along = np.abs(rel @ self.tangents.T)
        return np.all(along <= self.half_extents, axis=1) & (rel @ self.normal > -self.thickness)

    def moved(self, origin: np.ndarray, velocity: np.ndarray | None = None):
        """A shallow copy of this face with ``origin`` (d,) m and, if given, ``velocity``
        (d,) m/s; its other attributes are this face's objects (faces are not changed in
        place: a moved face is a copy)."""
        face = object.__new__(type(self))
        face.__dict__.update(self.__dict__)
        face.origin = origin
        if velocity is not None:
            face.velocity = velocity
        return face

    def may_touch(self, low: np.ndarray, high: np.ndarray) -> bool:
        """Broad phase: can any point of the box [low, high] (d,) be inside the face?"""
        corners = np.array(list(itertools.product(*zip(low, high))), dtype=float)
        return bool(np.min(self.gap(corners)) < 0)


@dataclass
class FlatFace(FaceGeometry):
    """A flat face in the plane (a segment).

    Attributes:
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
        """(1, 2) the tangent as the one row spanning the face's tangent space."""
        return np.array([[-self.normal[1], self.normal[0]]])

    @property
    def half_extents(self) -> np.ndarray:
        """(1,) m, the half length as the half-extent along ``tangents``."""
        return np.array([self.half_length])


@dataclass
class Plate(FaceGeometry):
    """A flat face in space (a rectangle).

    Attributes:
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
