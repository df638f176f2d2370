"""Volumes and edges of triangle and tetrahedron meshes (the 3D meshes' geometry).

Shapes: positions (n, 3) m, triangles (n_tri, 3) outward oriented, tetrahedra (n_tet, 4).
"""
from __future__ import annotations

import numpy as np


def signed_volumes(positions: np.ndarray, tets: np.ndarray) -> np.ndarray:
    """(n_tet,) m^3, ((x1 - x0) x (x2 - x0)) . (x3 - x0) / 6."""
    p = positions[tets]
    return np.einsum('ij,ij->i', np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]),
                     p[:, 3] - p[:, 0]) / 6.0


def enclosed_volume(positions: np.ndarray, triangles: np.ndarray) -> float:
    """m^3 enclosed by a closed outward surface (divergence theorem)."""
    p = positions[triangles]
    return float(np.einsum('ij,ij->', p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0)


def surface_edges(triangles: np.ndarray) -> np.ndarray:
    """(n_edge, 2) unique undirected edges of a triangle mesh."""
    t = np.asarray(triangles, dtype=np.int64)
    e = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    e.sort(axis=1)
    return np.unique(e, axis=0)
