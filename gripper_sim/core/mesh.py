"""Triangle meshes of the flesh inside a closed outline.

Nodes are placed on the outline and on inward offset rings (each outline node moved
along its inward normal; for a circle these are concentric circles) whose spacing grows
by ``grading`` per ring: fine near the skin where contact happens, coarse inside. Ring
points that fall outside the outline, closer to it than 0.8 times their ring's offset
(where the offset of a concave part folds over) or too close to a point already placed
are dropped. scipy's Delaunay triangulation connects the nodes and triangles whose
centroid lies outside the outline are dropped.

The mesh is then checked: its boundary must be exactly the outline's edges and the
triangle areas must add up to the outline's area (no hole, no overlap, no inverted
triangle); otherwise ``MeshError`` says so.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay

from gripper_sim.errors import ConfigError
from gripper_sim.geometry.shapes import polygon_area, resample_closed


class MeshError(ConfigError):
    """The outline cannot be meshed at this resolution (it is a configuration problem)."""


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


def distance_to_polyline(polygon: np.ndarray, points: np.ndarray) -> np.ndarray:
    """(n_points,) m, distance of each point to the closed polyline ``polygon``."""
    a = polygon
    d = np.roll(polygon, -1, axis=0) - a
    length2 = np.maximum(np.sum(d * d, axis=1), 1e-300)
    out = np.empty(len(points))
    for start in range(0, len(points), 256):
        p = points[start:start + 256, None, :]
        t = np.clip(np.sum((p - a[None]) * d[None], axis=2) / length2[None], 0.0, 1.0)
        closest = a[None] + t[..., None] * d[None]
        out[start:start + 256] = np.sqrt(np.min(np.sum((p - closest) ** 2, axis=2), axis=1))
    return out


def inward_normals(outline: np.ndarray) -> np.ndarray:
    """(n, 2) unit normals pointing into a counter-clockwise outline."""
    tangent = np.roll(outline, -1, axis=0) - np.roll(outline, 1, axis=0)
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)
    return normal / np.linalg.norm(normal, axis=1)[:, None]


def _offset_ring(outline, normals, offset):
    """The outline moved inwards by ``offset`` along each node's inward normal (for a
    circle: the concentric circle; where a concave part folds over, the filters of
    ``mesh_outline`` drop the points)."""
    return outline + offset * normals


def mesh_outline(outline: np.ndarray, grading: float = 1.25):
    """Mesh the region inside ``outline``.

    Args:
        outline: (n_b, 2) m, counter-clockwise boundary nodes; they become nodes
            0..n_b-1 of the mesh, in the same order.
        grading: ratio of successive ring spacings going inwards (>= 1).

    Returns:
        nodes (n_nodes, 2) m, triangles (n_tri, 3) counter-clockwise.

    Raises:
        MeshError: the triangulation does not follow the outline (a too sharp concave
            corner for the node count).
    """
    outline = np.asarray(outline, dtype=float)
    n_b = len(outline)
    perimeter = np.sum(np.linalg.norm(np.roll(outline, -1, axis=0) - outline, axis=1))
    h = perimeter / n_b
    normals = inward_normals(outline)
    centre = outline.mean(axis=0)
    inside_centre = bool(points_inside(outline, centre[None])[0])
    depth = float(distance_to_polyline(outline, centre[None])[0]) if inside_centre else 0.0
    # the deepest point of the region: the largest inscribed radius, sampled
    probe = np.vstack([centre[None], outline + 0.5 * h * normals])
    for _ in range(2):
        inner = probe[points_inside(outline, probe)]
        dist = distance_to_polyline(outline, inner)
        best = inner[np.argmax(dist)]
        depth = max(depth, float(dist.max()))
        probe = np.vstack([probe, best + np.outer(np.linspace(-1, 1, 9), [1, 0]) * h,
                           best + np.outer(np.linspace(-1, 1, 9), [0, 1]) * h])
    radii = np.linalg.norm(outline - centre, axis=1)
    extent = float(radii.max())
    round_outline = bool(np.ptp(radii) <= 1e-9 * extent)
    if round_outline:
        depth = extent
    kept = [outline]
    accepted = outline.copy()
    spacing, offset = h, 0.0
    while True:
        offset += spacing
        if depth - offset < 0.75 * spacing:
            break
        if round_outline:  # concentric scaling: the same nodes, bit for bit, as before
            ring = centre + (1.0 - offset / extent) * (outline - centre)
        else:
            ring = _offset_ring(outline, normals, offset)
        ring_perimeter = np.sum(np.linalg.norm(np.roll(ring, -1, axis=0) - ring, axis=1))
        n_ring = max(3, int(round(ring_perimeter / spacing)))
        candidates = resample_closed(ring, n_ring)
        ok = points_inside(outline, candidates)
        if np.any(ok):
            dist = distance_to_polyline(outline, candidates[ok])
            idx = np.flatnonzero(ok)
            ok[idx[dist < 0.8 * offset]] = False
        candidates = candidates[ok]
        if len(candidates):
            near = _min_distance(accepted, candidates)
            candidates = candidates[near >= 0.5 * spacing]
        if len(candidates):
            kept.append(candidates)
            accepted = np.vstack([accepted, candidates])
        spacing *= grading
    if inside_centre and _min_distance(accepted, centre[None])[0] >= 0.5 * spacing / grading:
        kept.append(centre[None, :])
    nodes = np.vstack(kept)
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
        if np.setdiff1d(np.arange(n_b), used).size:
            raise MeshError('the solid mesh leaves outline nodes out: the outline has a '
                            'concave corner too sharp for fruit.nodes; add nodes or '
                            'smooth the outline')
        remap = -np.ones(len(nodes), dtype=np.int64)
        remap[used] = np.arange(len(used))
        nodes, tri = nodes[used], remap[tri]
    check_mesh(outline, nodes, tri)
    return nodes, tri


def _min_distance(points: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """(n_queries,) m, distance from each query to the nearest of ``points``."""
    out = np.empty(len(queries))
    for start in range(0, len(queries), 256):
        q = queries[start:start + 256, None, :]
        out[start:start + 256] = np.sqrt(np.min(np.sum((q - points[None]) ** 2, axis=2),
                                                axis=1))
    return out


def triangle_areas(nodes: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(n_tri,) m^2 signed areas (> 0 counter-clockwise)."""
    p = nodes[tri]
    return 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))


def boundary_edges(tri: np.ndarray) -> set:
    """Edges (as sorted node pairs) that belong to exactly one triangle."""
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return {tuple(e) for e in unique[counts == 1].tolist()}


def check_mesh(outline: np.ndarray, nodes: np.ndarray, tri: np.ndarray) -> None:
    """MeshError unless the mesh fills the outline exactly with positive triangles."""
    n_b = len(outline)
    areas = triangle_areas(nodes, tri)
    if np.any(areas <= 0):
        raise MeshError(f'the solid mesh has {int(np.sum(areas <= 0))} inverted triangles')
    expected = {tuple(sorted((i, (i + 1) % n_b))) for i in range(n_b)}
    if boundary_edges(tri) != expected:
        raise MeshError('the solid mesh does not follow the outline (an outline edge is '
                        'missing from the triangulation): the outline has a concave '
                        'corner too sharp for fruit.nodes; add nodes or smooth it')
    total = float(areas.sum())
    if abs(total - polygon_area(outline)) > 1e-9 * abs(polygon_area(outline)) + 1e-15:
        raise MeshError('the solid mesh does not cover the outline exactly')
