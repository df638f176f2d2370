"""Compiled 2D barrier terms: the IPC barrier of edge-vertex pairs (``core.barrier``).

The same potential as ipctk's ``BarrierPotential(dhat, kappa, use_physical_barrier=True)``
on the collision set it builds from edge-vertex candidates (Li et al. 2020, "Incremental
Potential Contact", eq. 6 and section 4.1), evaluated here in one pass over the
candidates instead of through ipctk's collision objects and sparse matrices:

- per candidate (edge e0-e1, vertex p) its distance type: the parameter t of p's
  projection on the edge's line, t < 0 the point-point distance to e0, t > 1 to e1,
  else the point-line distance; s the squared distance of that type;
- a candidate with s < dhat^2 adds kappa b(s, dhat^2) / dhat^3, with
  b(s, S) = -(s - S)^2 ln(s / S) (ipctk's clamped log barrier on squared distances, its
  physical scaling dhat / units, units = (dhat^2)^2); ipctk merges the point-point
  pairs of several candidates into one pair of their summed weights, the same sum;
- its Hessian f'' grad s grad s^T + f' hess s, projected onto the positive
  semi-definite cone by clamping its negative eigenvalues to 0 (ipctk's
  ``PSDProjectionMethod.CLAMP``), in the subspace free of the pair's translations
  (``_clamp_pair_to_psd``).
"""
from __future__ import annotations

import numpy as np
from numba import njit, uint64

from gripper_sim.core.barrier_search import collision_free_step


@njit(cache=True)
def barrier_derivatives(s, s_hat, scale):
    """(value, first, second derivative) of scale * b(s, s_hat) in s, the IPC barrier
    b = -(s - s_hat)^2 ln(s / s_hat) of a squared gap s (m^2; scalars, or arrays of s)."""
    ratio = s_hat / s
    log = np.log(s / s_hat)
    value = -(s - s_hat) ** 2 * log * scale
    first = (s_hat - s) * (2.0 * log - ratio + 1.0) * scale
    second = ((ratio + 2.0) * ratio - 2.0 * log - 3.0) * scale
    return value, first, second


@njit(cache=True)
def _point_point(p, q, grad, hess):
    """Squared distance of p and q (2,); its gradient (4,) and Hessian (4, 4) over
    (p, q) into ``grad`` and ``hess``."""
    dx, dy = p[0] - q[0], p[1] - q[1]
    grad[0], grad[1], grad[2], grad[3] = 2 * dx, 2 * dy, -2 * dx, -2 * dy
    hess[:] = 0.0
    for a in range(2):
        hess[a, a] = 2.0
        hess[a + 2, a + 2] = 2.0
        hess[a, a + 2] = -2.0
        hess[a + 2, a] = -2.0
    return dx * dx + dy * dy


@njit(cache=True)
def _line_second_derivatives():
    """The constant second derivatives (6, 6) over (p, a, b) of c = (a - p) x (b - p)
    and of L = |b - a|^2 (``_point_line``)."""
    ddc = np.zeros((6, 6))
    ddl = np.zeros((6, 6))
    # c = a0 b1 - a0 p1 - p0 b1 - a1 b0 + a1 p0 + p1 b0 (the p0 p1 terms cancel)
    cross_terms = ((2, 5, 1.0), (2, 1, -1.0), (0, 5, -1.0), (3, 4, -1.0), (3, 0, 1.0),
                   (1, 4, 1.0))
    for i, j, value in cross_terms:
        ddc[i, j] += value
        ddc[j, i] += value
    for k in range(2):
        ddl[2 + k, 2 + k] = 2.0
        ddl[4 + k, 4 + k] = 2.0
        ddl[2 + k, 4 + k] = -2.0
        ddl[4 + k, 2 + k] = -2.0
    return ddc, ddl


@njit(cache=True)
def _point_line_squared(p, a, b):
    """Squared distance of p from the line through a and b (2,), as ``_point_line``
    computes it (the same operations: the same value to the last bit)."""
    ax, ay, bx, by = a[0] - p[0], a[1] - p[1], b[0] - p[0], b[1] - p[1]
    c = ax * by - ay * bx
    ex, ey = b[0] - a[0], b[1] - a[1]
    length = ex * ex + ey * ey
    return c * c * (1.0 / length)


