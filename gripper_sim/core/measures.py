"""Deformation measures of the fruit from its node positions and contact forces."""
from __future__ import annotations

import numpy as np

from gripper_sim.core.fruit import FruitModel
from gripper_sim.core.results import Deformation


def tributary_lengths(fruit: FruitModel, x: np.ndarray) -> np.ndarray:
    """(n_surface,) m, half the length of the two skin segments at each surface node."""
    if not len(fruit.skin_edges):
        return np.zeros(len(fruit.surface))
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    seg = np.hypot(e[:, 0], e[:, 1])
    return 0.5 * (seg + np.roll(seg, 1))


def touching_length(x: np.ndarray, edges: np.ndarray, touching: np.ndarray) -> float:
    """m, the length of an outline in contact: each edge (e, 2) of positions ``x`` (n, 2)
    counts by the share of its two ends that touch (``touching`` (n,) bool)."""
    seg = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1)
    return float(np.sum(seg * 0.5 * touching[edges].sum(axis=1)))


def skin_strains(fruit: FruitModel, x: np.ndarray) -> np.ndarray:
    """(n_surface,) engineering strains of the skin segments."""
    rest = fruit.rest_positions
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    e0 = rest[fruit.skin_edges[:, 1]] - rest[fruit.skin_edges[:, 0]]
    return np.hypot(e[:, 0], e[:, 1]) / np.hypot(e0[:, 0], e0[:, 1]) - 1.0


def _separation_offset(x, ring_order, start, step, face) -> float:
    """Distance (m) along the face from the last contact node to where the surface leaves it.

    The gap of the free surface just past the contact edge grows like s^2 (a smooth
    surface leaving a flat face tangentially); the next two free nodes fix where it is
    zero. Falls back to half the segment when their gaps do not fit that.
    """
    n = len(ring_order)
    node0 = ring_order[start % n]
    f1, f2 = ring_order[(start + step) % n], ring_order[(start + 2 * step) % n]
    g1, g2 = float(face.gap(x[f1])), float(face.gap(x[f2]))
    t = face.tangent
    h0 = abs(float((x[f1] - x[node0]) @ t))
    h1 = abs(float((x[f2] - x[f1]) @ t))
    if g1 <= 0 or g2 <= g1 or h1 <= 0:
        return 0.5 * h0
    s1 = h1 / (np.sqrt(g2 / g1) - 1.0)
    return float(min(max(h0 - s1, 0.0), h0))


def face_contact_length(fruit: FruitModel, x: np.ndarray, face, held: np.ndarray) -> float:
    """Length (m) of the fruit outline lying on a flat face.

    The span of the held surface nodes along the face, extended at each end to where
    the outline leaves the face (see ``_separation_offset``).

    Args:
        face: a FlatFace.  held: (n_nodes,) bool, node held by that face.
    """
    ring = fruit.surface
    in_contact = held[ring]
    if not np.any(in_contact) or len(ring) < 5:
        return 0.0
    t = face.tangent
    along = x[ring] @ t
    idx = np.flatnonzero(in_contact)
    top, bottom = idx[np.argmax(along[idx])], idx[np.argmin(along[idx])]
    length = float(along[top] - along[bottom])
    n = len(ring)
    for end in (top, bottom):
        if not in_contact[(end + 1) % n]:
            length += _separation_offset(x, ring, end, 1, face)
        elif not in_contact[(end - 1) % n]:
            length += _separation_offset(x, ring, end, -1, face)
    return length


def deformation(fruit: FruitModel, x: np.ndarray, normal_force: np.ndarray,
                jaw_contact: np.ndarray, jaw_contact_length: float | None = None) -> Deformation:
    """Measures at positions ``x`` (n_nodes, 2).

    Args:
        normal_force: (n_nodes,) N, normal contact reaction at each node (0 if free).
        jaw_contact: (n_nodes,) bool, node held by a jaw.
    """
    surface = fruit.surface
    xs = x[surface]
    width = float(np.ptp(xs[:, 0]))
    compression = fruit.rest_width - width
    ratio = compression / fruit.rest_width if fruit.rest_width > 0 else 0.0
    strains = skin_strains(fruit, x)
    max_strain = float(strains[np.argmax(np.abs(strains))]) if strains.size else 0.0
    trib = tributary_lengths(fruit, x)
    if jaw_contact_length is None:
        jaw_contact_length = float(np.sum(trib[jaw_contact[surface]]))
    contact_length = jaw_contact_length
    with np.errstate(divide='ignore', invalid='ignore'):
        pressure = np.where(trib > 0, np.maximum(normal_force[surface], 0.0)
                            / (trib * fruit.depth), 0.0)
    return Deformation(compression=compression,
                       compression_ratio=ratio,
                       max_skin_strain=max_strain, contact_length=contact_length,
                       peak_contact_pressure=float(pressure.max(initial=0.0)),
                       node_pressure=pressure)
