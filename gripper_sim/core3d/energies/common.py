"""Helpers shared by the 3D energies: dof indices and cross-product matrices."""
from __future__ import annotations

import os

import numpy as np

from gripper_sim.core3d import kernels


def element_dofs3(nodes: np.ndarray) -> np.ndarray:
    """(n_elem, k) node indices to (n_elem, 3k) dof indices [x, y, z] per node."""
    nodes = np.asarray(nodes, dtype=np.int64)
    return (3 * nodes[:, :, None] + np.arange(3)[None, None, :]).reshape(len(nodes), -1)


def cross_matrices(v: np.ndarray) -> np.ndarray:
    """(n, 3, 3) matrices [v]x with [v]x w = v x w."""
    m = np.zeros(v.shape[:-1] + (3, 3))
    m[..., 0, 1], m[..., 0, 2] = -v[..., 2], v[..., 1]
    m[..., 1, 0], m[..., 1, 2] = v[..., 2], -v[..., 0]
    m[..., 2, 0], m[..., 2, 1] = -v[..., 1], v[..., 0]
    return m


def empty_triplets():
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)


def fast_kernels():
    """``gripper_sim.core3d.kernels`` unless GRIPPER_SIM_FAST is 0, else None (the numpy
    reference path)."""
    if os.environ.get('GRIPPER_SIM_FAST', '1') == '0':
        return None
    return kernels