@njit(cache=True)
def _point_line(p, a, b, ddc, ddl, dc, dl, grad, hess):
    """Squared distance of p from the line through a and b (2,): c^2 / L with
    c = cross(a - p, b - p), L = |b - a|^2; its gradient (6,) and Hessian (6, 6) over
    (p, a, b) into ``grad`` and ``hess`` (``dc``, ``dl`` (6,) work space; ``ddc``,
    ``ddl`` from ``_line_second_derivatives``)."""
    ax, ay, bx, by = a[0] - p[0], a[1] - p[1], b[0] - p[0], b[1] - p[1]
    c = ax * by - ay * bx
    ex, ey = b[0] - a[0], b[1] - a[1]
    length = ex * ex + ey * ey
    dc[0], dc[1], dc[2], dc[3], dc[4], dc[5] = -(by - ay), bx - ax, by, -bx, -ay, ax
    dl[0], dl[1], dl[2], dl[3], dl[4], dl[5] = 0.0, 0.0, -2 * ex, -2 * ey, 2 * ex, 2 * ey
    l1, l2, l3 = 1.0 / length, 1.0 / length ** 2, 1.0 / length ** 3
    for i in range(6):
        grad[i] = 2 * c * dc[i] * l1 - c * c * dl[i] * l2
        for j in range(6):
            hess[i, j] = (2 * dc[i] * dc[j] * l1 + 2 * c * ddc[i, j] * l1
                          - 2 * c * (dc[i] * dl[j] + dl[i] * dc[j]) * l2
                          - c * c * ddl[i, j] * l2 + 2 * c * c * dl[i] * dl[j] * l3)
    return c * c * l1


#: sweeps of the cyclic Jacobi eigenvalue method (a 6 x 6 matrix converges to round-off
#: in 5-6; it stops earlier once the off-diagonal part vanishes)
JACOBI_SWEEPS = 12


@njit(cache=True)
def _clamp_4x4_to_psd(matrix, a, vectors, out):
    """``matrix`` (4, 4) symmetric with its negative eigenvalues set to 0: its
    eigensystem by cyclic Jacobi rotations (Golub & Van Loan, Matrix Computations,
    section 8.5), much cheaper than a LAPACK call. ``a``, ``vectors``, ``out`` (4, 4):
    work space (``out`` is returned where the clamp changes ``matrix``, else ``matrix``
    itself). The size is a constant, so the compiler unrolls the loops over it."""
    k = 4
    a[:] = matrix
    vectors[:] = 0.0
    for i in range(k):
        vectors[i, i] = 1.0
    scale = 0.0
    for i in range(k):
        for j in range(k):
            scale = max(scale, abs(a[i, j]))
    if scale == 0.0:
        return matrix
    for _ in range(JACOBI_SWEEPS):
        off = 0.0
        for i in range(k):
            for j in range(i + 1, k):
                off = max(off, abs(a[i, j]))
        if off <= 1e-17 * scale:
            break
        for p in range(k - 1):
            for q in range(p + 1, k):
                if a[p, q] == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * a[p, q])
                t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                c = 1.0 / np.sqrt(t * t + 1.0)
                s = t * c
                for r in range(k):       # A <- A J (columns p, q)
                    arp, arq = a[r, p], a[r, q]
                    a[r, p] = c * arp - s * arq
                    a[r, q] = s * arp + c * arq
                for r in range(k):       # A <- J^T A (rows p, q)
                    apr, aqr = a[p, r], a[q, r]
                    a[p, r] = c * apr - s * aqr
                    a[q, r] = s * apr + c * aqr
                for r in range(k):       # V <- V J
                    vrp, vrq = vectors[r, p], vectors[r, q]
                    vectors[r, p] = c * vrp - s * vrq
                    vectors[r, q] = s * vrp + c * vrq
    negative = False
    for i in range(k):
        if a[i, i] < 0.0:
            negative = True
    if not negative:
        return matrix
    out[:] = 0.0
    for m in range(k):
        value = a[m, m]
        if value <= 0.0:
            continue
        for i in range(k):
            for j in range(k):
                out[i, j] += value * vectors[i, m] * vectors[j, m]
    return out


@njit(cache=True)
def _clamp_2x2_to_psd(matrix, out):
    """``matrix`` (2, 2) symmetric with its negative eigenvalues set to 0, in closed form
    (a negative and a positive eigenvalue l1 < 0 <= l2: l2 (A - l1 I) / (l2 - l1)); into
    ``out`` (2, 2), returned, where the clamp changes ``matrix``, else ``matrix``."""
    a, b, d = matrix[0, 0], matrix[0, 1], matrix[1, 1]
    mean = 0.5 * (a + d)
    radius = np.sqrt((0.5 * (a - d)) ** 2 + b * b)
    low, high = mean - radius, mean + radius
    if low >= 0.0:
        return matrix
    out[:] = 0.0
    if high <= 0.0:
        return out
    factor = high / (high - low)
    out[0, 0], out[1, 1] = factor * (a - low), factor * (d - low)
    out[0, 1] = out[1, 0] = factor * b
    return out


