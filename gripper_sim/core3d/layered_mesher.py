"""Tetrahedra filling a star-shaped body: graded layers of its surface toward a centre.

Every fruit body is star-shaped about a centre c (each skin triangle seen from c from
outside, see ``meshes``). Surface vertex i lies on the ray c + r u_i; layer k puts a copy
of it on the same ray at c + rho_ik u_i, rho_i0 = r_i > rho_i1 > ... Each surface triangle
then spans a column of triangular prisms (a triangle of layer k over the same triangle
of layer k + 1) and, below the last layer, a cone to c. Each prism is cut into three
tetrahedra by the rule of Dompierre et al. (1999, "How to subdivide pyramids, prisms
and hexahedra into tetrahedra", Proc. 8th Int. Meshing Roundtable): order its triangle's
vertices by node number a < b < c, then (a, b, c, c'), (a, b, b', c'), (a, a', b', c'),
so that every quadrilateral face is cut along the diagonal from its lower-numbered outer
corner to the higher-numbered inner one, the same cut from both sides.

Validity does not depend on the shape: the side faces of a prism are planar (they hold c),
so a prism whose inner corners lie strictly inside its outer ones along their rays is
convex and its three tetrahedra have positive volume; a cone tetrahedron has the
orientation of its triangle seen from c. The surface is kept exactly.

Layer depth along each ray: the first layer is ``FIRST_LAYER`` times the local surface
edge length h_i deep, each next one ``LAYER_GROWTH`` times the one before, but never
deeper than the layer's own edges are long (``MAX_LAYER_ASPECT``; a layer's triangles are
the surface's shrunk toward c) nor than ``MAX_LAYER_FRACTION`` of what is left of the
ray: fine under a fine surface, coarser inward, no thin or tall prisms.

Shapes: positions (n, 3) m; tetrahedra (n_tet, 4) with positive volume.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linprog

from gripper_sim.core3d.mesh_geometry import signed_volumes, surface_edges
from gripper_sim.errors import ConfigError

#: depth of the first layer over the local surface edge length
FIRST_LAYER = 0.6
#: ratio of the depths of successive layers
LAYER_GROWTH = 1.6
#: a layer never takes more than this fraction of what is left of the ray to the centre
MAX_LAYER_FRACTION = 0.6
#: a layer is at most this many times as deep as its triangles' edges are long
MAX_LAYER_ASPECT = 1.0
#: smallest dihedral angle (deg) the mesh may have; a thinner tetrahedron is an error
MIN_DIHEDRAL = 5.0

_SHAPE_KEY = "config key 'fruit.shape.type'"


@dataclass(frozen=True)
class MeshQuality:
    """Attributes:
        min_volume: m^3, the smallest tetrahedron volume (> 0: none inverted).
        min_dihedral, max_dihedral: deg, over every edge of every tetrahedron.
        max_aspect: largest ratio of longest edge to the diameter of the inscribed
            sphere over sqrt(6) (1 for a regular tetrahedron).
    """

    min_volume: float
    min_dihedral: float
    max_dihedral: float
    max_aspect: float


def star_centre(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(3,) m, a point from which every triangle of a closed outward surface is seen
    from outside, as deep inside as possible (the Chebyshev centre of the kernel: the
    point farthest from every triangle's plane), or the volume centroid when that sees
    every triangle with at least half that margin.

    Raises:
        ConfigError: the surface is not star-shaped (its kernel is empty).
    """
    p = positions[triangles]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    offset = np.einsum('ij,ij->i', normal, p[:, 0])
    # maximise t subject to normal . x + t <= offset (x at least t inside every plane)
    result = linprog(np.array([0.0, 0.0, 0.0, -1.0]), A_ub=np.hstack([normal,
                     np.ones((len(normal), 1))]), b_ub=offset,
                     bounds=[(None, None)] * 3 + [(None, float(np.ptp(positions)))],
                     method='highs')
    if result.status != 0 or result.x[3] <= 0:
        raise ConfigError(f'{_SHAPE_KEY}: the body is not star-shaped about any point, '
                          'so it cannot be filled with tetrahedra')
    chebyshev, margin = result.x[:3], result.x[3]
    volume = np.einsum('ij,ij->i', p[:, 0], np.cross(p[:, 1], p[:, 2]))
    centroid = (volume[:, None] * p.sum(axis=1)).sum(axis=0) / (4 * volume.sum())
    if np.min(offset - normal @ centroid) >= 0.5 * margin:
        return centroid
    return chebyshev


