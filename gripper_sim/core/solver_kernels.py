"""Numba kernels of the fast Newton solver (``core.fast_solver``), for 2D and 3D.

Free functions ``@njit(cache=True)`` on the CSC values of a Newton matrix whose pattern
is fixed (the energies' elements plus every node's diagonal block) and on the per-node
contact filters S_i (n_nodes, d, d), d = 2 or 3 the coordinates per node. The filters'
node-block loops (``filter_blocks``, ``apply_filters``, ``filter_and_permute``) run
their inlined body with d = 2 as a constant for 2D filters, so the compiler unrolls
them and divides by a shift. Import this module only where numba is installed.
"""
from __future__ import annotations

import numpy as np
from numba import njit, uint64

from gripper_sim.core import potential_terms as terms


@njit(cache=True)
def filter_blocks(hdata, block_pos, block_nodes, node_ptr, node_blocks, diag_blocks, filters,
                  diag_extra, out):
    """The Newton matrix S H S + (I - S) + diag(extra) on H's pattern, into ``out``: H's
    values, then the blocks of the nodes whose filter is not the identity (few: the
    held ones) filtered, and the extra diagonal added.

    Args:
        hdata: CSC values of H (N/m).
        block_pos: (n_blocks, d, d) positions in data of each d x d node block (read as
            unsigned: no negative-index wraparound).
        block_nodes: (n_blocks, 2) node (row, column) of each block.
        node_ptr: (n_nodes + 1,), node_blocks: (m,) the blocks of each node (as row or
            column) in CSR: node i's at node_blocks[node_ptr[i]:node_ptr[i + 1]].
        diag_blocks: (n_nodes,) each node's diagonal block.
        filters: (n_nodes, d, d) the S_i.
        diag_extra: (d n,) added on the diagonal (the shifted inertia, N/m).
        out: values of the filtered matrix, same pattern (written).
    """
    if filters.shape[1] == 2:
        _filter_blocks(hdata, block_pos, block_nodes, node_ptr, node_blocks, diag_blocks,
                       filters, diag_extra, out, 2)
    else:
        _filter_blocks(hdata, block_pos, block_nodes, node_ptr, node_blocks, diag_blocks,
                       filters, diag_extra, out, filters.shape[1])


@njit(cache=True, inline='always')
def _filter_blocks(hdata, block_pos, block_nodes, node_ptr, node_blocks, diag_blocks,
                   filters, diag_extra, out, d):
    tmp = np.empty((d, d))
    free = np.ones(filters.shape[0], np.bool_)  # S_i = I (most nodes: no contact)
    for i in range(filters.shape[0]):
        for a in range(d):
            for c in range(d):
                if filters[i, a, c] != (1.0 if a == c else 0.0):
                    free[i] = False
    out[:] = hdata  # the blocks of free nodes as they are
    for node in range(filters.shape[0]):
        if free[node]:
            blk = diag_blocks[node]
            for a in range(d):
                out[uint64(block_pos[blk, a, a])] += diag_extra[d * node + a]
            continue
        for q in range(node_ptr[node], node_ptr[node + 1]):
            blk = node_blocks[q]
            i = block_nodes[blk, 0]
            j = block_nodes[blk, 1]
            other = j if i == node else i
            if other < node and not free[other]:
                continue  # filtered with the other node's blocks
            for a in range(d):
                for c in range(d):
                    acc = 0.0
                    for b in range(d):
                        acc += filters[i, a, b] * hdata[uint64(block_pos[blk, b, c])]
                    tmp[a, c] = acc
            for a in range(d):
                for c in range(d):
                    acc = 0.0
                    for b in range(d):
                        acc += tmp[a, b] * filters[j, b, c]
                    out[uint64(block_pos[blk, a, c])] = acc
            if i == j:
                for a in range(d):
                    for c in range(d):
                        identity = 1.0 if a == c else 0.0
                        out[uint64(block_pos[blk, a, c])] += identity - filters[i, a, c]
                    out[uint64(block_pos[blk, a, a])] += diag_extra[d * i + a]


@njit(cache=True)
def apply_filters(filters, vec, out):
    """out (d n,) = S vec: each node's d-vector times its filter (n, d, d)."""
    if filters.shape[1] == 2:
        _apply_filters(filters, vec, out, 2)
    else:
        _apply_filters(filters, vec, out, filters.shape[1])


@njit(cache=True, inline='always')
def _apply_filters(filters, vec, out, d):
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
def csc_matvec(indptr, indices, data, x, out):
    """out (n,) = A x for A given by its CSC values on (indptr, indices) (n + 1,), (nnz,)
    int64 (read as unsigned: no negative-index wraparound in the inner loop)."""
    out[:] = 0.0
    for j in range(indptr.shape[0] - 1):
        xj = x[j]
        for p in range(uint64(indptr[j]), uint64(indptr[j + 1])):
            out[uint64(indices[p])] += data[p] * xj


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
    if filters.shape[1] == 2:
        _filter_and_permute(filters, vec, perm, out, 2)
    else:
        _filter_and_permute(filters, vec, perm, out, filters.shape[1])