@njit(cache=True)
def _pair_bases():
    """The orthonormal bases B (m, m - 1) of ``_clamp_pair_to_psd``: (m = 2, m = 3)."""
    pair = np.zeros((2, 1))
    pair[0, 0], pair[1, 0] = np.sqrt(0.5), -np.sqrt(0.5)
    triple = np.zeros((3, 2))
    triple[0, 0], triple[1, 0] = np.sqrt(0.5), -np.sqrt(0.5)
    triple[0, 1] = triple[1, 1] = 1.0 / np.sqrt(6.0)
    triple[2, 1] = -2.0 / np.sqrt(6.0)
    return pair, triple


@njit(cache=True)
def psd_scratch():
    """The work arrays of ``_clamp_pair_to_psd``, made once per kernel call: (the bases
    B of m = 2 and 3 (2, 1), (3, 2); reduced (2, 2), (4, 4); the Jacobi copy and
    eigenvectors (4, 4); clamped (2, 2), (4, 4); out (4, 4), (6, 6))."""
    pair, triple = _pair_bases()
    return (pair, triple, np.empty((2, 2)), np.empty((4, 4)), np.empty((4, 4)),
            np.empty((4, 4)), np.empty((2, 2)), np.empty((4, 4)), np.empty((4, 4)),
            np.empty((6, 6)))


@njit(cache=True)
def _clamp_pair_to_psd(local, m, scratch):
    """A pair's Hessian ``local`` (2 m, 2 m) over its m = 2 or 3 vertices' (x, y) with its
    negative eigenvalues set to 0 (a Jacobi clamp of it, to round-off); ``scratch``
    the work arrays (``psd_scratch``), one of which is returned.

    The barrier depends on the differences of the pair's positions only, so its Hessian
    maps both translations to 0 and acts on their orthogonal complement: with an
    orthonormal basis Q = B (x) I_2 of it (B (m, m - 1), orthonormal columns summing to
    zero), L = Q (Q^T L Q) Q^T and the clamped L is Q clamp(Q^T L Q) Q^T, a 2 x 2 in
    closed form (point-point) or a 4 x 4 by Jacobi (point-line, ``_clamp_4x4_to_psd``)
    instead of a 4 x 4 or 6 x 6 by Jacobi."""
    pair, triple, reduced2, reduced4, jacobi, vectors, clamped2, clamped4, out4, out6 = scratch
    r = m - 1
    basis = pair if m == 2 else triple
    reduced = reduced2 if m == 2 else reduced4
    reduced[:] = 0.0
    for i in range(r):
        for j in range(r):
            for k in range(m):
                for n in range(m):
                    w = basis[k, i] * basis[n, j]
                    if w == 0.0:
                        continue
                    for c in range(2):
                        for e in range(2):
                            reduced[2 * i + c, 2 * j + e] += w * local[2 * k + c, 2 * n + e]
    if r == 1:
        clamped = _clamp_2x2_to_psd(reduced, clamped2)
    else:
        clamped = _clamp_4x4_to_psd(reduced, jacobi, vectors, clamped4)
    out = out4 if m == 2 else out6
    out[:] = 0.0
    for k in range(m):
        for n in range(m):
            for i in range(r):
                for j in range(r):
                    w = basis[k, i] * basis[n, j]
                    if w == 0.0:
                        continue
                    for c in range(2):
                        for e in range(2):
                            out[2 * k + c, 2 * n + e] += w * clamped[2 * i + c, 2 * j + e]
    return out


@njit(cache=True)
def same_values(a, b):
    """Whether the arrays ``a`` and ``b`` (n,) hold the same values (``np.array_equal``:
    NaN equals nothing), stopping at the first difference."""
    if a.shape[0] != b.shape[0]:
        return False
    for i in range(a.shape[0]):
        if a[i] != b[i]:
            return False
    return True


@njit(cache=True)
def largest_move(q, dofs, start):
    """m, the largest distance of a vertex at positions ``q`` (n_dof,) from ``start``
    (k, 2), its coordinates at ``dofs`` (k, 2)."""
    largest = 0.0
    for i in range(dofs.shape[0]):
        dx = q[dofs[i, 0]] - start[i, 0]
        dy = q[dofs[i, 1]] - start[i, 1]
        largest = max(largest, dx * dx + dy * dy)
    return np.sqrt(largest)


