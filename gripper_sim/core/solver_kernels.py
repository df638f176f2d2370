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


@njit(cache=True)
def csc_matvec(indptr, indices, data, x, out):
    """out (n,) = A x for A given by its CSC values on (indptr, indices) (n + 1,), (nnz,)
    int64."""
    out[:] = 0.0
    for j in range(indptr.shape[0] - 1):
        xj = x[j]
        for p in range(indptr[j], indptr[j + 1]):
            out[indices[p]] += data[p] * xj


@njit(cache=True)
def cg_update(x, r, p, ap, step):
    """x += step p, r -= step ap (n,); returns (max |r|, max |x|)."""
    residual = 0.0
    largest = 0.0
    for i in range(x.shape[0]):
        x[i] += step * p[i]
        r[i] -= step * ap[i]
        residual = max(residual, abs(r[i]))
        largest = max(largest, abs(x[i]))
    return residual, largest


@njit(cache=True)
def cg_direction(z, p, beta):
    """p = z + beta p (n,), in place."""
    for i in range(p.shape[0]):
        p[i] = z[i] + beta * p[i]


@njit(cache=True)
def filter_and_permute(filters, vec, perm, out):
    """out[k] (d n,) = (S vec)[perm[k]], S the node filters (n, d, d); out may be single
    precision (the right-hand side of a single-precision factorisation)."""
    d = filters.shape[1]
    for k in range(perm.shape[0]):
        dof = perm[k]
        i = dof // d
        a = dof - d * i
        acc = 0.0
        for b in range(d):
            acc += filters[i, a, b] * vec[d * i + b]
        out[k] = acc


@njit(cache=True)
def unpermute(vec, perm, out):
    """out[perm[k]] = vec[k] (n,), in double precision."""
    for k in range(perm.shape[0]):
        out[perm[k]] = vec[k]


@njit(cache=True)
def max_abs(vec):
    """max |vec[i]| of a (n,) array (0 for an empty one)."""
    largest = 0.0
    for i in range(vec.shape[0]):
        largest = max(largest, abs(vec[i]))
    return largest


@njit(cache=True)
def cone_friction(x, x_n, nodes, tangents, bounds, obstacle_speed, dt, eps, fric_grad,
                  blocks):
    """Kinetic friction of sliding nodes (``ImplicitEulerSolver._cone_friction``).

    With T (m, d) a node's tangents and s = T (x - x_n) / dt - v_obstacle (m/s), the
    potential b dt sqrt(|s|^2 + eps^2) has the gradient b T^T s / root and the Hessian
    (b / dt) T^T (I / root - s s^T / root^3) T.

    Args:
        x, x_n: (n, d) m.  nodes: (k,).  tangents: (k, m, d).  bounds: (k,) N.
        obstacle_speed: (k, m) m/s.  dt: s.  eps: m/s, the smoothing speed.
        fric_grad: (d n,) N, the gradient added into it.  blocks: (k, d, d) N/m, written.

    Returns:
        The potential (J).
    """
    d = x.shape[1]
    m = tangents.shape[1]
    s = np.empty(m)
    phi = 0.0
    for r in range(nodes.shape[0]):
        i = nodes[r]
        t = tangents[r]
        sq = 0.0
        for a in range(m):
            acc = 0.0
            for c in range(d):
                acc += t[a, c] * (x[i, c] - x_n[i, c])
            s[a] = acc / dt - obstacle_speed[r, a]
            sq += s[a] * s[a]
        root = np.sqrt(sq + eps * eps)
        b = bounds[r]
        phi += b * dt * root
        for c in range(d):
            acc = 0.0
            for a in range(m):
                acc += s[a] * t[a, c]
            fric_grad[d * i + c] += b / root * acc
        for c in range(d):
            for e in range(d):
                acc = 0.0
                proj_c = 0.0
                proj_e = 0.0
                for a in range(m):
                    acc += t[a, c] * t[a, e]
                    proj_c += s[a] * t[a, c]
                    proj_e += s[a] * t[a, e]
                blocks[r, c, e] = b / dt * (acc / root - proj_c * proj_e / root ** 3)
    return phi


@njit(cache=True)
def ldl_solve_3(l_ptr, l_row, l_values, d_inv, x):
    """x <- (L D L^T)^-1 x in place for 3 x 3 node blocks: ``sparse_ldl.solve`` written
    out for b = 3 (three independent sums per block; about six times faster than its
    loop over a run-time block size).

    Args:
        l_ptr: (n_nodes + 1,), l_row: (n_factor,) the factor's block columns
            (``sparse_ldl.SparsePattern``).  l_values: (n_factor, 9) L's blocks,
            row-major.  d_inv: (n_nodes, 9) D's inverse blocks, row-major.
        x: (3 n_nodes,) in position order.
    """
    n = d_inv.shape[0]
    for i in range(n):  # L z = x, by columns
        x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = 3 * l_row[p]
            x[j] -= l_values[p, 0] * x0 + l_values[p, 1] * x1 + l_values[p, 2] * x2
            x[j + 1] -= l_values[p, 3] * x0 + l_values[p, 4] * x1 + l_values[p, 5] * x2
            x[j + 2] -= l_values[p, 6] * x0 + l_values[p, 7] * x1 + l_values[p, 8] * x2
    for i in range(n):  # D y = z
        x0, x1, x2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        x[3 * i] = d_inv[i, 0] * x0 + d_inv[i, 1] * x1 + d_inv[i, 2] * x2
        x[3 * i + 1] = d_inv[i, 3] * x0 + d_inv[i, 4] * x1 + d_inv[i, 5] * x2
        x[3 * i + 2] = d_inv[i, 6] * x0 + d_inv[i, 7] * x1 + d_inv[i, 8] * x2
    for i in range(n - 1, -1, -1):  # L^T x = y, by columns of L (rows of L^T)
        s0, s1, s2 = x[3 * i], x[3 * i + 1], x[3 * i + 2]
        for p in range(l_ptr[i], l_ptr[i + 1]):
            j = 3 * l_row[p]
            x0, x1, x2 = x[j], x[j + 1], x[j + 2]
            s0 -= l_values[p, 0] * x0 + l_values[p, 3] * x1 + l_values[p, 6] * x2
            s1 -= l_values[p, 1] * x0 + l_values[p, 4] * x1 + l_values[p, 7] * x2
            s2 -= l_values[p, 2] * x0 + l_values[p, 5] * x1 + l_values[p, 8] * x2
        x[3 * i] = s0
        x[3 * i + 1] = s1
        x[3 * i + 2] = s2


