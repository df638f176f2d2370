"""Finger geometries: the jaw face profile in the x-z plane as rigid flat facets.

Each jaw's face is described in the left jaw's frame: origin at the centre of the jaw's
front plane (where ``gap`` is measured), x towards the fruit, z up; the right jaw is
its mirror image. ``gripper.finger.type``:

- ``flat``: one facet, the front plane itself, ``gripper.jaw_height`` long.
- ``vgroove``: two flanks meeting at the apex of a V of opening angle
  ``gripper.finger.groove_angle`` recessed into the jaw, rims on the front plane at
  z = +/- h/2: depth d = (h/2) / tan(angle/2).
- ``arc``: a concave circular arc of radius Rf = ``gripper.finger.radius`` whose chord
  is the jaw height (rims on the front plane, deepest point at the sagitta
  s = Rf - sqrt(Rf^2 - h^2/4)), made of ``gripper.finger.segments`` flat facets.

Facets are ``FlatFace`` obstacles that move with their jaw; the contact machinery
treats them as any face (a node held by one facet and pushed into another, at a V's
apex or between arc facets, gets a frictionless second hold). A soft pad
(``gripper.finger.pad.*``) lies on every facet of the face, see
``gripper_sim.core.pad``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gripper_sim.errors import ConfigError


@dataclass(frozen=True)
class Facet:
    """A flat piece of the left jaw's face.

    Attributes:
        name: suffix of the obstacle name ('' for the single facet of a flat finger).
        offset: (2,) m, facet centre relative to the jaw origin.
        normal: (2,) unit normal towards the fruit.
        half_length: m.
        curvature: 1/m, in-plane curvature of the face it approximates (negative:
            concave, e.g. -1/Rf for the arc; 0 flat).
    """

    name: str
    offset: np.ndarray
    normal: np.ndarray
    half_length: float
    curvature: float = 0.0

    def mirrored(self) -> 'Facet':
        """The same facet on the right jaw (x mirrored)."""
        return Facet(self.name, self.offset * np.array([-1.0, 1.0]),
                     self.normal * np.array([-1.0, 1.0]), self.half_length, self.curvature)


def check_finger(config) -> None:
    """ConfigError if the finger does not fit the jaw."""
    h = config['gripper.jaw_height']
    kind = config['gripper.finger.type']
    if kind == 'arc' and config['gripper.finger.radius'] < 0.5 * h:
        raise ConfigError(f"config key 'gripper.finger.radius' = "
                          f"{config['gripper.finger.radius']} m is too small: the arc's chord "
                          f"is gripper.jaw_height ({h} m), so the radius must be at least "
                          f'{0.5 * h} m')


def profile(config) -> np.ndarray:
    """(k, 2) m, the left jaw's face profile from its bottom rim to its top rim."""
    h = config['gripper.jaw_height']
    kind = config['gripper.finger.type']
    if kind in ('flat', 'solid_pad', 'fin_ray'):  # a deformable finger's backing is flat
        return np.array([[0.0, -0.5 * h], [0.0, 0.5 * h]])
    if kind == 'vgroove':
        depth = 0.5 * h / math.tan(math.radians(0.5 * config['gripper.finger.groove_angle']))
        return np.array([[0.0, -0.5 * h], [-depth, 0.0], [0.0, 0.5 * h]])
    if kind == 'arc':
        check_finger(config)
        radius = config['gripper.finger.radius']
        centre_x = math.sqrt(radius ** 2 - 0.25 * h * h)
        phi_max = math.asin(0.5 * h / radius)
        phi = np.linspace(-phi_max, phi_max, int(config['gripper.finger.segments']) + 1)
        return np.stack([centre_x - radius * np.cos(phi), radius * np.sin(phi)], axis=1)
    raise ConfigError(f"config key 'gripper.finger.type': unknown finger '{kind}'")


def left_facets(config) -> list[Facet]:
    """The facets of the left jaw's face (bottom to top)."""
    points = profile(config)
    kind = config['gripper.finger.type']
    curvature = -1.0 / config['gripper.finger.radius'] if kind == 'arc' else 0.0
    facets = []
    names = {'flat': [''], 'vgroove': ['lower', 'upper']}.get(kind)
    for k in range(len(points) - 1):
        a, b = points[k], points[k + 1]
        t = (b - a) / np.linalg.norm(b - a)
        normal = np.array([t[1], -t[0]])  # the tangent turned clockwise: towards +x
        name = names[k] if names else str(k)
        facets.append(Facet(name, 0.5 * (a + b), normal, 0.5 * float(np.linalg.norm(b - a)),
                            curvature))
    return facets


def depth(config) -> float:
    """m, how far the face is recessed behind the jaw's front plane (0 for flat)."""
    return float(-profile(config)[:, 0].min())


def finger_outline(config, side: str = 'left') -> np.ndarray:
    """(k, 2) m, closed outline of a finger body in its jaw frame (for drawing).

    The face profile, then the back of the jaw ``gripper.jaw_thickness`` behind the
    deepest point of the face. Mirrored for ``side='right'``.
    """
    face = profile(config)
    back = -depth(config) - config['gripper.jaw_thickness']
    h = config['gripper.jaw_height']
    outline = np.vstack([face, [[back, 0.5 * h], [back, -0.5 * h]]])
    if side == 'right':
        outline = outline * np.array([-1.0, 1.0])
    return outline
