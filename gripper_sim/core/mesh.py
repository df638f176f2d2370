"""Triangle meshes of the flesh inside a closed outline.

Nodes are placed on the outline and on inward offset rings whose spacing grows by
``grading`` per ring (fine near the skin where contact happens, coarse inside);
scipy's Delaunay triangulation connects them and triangles whose centroid lies
outside the outline are dropped.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay



def points_inside(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n_points,) bool, even-odd rule: which points lie inside the closed polygon."""
    a = polygon[None, :, :]
    b = np.roll(polygon, -1, axis=0)[None, :, :]
    p = points[:, None, :]
    straddles = (a[..., 1] > p[..., 1]) != (b[..., 1] > p[..., 1])
    with np.errstate(divide='ignore', invalid='ignore'):
        x_cross = a[..., 0] + (p[..., 1] - a[..., 1]) * (b[..., 0] - a[..., 0]) / (
            b[..., 1] - a[..., 1])
    return np.count_nonzero(straddles & (p[..., 0] < x_cross), axis=1) % 2 == 1


def _resample_closed(points: np.ndarray, n: int) -> np.ndarray:
    closed = np.vstack([points, points[:1]])
    seg = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    t = np.linspace(0, s[-1], n, endpoint=False)
    return np.stack([np.interp(t, s, closed[:, 0]), np.interp(t, s, closed[:, 1])], axis=1)


def mesh_outline(outline: np.ndarray, grading: float = 1.25):
    """Mesh the region inside ``outline``.

    Args:
        outline: (n_b, 2) m, counter-clockwise boundary nodes; they become nodes
            0..n_b-1 of the mesh, in the same order.
        grading: ratio of successive ring spacings going inwards (>= 1).

    Returns:
        nodes (n_nodes, 2) m, triangles (n_tri, 3) counter-clockwise.
    """
    centre = outline.mean(axis=0)
    perimeter = np.sum(np.linalg.norm(np.roll(outline, -1, axis=0) - outline, axis=1))
    h = perimeter / len(outline)
    rel = outline - centre
    points = [outline]
    scale, spacing, offset = 1.0, h, 0.0
    extent = np.max(np.linalg.norm(rel, axis=1))
    while True:
        offset += spacing
        scale = 1.0 - offset / extent
        if scale * extent < 0.75 * spacing:
            break
        ring = centre + scale * rel
        n_ring = max(3, int(round(perimeter * scale / spacing)))
        points.append(_resample_closed(ring, n_ring))
        spacing *= grading
    points.append(centre[None, :])
    nodes = np.vstack(points)
    tri = Delaunay(nodes).simplices
    inside = points_inside(outline, nodes[tri].mean(axis=1))
    tri = tri[inside]
    p = nodes[tri]
    signed = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
              - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    tri[signed < 0] = tri[signed < 0][:, [0, 2, 1]]
    area = 0.5 * np.abs(signed)
    tri = tri[area > 1e-6 * h * h]
    used = np.unique(tri)
    if len(used) != len(nodes):
        remap = -np.ones(len(nodes), dtype=np.int64)
        remap[used] = np.arange(len(used))
        nodes, tri = nodes[used], remap[tri]
    return nodes, tri