def vertex_edge_lengths(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(n,) m, the mean length of the surface edges at each vertex."""
    edges = surface_edges(triangles)
    length = np.linalg.norm(positions[edges[:, 0]] - positions[edges[:, 1]], axis=1)
    n = len(positions)
    total = np.bincount(edges.ravel(), weights=np.repeat(length, 2), minlength=n)
    return total / np.bincount(edges.ravel(), minlength=n)


def layer_radii(radius: np.ndarray, spacing: np.ndarray, layers: int,
                first_layer: float = FIRST_LAYER, growth: float = LAYER_GROWTH,
                max_fraction: float = MAX_LAYER_FRACTION,
                max_aspect: float = MAX_LAYER_ASPECT) -> np.ndarray:
    """(layers + 1, n) m, the distance from the centre of each vertex's copy per layer.

    Args:
        radius: (n,) m, distance of each surface vertex from the centre.
        spacing: (n,) m, local surface edge length at each vertex.
        layers: number of layers below the surface.
    """
    radius = np.asarray(radius, dtype=float)
    spacing = np.asarray(spacing, dtype=float)
    rho = [radius]
    depth = first_layer * spacing
    for _ in range(layers):
        # the layer's triangles are the surface's shrunk by rho / radius
        width = spacing * rho[-1] / radius
        rho.append(rho[-1] - np.minimum(np.minimum(depth, max_aspect * width),
                                        max_fraction * rho[-1]))
        depth = depth * growth
    return np.array(rho)


def layered_tetrahedra(positions: np.ndarray, triangles: np.ndarray, layers: int,
                       centre: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fill a closed outward star-shaped surface with tetrahedra.

    Args:
        positions: (n_s, 3) m, surface vertices (nodes 0..n_s-1 of the result).
        triangles: (n_tri, 3) outward surface triangles.
        layers: number of prism layers below the surface (0: cones to the centre only).
        centre: (3,) m, the point the layers shrink toward; None = ``star_centre``.

    Returns:
        positions (n_s (layers + 1) + 1, 3) m: the surface, each layer in the same vertex
        order, then the centre; tetrahedra (n_tri (3 layers + 1), 4) positively oriented.

    Raises:
        ConfigError: the body is not star-shaped about ``centre``.
    """
    surface = np.asarray(positions, dtype=float)
    tris = np.asarray(triangles, dtype=np.int64)
    if centre is None:
        centre = star_centre(surface, tris)
    ray = surface - centre
    radius = np.linalg.norm(ray, axis=1)
    seen = np.einsum('ij,ij->i', ray[tris[:, 0]], np.cross(ray[tris[:, 1]], ray[tris[:, 2]]))
    if np.any(radius <= 0) or np.any(seen <= 0):
        raise ConfigError(f'{_SHAPE_KEY}: the body is not star-shaped about its centre, so '
                          'it cannot be filled with tetrahedra')
    rho = layer_radii(radius, vertex_edge_lengths(surface, tris), layers)
    n_s = len(surface)
    nodes = np.vstack([surface] + [centre + (rho[k] / radius)[:, None] * ray
                                   for k in range(1, layers + 1)] + [centre[None, :]])
    tets = [prism_tetrahedra(tris, k * n_s, (k + 1) * n_s) for k in range(layers)]
    ordered = np.sort(tris, axis=1)
    a, b, c = ordered[:, 0], ordered[:, 1], ordered[:, 2]
    last = layers * n_s
    tets.append(np.stack([a + last, b + last, c + last, np.full_like(a, len(nodes) - 1)], 1))
    tets = np.vstack(tets)
    negative = signed_volumes(nodes, tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    return nodes, tets


def prism_tetrahedra(triangles: np.ndarray, outer: int, inner: int) -> np.ndarray:
    """(3 n_tri, 4) the tetrahedra of the prisms spanned by ``triangles`` (n_tri, 3) of one
    layer of nodes (node i + ``outer``) over the same triangles of another (node i +
    ``inner``), cut by Dompierre's rule (module docstring), not yet oriented: every
    quadrilateral face cut the same way from both sides, so prisms sharing it conform."""
    ordered = np.sort(np.asarray(triangles, dtype=np.int64), axis=1)
    a, b, c = ordered[:, 0], ordered[:, 1], ordered[:, 2]
    return np.vstack([np.stack([a + outer, b + outer, c + outer, c + inner], axis=1),
                      np.stack([a + outer, b + outer, b + inner, c + inner], axis=1),
                      np.stack([a + outer, a + inner, b + inner, c + inner], axis=1)])


#: the six edges of a tetrahedron and, for each, the two corners off it
_EDGES = ((0, 1, 2, 3), (0, 2, 1, 3), (0, 3, 1, 2), (1, 2, 0, 3), (1, 3, 0, 2), (2, 3, 0, 1))


def mesh_quality(positions: np.ndarray, tets: np.ndarray) -> MeshQuality:
    """Volumes, dihedral angles and aspect ratios of linear tetrahedra (n_tet, 4)."""
    p = positions[tets[:, :4]]
    volume = signed_volumes(positions, tets[:, :4])
    dihedral = []
    longest = np.zeros(len(tets))
    for i, j, k, m in _EDGES:
        edge = p[:, j] - p[:, i]
        longest = np.maximum(longest, np.linalg.norm(edge, axis=1))
        n1 = np.cross(edge, p[:, k] - p[:, i])
        n2 = np.cross(edge, p[:, m] - p[:, i])
        cosine = np.einsum('ij,ij->i', n1, n2) / (np.linalg.norm(n1, axis=1)
                                                  * np.linalg.norm(n2, axis=1))
        dihedral.append(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
    dihedral = np.array(dihedral)
    faces = sum(np.linalg.norm(np.cross(p[:, j] - p[:, i], p[:, k] - p[:, i]), axis=1)
                for i, j, k in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3))) / 2.0
    inradius = 3.0 * np.abs(volume) / faces
    aspect = longest / (2.0 * inradius * 6 ** 0.5)
    return MeshQuality(float(volume.min()), float(dihedral.min()), float(dihedral.max()),
                       float(aspect.max()))