@njit(cache=True)
def mesh_vertices(q, dofs, corners, out):
    """out (n_v + c k, d) m (C or Fortran order): the collision mesh's vertices, the
    deformable ones at positions q (d n,) m (their dofs (n_v, d)), then the faces'
    corners (c k, d) m."""
    n_v, d = dofs.shape
    for i in range(n_v):
        for k in range(d):
            out[i, k] = q[dofs[i, k]]
    for i in range(corners.shape[0]):
        for k in range(d):
            out[n_v + i, k] = corners[i, k]


@njit(cache=True)
def kept_step_bound(q, dq, dofs, corners, edges, anchor, pairs, margin):
    """The CCD's largest fraction (0, 1] of the step ``dq`` from positions ``q`` (n_dof,)
    m free of crossings (``barrier_search.collision_free_step``) over kept candidate
    ``pairs`` (k, 2), or -1 if they may miss a pair: a deformable vertex (coordinates at
    ``dofs`` (n_v, 2)) further than ``margin`` m from ``anchor`` (n_v, 2), where they
    were sought, at either end. The collision mesh's vertices are the deformable ones
    then the faces' ``corners`` (c k, 2) m, standing still; ``edges`` (n_e, 2)."""
    end = q + dq
    if largest_move(q, dofs, anchor) > margin or largest_move(end, dofs, anchor) > margin:
        return -1.0
    n_v = dofs.shape[0]
    v0 = np.empty((n_v + corners.shape[0], 2))
    v1 = np.empty((n_v + corners.shape[0], 2))
    for i in range(n_v):
        for c in range(2):
            v0[i, c] = q[dofs[i, c]]
            v1[i, c] = end[dofs[i, c]]
    v0[n_v:] = corners
    v1[n_v:] = corners
    return collision_free_step(v0, v1, edges, pairs)


@njit(cache=True)
def largest_relative_move(q, dofs, start, body, n_bodies):
    """m, the largest distance of a vertex at positions ``q`` (n_dof,) from ``start``
    (k, d), its coordinates at ``dofs`` (k, d), once its body's mean move is taken off
    (``body`` (k,) each vertex's body in 0 .. ``n_bodies`` - 1): a bound on how far a
    body's own primitives came closer to each other, whatever the bodies' translations.
    The loops run with d = 2 a constant for 2D (unrolled)."""
    if dofs.shape[1] == 2:
        return _largest_relative_move(q, q, False, dofs, start, body, n_bodies, 2)
    return _largest_relative_move(q, q, False, dofs, start, body, n_bodies, dofs.shape[1])


@njit(cache=True, inline='always')
def _largest_relative_move(q, dq, shifted, dofs, start, body, n_bodies, d):
    """``largest_relative_move`` at positions q, or (``shifted``) q + dq (n_dof,) m, each
    coordinate's sum formed where it is read (no q + dq array; the same sums)."""
    mean = np.zeros((n_bodies, d))
    count = np.zeros(n_bodies)
    for i in range(dofs.shape[0]):
        b = body[i]
        for a in range(d):
            m = dofs[i, a]
            x = q[m] + dq[m] if shifted else q[m]
            mean[b, a] += x - start[i, a]
        count[b] += 1.0
    for b in range(n_bodies):
        if count[b] > 0.0:
            for a in range(d):
                mean[b, a] /= count[b]
    largest = 0.0
    for i in range(dofs.shape[0]):
        b = body[i]
        squared = 0.0
        for a in range(d):
            m = dofs[i, a]
            x = q[m] + dq[m] if shifted else q[m]
            r = x - start[i, a] - mean[b, a]
            squared += r * r
        largest = max(largest, squared)
    return np.sqrt(largest)


@njit(cache=True)
def relative_moves_within(q, dq, dofs, start, body, n_bodies, reach):
    """Whether ``largest_relative_move`` at positions ``q`` (n_dof,) m, and at q + dq if
    ``dq`` (n_dof,) m is not empty, is at most ``reach`` m."""
    if largest_relative_move(q, dofs, start, body, n_bodies) > reach:
        return False
    if dq.shape[0] == 0:
        return True
    if dofs.shape[1] == 2:
        return _largest_relative_move(q, dq, True, dofs, start, body, n_bodies, 2) <= reach
    return _largest_relative_move(q, dq, True, dofs, start, body, n_bodies,
                                  dofs.shape[1]) <= reach


