"""Markers of shaped fingers and soft pads (ns ``fingers`` and ``pads``), moving with the jaws.

Geometry from ``gripper_sim.geometry.fingers``: the face profile of the left
jaw in its frame (x towards the fruit, z up, origin at the centre of the jaw's front
plane), from its bottom rim to its top rim; the right jaw is its mirror image. A pad
(``gripper.finger.pad.*``) of thickness t lies on the face: its free surface is the
profile, the rigid finger's face is the profile moved t back along the face normals.
The finger body reaches ``gripper.jaw_thickness`` behind the deepest point of its face
(``fingers.finger_outline``).

Per jaw (id 0 left, 1 right), frame ``world``:

- ``fingers``: id 0/1, TRIANGLE_LIST, the finger body extruded over the jaw width
  (y in [-w/2, w/2]); id 2/3, LINE_STRIP, its closed outline in the plane y = 0 (the
  section the planar model simulates; ``fingers.finger_outline`` moved to the jaw).
- ``pads``: id 0/1, TRIANGLE_LIST, the pad layer extruded likewise.

Nothing is drawn for a flat finger without a pad (the ``jaws`` cubes show it), nor for a
deformable finger (``soft_fingers`` draws its body, the ``jaws`` cube its backing).

The jaw plate (``JawPlate``, the ``jaws`` cube) is where the finger is held: behind the
face of a rigid finger and of a solid pad (whose base nodes are on the backing x = 0 over
the jaw height); on the base of a Fin Ray, which lies along the top of the finger
(``geometry.fin_ray``), so that the nodes held to the jaw lie on the plate's face.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA, Header
from visualization_msgs.msg import Marker

from gripper_sim.geometry import fingers
from gripper_sim.geometry.fin_ray import FinRayGeometry, layout

FINGER_COLOUR = ColorRGBA(r=0.45, g=0.45, b=0.5, a=0.9)
PAD_COLOUR = ColorRGBA(r=0.15, g=0.35, b=0.75, a=0.9)
OUTLINE_COLOUR = ColorRGBA(r=0.1, g=0.1, b=0.1, a=1.0)
OUTLINE_WIDTH = 0.0005   # m


@dataclass(frozen=True)
class FingerGeometry:
    """The left finger in its jaw frame (m; (k, 2) arrays of (x, z), bottom to top).

    Attributes:
        face: the face profile (the pad's free surface when there is a pad).
        body_face: the rigid finger's face (``face`` moved ``pad_thickness`` back).
        back: x of the finger's back plane.
        pad_thickness: m, 0 without a pad.
    """

    face: np.ndarray
    body_face: np.ndarray
    back: float
    pad_thickness: float
    _solids: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def recess(self) -> float:
        """m, how far the deepest point of the rigid face lies behind the front plane."""
        return float(-self.body_face[:, 0].min())

    def solids(self, width: float) -> tuple:
        """(body, section, pad) in the jaw frame, (n, 3) points, built once per width:
        the body's triangles, its closed outline at y = 0, the pad's triangles (None
        without a pad)."""
        if width not in self._solids:
            body = extruded(self.body_face, np.column_stack(
                [np.full(len(self.body_face), self.back), self.body_face[:, 1]]), width)
            outline = self.outline()
            section = np.column_stack([outline[:, 0], np.zeros(len(outline)), outline[:, 1]])
            section = np.vstack([section, section[:1]])
            pad = (extruded(self.face, self.body_face, width)
                   if self.pad_thickness > 0 else None)
            self._solids[width] = (body, section, pad)
        return self._solids[width]

    def outline(self) -> np.ndarray:
        """(k + 2, 2) closed-polygon outline of the rigid finger body (not repeated)."""
        return np.vstack([self.body_face, [[self.back, self.body_face[-1, 1]],
                                           [self.back, self.body_face[0, 1]]]])


#: the finger types whose body is deformable (drawn by the ``soft_fingers`` marker)
DEFORMABLE = ('solid_pad', 'fin_ray')


def finger_geometry(config: Mapping[str, Any]) -> FingerGeometry | None:
    """The finger of a flat configuration; None for a flat finger without a pad and for
    a deformable finger."""
    kind = config.get('gripper.finger.type', 'flat')
    padded = bool(config.get('gripper.finger.pad.enabled', False))
    if (kind == 'flat' and not padded) or kind in DEFORMABLE:
        return None
    face = fingers.profile(config)
    t = float(config['gripper.finger.pad.thickness']) if padded else 0.0
    body_face = face - t * _vertex_normals(face) if t > 0 else face.copy()
    outline = fingers.finger_outline(config, 'left')
    back = float(outline[-1, 0]) - t
    return FingerGeometry(face, body_face, back, t)


@dataclass(frozen=True)
class JawPlate:
    """The left jaw's plate in its jaw frame (x towards the fruit, z up, origin at the
    centre of the jaw's front plane; the right jaw's is its mirror image).

    Attributes:
        centre: (2,) m, (x, z) of the plate's centre.
        size: (2,) m, its full size along x and along z (along y it is the jaw's width).
    """

    centre: tuple[float, float]
    size: tuple[float, float]


def rigid_jaw_plate(finger: FingerGeometry | None, thickness: float,
                    height: float) -> JawPlate:
    """The plate of a rigid finger (or a solid pad): ``thickness`` (m) along x behind the
    deepest point of the finger's face (``FingerGeometry.recess``; the front plane
    without one), ``height`` (m) along z about the jaw centre."""
    recess = finger.recess if finger is not None else 0.0
    return JawPlate((-(recess + 0.5 * thickness), 0.0), (thickness, height))


def fin_ray_jaw_plate(config: Mapping[str, Any], thickness: float) -> JawPlate:
    """The plate a Fin Ray's base is held on: along x over its base nodes (x from 0 to
    ``base_width``), ``thickness`` (m) along z above them (the base is the top of the
    finger, its tip below), so that the base nodes lie on the plate's lower face."""
    plan = layout(FinRayGeometry.from_config(config))
    base = plan.positions[plan.base_nodes]
    low, high = base.min(axis=0), base.max(axis=0)
    return JawPlate((float(0.5 * (low[0] + high[0])), float(high[1] + 0.5 * thickness)),
                    (float(high[0] - low[0]), float(thickness)))


