"""Numba kernels of the fast Newton solver (``core.fast_solver``), for 2D and 3D.

Free functions ``@njit(cache=True)`` on the CSC values of a Newton matrix whose pattern
is fixed (the energies' elements plus every node's diagonal block) and on the per-node
contact filters S_i (n_nodes, d, d), d = 2 or 3 the coordinates per node.
Import this module only where numba is installed.
"""
from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def filter_blocks(hdata, block_pos, block_nodes, filters, diag_extra, out):
    """The Newton matrix S H S + (I - S) + diag(extra) on H's pattern, into ``out``.

    Args:
        hdata: CSC values of H (N/m).
        block_pos: (n_blocks, d, d) positions in data of each d x d node block.
        block_nodes: (n_blocks, 2) node (row, column) of each block.
        filters: (n_nodes, d, d) the S_i.
        diag_extra: (d n,) added on the diagonal (the shifted inertia, N/m).
        out: values of the filtered matrix, same pattern (written).
    """
    d = filters.shape[1]
    tmp = np.empty((d, d))
    free = np.ones(filters.shape[0], np.bool_)  # S_i = I (most nodes: no contact)
    for i in range(filters.shape[0]):
        for a in range(d):
            for c in range(d):
                if filters[i, a, c] != (1.0 if a == c else 0.0):
                    free[i] = False
    for blk in range(block_pos.shape[0]):
        i = block_nodes[blk, 0]
        j = block_nodes[blk, 1]
        pos = block_pos[blk]
        if free[i] and free[j]:
            for a in range(d):
                for c in range(d):
                    out[pos[a, c]] = hdata[pos[a, c]]
            if i == j:
                for a in range(d):
                    out[pos[a, a]] += diag_extra[d * i + a]
            continue
        si = filters[i]
        sj = filters[j]
        for a in range(d):
            for c in range(d):
                acc = 0.0
                for b in range(d):
                    acc += si[a, b] * hdata[pos[b, c]]
                tmp[a, c] = acc
        for a in range(d):
            for c in range(d):
                acc = 0.0
                for b in range(d):
                    acc += tmp[a, b] * sj[b, c]
                out[pos[a, c]] = acc
        if i == j:
            for a in range(d):
                for c in range(d):
                    out[pos[a, c]] += (1.0 if a == c else 0.0) - si[a, c]
                out[pos[a, a]] += diag_extra[d * i + a]


@njit(cache=True)
def apply_filters(filters, vec, out):
    """out (d n,) = S vec: each node's d-vector times its filter (n, d, d)."""
    d = filters.shape[1]
    for i in range(filters.shape[0]):
        for a in range(d):
            acc = 0.0
            for b in range(d):
                acc += filters[i, a, b] * vec[d * i + b]
            out[d * i + a] = acc


@njit(cache=True)
def add_node_blocks(data, diag_block_pos, nodes, blocks):
    """Add (k, d, d) blocks at the diagonal node blocks of ``nodes`` (k,) into data."""
    d = blocks.shape[1]
    for r in range(nodes.shape[0]):
        pos = diag_block_pos[nodes[r]]
        for a in range(d):
            for c in range(d):
                data[pos[a, c]] += blocks[r, a, c]


@njit(cache=True)
def add_diagonal(data, diag_pos, values):
    """data[diag_pos[d]] += values[d] for every dof d."""
    for d in range(values.shape[0]):
        data[diag_pos[d]] += values[d]