@njit(cache=True)
def edge_vertex_barrier(v, edges, candidates, dhat, stiffness, vertex_dofs, gradient,
                        want_hessian, project, pattern_keys, n_dof, slots, hessian_values):
    """The barrier of the edge-vertex ``candidates`` at the collision mesh's vertices.

    Args:
        v: (n_m, 2) m, the collision mesh's vertices.
        edges: (n_e, 2) its edges.  candidates: (k, 2) (edge, vertex) pairs.
        dhat: m.  stiffness: N, kappa.
        vertex_dofs: (n_m, 2) the state's dof of each vertex coordinate, -1 for the
            vertices that are no degrees of freedom (faces' corners).
        gradient: (n_dof,) N, the barrier's gradient is added into it.
        want_hessian: whether to give the Hessian's entries.
        project: whether each pair's Hessian is clamped to its positive semi-definite
            part (else the exact one).
        pattern_keys: (p,) sorted keys col n_dof + row of the Hessian's pattern.
        slots: (p,) where in ``hessian_values`` each key of the pattern adds.
        hessian_values: the Hessian's entries (N/m) are added into it.

    Returns:
        (value J, the Hessian's entries outside the pattern, left out); value inf if a
        pair touches.
    """
    s_hat = dhat * dhat
    scale = stiffness / dhat ** 3
    total = 0.0
    outside = 0
    grad4 = np.empty(4)
    hess4 = np.empty((4, 4))
    grad6 = np.empty(6)
    hess6 = np.empty((6, 6))
    ids = np.empty(3, np.int64)
    ddc, ddl = _line_second_derivatives()
    dc, dl = np.empty(6), np.empty(6)
    local6 = np.empty((6, 6))
    local4 = np.empty((4, 4))
    scratch = psd_scratch()
    for k in range(candidates.shape[0]):
        edge, vertex = candidates[k, 0], candidates[k, 1]
        p, a, b = v[vertex], v[edges[edge, 0]], v[edges[edge, 1]]
        ex, ey = b[0] - a[0], b[1] - a[1]
        t = (ex * (p[0] - a[0]) + ey * (p[1] - a[1])) / (ex * ex + ey * ey)
        ids[0] = vertex
        # a pair beyond dhat (most candidates) is dropped before its derivatives
        if t < 0.0 or t > 1.0:
            end = a if t < 0.0 else b
            dx, dy = p[0] - end[0], p[1] - end[1]
            if dx * dx + dy * dy >= s_hat:
                continue
            ids[1] = edges[edge, 0] if t < 0.0 else edges[edge, 1]
            s = _point_point(p, end, grad4, hess4)
            m, grad, hess = 2, grad4, hess4
        else:
            if _point_line_squared(p, a, b) >= s_hat:
                continue
            ids[1], ids[2] = edges[edge, 0], edges[edge, 1]
            s = _point_line(p, a, b, ddc, ddl, dc, dl, grad6, hess6)
            m, grad, hess = 3, grad6, hess6
        if s >= s_hat:
            continue
        if s <= 0.0:
            return np.inf, 0
        value, first, second = barrier_derivatives(s, s_hat, scale)
        total += value
        for i in range(m):
            for c in range(2):
                dof = vertex_dofs[ids[i], c]
                if dof >= 0:
                    gradient[dof] += first * grad[2 * i + c]
        if not want_hessian:
            continue
        local = local6 if m == 3 else local4
        for i in range(2 * m):
            for j in range(2 * m):
                local[i, j] = second * grad[i] * grad[j] + first * hess[i, j]
        if project:
            local = _clamp_pair_to_psd(local, m, scratch)
        outside += add_local_hessian(local, ids, m, vertex_dofs, n_dof, pattern_keys, slots,
                                     hessian_values)
    return total, outside


@njit(cache=True, inline='always')
def lower_bound(keys, key):
    """``np.searchsorted(keys, key)`` (the first index whose key is not below ``key``) in
    the sorted ``keys`` (p,), by halving without branches: the halves' choice is a
    select, not a jump the processor mispredicts half the time (Khuong & Morin, Array
    layouts for comparison-based searching, 2017)."""
    n = keys.shape[0]
    if n == 0:
        return 0
    base = 0
    while n > 1:
        half = n >> 1
        base += half * (keys[uint64(base + half)] < key)
        n -= half
    return base + (keys[uint64(base)] < key)


