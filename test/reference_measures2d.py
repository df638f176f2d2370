"""Numpy reference of the 2D outline measures, for the tests only.

The simulation computes them with the compiled functions of ``gripper_sim.core.measures``
on both routes; these are the same measures written again in numpy, for the tests to
check the compiled ones against (equal to round-off).
"""
from __future__ import annotations

import numpy as np


def tributary_lengths(fruit, x: np.ndarray) -> np.ndarray:
    """(n_surface,) m, half the length of the two skin segments at each surface node."""
    if not len(fruit.skin_edges):
        return np.zeros(len(fruit.surface))
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    seg = np.hypot(e[:, 0], e[:, 1])
    return 0.5 * (seg + np.roll(seg, 1))


def skin_strains(fruit, x: np.ndarray) -> np.ndarray:
    """(n_e,) engineering strains of the skin segments."""
    rest = fruit.rest_positions
    e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
    e0 = rest[fruit.skin_edges[:, 1]] - rest[fruit.skin_edges[:, 0]]
    return np.hypot(e[:, 0], e[:, 1]) / np.hypot(e0[:, 0], e0[:, 1]) - 1.0


def outline(fruit, x: np.ndarray, normal: np.ndarray):
    """(width m, skin strain of largest magnitude, peak line pressure Pa, line pressure
    per outline node (n_s,) Pa)."""
    xs = x[fruit.surface]
    strains = skin_strains(fruit, x)
    max_strain = float(strains[np.argmax(np.abs(strains))]) if strains.size else 0.0
    trib = tributary_lengths(fruit, x)
    with np.errstate(divide='ignore', invalid='ignore'):
        pressure = np.where(trib > 0, np.maximum(normal[fruit.surface], 0.0)
                            / (trib * fruit.depth), 0.0)
    return float(np.ptp(xs[:, 0])), max_strain, float(pressure.max(initial=0.0)), pressure


def separation_offset(x, ring, start, step, face) -> float:
    """m, from the last contact node along the face to where the outline leaves it."""
    n = len(ring)
    node0 = ring[start % n]
    f1, f2 = ring[(start + step) % n], ring[(start + 2 * step) % n]
    g1, g2 = float(face.gap(x[f1])), float(face.gap(x[f2]))
    t = face.tangent
    h0 = abs(float((x[f1] - x[node0]) @ t))
    h1 = abs(float((x[f2] - x[f1]) @ t))
    if g1 <= 0 or g2 <= g1 or h1 <= 0:
        return 0.5 * h0
    s1 = h1 / (np.sqrt(g2 / g1) - 1.0)
    return float(min(max(h0 - s1, 0.0), h0))


def face_contact_length(fruit, x: np.ndarray, face, held: np.ndarray) -> float:
    """m, the outline on a flat face: the held nodes' span along it, extended at each
    end to where the outline leaves it."""
    ring = fruit.surface
    in_contact = held[ring]
    if not np.any(in_contact) or len(ring) < 5:
        return 0.0
    along = x[ring] @ face.tangent
    idx = np.flatnonzero(in_contact)
    top, bottom = idx[np.argmax(along[idx])], idx[np.argmin(along[idx])]
    length = float(along[top] - along[bottom])
    n = len(ring)
    for end in (top, bottom):
        if not in_contact[(end + 1) % n]:
            length += separation_offset(x, ring, end, 1, face)
        elif not in_contact[(end - 1) % n]:
            length += separation_offset(x, ring, end, -1, face)
    return length