@njit(cache=True)
def ldl_factor_3(arrays, values, l_values, d_inv):
    """A = L D L^T for 3 x 3 node blocks: ``sparse_ldl.factor`` written out for b = 3
    (the same up-looking algorithm, storage and return value; about three times
    faster than its loops over a run-time block size).

    Args:
        arrays: ``sparse_ldl.SparsePattern.arrays``.
        values: (n_blocks + 1, 9) A's blocks, row-major (read only).
        l_values: (n_factor, 9), d_inv: (n_nodes, 9): the factors, row-major (written).

    Returns:
        the number of pivot blocks that are not positive definite, or -1 - k when the
        pivot block at position k is singular or not finite.
    """
    _order, _position, a_ptr, a_col, l_ptr, l_row, r_ptr, r_col, r_index = arrays
    n = d_inv.shape[0]
    y = np.zeros((n, 9))  # row k of L D, being formed (zero outside its pattern)
    indefinite = 0
    for k in range(n):
        for m in range(a_ptr[k], a_ptr[k + 1]):
            for e in range(9):
                y[a_col[m], e] = values[n + m, e]
        d00, d01, d02 = values[k, 0], values[k, 1], values[k, 2]
        d11, d12, d22 = values[k, 4], values[k, 5], values[k, 8]
        for t in range(r_ptr[k], r_ptr[k + 1]):
            i = r_col[t]
            here = r_index[t]
            w00, w01, w02 = y[i, 0], y[i, 1], y[i, 2]
            w10, w11, w12 = y[i, 3], y[i, 4], y[i, 5]
            w20, w21, w22 = y[i, 6], y[i, 7], y[i, 8]
            for e in range(9):
                y[i, e] = 0.0
            # the rows j < k of column i take w L[j, i]^T off y[j]
            for p in range(l_ptr[i], here):
                j = l_row[p]
                for c in range(3):
                    l0, l1, l2 = l_values[p, 3 * c], l_values[p, 3 * c + 1], l_values[p, 3 * c + 2]
                    y[j, c] -= w00 * l0 + w01 * l1 + w02 * l2
                    y[j, 3 + c] -= w10 * l0 + w11 * l1 + w12 * l2
                    y[j, 6 + c] -= w20 * l0 + w21 * l1 + w22 * l2
            # L[k, i] = w D_i^-1 and D_k -= w L[k, i]^T
            for c in range(3):
                i0, i1, i2 = d_inv[i, c], d_inv[i, 3 + c], d_inv[i, 6 + c]
                l_values[here, c] = w00 * i0 + w01 * i1 + w02 * i2
                l_values[here, 3 + c] = w10 * i0 + w11 * i1 + w12 * i2
                l_values[here, 6 + c] = w20 * i0 + w21 * i1 + w22 * i2
            l00, l01, l02 = l_values[here, 0], l_values[here, 1], l_values[here, 2]
            l10, l11, l12 = l_values[here, 3], l_values[here, 4], l_values[here, 5]
            l20, l21, l22 = l_values[here, 6], l_values[here, 7], l_values[here, 8]
            d00 -= w00 * l00 + w01 * l01 + w02 * l02
            d01 -= w00 * l10 + w01 * l11 + w02 * l12
            d02 -= w00 * l20 + w01 * l21 + w02 * l22
            d11 -= w10 * l10 + w11 * l11 + w12 * l12
            d12 -= w10 * l20 + w11 * l21 + w12 * l22
            d22 -= w20 * l20 + w21 * l21 + w22 * l22
        # D_k^-1 by cofactors (D_k symmetric)
        c00 = d11 * d22 - d12 * d12
        c01 = d02 * d12 - d01 * d22
        c02 = d01 * d12 - d02 * d11
        det = d00 * c00 + d01 * c01 + d02 * c02
        if det == 0.0 or not np.isfinite(det):
            return -1 - k
        c11 = d00 * d22 - d02 * d02
        c12 = d01 * d02 - d00 * d12
        c22 = d00 * d11 - d01 * d01
        d_inv[k, 0] = c00 / det
        d_inv[k, 1] = c01 / det
        d_inv[k, 2] = c02 / det
        d_inv[k, 3] = c01 / det
        d_inv[k, 4] = c11 / det
        d_inv[k, 5] = c12 / det
        d_inv[k, 6] = c02 / det
        d_inv[k, 7] = c12 / det
        d_inv[k, 8] = c22 / det
        if not (d00 > 0.0 and c22 > 0.0 and det > 0.0):  # leading minors (Sylvester)
            indefinite += 1
    return indefinite