@njit(cache=True)
def add_local_hessian(local, ids, m, vertex_dofs, n_dof, pattern_keys, slots,
                      hessian_values):
    """Add a pair's local Hessian into a CSC matrix's values; returns how many of its
    entries fall outside the pattern (left out).

    Args:
        local: (2 m, 2 m) N/m, over the (x, y) dofs of the pair's vertices ``ids[:m]``.
        vertex_dofs: (n_v, 2) each vertex's dof per coordinate, -1 where fixed.
        n_dof: the matrix's size.  pattern_keys: sorted (nnz,) distinct keys
        col * n_dof + row of the pattern.  slots: (nnz,) the value index of each key.
        hessian_values: the CSC values, added into.

    A vertex's y dof follows its x dof (row + 1): its key then follows the x key's in
    the sorted keys, so one binary search (``lower_bound``) serves both (each entry adds
    to its own slot, so the order of the adds is free). The slots are read as unsigned
    (no negative-index wraparound).
    """
    outside = 0
    size = pattern_keys.size
    for i in range(m):
        row_x, row_y = vertex_dofs[ids[i], 0], vertex_dofs[ids[i], 1]
        adjacent = row_x >= 0 and row_y == row_x + 1
        for j in range(m):
            for cj in range(2):
                col = vertex_dofs[ids[j], cj]
                if col < 0:
                    continue
                at_x = 0
                found_x = False
                if row_x >= 0:
                    key = col * n_dof + row_x
                    at_x = lower_bound(pattern_keys, key)
                    found_x = at_x < size and pattern_keys[at_x] == key
                    if found_x:
                        hessian_values[uint64(slots[at_x])] += local[2 * i, 2 * j + cj]
                    else:
                        outside += 1
                if row_y < 0:
                    continue
                key = col * n_dof + row_y
                if adjacent:  # the first key >= row_x's key + 1
                    at = at_x + 1 if found_x else at_x
                else:
                    at = lower_bound(pattern_keys, key)
                if at < size and pattern_keys[at] == key:
                    hessian_values[uint64(slots[at])] += local[2 * i + 1, 2 * j + cj]
                else:
                    outside += 1
    return outside


@njit(cache=True)
def _offer(node, other, gap, n_deformable, best, partner):
    if node < n_deformable and gap < best[node]:
        best[node] = gap
        partner[node] = other


@njit(cache=True)
def nearest_partners(v, edges, candidates, dhat, vertex_nodes, owner, partner):
    """Set ``partner`` (n,) to, at the node of each deformable vertex of the collision
    mesh, the body (``owner`` (n_m,) of each vertex) of the vertex on the other side of
    its nearest pair within dhat, and to -1 at the others (and every node that is no
    deformable vertex), over the edge-vertex ``candidates`` (k, 2) at the vertices ``v``
    (n_m, 2) m, ``edges`` (n_e, 2); the deformable vertices come first, at the nodes
    ``vertex_nodes`` (n_v,).

    A point-line pair couples its vertex with both ends of its edge at the distance of
    the nearer end, a point-point pair its two vertices at their distance; of equally
    near pairs the first counts."""
    n_deformable = vertex_nodes.shape[0]
    best = np.full(n_deformable, np.inf)
    other = -np.ones(n_deformable, np.int64)
    s_hat = dhat * dhat
    for k in range(candidates.shape[0]):
        edge, vertex = candidates[k, 0], candidates[k, 1]
        e0, e1 = edges[edge, 0], edges[edge, 1]
        p, a, b = v[vertex], v[e0], v[e1]
        ex, ey = b[0] - a[0], b[1] - a[1]
        t = (ex * (p[0] - a[0]) + ey * (p[1] - a[1])) / (ex * ex + ey * ey)
        to_a = (p[0] - a[0]) ** 2 + (p[1] - a[1]) ** 2
        to_b = (p[0] - b[0]) ** 2 + (p[1] - b[1]) ** 2
        if t < 0.0 or t > 1.0:
            end = e0 if t < 0.0 else e1
            squared = to_a if t < 0.0 else to_b
            if squared >= s_hat:
                continue
            gap = np.sqrt(squared)
            _offer(vertex, end, gap, n_deformable, best, other)
            _offer(end, vertex, gap, n_deformable, best, other)
            continue
        cross = (a[0] - p[0]) * (b[1] - p[1]) - (a[1] - p[1]) * (b[0] - p[0])
        if cross * cross / (ex * ex + ey * ey) >= s_hat:
            continue
        gap = np.sqrt(min(to_a, to_b))
        _offer(vertex, e0, gap, n_deformable, best, other)
        _offer(vertex, e1, gap, n_deformable, best, other)
        _offer(e0, vertex, gap, n_deformable, best, other)
        _offer(e1, vertex, gap, n_deformable, best, other)
    partner[:] = -1
    for i in range(n_deformable):
        if other[i] >= 0:
            partner[vertex_nodes[i]] = owner[other[i]]