@njit(cache=True, inline='always')
def _filter_and_permute(filters, vec, perm, out, d):
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
        out[uint64(perm[k])] = vec[k]


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
    """Kinetic friction of sliding nodes (``potential_terms.friction``, the Coulomb cone
    of ``core.stepper``): its gradient added into ``fric_grad``, its Hessian blocks
    written.

    Args:
        x, x_n: (n_dof,) m.  nodes: (k,).  tangents: (k, m, d).  bounds: (k,) N.
        obstacle_speed: (k, m) m/s.  dt: s.  eps: m/s, the smoothing speed.
        fric_grad: (n_dof,) N, the gradient added into it.  blocks: (k, d, d) N/m, written.

    Returns:
        The potential (J).
    """
    d = tangents.shape[2]
    phi = 0.0
    for r in range(nodes.shape[0]):
        value, s0, s1, root = terms.friction(x, x_n, nodes[r], tangents[r], obstacle_speed[r],
                                             bounds[r], dt, eps, fric_grad)
        phi += value
        for c in range(d):
            for e in range(d):
                blocks[r, c, e] = terms.friction_block(tangents[r], s0, s1, root, bounds[r],
                                                       dt, eps, c, e)
    return phi


@njit(cache=True)
def inertia_and_mass_damping(q, q_n, v_n, dt, masses, alpha, dq, grad):
    """``potential_terms.inertia`` and ``mass_damping``: the gradient written into
    ``grad`` (n_dof,) N, dq = q - q_n into ``dq``. Returns their value (J)."""
    phi = terms.inertia(q, q_n, v_n, dt, masses, grad)
    for m in range(q.shape[0]):
        dq[m] = q[m] - q_n[m]
    return phi + terms.mass_damping(dq, masses, alpha, dt, grad)


@njit(cache=True)
def add_inertia_diagonal(data, diag_pos, masses, dt, alpha):
    """The Hessian of inertia and mass damping (``potential_terms.inertia_diagonal``)
    added at the diagonal positions ``diag_pos`` (n_dof,) of the CSC values ``data``."""
    for m in range(masses.shape[0]):
        data[diag_pos[m]] += terms.inertia_diagonal(masses, dt, alpha, m)


@njit(cache=True)
def stiffness_damping(indptr, indices, stiffness, dq, beta, dt, k_dq, grad):
    """``potential_terms.stiffness_damping`` with K_n the CSC values ``stiffness`` on
    (indptr, indices): K_n dq written into ``k_dq``, the gradient added into ``grad``.
    Returns its value (J)."""
    csc_matvec(indptr, indices, stiffness, dq, k_dq)
    return terms.stiffness_damping(dq, k_dq, beta, dt, grad)


@njit(cache=True)
def add_step_terms(phi, hessian, x, x_n, dq, dt, masses, alpha, beta, indptr, indices,
                   stiffness, k_dq, nodes, tangents, bounds, obstacle_speed, eps,
                   diag_pos, diag_block_pos, grad, fric_grad, blocks, data):
    """The incremental potential's terms that follow the energies, in one call:
    stiffness damping (``stiffness_damping``, if beta > 0), kinetic friction
    (``cone_friction``) and, with ``hessian``, their Hessians and that of inertia and
    mass damping (``add_inertia_diagonal``) added into the CSC values ``data``, in the
    order ``PatternCachingSolver.evaluate_fast`` sums them.

    Args:
        phi: J, the potential so far.  x, x_n, dq = x - x_n: (n_dof,) m.  dt: s.
        masses: (n_dof,) kg.  alpha: 1/s.  beta: s.
        indptr, indices: the CSC pattern (int64).  stiffness: its values of K_n (N/m).
        k_dq: (n_dof,) N, scratch for K_n dq.
        nodes, tangents, bounds, obstacle_speed, eps: the sliding nodes, as
            ``cone_friction``'s.
        diag_pos: (n_dof,) the diagonal's positions in ``data``.
        diag_block_pos: (n_nodes, d, d) the diagonal node blocks' positions.
        grad: (n_dof,) N, added into.  fric_grad: (n_dof,) N, zeroed and written.
        blocks: (k, d, d) N/m, the friction blocks, written.

    Returns:
        phi plus these terms' value (J).
    """
    if beta > 0:
        phi += stiffness_damping(indptr, indices, stiffness, dq, beta, dt, k_dq, grad)
        if hessian:
            scale = beta / dt
            for p in range(stiffness.shape[0]):
                data[p] += scale * stiffness[p]
    fric_grad[:] = 0.0
    if nodes.shape[0]:
        phi += cone_friction(x, x_n, nodes, tangents, bounds, obstacle_speed, dt, eps,
                             fric_grad, blocks)
        for m in range(grad.shape[0]):
            grad[m] += fric_grad[m]
    if hessian:
        add_inertia_diagonal(data, diag_pos, masses, dt, alpha)
        if nodes.shape[0]:
            add_node_blocks(data, diag_block_pos, nodes, blocks)
    return phi
