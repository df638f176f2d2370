"""Shaped 3D fingers: the 2D jaw face profile extruded along y over the jaw width.

The 2D fingers (``gripper_sim.geometry.fingers``: flat, arc, vgroove) are profiles in the
x-z plane made of flat facets. In 3D each facet becomes a rectangular ``Plate``: normal
(n_x, 0, n_z) of the facet, tangents y and the facet's in-plane direction
(-n_z, 0, n_x), half-extents (``gripper.jaw_width`` / 2, facet half length). The arc is
thus a concave cylinder of ``gripper.finger.segments`` flat strips and the V-groove two
flanks whose edge runs along y. A node's contact with a finger is the contact with one
of its facets (the plate's signed distance, bounded in y and along the profile); a node
pushed into a second facet of the same jaw (at the V's edge, between arc strips) gets a
frictionless second hold, as in 2D.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.obstacles import Plate
from gripper_sim.geometry import fingers

LEFT, RIGHT = 0, 1
_Y = np.array([0.0, 1.0, 0.0])


def _lift(vector2: np.ndarray) -> np.ndarray:
    """(3,) the x-z plane vector (x, z) as (x, 0, z)."""
    return np.array([vector2[0], 0.0, vector2[1]])


def jaw_facet_plates(config, pad_thickness: float = 0.0):
    """The jaw faces of a shaped or padded finger, both jaws.

    Args:
        config: validated flat configuration.
        pad_thickness: m; with a pad the rigid faces lie this far behind the configured
            face (the pad's free surface is where the rigid face would be).

    Returns:
        (plates, sides, offsets): ``Plate`` per facet (left jaw first, bottom to top,
        origin at zero), the jaw side of each (LEFT, RIGHT), and each one's centre
        (3,) m relative to its jaw's origin (centre of the jaw's front plane).
    """
    c = config
    half_width = 0.5 * c['gripper.jaw_width']
    plates, sides, offsets = [], [], []
    for side, name in ((LEFT, 'left_jaw'), (RIGHT, 'right_jaw')):
        for facet in fingers.left_facets(c):
            f = facet if side == LEFT else facet.mirrored()
            normal = _lift(f.normal)
            along = _lift(np.array([-f.normal[1], f.normal[0]]))
            plates.append(Plate(
                f'{name}.{f.name}' if f.name else name, np.zeros(3), normal,
                np.stack([_Y, along]), half_extents=np.array([half_width, f.half_length]),
                thickness=c['gripper.jaw_thickness'],
                static_friction=c['contact.jaw.static_friction'],
                kinetic_friction=c['contact.jaw.kinetic_friction']))
            sides.append(side)
            offsets.append(_lift(f.offset) - pad_thickness * normal)
    return plates, sides, offsets