@njit(cache=True)
def mark_sticking(velocities, obstacle, normals, obstacle_velocities, smoothing, stick,
                  slip, mode):
    """Set ``mode`` (n,) of each node held by an obstacle (``obstacle`` (n,) >= 0) to
    ``stick`` where it moves along that obstacle (velocities (n, d) m/s, the obstacles'
    unit normals and velocities (k, d)) slower than ``smoothing`` m/s, else ``slip``:
    the barrier's friction creeps below that speed (its static friction)."""
    d = velocities.shape[1]
    for i in range(obstacle.shape[0]):
        k = obstacle[i]
        if k < 0:
            continue
        normal_speed = 0.0
        for c in range(d):
            normal_speed += (velocities[i, c] - obstacle_velocities[k, c]) * normals[k, c]
        along = 0.0
        for c in range(d):
            a = (velocities[i, c] - obstacle_velocities[k, c]) - normal_speed * normals[k, c]
            along += a * a
        mode[i] = stick if np.sqrt(along) < smoothing else slip


@njit(cache=True)
def split_partners(partner, obstacle, touching):
    """From ``partner`` (n + m,) (``BarrierContact.partners``: the fruit's n nodes, then
    the soft bodies' m; 0 the fruit, 1 + b soft body b, then the faces, -1 none): set
    ``obstacle`` (n,) to each fruit node's partner less one (the obstacles' order:
    the soft bodies, then the faces), -1 for none, and ``touching`` (m,) bool to the
    soft bodies' nodes whose partner is the fruit."""
    n = obstacle.shape[0]
    for i in range(n):
        obstacle[i] = partner[i] - 1 if partner[i] > 0 else -1
    for i in range(touching.shape[0]):
        touching[i] = partner[n + i] == 0


@njit(cache=True)
def held_normal_forces(forces, obstacle, normal):
    """Set ``normal`` (n,) N to the magnitude of each held node's force (``forces``
    (n', d) N, n' >= n: the barrier's normal force, sums as ``np.linalg.norm``'s) where
    ``obstacle`` (n,) >= 0, else 0."""
    d = forces.shape[1]
    for i in range(obstacle.shape[0]):
        if obstacle[i] < 0:
            normal[i] = 0.0
            continue
        square = 0.0
        for c in range(d):
            square += forces[i, c] * forces[i, c]
        normal[i] = np.sqrt(square)


@njit(cache=True)
def push_ahead(x_n, surface, origins, normals, tangents, half_extents, thickness, shifts,
               dhat, fraction, plain, predicted):
    """``BarrierContact.pushed_starts``: for each face k that moves by ``shifts[k]`` (k, d)
    m (origin ``origins[k]``, unit normal ``normals[k]`` (k, d) at the step's start), each
    node of ``surface`` (s,) at positions ``x_n`` (n, d) m that the face covers there
    (``FaceGeometry.covers``: within ``half_extents[k]`` (k, d - 1) m along its
    ``tangents[k]`` (k, d - 1, d), less than ``thickness[k]`` (k,) m behind it) and that
    lies in front of it is moved along the normal by as much as the face's advance and
    the node's own move bring it closer than its gap at x_n (below ``dhat`` m) or
    ``fraction`` dhat: in ``plain`` (n, d) m (x_n on entry; a node that touches the face,
    gap below dhat, is moved with the face instead, its gap kept, where the face recedes
    too) and, if not empty, ``predicted`` (n, d) m (the predictor on entry).

    Left behind by a receding face (a force drive opening its jaws on a fruit squeezed
    past its command), the touching nodes start beyond the barrier's reach: Newton's
    first model then has no barrier, moves the fruit's spring-back through the face, and
    the step bound lets it land a few percent at a time (the 3D solid apple at 120 N: 77
    iterations, or no convergence within 25 even in sub-steps; 4 now)."""
    d = x_n.shape[1]
    for k in range(shifts.shape[0]):
        moving = False
        advance = 0.0
        for c in range(d):
            moving = moving or shifts[k, c] != 0.0
            advance += shifts[k, c] * normals[k, c]
        if moving:
            _push_face(x_n, surface, origins[k], normals[k], tangents[k], half_extents[k],
                       thickness[k], shifts[k], advance, dhat, fraction, plain, predicted)