def _vertex_normals(curve: np.ndarray) -> np.ndarray:
    """(k, 2) unit normals (towards +x) at the vertices of a bottom-to-top curve."""
    tangents = np.diff(curve, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normals = np.column_stack([tangents[:, 1], -tangents[:, 0]])
    at_vertex = np.vstack([normals[:1], normals[:-1] + normals[1:], normals[-1:]])
    return at_vertex / np.linalg.norm(at_vertex, axis=1, keepdims=True)


def extruded(front: np.ndarray, rear: np.ndarray, width: float) -> np.ndarray:
    """(3 m, 3) triangle corners (x, y, z) of the solid between two bottom-to-top curves
    (k, 2) of the same length, extruded over y in [-width/2, width/2]: the two caps,
    the front and rear walls, the bottom and top ends."""
    half = 0.5 * width
    triangles = []

    def quad(a, b, c, d):
        triangles.extend([(a, b, c), (a, c, d)])

    def at(p, y):
        return (p[0], y, p[1])

    for k in range(len(front) - 1):
        f0, f1, r0, r1 = front[k], front[k + 1], rear[k], rear[k + 1]
        for y in (-half, half):                                   # caps
            quad(at(f0, y), at(f1, y), at(r1, y), at(r0, y))
        quad(at(f0, -half), at(f1, -half), at(f1, half), at(f0, half))   # front wall
        quad(at(r0, -half), at(r1, -half), at(r1, half), at(r0, half))   # rear wall
    for end in (0, -1):                                          # bottom and top
        f, r = front[end], rear[end]
        quad(at(f, -half), at(r, -half), at(r, half), at(f, half))
    return np.asarray(triangles, dtype=float).reshape(-1, 3)


def _to_world(local: np.ndarray, face_x: float, inward: float, lift: float) -> np.ndarray:
    """(n, 3) jaw-frame points (x towards the fruit, y, z) to world points."""
    world = np.array(local, dtype=float)
    world[:, 0] = face_x + inward * world[:, 0]
    world[:, 2] = world[:, 2] + lift
    return world


def base_marker(header: Header, ns: str, marker_id: int, kind: int) -> Marker:
    """An ADD marker of ``kind`` with the identity pose and no lifetime limit."""
    marker = Marker()
    marker.header = header
    marker.ns = ns
    marker.id = marker_id
    marker.type = kind
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    return marker


def _marker(header: Header, ns: str, marker_id: int, kind: int, colour: ColorRGBA,
            points: np.ndarray) -> Marker:
    marker = base_marker(header, ns, marker_id, kind)
    marker.scale.x = OUTLINE_WIDTH if kind == Marker.LINE_STRIP else 1.0
    marker.scale.y = marker.scale.z = 1.0
    marker.color = colour
    marker.points = [Point(x=x, y=y, z=z) for x, y, z in points.tolist()]
    return marker


def finger_markers(geometry: FingerGeometry | None, header: Header, jaws,
                   lift: float, width: float) -> list[Marker]:
    """The ``fingers`` and ``pads`` markers of both jaws (module docstring).

    Args:
        geometry: from ``finger_geometry``; None draws nothing.
        jaws: ((face_x, inward), (face_x, inward)) of the left and right jaw: x (m) of
            the jaw's front plane and +1 / -1 when the fruit is towards +x / -x.
        lift: m, height of the jaw centre.  width: m, extrusion width along y.
    """
    if geometry is None:
        return []
    body, section, pad = geometry.solids(width)
    out = []
    for side, (face_x, inward) in enumerate(jaws):
        out.append(_marker(header, 'fingers', side, Marker.TRIANGLE_LIST, FINGER_COLOUR,
                           _to_world(body, face_x, inward, lift)))
        out.append(_marker(header, 'fingers', side + 2, Marker.LINE_STRIP, OUTLINE_COLOUR,
                           _to_world(section, face_x, inward, lift)))
        if pad is not None:
            out.append(_marker(header, 'pads', side, Marker.TRIANGLE_LIST, PAD_COLOUR,
                               _to_world(pad, face_x, inward, lift)))
    return out