@njit(cache=True)
def _push_face(x_n, surface, origin, normal, tangents, half_extents, thickness, shift,
               advance, dhat, fraction, plain, predicted):
    """``push_ahead`` for one face."""
    d = x_n.shape[1]
    for s in range(surface.shape[0]):
        i = surface[s]
        gap = 0.0
        for c in range(d):
            gap += (x_n[i, c] - origin[c]) * normal[c]
        if not gap >= 0.0 or not gap > -thickness:
            continue
        covered = True
        for t in range(d - 1):
            along = 0.0
            for c in range(d):
                along += (x_n[i, c] - origin[c]) * tangents[t, c]
            if not abs(along) <= half_extents[t]:
                covered = False
        if not covered:
            continue
        target = gap if gap < dhat else fraction * dhat
        if gap < dhat:
            for c in range(d):
                plain[i, c] += shift[c]
        else:
            push = max(advance - gap + target, 0.0)
            for c in range(d):
                plain[i, c] += push * normal[c]
        if predicted.shape[0]:
            move = 0.0
            for c in range(d):
                move += (predicted[i, c] - x_n[i, c]) * normal[c]
            push = max(advance - gap - move + target, 0.0)
            for c in range(d):
                predicted[i, c] += push * normal[c]


@njit(cache=True)
def mean_gap(x, holder, face, origin, normal):
    """m, the mean signed distance from the plane of face ``face`` (its ``origin`` and
    unit ``normal`` (d,)) of the nodes of positions ``x`` (n, d) m that ``holder`` (n,)
    gives to it; 0.0 for none."""
    d = x.shape[1]
    count = 0
    total = 0.0
    for i in range(holder.shape[0]):
        if holder[i] != face:
            continue
        gap = 0.0
        for c in range(d):
            gap += (x[i, c] - origin[c]) * normal[c]
        total += gap
        count += 1
    return total / count if count else 0.0


@njit(cache=True)
def balance_forces(forces, residual):
    """Add to the contact force (``forces`` (n, d) N) of each node that the contact pushes
    (a nonzero row) the Newton solution's ``residual`` (n, d) N: the gradient of the
    step's incremental potential there. The contact's part of that gradient is stiff (a
    barrier's force changes by newtons with nanometres of gap), so a force read from it
    carries the whole residual of a solve stopped at ``sim.newton_tolerance``, while the
    node's other forces (inertia, elasticity, gravity, damping) are smooth: the contact
    force that balances them, ``forces + residual``, is the converged one to within
    their change over the solution's error (the 2D solid apple held at 40 N with
    ``ipc``: 35 to 49 N read from the barrier, 40.00 N balanced)."""
    d = forces.shape[1]
    for i in range(forces.shape[0]):
        pushed = False
        for c in range(d):
            pushed = pushed or forces[i, c] != 0.0
        if pushed:
            for c in range(d):
                forces[i, c] += residual[i, c]


@njit(cache=True)
def normal_components(holder, forces, normals, normal_force):
    """Set ``normal_force`` (n,) N of each node held by a face (``holder`` (n,) >= 0, the
    face's index) to its force (``forces`` (n, d) N) along the face's unit normal
    (``normals`` (k, d)); the other nodes are left as they are."""
    d = forces.shape[1]
    for i in range(holder.shape[0]):
        k = holder[i]
        if k < 0:
            continue
        along = 0.0
        for c in range(d):
            along += forces[i, c] * normals[k, c]
        normal_force[i] = along


@njit(cache=True)
def nearest_faces(x, forces, origins, normals, tangents, half_extents, dhat, holder):
    """Set ``holder`` (n,) to the face (index) nearest to each node of positions ``x``
    (n, d) m with a nonzero force ``forces`` (n, d) N, of the faces within ``dhat`` m
    of it, else -1. The k faces: their ``origins`` and unit ``normals`` (k, d), their
    ``tangents`` (k, d - 1, d) and ``half_extents`` (k, d - 1) m (``barrier.face_distances``:
    the distance to the segment or rectangle; the first face of the nearest ones)."""
    n, d = x.shape
    for i in range(n):
        holder[i] = -1
        loaded = False
        for c in range(d):
            if forces[i, c] != 0.0:
                loaded = True
        if not loaded:
            continue
        best = np.inf
        for k in range(origins.shape[0]):
            normal = 0.0
            for c in range(d):
                normal += (x[i, c] - origins[k, c]) * normals[k, c]
            squared = normal * normal
            for t in range(d - 1):
                along = 0.0
                for c in range(d):
                    along += (x[i, c] - origins[k, c]) * tangents[k, t, c]
                half = half_extents[k, t]
                outside = along - min(max(along, -half), half)
                squared += outside * outside
            distance = np.sqrt(squared)
            if distance < dhat and distance < best:
                holder[i] = k
                best = distance
