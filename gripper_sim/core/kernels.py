"""Numba array kernels of the fast path for the ring (shell) and point fruit models.

Free functions ``@njit(cache=True)`` on arrays with preallocated outputs; the Python
glue is ``gripper_sim.core.fast``. What an element does (an edge, a bending triple, the
enclosed area, a soft pad point, a measure, the damage rule) is a compiled function of
its own module, which the generic route calls too; this module assembles them in its
layout. The rest follows the generic route's Python, in the same order of operations
where it matters:

- ``ring_stretching``, ``ring_bending``, ``ring_pressure``: the band assembly of the
  energies' element functions (``energies.kernels``: ``edge_spring``, ``hinge``,
  ``area_pressure``), which their classes' CSC kernels call too;
- ``newton_solve``: the one Newton iteration (``newton.newton_iteration``) compiled on
  this module's Newton matrices, its hooks the overloads of the Newton section;
- ``substep``: ``contact_passes.contact_step``: the one pass driver
  (``contact_passes.contact_passes``) compiled on this module's Newton solve, its hooks
  the overloads after the Newton section's;
- ``step_measures``: the numbers ``Simulation._measure`` reports, the outline's by
  ``measures.outline_measures`` and ``measures.face_contact_length_of`` (as
  ``measures.deformation``);
- ``damage_update``: ``damage.damage_patches`` (the rule ``DamageTracker.update`` calls)
  on this module's faces; ``_pad_rows``, ``_pad_forces``, ``_pad_blocks``: the soft pad's
  ``pad.pad_rows``, ``pad.pad_forces``, ``pad.pad_blocks`` on them.

Layout. Positions are flat, q = [x0, z0, x1, z1, ...] (m). Hessians are kept as a
symmetric node-block band: ``band[p, d]`` (2, 2) is the block of the node at band
position p (row) and the node at position p - d (column), d = 0 .. nbw; ``pos[i]``
is the band position of node i. A ring numbered 0, N-1, 1, N-2, ... (interleaved,
see ``band_order``) has nbw = 4 for stretching + bending + pressure, so the Newton
matrix (same block band) is factorised by a block LDL^T in O(N) time, with the
rank-one pressure term added by Sherman-Morrison. A meshed solid's Hessian and Newton
matrix are sparse instead (``core.sparse_ldl``: 2 x 2 node blocks in a minimum-degree
order, one block per row of the same 4-D arrays, ``pos[i]`` the position of node i; see
the solid's section below), factorised by the sparse block LDL^T.

Faces (rigid obstacles) are rows of two arrays: ``face_par`` (n_faces, FP_SIZE)
[normal x, normal z, half_length, thickness, static friction, kinetic friction,
restitution, jaw (0 left, 1 right, -1 none), offset x, offset z] and ``face_dyn``
(n_faces, 6) [origin at the start of the step (x, z), origin at the end (x, z), velocity
(x, z)]. A jaw has one face (flat finger) or several (the facets of an arc or V-groove
finger); each face of a jaw moves with it, its origin the jaw's origin plus its offset
(m); the faces of no jaw (table, walls) are fixed.

Import this module only where numba is installed (``gripper_sim.core.fast`` checks).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, overload

from gripper_sim.core import contact_passes, newton, sparse_ldl
from gripper_sim.core.damage import P_SIZE  # noqa: F401 (the patch table's width, for fast.py)
from gripper_sim.core.damage import (FACE_BODY, FACE_CURVATURE, FACE_PADDED, FACE_SIZE,
                                     damage_patches)
from gripper_sim.core.energies.kernels import (area_and_gradient, area_pressure, bending,
                                               edge_spring, hinge, hinge_block,
                                               neohookean_triangles, neohookean_von_mises,
                                               stretching)
from gripper_sim.core.measures import face_contact_length_of, outline_measures
from gripper_sim.core import potential_terms as terms
from gripper_sim.core.pad import (PAD_SIZE, PF_HALF, PF_INDEX, PF_NEW_X, PF_NEW_Z, PF_NX,
                                  PF_NZ, PF_OLD_X, PF_OLD_Z, PF_SIDE, PF_SIZE, PF_SPEED,
                                  pad_blocks, pad_forces, pad_rows, pad_terms)
from gripper_sim.core.newton import (C_DIRECTIONS, C_EVALS, C_FACTORS,  # noqa: F401
                                     C_HESSIAN_EVALS, C_SIZE, C_SOLVES, C_SUBSTEPS,
                                     INFEASIBLE_START, LINE_SEARCH_FAILED, MAX_FACTOR_AGE,
                                     NO_CONVERGENCE, NO_DESCENT, OK, UNSUPPORTED)
#: regularisation speed (m/s) of the kinetic friction law, as stepper.FRICTION_SMOOTHING
FRICTION_SMOOTHING = 1e-4

#: columns of ``face_par`` after the seven face parameters: the jaw of the face (-1: none)
#: and the face origin's offset (x, z) m from the jaw origin
FP_JAW, FP_OFFSET_X, FP_OFFSET_Z, FP_SIZE = 7, 8, 9, 10

# fpar layout of ``substep`` / ``newton_solve``
F_DT, F_ALPHA, F_BETA, F_TOL, F_GRAVITY, F_RELEASE, F_VCORR, F_DEPTH = range(8)
# ipar layout
I_MAX_IT, I_MAX_PASSES = range(2)


def band_order(n_nodes: int) -> np.ndarray:
    """(n_nodes,) int64, band position of each node of a ring 0 .. n-1 (interleaved order).

    Positions 0, 1, 2, 3, ... hold nodes 0, n-1, 1, n-2, ...: ring neighbours are at
    most 2 positions apart and next-but-one neighbours at most 4.
    """
    pos = np.empty(n_nodes, np.int64)
    for k in range(n_nodes):
        if 2 * k < n_nodes:
            pos[k] = 2 * k
        else:
            pos[k] = 2 * (n_nodes - 1 - k) + 1
    return pos


# ---------------------------------------------------------------------- band helpers
@njit(cache=True, error_model='numpy')
def _add_diag(band, pos, i, h00, h01, h10, h11):
    p = pos[i]
    band[p, 0, 0, 0] += h00
    band[p, 0, 0, 1] += h01
    band[p, 0, 1, 0] += h10
    band[p, 0, 1, 1] += h11


@njit(cache=True, error_model='numpy')
def _add_off(band, pos, i, j, h00, h01, h10, h11):
    """Add the block H_ij (rows node i, columns node j, i != j) and so its transpose."""
    pi, pj = pos[i], pos[j]
    if pi > pj:
        d = pi - pj
        band[pi, d, 0, 0] += h00
        band[pi, d, 0, 1] += h01
        band[pi, d, 1, 0] += h10
        band[pi, d, 1, 1] += h11
    else:
        d = pj - pi
        band[pj, d, 0, 0] += h00
        band[pj, d, 0, 1] += h10
        band[pj, d, 1, 0] += h01
        band[pj, d, 1, 1] += h11


@njit(cache=True, error_model='numpy', inline='always')
def band_matvec(band, order, v, out):
    """out = B v for a symmetric node-block band (n, nbw+1, 2, 2), v and out (2n,)."""
    n = band.shape[0]
    nbw = band.shape[1] - 1
    out[:] = 0.0
    for p in range(n):
        i = order[p]
        for d in range(min(p, nbw) + 1):
            j = order[p - d]
            b00, b01, b10, b11 = band[p, d, 0, 0], band[p, d, 0, 1], band[p, d, 1, 0], band[
                p, d, 1, 1]
            out[2 * i] += b00 * v[2 * j] + b01 * v[2 * j + 1]
            out[2 * i + 1] += b10 * v[2 * j] + b11 * v[2 * j + 1]
            if d > 0:
                out[2 * j] += b00 * v[2 * i] + b10 * v[2 * i + 1]
                out[2 * j + 1] += b01 * v[2 * i] + b11 * v[2 * i + 1]


@njit(cache=True, error_model='numpy')
def band_to_dense(band, order, out):
    """Expand a node-block band into a dense (2n, 2n) matrix ``out`` (for tests)."""
    n = band.shape[0]
    nbw = band.shape[1] - 1
    out[:, :] = 0.0
    for p in range(n):
        i = order[p]
        for d in range(min(p, nbw) + 1):
            j = order[p - d]
            for a in range(2):
                for b in range(2):
                    out[2 * i + a, 2 * j + b] = band[p, d, a, b]
                    out[2 * j + b, 2 * i + a] = band[p, d, a, b]


# ---------------------------------------------------------------------- energies
@njit(cache=True, error_model='numpy', inline='always')
def ring_stretching(q, edges, spar, pos, hessian, grad, band):
    """Skin stretching (energies/stretching.py): ``energies.kernels.edge_spring`` per edge,
    its Hessian into the band.

    Args:
        q: (2n,) m.  edges: (n_edge, 2) nodes.  spar: (n_edge, 2) [L (m), EA / L (N/m)].
        pos: (n,) band positions.  hessian: also add the Hessian into ``band``.
        grad: (2n,) N, output (overwritten).  band: (n, nbw+1, 2, 2) N/m, added to.

    Returns:
        the energy, J.
    """
    grad[:] = 0.0
    value = 0.0
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        v, fx, fz, b00, b01, b11 = edge_spring(q[2 * j] - q[2 * i], q[2 * j + 1] - q[2 * i + 1],
                                               spar[e, 0], spar[e, 1])
        value += v
        grad[2 * i] -= fx
        grad[2 * i + 1] -= fz
        grad[2 * j] += fx
        grad[2 * j + 1] += fz
        if hessian:
            _add_diag(band, pos, i, b00, b01, b01, b11)
            _add_diag(band, pos, j, b00, b01, b01, b11)
            _add_off(band, pos, i, j, -b00, -b01, -b01, -b11)
    return value


@njit(cache=True, error_model='numpy', inline='always')
def ring_bending(q, triples, bpar, pos, hessian, grad, band):
    """Ring bending (energies/bending.py): ``energies.kernels.hinge`` per triple, its
    Hessian blocks (``hinge_block``) into the band.

    Args:
        triples: (n_t, 3) nodes (previous, middle, next).
        bpar: (n_t, 2) [phi0 (rad), k = EI / l (N m)].
        Others as ``ring_stretching``.
    """
    grad[:] = 0.0
    value = 0.0
    for t in range(triples.shape[0]):
        i0, i1, i2 = triples[t, 0], triples[t, 1], triples[t, 2]
        k = bpar[t, 1]
        v, kd, j0, j1, j2, j3, j4, j5, ha00, ha01, hb00, hb01 = hinge(
            q[2 * i1] - q[2 * i0], q[2 * i1 + 1] - q[2 * i0 + 1], q[2 * i2] - q[2 * i1],
            q[2 * i2 + 1] - q[2 * i1 + 1], bpar[t, 0], k)
        value += v
        grad[2 * i0] += kd * j0
        grad[2 * i0 + 1] += kd * j1
        grad[2 * i1] += kd * j2
        grad[2 * i1 + 1] += kd * j3
        grad[2 * i2] += kd * j4
        grad[2 * i2 + 1] += kd * j5
        if hessian:
            b00, b01, b10, b11 = hinge_block(k, kd, j0, j1, j0, j1, ha00, ha01)
            _add_diag(band, pos, i0, b00, b01, b10, b11)
            b00, b01, b10, b11 = hinge_block(k, kd, j2, j3, j2, j3, ha00 + hb00, ha01 + hb01)
            _add_diag(band, pos, i1, b00, b01, b10, b11)
            b00, b01, b10, b11 = hinge_block(k, kd, j4, j5, j4, j5, hb00, hb01)
            _add_diag(band, pos, i2, b00, b01, b10, b11)
            b00, b01, b10, b11 = hinge_block(k, kd, j2, j3, j0, j1, -ha00, -ha01)
            _add_off(band, pos, i1, i0, b00, b01, b10, b11)
            b00, b01, b10, b11 = hinge_block(k, kd, j4, j5, j2, j3, -hb00, -hb01)
            _add_off(band, pos, i2, i1, b00, b01, b10, b11)
            b00, b01, b10, b11 = hinge_block(k, kd, j4, j5, j0, j1, 0.0, 0.0)
            _add_off(band, pos, i2, i0, b00, b01, b10, b11)
    return value


@njit(cache=True, error_model='numpy', inline='always')
def ring_pressure(q, ring, press, pos, hessian, grad, band, area_grad):
    """Enclosed-area pressure (energies/pressure.py): ``energies.kernels.area_and_gradient``
    and ``area_pressure``, the sparse part of its Hessian into the band.

    Args:
        ring: (n_r,) nodes counter-clockwise (empty: no pressure).
        press: (4,) [A0 (m^2), depth b (m), turgor p0 (Pa), bulk modulus K (Pa)].
        area_grad: (2n,) output, dA/dq (the rank-one direction u).
        Others as ``ring_stretching``.

    Returns:
        (energy J, rank-one coefficient c = b K / A0 (0 if none)); the Hessian is the
        band part plus c u u^T.
    """
    n = ring.shape[0]
    if n == 0:
        grad[:] = 0.0
        area_grad[:] = 0.0
        return 0.0, 0.0
    area = area_and_gradient(q.reshape((q.shape[0] // 2, 2)), ring, area_grad)
    value, de_da, c = area_pressure(area, press[0], press[1], press[2], press[3])
    for m in range(q.shape[0]):
        grad[m] = de_da * area_grad[m]
    if hessian:
        h = de_da * 0.5
        for r in range(n):
            _add_off(band, pos, ring[r], ring[(r + 1) % n], 0.0, h, -h, 0.0)
    return value, c


@njit(cache=True, error_model='numpy', inline='always')
def _energies(q, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, hessian,
              grads, band, area_grad, values):
    """All ring energies, the flesh and gravity: grads (4, 2n) per energy, band = elastic
    Hessian, values (4,) J: stretching, bending, pressure (plus the flesh), gravity.
    Returns the rank-one c.

    ``flesh``: the neo-Hookean triangles of a solid fruit (``NeoHookeanTriangles``) and
    the solid's sparse Newton matrix as (tri (n_tri, 3), dm_inv (n_tri, 2, 2), volume
    (n_tri,) m^3, [mu, lambda] Pa, scatter (n_tri, 36) flat indices of each element's
    Hessian entries into the sparse values, the skin's arrays (``fast._solid_skin``), the
    pattern's ``SparsePattern.arrays``); n_tri = 0: none (the band). A solid's energies
    are ``_solid_energies``.
    """
    if flesh[0].shape[0] > 0:  # a meshed solid: its sparse Hessian
        return _solid_energies(q, edges, triples, flesh, gravity_grad, hessian, grads, band,
                               values)
    if hessian:
        flat = band.reshape(band.size)  # a flat loop: ~10x faster than band[:] = 0 in 4-D
        for m in range(flat.shape[0]):
            flat[m] = 0.0
    values[0] = ring_stretching(q, edges, spar, pos, hessian, grads[0], band)
    values[1] = ring_bending(q, triples, bpar, pos, hessian, grads[1], band)
    vp, c = ring_pressure(q, ring, press, pos, hessian, grads[2], band, area_grad)
    values[2] = vp
    vg = 0.0
    for m in range(q.shape[0]):
        vg += gravity_grad[m] * q[m]
        grads[3, m] = gravity_grad[m]
    values[3] = vg
    return c


# ---------------------------------------------------------------------- Newton
@njit(cache=True, error_model='numpy')
def _evaluate(q, q_n, v_n, dt, masses2, alpha, beta, filters, fr_nodes, fr_t, fr_bound,
              fr_speed, n_fr, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos,
              hessian, grad, fric_grad, grads, band, stiffness, area_grad, dq_tmp, cdq, values,
              pad_nodes, pad_par):
    """Phi (``core.potential_terms`` and the energies) in band storage, its gradient (into
    ``grad``) and the friction gradient (into ``fric_grad``); the elastic band Hessian
    into ``band``, the energies (4,) into ``values``. Stiffness damping (beta > 0) is
    beta dq^T K_n dq / (2 dt) with K_n = ``stiffness`` (the elastic Hessian at q_n,
    evaluated once per solve by ``_newton_solve``, in ``band``'s layout).

    Returns (phi, rank-one c).
    """
    n2 = q.shape[0]
    phi = terms.inertia(q, q_n, v_n, dt, masses2, grad)
    c = _energies(q, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos,
                  hessian, grads, band, area_grad, values)
    for e in range(4):
        phi += values[e]
        for m in range(n2):
            grad[m] += grads[e, m]
    if not math.isfinite(phi):
        return np.inf, c
    for m in range(n2):
        dq_tmp[m] = q[m] - q_n[m]
    phi += terms.mass_damping(dq_tmp, masses2, alpha, dt, grad)
    solid = flesh[0].shape[0] > 0
    if beta > 0 and (solid or edges.shape[0] + triples.shape[0] + ring.shape[0] > 0):
        if solid:
            sparse_ldl.multiply(flesh[6], stiffness.reshape((stiffness.shape[0], 2, 2)),
                                dq_tmp, cdq)
        else:
            order = np.empty(pos.shape[0], np.int64)
            for i in range(pos.shape[0]):
                order[pos[i]] = i
            band_matvec(stiffness, order, dq_tmp, cdq)
        phi += terms.stiffness_damping(dq_tmp, cdq, beta, dt, grad)
    fric_grad[:] = 0.0
    if n_fr > 0:
        acc = 0.0
        for f in range(n_fr):
            acc += terms.friction(q, q_n, fr_nodes[f], fr_t[f:f + 1], fr_speed[f:f + 1],
                                  fr_bound[f], dt, FRICTION_SMOOTHING, fric_grad)[0]
        phi += acc
        for m in range(n2):
            grad[m] += fric_grad[m]
    if pad_nodes.shape[0] > 0:
        phi += pad_terms(q, q_n, dt, pad_nodes, pad_par, grad)
    return phi, c


@njit(cache=True, error_model='numpy')
def _pad_blocks(q, q_n, dt, pad_nodes, pad_par, filters, pos, ab):
    """Adds the pads' Hessian node blocks B (``pad.pad_blocks``), filtered (S_i B S_i), to
    the band ``ab``."""
    blocks = np.empty((pad_nodes.shape[0], 2, 2))
    pad_blocks(q, q_n, dt, pad_nodes, pad_par, blocks)
    for e in range(pad_nodes.shape[0]):
        i = pad_nodes[e]
        p = pos[i]
        for r in range(2):
            for c in range(2):
                acc = 0.0
                for m in range(2):
                    for l in range(2):
                        acc += filters[i, r, m] * blocks[e, m, l] * filters[i, l, c]
                ab[p, 0, r, c] += acc


@njit(cache=True, error_model='numpy')
def _filtered_max(filters, g):
    """max |S g| over dofs."""
    out = 0.0
    for i in range(filters.shape[0]):
        a = filters[i, 0, 0] * g[2 * i] + filters[i, 0, 1] * g[2 * i + 1]
        b = filters[i, 1, 0] * g[2 * i] + filters[i, 1, 1] * g[2 * i + 1]
        out = max(out, abs(a), abs(b))
    return out


@njit(cache=True, error_model='numpy')
def _ldl_blocks(ab):
    """In-place block LDL^T of a symmetric node-block band ab (n, nbw+1, 2, 2).

    ab[p, d] is the block (p, p - d); afterwards ab[p, 0] holds D_p^-1 and ab[p, d] the
    block L[p, p - d]. The 2x2 blocks keep four independent sums in every inner loop.
    Each row is factorised from its first non-zero block on (its envelope: L has no
    entries before it), so a mesh in reverse Cuthill-McKee order, whose rows reach back
    less far than the half-bandwidth, costs less than the full band.
    Returns False on a singular or non-finite pivot block (the reference's 'singular
    factor').
    """
    n = ab.shape[0]
    nbw = ab.shape[1] - 1
    w = np.empty((nbw + 1, 2, 2))  # w[p - k] = L[p, k] D_k of the current row
    first = np.empty(n, np.int64)  # the first non-zero block of each row
    for p in range(n):
        lo = p
        for d in range(min(p, nbw), 0, -1):
            if (ab[p, d, 0, 0] != 0.0 or ab[p, d, 0, 1] != 0.0 or ab[p, d, 1, 0] != 0.0
                    or ab[p, d, 1, 1] != 0.0):
                lo = p - d
                break
        first[p] = lo
        for j in range(lo, p):
            dj = p - j
            s00 = ab[p, dj, 0, 0]
            s01 = ab[p, dj, 0, 1]
            s10 = ab[p, dj, 1, 0]
            s11 = ab[p, dj, 1, 1]
            for k in range(max(lo, first[j]), j):
                a = p - k
                b = j - k
                # S -= W L_jk^T
                s00 -= w[a, 0, 0] * ab[j, b, 0, 0] + w[a, 0, 1] * ab[j, b, 0, 1]
                s01 -= w[a, 0, 0] * ab[j, b, 1, 0] + w[a, 0, 1] * ab[j, b, 1, 1]
                s10 -= w[a, 1, 0] * ab[j, b, 0, 0] + w[a, 1, 1] * ab[j, b, 0, 1]
                s11 -= w[a, 1, 0] * ab[j, b, 1, 0] + w[a, 1, 1] * ab[j, b, 1, 1]
            w[dj, 0, 0] = s00
            w[dj, 0, 1] = s01
            w[dj, 1, 0] = s10
            w[dj, 1, 1] = s11
            i00, i01, i10, i11 = ab[j, 0, 0, 0], ab[j, 0, 0, 1], ab[j, 0, 1, 0], ab[j, 0, 1, 1]
            ab[p, dj, 0, 0] = s00 * i00 + s01 * i10
            ab[p, dj, 0, 1] = s00 * i01 + s01 * i11
            ab[p, dj, 1, 0] = s10 * i00 + s11 * i10
            ab[p, dj, 1, 1] = s10 * i01 + s11 * i11
        d00 = ab[p, 0, 0, 0]
        d01 = ab[p, 0, 1, 0]
        d11 = ab[p, 0, 1, 1]
        for k in range(lo, p):
            a = p - k
            d00 -= w[a, 0, 0] * ab[p, a, 0, 0] + w[a, 0, 1] * ab[p, a, 0, 1]
            d01 -= w[a, 1, 0] * ab[p, a, 0, 0] + w[a, 1, 1] * ab[p, a, 0, 1]
            d11 -= w[a, 1, 0] * ab[p, a, 1, 0] + w[a, 1, 1] * ab[p, a, 1, 1]
        det = d00 * d11 - d01 * d01
        if det == 0.0 or not math.isfinite(det):
            return False
        ab[p, 0, 0, 0] = d11 / det
        ab[p, 0, 0, 1] = -d01 / det
        ab[p, 0, 1, 0] = -d01 / det
        ab[p, 0, 1, 1] = d00 / det
    return True


@njit(cache=True, error_model='numpy')
def _ldl_solve(ab, x):
    """Solve (L D L^T) y = x in place after ``_ldl_blocks``; x (2n,) in band order."""
    n = ab.shape[0]
    nbw = ab.shape[1] - 1
    for p in range(n):
        s0, s1 = x[2 * p], x[2 * p + 1]
        for k in range(max(0, p - nbw), p):
            a = p - k
            s0 -= ab[p, a, 0, 0] * x[2 * k] + ab[p, a, 0, 1] * x[2 * k + 1]
            s1 -= ab[p, a, 1, 0] * x[2 * k] + ab[p, a, 1, 1] * x[2 * k + 1]
        x[2 * p], x[2 * p + 1] = s0, s1
    for p in range(n):
        s0, s1 = x[2 * p], x[2 * p + 1]
        x[2 * p] = ab[p, 0, 0, 0] * s0 + ab[p, 0, 0, 1] * s1
        x[2 * p + 1] = ab[p, 0, 1, 0] * s0 + ab[p, 0, 1, 1] * s1
    for p in range(n - 1, -1, -1):
        s0, s1 = x[2 * p], x[2 * p + 1]
        for k in range(p + 1, min(n, p + nbw + 1)):
            a = k - p
            s0 -= ab[k, a, 0, 0] * x[2 * k] + ab[k, a, 1, 0] * x[2 * k + 1]
            s1 -= ab[k, a, 0, 1] * x[2 * k] + ab[k, a, 1, 1] * x[2 * k + 1]
        x[2 * p], x[2 * p + 1] = s0, s1


@njit(cache=True, error_model='numpy')
def _ldl_solve2(ab, x, y):
    """``_ldl_solve`` for two right-hand sides at once (x and y, in place)."""
    n = ab.shape[0]
    nbw = ab.shape[1] - 1
    for p in range(n):
        s0, s1 = x[2 * p], x[2 * p + 1]
        r0, r1 = y[2 * p], y[2 * p + 1]
        for k in range(max(0, p - nbw), p):
            a = p - k
            l00, l01, l10, l11 = ab[p, a, 0, 0], ab[p, a, 0, 1], ab[p, a, 1, 0], ab[p, a, 1, 1]
            s0 -= l00 * x[2 * k] + l01 * x[2 * k + 1]
            s1 -= l10 * x[2 * k] + l11 * x[2 * k + 1]
            r0 -= l00 * y[2 * k] + l01 * y[2 * k + 1]
            r1 -= l10 * y[2 * k] + l11 * y[2 * k + 1]
        x[2 * p], x[2 * p + 1] = s0, s1
        y[2 * p], y[2 * p + 1] = r0, r1
    for p in range(n):
        i00, i01, i10, i11 = ab[p, 0, 0, 0], ab[p, 0, 0, 1], ab[p, 0, 1, 0], ab[p, 0, 1, 1]
        s0, s1 = x[2 * p], x[2 * p + 1]
        x[2 * p] = i00 * s0 + i01 * s1
        x[2 * p + 1] = i10 * s0 + i11 * s1
        r0, r1 = y[2 * p], y[2 * p + 1]
        y[2 * p] = i00 * r0 + i01 * r1
        y[2 * p + 1] = i10 * r0 + i11 * r1
    for p in range(n - 1, -1, -1):
        s0, s1 = x[2 * p], x[2 * p + 1]
        r0, r1 = y[2 * p], y[2 * p + 1]
        for k in range(p + 1, min(n, p + nbw + 1)):
            a = k - p
            l00, l01, l10, l11 = ab[k, a, 0, 0], ab[k, a, 0, 1], ab[k, a, 1, 0], ab[k, a, 1, 1]
            s0 -= l00 * x[2 * k] + l10 * x[2 * k + 1]
            s1 -= l01 * x[2 * k] + l11 * x[2 * k + 1]
            r0 -= l00 * y[2 * k] + l10 * y[2 * k + 1]
            r1 -= l01 * y[2 * k] + l11 * y[2 * k + 1]
        x[2 * p], x[2 * p + 1] = s0, s1
        y[2 * p], y[2 * p + 1] = r0, r1


@njit(cache=True, error_model='numpy')
def _pad_rows(x_n, surface, pad_k, thickness, mu, face_par, face_dyn):
    """``pad.pad_rows`` of a step on the jaw faces of ``face_par`` / ``face_dyn`` (set for
    the step): (nodes (m,), rows (m, PAD_SIZE), face (m,))."""
    n_jaw = 0
    for f in range(face_par.shape[0]):
        if face_par[f, FP_JAW] >= 0:
            n_jaw += 1
    faces = np.empty((n_jaw, PF_SIZE))
    m = 0
    for f in range(face_par.shape[0]):
        if face_par[f, FP_JAW] < 0:
            continue
        nx, nz = face_par[f, 0], face_par[f, 1]
        faces[m, PF_OLD_X], faces[m, PF_OLD_Z] = face_dyn[f, 0], face_dyn[f, 1]
        faces[m, PF_NEW_X], faces[m, PF_NEW_Z] = face_dyn[f, 2], face_dyn[f, 3]
        faces[m, PF_NX], faces[m, PF_NZ] = nx, nz
        faces[m, PF_HALF] = face_par[f, 2]
        faces[m, PF_SPEED] = face_dyn[f, 4] * -nz + face_dyn[f, 5] * nx
        faces[m, PF_SIDE] = face_par[f, FP_JAW]
        faces[m, PF_INDEX] = f
        m += 1
    positions, rows, face = pad_rows(x_n, surface, pad_k, thickness, mu, faces)
    return surface[positions], rows, face


@njit(cache=True, error_model='numpy')
def _pad_forces(x, x_n, dt, pad_nodes, pad_par, pad_face, face_par, forces, normal, holder,
                side_force):
    """``pad.pad_forces``: the pads' forces on the fruit at the step's end positions x
    (n, 2), as ``pad.PadLayer.finish_step`` records them (outputs: see ``substep``)."""
    pad_forces(x, x_n, dt, pad_nodes, pad_par, pad_face, forces, normal, holder, side_force)


@njit(cache=True, error_model='numpy')
def _newton_matrix(band, stiffness, masses2, dt, alpha, beta, filters, fr_nodes, fr_t,
                   fr_bound, fr_speed, n_fr, q, q_n, pos, order, shift, ab, pad_nodes, pad_par):
    """Node-block band ab (n, nbw+1, 2, 2) of S H S + I - S + shift diag(S) m / dt^2.

    H = (m/dt^2 + alpha m/dt) I + C + (beta/dt) K_n + friction, C = ``band``, K_n =
    ``stiffness`` (read only with beta > 0).
    """
    n = band.shape[0]
    nbw = band.shape[1] - 1
    damping = beta / dt if beta > 0 else 0.0
    kind = _filter_kinds(filters)
    for p in range(n):
        i = order[p]
        for d in range(nbw + 1):
            if d > p:
                ab[p, d, 0, 0] = 0.0
                ab[p, d, 0, 1] = 0.0
                ab[p, d, 1, 0] = 0.0
                ab[p, d, 1, 1] = 0.0
                continue
            h00, h01, h10, h11 = _damped_block(band, stiffness, damping, p, d)
            if d == 0:
                h00 += terms.inertia_diagonal(masses2, dt, alpha, 2 * i)
                h11 += terms.inertia_diagonal(masses2, dt, alpha, 2 * i + 1)
            j = order[p - d]
            (ab[p, d, 0, 0], ab[p, d, 0, 1], ab[p, d, 1, 0],
             ab[p, d, 1, 1]) = _filtered_block(filters, kind[i], kind[j], i, j, h00, h01, h10,
                                               h11)
    _friction_blocks(q, q_n, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, n_fr, pos, ab)
    _pad_blocks(q, q_n, dt, pad_nodes, pad_par, filters, pos, ab)
    _held_diagonal(filters, masses2, dt, shift, pos, ab)


@njit(cache=True, error_model='numpy')
def _filter_kinds(filters):
    """(n,) int64, each node's contact filter: 0 S = 0, 1 S = I, 2 other."""
    n = filters.shape[0]
    kind = np.empty(n, np.int64)
    for i in range(n):
        f00, f01, f10, f11 = filters[i, 0, 0], filters[i, 0, 1], filters[i, 1, 0], filters[
            i, 1, 1]
        if f00 == 0.0 and f01 == 0.0 and f10 == 0.0 and f11 == 0.0:
            kind[i] = 0
        elif f00 == 1.0 and f01 == 0.0 and f10 == 0.0 and f11 == 1.0:
            kind[i] = 1
        else:
            kind[i] = 2
    return kind


@njit(cache=True, error_model='numpy')
def _filtered_block(filters, kind_i, kind_j, i, j, h00, h01, h10, h11):
    """S_i H S_j (4 values, row-major) of the node block H = [[h00, h01], [h10, h11]] of
    rows i and columns j (kind_i, kind_j: their ``_filter_kinds``)."""
    if kind_i == 0 or kind_j == 0:
        return 0.0, 0.0, 0.0, 0.0
    if kind_i == 1 and kind_j == 1:
        return h00, h01, h10, h11
    t00 = filters[i, 0, 0] * h00 + filters[i, 0, 1] * h10
    t01 = filters[i, 0, 0] * h01 + filters[i, 0, 1] * h11
    t10 = filters[i, 1, 0] * h00 + filters[i, 1, 1] * h10
    t11 = filters[i, 1, 0] * h01 + filters[i, 1, 1] * h11
    return (t00 * filters[j, 0, 0] + t01 * filters[j, 1, 0],
            t00 * filters[j, 0, 1] + t01 * filters[j, 1, 1],
            t10 * filters[j, 0, 0] + t11 * filters[j, 1, 0],
            t10 * filters[j, 0, 1] + t11 * filters[j, 1, 1])


@njit(cache=True, error_model='numpy')
def _friction_blocks(q, q_n, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, n_fr, pos, ab):
    """Adds the kinetic friction's node blocks S_k (g t t^T) S_k to the diagonal blocks
    ab[pos[k], 0] (``potential_terms``: one tangent t per node)."""
    for f in range(n_fr):
        k = fr_nodes[f]
        s, _ = terms.slip(q, q_n, k, fr_t[f:f + 1], fr_speed[f:f + 1], dt)
        root = math.sqrt(s ** 2 + FRICTION_SMOOTHING ** 2)
        g = terms.one_tangent_curvature(root, fr_bound[f], dt, FRICTION_SMOOTHING)
        tx, tz = fr_t[f, 0], fr_t[f, 1]
        ux = filters[k, 0, 0] * tx + filters[k, 0, 1] * tz  # S t
        uz = filters[k, 1, 0] * tx + filters[k, 1, 1] * tz
        vx = tx * filters[k, 0, 0] + tz * filters[k, 1, 0]  # S^T t
        vz = tx * filters[k, 0, 1] + tz * filters[k, 1, 1]
        p = pos[k]
        ab[p, 0, 0, 0] += g * ux * vx
        ab[p, 0, 0, 1] += g * ux * vz
        ab[p, 0, 1, 0] += g * uz * vx
        ab[p, 0, 1, 1] += g * uz * vz


@njit(cache=True, error_model='numpy')
def _held_diagonal(filters, masses2, dt, shift, pos, ab):
    """Adds I - S + shift diag(S) m / dt^2 to the diagonal blocks ab[pos[i], 0]."""
    for i in range(filters.shape[0]):
        p = pos[i]
        ab[p, 0, 0, 0] += 1.0 - filters[i, 0, 0] + shift * filters[i, 0, 0] * masses2[
            2 * i] / dt ** 2
        ab[p, 0, 0, 1] += 0.0 - filters[i, 0, 1]
        ab[p, 0, 1, 0] += 0.0 - filters[i, 1, 0]
        ab[p, 0, 1, 1] += 1.0 - filters[i, 1, 1] + shift * filters[i, 1, 1] * masses2[
            2 * i + 1] / dt ** 2


# ---------------------------------------------------------------------- the solid's matrix
# A meshed solid's Newton matrix is sparse (``core.sparse_ldl``, 2 x 2 node blocks in a
# minimum-degree order): ``flesh[6]`` holds its pattern (``SparsePattern.arrays``), the
# Hessian C and the Newton matrix are its values (n_blocks + 1, 1, 2, 2) (the band's
# layout with one block per row: the diagonal block of node i at pos[i], 0), assembled
# through the element scatter maps of ``flesh[4]`` and ``flesh[5]``.
@njit(cache=True, error_model='numpy')
def _solid_energies(q, edges, triples, flesh, gravity_grad, hessian, grads, hvals, values):
    """``_energies`` of a meshed solid (skin stretching and bending, the flesh, gravity)
    with the elastic Hessian into the sparse values ``hvals``. Returns the rank-one c (0)."""
    x = q.reshape((q.shape[0] // 2, 2))
    flat = hvals.reshape(hvals.size)
    if hessian:
        for m in range(flat.shape[0]):
            flat[m] = 0.0
    for e in range(3):
        for m in range(q.shape[0]):
            grads[e, m] = 0.0
    rest, k_stretch, s_scatter, phi0, k_bend, b_scatter = flesh[5]
    values[0] = stretching(x, edges, rest, k_stretch, grads[0], flat, s_scatter, hessian)
    values[1] = bending(x, triples, phi0, k_bend, grads[1], flat, b_scatter, hessian)
    values[2] = neohookean_triangles(x, flesh[0], flesh[1], flesh[2], flesh[3][0],
                                     flesh[3][1], grads[2], flat, flesh[4], hessian)
    vg = 0.0
    for m in range(q.shape[0]):
        vg += gravity_grad[m] * q[m]
        grads[3, m] = gravity_grad[m]
    values[3] = vg
    return 0.0


@njit(cache=True, error_model='numpy')
def _solid_newton_matrix(hvals, stiffness, masses2, dt, alpha, beta, filters, fr_nodes, fr_t,
                         fr_bound, fr_speed, n_fr, q, q_n, pos, arrays, shift, ab, pad_nodes,
                         pad_par):
    """``_newton_matrix`` on the solid's sparse values: ab (n_blocks + 1, 1, 2, 2) from
    the elastic Hessian hvals and K_n ``stiffness`` (same layout)."""
    order, a_ptr, a_col = arrays[0], arrays[2], arrays[3]
    n = order.shape[0]
    damping = beta / dt if beta > 0 else 0.0
    kind = _filter_kinds(filters)
    for k in range(n):
        i = order[k]
        h00, h01, h10, h11 = _damped_block(hvals, stiffness, damping, k, 0)
        (ab[k, 0, 0, 0], ab[k, 0, 0, 1], ab[k, 0, 1, 0],
         ab[k, 0, 1, 1]) = _filtered_block(filters, kind[i], kind[i], i, i,
                                           h00 + terms.inertia_diagonal(masses2, dt, alpha, 2 * i),
                                           h01, h10,
                                           h11 + terms.inertia_diagonal(masses2, dt, alpha,
                                                                        2 * i + 1))
        for m in range(a_ptr[k], a_ptr[k + 1]):
            b = n + m
            j = order[a_col[m]]
            h00, h01, h10, h11 = _damped_block(hvals, stiffness, damping, b, 0)
            (ab[b, 0, 0, 0], ab[b, 0, 0, 1], ab[b, 0, 1, 0],
             ab[b, 0, 1, 1]) = _filtered_block(filters, kind[i], kind[j], i, j, h00, h01, h10,
                                               h11)
    _friction_blocks(q, q_n, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, n_fr, pos, ab)
    _pad_blocks(q, q_n, dt, pad_nodes, pad_par, filters, pos, ab)
    _held_diagonal(filters, masses2, dt, shift, pos, ab)


@njit(cache=True, error_model='numpy', inline='always')
def _damped_block(hessian, stiffness, damping, p, d):
    """The node block [p, d] of C + damping K_n (4 values, row-major), C = ``hessian`` and
    K_n = ``stiffness`` in one layout (the band (n, nbw+1, 2, 2), or the solid's sparse
    values (n_blocks + 1, 1, 2, 2) with d = 0); K_n read only with damping > 0."""
    h00, h01 = hessian[p, d, 0, 0], hessian[p, d, 0, 1]
    h10, h11 = hessian[p, d, 1, 0], hessian[p, d, 1, 1]
    if damping > 0:
        h00 += damping * stiffness[p, d, 0, 0]
        h01 += damping * stiffness[p, d, 0, 1]
        h10 += damping * stiffness[p, d, 1, 0]
        h11 += damping * stiffness[p, d, 1, 1]
    return h00, h01, h10, h11


@njit(cache=True, error_model='numpy')
def _newton_storage(n, nbw, flesh):
    """The Hessian and Newton matrix arrays of ``newton_solve``: (C, A, L's blocks, D^-1,
    K_n): the node-block band (n, nbw+1, 2, 2) twice, or a meshed solid's sparse values
    (n_blocks + 1, 1, 2, 2) twice and its factor (n_factor, 2, 2), (n, 2, 2); then the
    step's stiffness K_n in C's layout (the stiffness damping's, ``_newton_solve``)."""
    if flesh[0].shape[0] == 0:
        return (np.zeros((n, nbw + 1, 2, 2)), np.empty((n, nbw + 1, 2, 2)),
                np.empty((0, 2, 2)), np.empty((0, 2, 2)), np.zeros((n, nbw + 1, 2, 2)))
    arrays = flesh[6]
    rows = n + arrays[3].shape[0] + 1
    return (np.zeros((rows, 1, 2, 2)), np.empty((rows, 1, 2, 2)),
            np.empty((arrays[5].shape[0], 2, 2)), np.empty((n, 2, 2)),
            np.zeros((rows, 1, 2, 2)))


@njit(cache=True, error_model='numpy')
def _newton_factor(band, stiffness, masses2, dt, alpha, beta, filters, fr_nodes, fr_t,
                   fr_bound, fr_speed, n_fr, q, q_n, pos, order, shift, ab, pad_nodes, pad_par,
                   flesh, l_values, d_inv):
    """The Newton matrix (``_newton_matrix``) factorised: the band's block LDL^T in ab,
    or a meshed solid's sparse LDL^T in (l_values, d_inv). False if singular."""
    if flesh[0].shape[0] == 0:
        _newton_matrix(band, stiffness, masses2, dt, alpha, beta, filters, fr_nodes, fr_t,
                       fr_bound, fr_speed, n_fr, q, q_n, pos, order, shift, ab, pad_nodes,
                       pad_par)
        return _ldl_blocks(ab)
    _solid_newton_matrix(band, stiffness, masses2, dt, alpha, beta, filters, fr_nodes, fr_t,
                         fr_bound, fr_speed, n_fr, q, q_n, pos, flesh[6], shift, ab, pad_nodes,
                         pad_par)
    return sparse_ldl.factor(flesh[6], ab.reshape((ab.shape[0], 2, 2)), l_values, d_inv) >= 0


@njit(cache=True, error_model='numpy')
def _newton_inverse(ab, l_values, d_inv, flesh, x, y, two):
    """x (and y when ``two``) <- A^-1 in place after ``_newton_factor``, in band
    positions (pos)."""
    if flesh[0].shape[0] == 0:
        if two:
            _ldl_solve2(ab, x, y)
        else:
            _ldl_solve(ab, x)
        return
    sparse_ldl.solve(flesh[6], l_values, d_inv, x)
    if two:
        sparse_ldl.solve(flesh[6], l_values, d_inv, y)


@njit(cache=True, error_model='numpy')
def newton_scratch(n, nbw, flesh):
    """The scratch space of ``_newton_solve`` for n nodes, allocated once and reused by
    every solve: (order (n,) int64 - the node at each band position, to be filled from
    ``pos`` (``band_order_inverse``) -, the Newton storage (``_newton_storage``), work
    (NEWTON_WORK * 2n,) float64)."""
    work = np.empty(NEWTON_WORK * 2 * n + KEPT_PER_NODE * n + KEPT_META)
    work[-KEPT_META + K_VALID] = 0.0  # no factor kept yet
    return np.empty(n, np.int64), _newton_storage(n, nbw, flesh), work


@njit(cache=True, error_model='numpy')
def band_order_inverse(pos, order):
    """order[pos[i]] = i: the node at each band position."""
    for i in range(pos.shape[0]):
        order[pos[i]] = i


@njit(cache=True, error_model='numpy')
def newton_solve(q_n, v_n, dt, q_start, filters, fr_nodes, fr_t, fr_bound, fr_speed,
                 masses2, alpha, beta, tol, max_it, edges, spar, triples, bpar, ring, press, flesh,
                 gravity_grad, pos, nbw, q_out, reaction_out, history, values, counts,
                 pad_nodes, pad_par):
    """``_newton_solve`` with scratch space of its own (see there for the arguments)."""
    order, storage, work = newton_scratch(pos.shape[0], nbw, flesh)
    band_order_inverse(pos, order)
    return _newton_solve(q_n, v_n, dt, q_start, filters, fr_nodes, fr_t, fr_bound, fr_speed,
                         masses2, alpha, beta, tol, max_it, edges, spar, triples, bpar, ring,
                         press, flesh, gravity_grad, pos, q_out, reaction_out, history, values,
                         counts, pad_nodes, pad_par, order, storage, work)


#: float vectors of 2n in ``_newton_solve``'s work array: grads (4 of them), grad, grad_t,
#: fric_grad, area_grad, tmp, cdq, g_f, dq, x, y, u, trial; after them the kept factor
#: (``_kept_key``): KEPT_PER_NODE floats a node and KEPT_META more
NEWTON_WORK = 16
KEPT_PER_NODE = 8
#: the kept factor's metadata: valid (1.0 or 0.0), the step dt (s) it was made for, the
#: solves it has served, its kinetic friction nodes and soft pad rows (counts), its
#: rank-one coefficient c; then the rank-one c of the last evaluation
K_VALID, K_DT, K_AGE, K_FRICTION, K_PADS, K_C, K_LAST_C, KEPT_META = range(8)


@njit(cache=True, error_model='numpy')
def _kept_key(kept, n):
    """The kept factor's record in the tail of ``_newton_solve``'s work array: (filters
    (n, 2, 2) it was made with, friction mask (n,) and pad mask (n,) 1.0 at its kinetic
    friction nodes and soft pad rows' nodes, its rank-one direction S u (2n,),
    metadata (KEPT_META,))."""
    return (kept[:4 * n].reshape((n, 2, 2)), kept[4 * n:5 * n], kept[5 * n:6 * n],
            kept[6 * n:8 * n], kept[8 * n:8 * n + KEPT_META])


@njit(cache=True, error_model='numpy')
def forget_kept(work):
    """Drops the factor ``_newton_solve`` keeps in ``work`` (its work array, or
    ``substep``'s, whose tail it is): the next solve makes it afresh."""
    work[work.shape[0] - KEPT_META + K_VALID] = 0.0


@njit(cache=True, error_model='numpy')
def _kept_fits(kept, filters, fr_nodes, dt, pad_nodes):
    """Whether the kept factor was made for this step's constraints: the same filters S,
    kinetic friction nodes, soft pad rows and dt, and is younger than MAX_FACTOR_AGE solves."""
    n = filters.shape[0]
    key_filters, fr_mask, pad_mask, _, meta = _kept_key(kept, n)
    if (meta[K_VALID] == 0.0 or meta[K_DT] != dt or meta[K_AGE] >= MAX_FACTOR_AGE
            or meta[K_FRICTION] != fr_nodes.shape[0] or meta[K_PADS] != pad_nodes.shape[0]):
        return False
    for f in range(fr_nodes.shape[0]):
        if fr_mask[fr_nodes[f]] == 0.0:
            return False
    for e in range(pad_nodes.shape[0]):
        if pad_mask[pad_nodes[e]] == 0.0:
            return False
    for i in range(n):
        for a in range(2):
            for b in range(2):
                if key_filters[i, a, b] != filters[i, a, b]:
                    return False
    return True


@njit(cache=True, error_model='numpy')
def _keep(kept, filters, fr_nodes, dt, pad_nodes, u, c):
    """Records the constraints of a factor just made (see ``_kept_fits``) and its
    rank-one term c S u S (u (2n,) filtered)."""
    n = filters.shape[0]
    key_filters, fr_mask, pad_mask, kept_u, meta = _kept_key(kept, n)
    key_filters[:] = filters
    fr_mask[:] = 0.0
    for f in range(fr_nodes.shape[0]):
        fr_mask[fr_nodes[f]] = 1.0
    pad_mask[:] = 0.0
    for e in range(pad_nodes.shape[0]):
        pad_mask[pad_nodes[e]] = 1.0
    kept_u[:] = u
    meta[K_VALID] = 1.0
    meta[K_DT] = dt
    meta[K_AGE] = 0.0
    meta[K_FRICTION] = fr_nodes.shape[0]
    meta[K_PADS] = pad_nodes.shape[0]
    meta[K_C] = c


@njit(cache=True, error_model='numpy')
def _direction(ab, l_values, d_inv, flesh, pos, g_f, u, c, x, y, dq):
    """The step dq (2n,) = -(A + c u u^T)^-1 S g: A factorised (``_newton_factor``), the
    pressure's rank-one term c u u^T (u = S dA/dq) by Sherman-Morrison. Returns (finite,
    slope S g . dq)."""
    n = pos.shape[0]
    n2 = 2 * n
    for i in range(n):
        p = pos[i]
        x[2 * p] = -g_f[2 * i]
        x[2 * p + 1] = -g_f[2 * i + 1]
    if c == 0.0:
        _newton_inverse(ab, l_values, d_inv, flesh, x, y, False)
    else:
        for i in range(n):
            p = pos[i]
            y[2 * p] = u[2 * i]
            y[2 * p + 1] = u[2 * i + 1]
        _newton_inverse(ab, l_values, d_inv, flesh, x, y, True)
        ux = 0.0
        uy = 0.0
        for i in range(n):
            p = pos[i]
            ux += u[2 * i] * x[2 * p] + u[2 * i + 1] * x[2 * p + 1]
            uy += u[2 * i] * y[2 * p] + u[2 * i + 1] * y[2 * p + 1]
        w = ux / (1.0 / c + uy)
        for m in range(n2):
            x[m] -= y[m] * w
    finite = True
    slope = 0.0
    for i in range(n):
        p = pos[i]
        dq[2 * i] = x[2 * p]
        dq[2 * i + 1] = x[2 * p + 1]
    for m in range(n2):
        if not math.isfinite(dq[m]):
            finite = False
        slope += g_f[m] * dq[m]
    return finite, slope


@njit(cache=True, error_model='numpy')
def _newton_solve(q_n, v_n, dt, q_start, filters, fr_nodes, fr_t, fr_bound, fr_speed,
                  masses2, alpha, beta, tol, max_it, edges, spar, triples, bpar, ring, press,
                  flesh, gravity_grad, pos, q_out, reaction_out, history, values, counts,
                  pad_nodes, pad_par, order, storage, work):
    """One implicit Euler step by Newton: ``newton.newton_iteration`` on the ring's block
    band or the solid's sparse block LDL^T (its hooks: the overloads below).

    The kept matrix is the factorised Newton matrix with its rank-one pressure term; it
    fits (``_kept_fits``) under the same constraints and dt.

    Args:
        q_n, v_n: (2n,) m and m/s at the start of the step.  dt: s.
        q_start: (2n,) m, constrained dofs at their targets.
        filters: (n, 2, 2) S_i (must be symmetric).
        fr_nodes (k,), fr_t (k, 2), fr_bound (k,) N, fr_speed (k,) m/s: kinetic friction.
        masses2: (2n,) kg per dof.  alpha (1/s), beta (s): Rayleigh damping.
        tol: m/s.  max_it: iterations.
        edges, spar, triples, bpar, ring, press: the energies (see ring_*); flesh: the
            neo-Hookean triangles (see ``_energies``).
        gravity_grad: (2n,) N, the constant gradient of gravity.
        pos: (n,) band positions.
        q_out, reaction_out: (2n,) outputs. history: (max_it,) output, m/s.
        values: (4,) output, J: stretching, bending, pressure and gravity at q_out.
        counts: (C_SIZE,) int64, work counters added to (see C_*).
        pad_nodes: (m,) int64 nodes, pad_par: (m, PAD_SIZE) the soft pads' rows (m = 0:
            no pads).
        With beta > 0 the elastic Hessian at q_n (K_n of the stiffness damping) is
        evaluated once, into ``storage[4]``.
        order, storage, work: scratch space (``newton_scratch``; order filled from pos);
            reused from solve to solve, no allocation here; storage and the tail of
            work hold the kept factor and its key.

    Returns:
        (status, iterations, len(history)); status OK or a failure code.
    """
    n2 = q_n.shape[0]
    n = n2 // 2
    for i in range(n):
        if filters[i, 0, 1] != filters[i, 1, 0]:
            return UNSUPPORTED, 0, 0
    work[7 * n2:8 * n2] = 0.0  # area_grad: only a ring's pressure writes it
    if beta > 0:
        vectors = _work_vectors(work, n2)
        grads, area_grad = vectors[0], vectors[4]
        _energies(q_n, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, True,
                  grads, storage[4], area_grad, values)
    q_out[:] = q_start
    problem = (q_n, v_n, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, masses2, alpha, beta,
               edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, reaction_out,
               values, pad_nodes, pad_par, order, storage, work)
    return newton.newton_iteration(problem, q_out, dt, tol, max_it, history, counts)


# The hooks of ``newton.newton_iteration`` for ``_newton_solve``'s problem tuple. Its
# work array holds (``NEWTON_WORK`` vectors of 2n) grads (4 of them), grad, grad_t,
# fric_grad, area_grad, tmp, cdq, g_f, dq, x, y, u, trial; then the kept factor.
@njit(cache=True, error_model='numpy', inline='always')
def _work_vectors(work, n2):
    """(grads (4, 2n), grad, grad_t, fric_grad, area_grad, tmp, cdq, g_f, dq, x, y, u,
    trial, kept) of the work array."""
    return (work[:4 * n2].reshape((4, n2)), work[4 * n2:5 * n2], work[5 * n2:6 * n2],
            work[6 * n2:7 * n2], work[7 * n2:8 * n2], work[8 * n2:9 * n2],
            work[9 * n2:10 * n2], work[10 * n2:11 * n2], work[11 * n2:12 * n2],
            work[12 * n2:13 * n2], work[13 * n2:14 * n2], work[14 * n2:15 * n2],
            work[15 * n2:16 * n2], work[16 * n2:])


def _is_problem(problem):
    return isinstance(problem, types.BaseTuple)


@overload(newton.vectors, jit_options=dict(error_model='numpy'), inline='always')
def _vectors(problem):
    if _is_problem(problem):
        def impl(problem):
            work = problem[26]
            n2 = problem[0].shape[0]
            (_, grad, grad_t, _, _, _, _, g_f, dq, _, _, _, trial,
             _) = _work_vectors(work, n2)
            return grad, grad_t, g_f, dq, trial
        return impl


@overload(newton.kept_fits, jit_options=dict(error_model='numpy'), inline='always')
def _kept_fits_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            dt, filters, fr_nodes, pad_nodes, work = (problem[2], problem[3], problem[4],
                                                      problem[22], problem[26])
            n = filters.shape[0]
            kept = work[16 * 2 * n:]
            fits = _kept_fits(kept, filters, fr_nodes, dt, pad_nodes)
            if fits:
                meta = _kept_key(kept, n)[4]
                meta[K_AGE] += 1.0
            return fits
        return impl


@overload(newton.evaluate, jit_options=dict(error_model='numpy'), inline='always')
def _evaluate_hook(problem, x, hessian, grad):
    if _is_problem(problem):
        def impl(problem, x, hessian, grad):
            (q_n, v_n, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, masses2, alpha, beta,
             edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, _, values,
             pad_nodes, pad_par, _, storage, work) = problem
            n2 = q_n.shape[0]
            (grads, _, _, fric_grad, area_grad, tmp, cdq, _, _, _, _, _, _,
             kept) = _work_vectors(work, n2)
            phi, c = _evaluate(x, q_n, v_n, dt, masses2, alpha, beta, filters, fr_nodes, fr_t,
                               fr_bound, fr_speed, fr_nodes.shape[0], edges, spar, triples,
                               bpar, ring, press, flesh, gravity_grad, pos, hessian, grad,
                               fric_grad, grads, storage[0], storage[4], area_grad, tmp, cdq,
                               values, pad_nodes, pad_par)
            _kept_key(kept, n2 // 2)[4][K_LAST_C] = c
            return phi
        return impl


@overload(newton.project, jit_options=dict(error_model='numpy'), inline='always')
def _project_hook(problem, grad, g_f):
    if _is_problem(problem):
        def impl(problem, grad, g_f):
            filters, work = problem[3], problem[26]
            n = filters.shape[0]
            (_, _, _, _, area_grad, _, _, _, _, _, _, u, _,
             _) = _work_vectors(work, 2 * n)
            for i in range(n):
                for a in range(2):
                    g_f[2 * i + a] = (filters[i, a, 0] * grad[2 * i]
                                      + filters[i, a, 1] * grad[2 * i + 1])
                    u[2 * i + a] = (filters[i, a, 0] * area_grad[2 * i]
                                    + filters[i, a, 1] * area_grad[2 * i + 1])
        return impl


@overload(newton.forget, jit_options=dict(error_model='numpy'), inline='always')
def _forget_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            forget_kept(problem[26])
        return impl


@overload(newton.keep, jit_options=dict(error_model='numpy'), inline='always')
def _keep_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            dt, filters, fr_nodes, pad_nodes, work = (problem[2], problem[3], problem[4],
                                                      problem[22], problem[26])
            n = filters.shape[0]
            (_, _, _, _, _, _, _, _, _, _, _, u, _, kept) = _work_vectors(work, 2 * n)
            meta = _kept_key(kept, n)[4]
            _keep(kept, filters, fr_nodes, dt, pad_nodes, u, meta[K_LAST_C])
        return impl


@overload(newton.factorise, jit_options=dict(error_model='numpy'), inline='always')
def _factorise_hook(problem, x, shift):
    if _is_problem(problem):
        def impl(problem, x, shift):
            (q_n, _, dt, filters, fr_nodes, fr_t, fr_bound, fr_speed, masses2, alpha, beta,
             _, _, _, _, _, _, flesh, _, pos, _, _, pad_nodes, pad_par, order, storage,
             _) = problem
            band, ab, l_values, d_inv, stiffness = storage
            return _newton_factor(band, stiffness, masses2, dt, alpha, beta, filters, fr_nodes,
                                  fr_t, fr_bound, fr_speed, fr_nodes.shape[0], x, q_n, pos,
                                  order, shift, ab, pad_nodes, pad_par, flesh, l_values, d_inv)
        return impl


@overload(newton.direction, jit_options=dict(error_model='numpy'), inline='always')
def _direction_hook(problem, g_f, dq, fresh):
    if _is_problem(problem):
        def impl(problem, g_f, dq, fresh):
            flesh, pos, storage, work = problem[17], problem[19], problem[25], problem[26]
            n = pos.shape[0]
            (_, _, _, _, _, _, _, _, _, x, y, u, _, kept) = _work_vectors(work, 2 * n)
            _, ab, l_values, d_inv, _ = storage
            _, _, _, kept_u, meta = _kept_key(kept, n)
            if fresh:
                return _direction(ab, l_values, d_inv, flesh, pos, g_f, u, meta[K_LAST_C], x,
                                  y, dq)
            return _direction(ab, l_values, d_inv, flesh, pos, g_f, kept_u, meta[K_C], x, y,
                              dq)
        return impl


@overload(newton.definite, jit_options=dict(error_model='numpy'), inline='always')
def _definite_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return True  # the inertia is not counted: a descending direction is taken
        return impl


@overload(newton.step_bound, jit_options=dict(error_model='numpy'), inline='always')
def _step_bound_hook(problem, x, dq):
    if _is_problem(problem):
        def impl(problem, x, dq):
            return 1.0
        return impl


@overload(newton.keep_limit, jit_options=dict(error_model='numpy'), inline='always')
def _keep_limit_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return np.inf
        return impl


@overload(newton.filtered_max, jit_options=dict(error_model='numpy'), inline='always')
def _filtered_max_hook(problem, g):
    if _is_problem(problem):
        def impl(problem, g):
            return _filtered_max(problem[3], g)
        return impl


@overload(newton.finish, jit_options=dict(error_model='numpy'), inline='always')
def _finish_hook(problem, x, grad):
    if _is_problem(problem):
        def impl(problem, x, grad):
            reaction_out, work = problem[20], problem[26]
            n2 = x.shape[0]
            fric_grad = _work_vectors(work, n2)[3]
            for m in range(n2):
                reaction_out[m] = grad[m] - fric_grad[m]
        return impl


# The hooks of ``contact_passes.contact_passes`` for ``substep``'s problem tuple: the
# constraint arrays are views of substep's work array, the solve is ``_newton_solve``.
# Not inlined (a call each per pass): inlined, next to the inlined contact kernels, numba
# 0.68 compiled ``contact_kernels.update`` wrongly (its ``release`` wrote nothing).
@overload(contact_passes.pass_arrays, jit_options=dict(error_model='numpy'))
def _pass_arrays_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return problem[3], problem[4], problem[5], problem[6], problem[8], problem[9]
        return impl


@overload(contact_passes.solve, jit_options=dict(error_model='numpy'))
def _solve_hook(problem, start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed, k):
    if _is_problem(problem):
        def impl(problem, start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed, k):
            (q_n, v_flat, dt, _, _, _, _, fr_t, _, _, fr_speed_flat, masses2, alpha, beta, tol,
             max_it, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, q,
             reaction, history, values, counts, pad_nodes, pad_par, order, storage,
             newton_work, out) = problem
            status, its, n_hist = _newton_solve(
                q_n, v_flat, dt, start.reshape(q_n.shape[0]), filters, fr_nodes[:k],
                fr_t[:k], fr_bound[:k], fr_speed_flat[:k], masses2, alpha, beta, tol, max_it,
                edges, spar, triples, bpar, ring, press, flesh, gravity_grad, pos, q,
                reaction, history, values, counts, pad_nodes, pad_par, order, storage,
                newton_work)
            out[1] = n_hist
            return status, its
        return impl


@overload(contact_passes.solution, jit_options=dict(error_model='numpy'))
def _solution_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            q, reaction = problem[25], problem[26]
            n = q.shape[0] // 2
            return q.reshape((n, 2)), reaction.reshape((n, 2))
        return impl


# ---------------------------------------------------------------------- contact
@njit(cache=True, error_model='numpy')
def contact_faces(face_par, face_dyn):
    """The faces of the step as the contact passes take them (the ``faces`` tuple of
    ``contact_kernels``) from the rows of ``face_par`` and ``face_dyn`` (module doc)."""
    n_faces = face_par.shape[0]
    normal = np.empty((n_faces, 2))
    tangents = np.empty((n_faces, 1, 2))
    half_extents = np.empty((n_faces, 1))
    props = np.empty((n_faces, 4))
    origin_start = np.empty((n_faces, 2))
    origin_end = np.empty((n_faces, 2))
    velocity = np.empty((n_faces, 2))
    for f in range(n_faces):
        nx, nz = face_par[f, 0], face_par[f, 1]
        normal[f, 0], normal[f, 1] = nx, nz
        tangents[f, 0, 0], tangents[f, 0, 1] = -nz, nx
        half_extents[f, 0] = face_par[f, 2]
        for c in range(4):  # thickness, static and kinetic friction, restitution
            props[f, c] = face_par[f, 3 + c]
        for c in range(2):
            origin_start[f, c] = face_dyn[f, c]
            origin_end[f, c] = face_dyn[f, 2 + c]
            velocity[f, c] = face_dyn[f, 4 + c]
    return normal, tangents, half_extents, props, origin_start, origin_end, velocity


#: float scratch of ``substep`` besides the Newton solve's: SUBSTEP_WORK per node (x_pred,
#: start, filters, friction rows, q, reaction) and SUBSTEP_WORK_EXTRA (energies, jaw
#: origins)
SUBSTEP_WORK, SUBSTEP_WORK_EXTRA = 16, 8


@njit(cache=True, error_model='numpy')
def substep_scratch(pos, nbw, flesh):
    """The scratch space of ``substep`` for the fruit of band positions ``pos`` (n,),
    allocated once: (work float64, iwork int64, bwork bool, Newton storage, stress
    (n_tri,) float64)."""
    n = pos.shape[0]
    order, storage, newton_work = newton_scratch(n, nbw, flesh)
    work = np.empty(SUBSTEP_WORK * n + SUBSTEP_WORK_EXTRA + newton_work.shape[0])
    work[SUBSTEP_WORK * n + SUBSTEP_WORK_EXTRA:] = newton_work
    iwork = np.empty(2 * n, np.int64)
    band_order_inverse(pos, iwork[:n])
    return work, iwork, np.empty(2 * n, np.bool_), storage, np.empty(flesh[0].shape[0])


#: slots of the fruit's constant arrays packed for ``substep`` (``pack_constants``): the
#: float arrays, then the int64 ones; the flesh's as in ``fast._solid_model`` (its skin's
#: arrays, ``fast._solid_skin``, and its pattern's nine ``SparsePattern.arrays``)
(KF_MASSES2, KF_MASSES, KF_REST_SEGMENTS, KF_SPAR, KF_BPAR, KF_PRESS, KF_GRAVITY, KF_DM_INV,
 KF_VOLUME, KF_LAME, KF_SKIN_REST, KF_SKIN_STRETCH, KF_SKIN_PHI0, KF_SKIN_BEND,
 KI_SURFACE, KI_SKIN_EDGES, KI_POS, KI_EDGES, KI_TRIPLES, KI_RING, KI_TRI, KI_TRI_SCATTER,
 KI_SKIN_S_SCATTER, KI_SKIN_B_SCATTER, KI_PATTERN) = range(25)
K_SLOTS = KI_PATTERN + 9


def pack_constants(floats: list, ints: list) -> tuple:
    """The fruit's constant arrays as ``substep`` takes them: one float64 array, one int64
    array and their layout (K_SLOTS, 4) int64 [offset, shape...] per slot (floats in the
    KF_* order, then ints in the KI_* order; up to three dimensions each). One call of a
    kernel with ~40 array arguments fewer: numba's dispatch costs ~0.1 us per array."""
    arrays = list(floats) + list(ints)
    if len(arrays) != K_SLOTS:
        raise ValueError(f'{len(arrays)} arrays to pack, {K_SLOTS} slots')
    layout = np.zeros((K_SLOTS, 4), np.int64)
    offsets = [0, 0]
    for k, array in enumerate(arrays):
        kind = 0 if k < len(floats) else 1
        layout[k, 0] = offsets[kind]
        layout[k, 1:1 + array.ndim] = array.shape
        offsets[kind] += array.size
    pieces = ([np.ravel(a) for a in floats] or [np.zeros(0)],
              [np.ravel(a) for a in ints] or [np.zeros(0, np.int64)])
    return (np.concatenate(pieces[0]).astype(np.float64),
            np.concatenate(pieces[1]).astype(np.int64), layout)


@njit(cache=True, error_model='numpy', inline='always')
def _packed1(flat, layout, k):
    """Slot k of a ``pack_constants`` array: a 1-D view."""
    start = layout[k, 0]
    return flat[start:start + layout[k, 1]]


@njit(cache=True, error_model='numpy', inline='always')
def _packed2(flat, layout, k):
    """Slot k of a ``pack_constants`` array: a 2-D view."""
    start = layout[k, 0]
    return flat[start:start + layout[k, 1] * layout[k, 2]].reshape((layout[k, 1], layout[k, 2]))


@njit(cache=True, error_model='numpy', inline='always')
def _packed3(flat, layout, k):
    """Slot k of a ``pack_constants`` array: a 3-D view."""
    start = layout[k, 0]
    size = layout[k, 1] * layout[k, 2] * layout[k, 3]
    return flat[start:start + size].reshape((layout[k, 1], layout[k, 2], layout[k, 3]))


@intrinsic
def borrowed(typingctx, array):
    """A view of ``array`` that numba does not reference-count (no meminfo), nor the
    views and slices taken of it: for arrays the caller keeps alive for the whole call
    (a kernel's arguments). Each count is an atomic increment and decrement of the
    array's shared count (~10-20 ns); a step of ``substep`` took ~1,500 of them, from
    the views of its scratch and constant arrays and the arguments of its calls."""
    if not isinstance(array, types.Array):
        return None

    def codegen(context, builder, signature, args):
        source = context.make_array(array)(context, builder, value=args[0])
        view = context.make_array(array)(context, builder)
        for name in ('nitems', 'itemsize', 'data', 'shape', 'strides'):
            setattr(view, name, getattr(source, name))
        view.meminfo = cgutils.get_null_value(view.meminfo.type)
        view.parent = cgutils.get_null_value(view.parent.type)
        return view._getvalue()
    return array(array), codegen


@njit(cache=True, error_model='numpy')
def substep(x_n, v_n, obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce,
            face_par, face_dyn, grip, fconst, iconst, layout, fpar, ipar, x_out,
            v_out, forces_out, history, out, normal_out, pressure_out, meas_out, counts, d_face,
            d_rest, d_par, covered_in, covered_out, d_pressure, patches, d_out, pad_k, pad_scalars,
            pad_forces, pad_normal, pad_holder, pad_side, work, iwork, bwork, storage,
            stress):
    """One implicit Euler step with predictor-corrector contact, as
    ``contact_passes.contact_step``, and the measures of its end state, as
    ``Simulation._measure`` (``step_measures``).

    Args:
        x_n, v_n: (n, 2) state at the start of the step.
        obstacle .. secondary_bounce: (n,) the contact state, updated in place (pass
            copies).
        face_par, face_dyn: the faces (see the module doc); the rows of face_dyn of the
            jaws' faces are set here from ``grip``.
        grip: (gap, lift, x) at the start, (gap, lift, x, gap rate, lift rate, x rate)
            at the end, m and m/s (x: the gripper centre on the transport axis).
        fconst, iconst, layout: the fruit's constant arrays (``pack_constants``):
            masses2 (2n,), masses (n,) kg; surface, skin_edges, rest_segments: see
            ``step_measures``; pos and edges .. gravity_grad: see ``newton_solve``.
        fpar: (8,) [dt, alpha, beta, tolerance, gravity, release threshold, correction
            speed, depth].  ipar: (2,) [max Newton iterations, max contact passes].
        x_out, v_out, forces_out: (n, 2) the new state and contact forces (N).
        history: (max_it,) Newton history of the last solve.
        out: (9,) [iterations, len(history), left jaw normal force N, right jaw normal
            force N, then the stretching, bending, pressure and gravity energies J, the
            flesh's largest von Mises stress Pa (as ``NeoHookeanTriangles.von_mises``; 0
            without flesh)].
        normal_out, pressure_out, meas_out: the outputs of ``step_measures``.
        counts: (C_SIZE,) int64, work counters added to (see C_*).
        d_face .. d_out: damage of the end state by ``damage_update``, skipped when
            d_rest is empty: d_face (n_faces, 3) [body id, curvature 1/m, padded],
            d_rest (n_s,) rest curvature 1/m, d_par (3,) [bruise pressure, rigid and pad
            contact moduli] Pa, covered_in (n_s,) m the bruised cover so far, outputs
            covered_out (n_s,), d_pressure (n_s,) Pa, patches (n_s, P_SIZE) and d_out (3,)
            [patches, largest peak pressure Pa, bruised length m].
        pad_k: (n_s,) N/m, the soft pads' foundation stiffness per outline node (empty: no
            pads), pad_scalars: (2,) [pad thickness m, pad friction mu]; outputs, as
            ``pad.PadLayer.finish_step`` records them: pad_forces (n, 2) N, pad_normal (n,)
            N, pad_holder (n,) int64 the jaw face whose pad presses each node hardest (-1:
            none), pad_side (2,) N each jaw's pads' push along the closing axis. With pads
            the measures and damage take every contact force (hard and pad) and each
            node's holder (its hard face, else its pad's face), as ``Simulation._measure``.
        work, iwork, bwork, storage, stress: scratch space (``substep_scratch``), reused
            from step to step: for a fruit without pads only the step's face arrays
            (``contact_faces``, a few per face) are allocated here.

    Returns:
        a status code (OK, or the failure of the last solve).
    """
    b = borrowed  # the caller keeps every argument alive for the call
    x_n, v_n, obstacle, mode, normal_force = b(x_n), b(v_n), b(obstacle), b(mode), b(normal_force)
    bounce_speed, secondary, secondary_bounce = b(bounce_speed), b(secondary), b(secondary_bounce)
    face_par, face_dyn, fconst, iconst, layout = (b(face_par), b(face_dyn), b(fconst), b(iconst),
                                                  b(layout))
    fpar, ipar, x_out, v_out, forces_out = b(fpar), b(ipar), b(x_out), b(v_out), b(forces_out)
    history, out, normal_out, pressure_out = b(history), b(out), b(normal_out), b(pressure_out)
    meas_out, counts, d_face, d_rest, d_par = b(meas_out), b(counts), b(d_face), b(d_rest), b(d_par)
    covered_in, covered_out, d_pressure = b(covered_in), b(covered_out), b(d_pressure)
    patches, d_out, pad_k, pad_scalars = b(patches), b(d_out), b(pad_k), b(pad_scalars)
    pad_forces, pad_normal, pad_holder, pad_side = (b(pad_forces), b(pad_normal), b(pad_holder),
                                                    b(pad_side))
    work, iwork, bwork, stress = b(work), b(iwork), b(bwork), b(stress)
    storage = (b(storage[0]), b(storage[1]), b(storage[2]), b(storage[3]), b(storage[4]))
    masses2 = _packed1(fconst, layout, KF_MASSES2)
    masses = _packed1(fconst, layout, KF_MASSES)
    rest_segments = _packed1(fconst, layout, KF_REST_SEGMENTS)
    spar = _packed2(fconst, layout, KF_SPAR)
    bpar = _packed2(fconst, layout, KF_BPAR)
    press = _packed1(fconst, layout, KF_PRESS)
    gravity_grad = _packed1(fconst, layout, KF_GRAVITY)
    surface = _packed1(iconst, layout, KI_SURFACE)
    skin_edges = _packed2(iconst, layout, KI_SKIN_EDGES)
    pos = _packed1(iconst, layout, KI_POS)
    edges = _packed2(iconst, layout, KI_EDGES)
    triples = _packed2(iconst, layout, KI_TRIPLES)
    ring = _packed1(iconst, layout, KI_RING)
    kp = KI_PATTERN
    flesh = (_packed2(iconst, layout, KI_TRI), _packed3(fconst, layout, KF_DM_INV),
             _packed1(fconst, layout, KF_VOLUME), _packed1(fconst, layout, KF_LAME),
             _packed2(iconst, layout, KI_TRI_SCATTER),
             (_packed1(fconst, layout, KF_SKIN_REST), _packed1(fconst, layout, KF_SKIN_STRETCH),
              _packed2(iconst, layout, KI_SKIN_S_SCATTER),
              _packed1(fconst, layout, KF_SKIN_PHI0), _packed1(fconst, layout, KF_SKIN_BEND),
              _packed2(iconst, layout, KI_SKIN_B_SCATTER)),
             (_packed1(iconst, layout, kp), _packed1(iconst, layout, kp + 1),
              _packed1(iconst, layout, kp + 2), _packed1(iconst, layout, kp + 3),
              _packed1(iconst, layout, kp + 4), _packed1(iconst, layout, kp + 5),
              _packed1(iconst, layout, kp + 6), _packed1(iconst, layout, kp + 7),
              _packed1(iconst, layout, kp + 8)))
    n = x_n.shape[0]
    dt = fpar[F_DT]
    counts[C_SUBSTEPS] += 1
    gap0, lift0, x0, gap1, lift1, x1, gap_rate, lift_rate, x_rate = grip
    for f in range(face_par.shape[0]):
        side = face_par[f, FP_JAW]
        if side < 0:
            continue
        sign = -1.0 if side == 0 else 1.0
        ox, oz = face_par[f, FP_OFFSET_X], face_par[f, FP_OFFSET_Z]
        face_dyn[f, 0] = (x0 + sign * (0.5 * gap0)) + ox
        face_dyn[f, 1] = lift0 + oz
        face_dyn[f, 2] = (x1 + sign * (0.5 * gap1)) + ox
        face_dyn[f, 3] = lift1 + oz
        face_dyn[f, 4] = x_rate + sign * (0.5 * gap_rate)
        face_dyn[f, 5] = lift_rate
    padded = pad_k.shape[0] > 0
    if padded:
        pad_nodes, pad_par, pad_face = _pad_rows(x_n, surface, pad_k, pad_scalars[0],
                                                 pad_scalars[1], face_par, face_dyn)
    else:
        pad_nodes = np.zeros(0, np.int64)
        pad_par = np.zeros((0, PAD_SIZE))
        pad_face = np.zeros(0, np.int64)
    x_pred = work[:2 * n].reshape((n, 2))
    for i in range(n):
        x_pred[i, 0] = x_n[i, 0] + dt * v_n[i, 0]
        x_pred[i, 1] = x_n[i, 1] + dt * v_n[i, 1]
    q_n = x_n.reshape(2 * n)  # x_n is C-contiguous
    v_flat = v_n.reshape(2 * n)
    released = bwork[:n]
    slipped = bwork[n:2 * n]
    faces = contact_faces(face_par, face_dyn)
    state = (obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce)
    start = work[2 * n:4 * n].reshape((n, 2))
    filters = work[4 * n:8 * n].reshape((n, 2, 2))
    fr_tangents = work[8 * n:10 * n].reshape((n, 1, 2))  # one tangent per row in 2D
    fr_t = work[8 * n:10 * n].reshape((n, 2))
    fr_bound = work[10 * n:11 * n]
    fr_speeds = work[11 * n:12 * n].reshape((n, 1))
    fr_speed = work[11 * n:12 * n]
    q = work[12 * n:14 * n]
    reaction = work[14 * n:16 * n]
    values = work[16 * n:16 * n + 4]
    values[:] = 0.0
    jaw_origins = work[16 * n + 4:16 * n + 8].reshape((2, 2))
    newton_work = work[SUBSTEP_WORK * n + SUBSTEP_WORK_EXTRA:]
    order = iwork[:n]
    fr_nodes = iwork[n:2 * n]
    v_min = max(5.0 * fpar[F_GRAVITY] * dt, 1e-3)
    problem = (q_n, v_flat, dt, start, filters, fr_nodes, fr_tangents, fr_t, fr_bound,
               fr_speeds, fr_speed, masses2, fpar[F_ALPHA], fpar[F_BETA], fpar[F_TOL],
               ipar[I_MAX_IT], edges, spar, triples, bpar, ring, press, flesh, gravity_grad,
               pos, q, reaction, history, values, counts, pad_nodes, pad_par, order, storage,
               newton_work, out)
    rules = (ipar[I_MAX_PASSES], fpar[F_VCORR], fpar[F_RELEASE], v_min, 0.0, False)
    status, iterations = contact_passes.contact_passes(
        problem, state, faces, x_n, v_n, x_pred, surface, masses, dt, rules, released,
        slipped, v_out, forces_out)
    if status != OK:
        return status
    x_out[:] = q.reshape((n, 2))
    out[2] = out[3] = 0.0
    for i in range(n):  # each jaw's force along its closing axis, summed over its faces
        f = obstacle[i]
        if f >= 0 and face_par[f, FP_JAW] >= 0:
            side = np.int64(face_par[f, FP_JAW])
            out[2 + side] += forces_out[i, 0] if side == 0 else -forces_out[i, 0]
    out[0] = iterations
    for side in range(2):
        sign = -1.0 if side == 0 else 1.0
        jaw_origins[side, 0] = x1 + sign * (0.5 * gap1)
        jaw_origins[side, 1] = lift1
    for e in range(4):
        out[4 + e] = values[e]
    holder = obstacle
    forces_all = forces_out
    if padded:
        _pad_forces(x_out, x_n, dt, pad_nodes, pad_par, pad_face, face_par, pad_forces,
                    pad_normal, pad_holder, pad_side)
        out[2] += pad_side[0]
        out[3] += pad_side[1]
        holder = obstacle.copy()
        forces_all = forces_out + pad_forces
        for i in range(n):
            if holder[i] < 0 and pad_holder[i] >= 0:
                holder[i] = pad_holder[i]
    step_measures(x_out, v_out, forces_all, holder, masses, surface, skin_edges,
                  rest_segments, face_par, jaw_origins, fpar[F_DEPTH], edges, spar, triples,
                  bpar, ring, press, flesh, gravity_grad, np.bool_(True), values, normal_out,
                  pressure_out, meas_out)
    if padded:  # the hard contacts' length along the faces, plus the pads'
        meas_out[M_CONTACT_LENGTH] = _jaw_contact_length(x_out, surface, obstacle, face_par,
                                                         jaw_origins)
        on_pad = 0.0
        n_e = skin_edges.shape[0]
        for s in range(surface.shape[0]):
            i = surface[s]
            if obstacle[i] < 0 and pad_holder[i] >= 0 and n_e > 0:
                a, b = skin_edges[s, 0], skin_edges[s, 1]
                seg = math.hypot(x_out[b, 0] - x_out[a, 0], x_out[b, 1] - x_out[a, 1])
                a, b = skin_edges[(s - 1) % n_e, 0], skin_edges[(s - 1) % n_e, 1]
                prev = math.hypot(x_out[b, 0] - x_out[a, 0], x_out[b, 1] - x_out[a, 1])
                on_pad += 0.5 * (seg + prev)
        meas_out[M_CONTACT_LENGTH] += on_pad
    if d_rest.shape[0] > 0:
        n_faces = d_face.shape[0]
        groups = np.empty(n_faces, np.int64)
        curvature = np.empty(n_faces)
        padded_face = np.empty(n_faces)
        for f in range(n_faces):
            groups[f] = np.int64(d_face[f, 0])
            curvature[f] = d_face[f, 1]
            padded_face[f] = d_face[f, 2]
        covered_out[:] = covered_in
        count, pressure, length = damage_update(
            x_out, normal_out, holder, surface, groups, curvature, padded_face, d_rest,
            d_par[0], d_par[1], d_par[2], covered_out, d_pressure, patches)
        d_out[0] = count
        d_out[1] = pressure
        d_out[2] = length
    out[8] = 0.0
    if flesh[0].shape[0] > 0:  # the damage tracker's flesh stress: np.max(initial=0.0)
        neohookean_von_mises(x_out, flesh[0], flesh[1], flesh[3][0], flesh[3][1], stress)
        for t in range(stress.shape[0]):
            if math.isnan(stress[t]):
                out[8] = stress[t]
                break
            out[8] = max(out[8], stress[t])
    return OK


# ---------------------------------------------------------------------- measures
#: layout of the ``step_measures`` output
(M_LEFT_FX, M_LEFT_FZ, M_LEFT_TY, M_RIGHT_FX, M_RIGHT_FZ, M_RIGHT_TY, M_LEFT_N, M_RIGHT_N,
 M_CX, M_CZ, M_CVX, M_CVZ, M_ANY_LEFT, M_ANY_RIGHT, M_KINETIC, M_ELASTIC, M_GRAVITY,
 M_WIDTH, M_MAX_STRAIN, M_CONTACT_LENGTH, M_PEAK_PRESSURE, M_SIZE) = range(22)


@njit(cache=True, error_model='numpy', inline='always')
def step_measures(x, v, forces, obstacle, masses, surface, skin_edges, rest_segments,
                  face_par, jaw_origins, depth, edges, spar, triples, bpar, ring, press, flesh,
                  gravity_grad, known, energies, normal_out, pressure_out, out):
    """The numbers of ``Simulation._measure`` and ``measures.deformation``.

    Args:
        x, v, forces: (n, 2) positions m, velocities m/s, contact forces N.
        obstacle: (n,) holding obstacle per node.  masses: (n,) kg.
        surface: (n_s,) outline nodes.  skin_edges: (n_e, 2).  rest_segments: (n_e,) m,
        skin segment lengths of the rest shape.  face_par: see the module doc.
        jaw_origins: (2, 2) m, left and right jaw origins (a jaw face's centre is its
        origin plus the face's offset).  depth: m.
        edges .. gravity_grad: the energies (as ``newton_solve``).
        known: the energies at x are ``energies`` (4,) [stretching, bending, pressure,
        gravity] J, as ``substep`` reports them; else they are computed.
        normal_out: (n,) N, normal contact force per node.  pressure_out: (n_s,) Pa.
        out: (M_SIZE,) the scalars, see the M_* indices.
    """
    n = x.shape[0]
    out[:] = 0.0
    normal_out[:] = 0.0
    for side in range(2):
        fx = 0.0
        fz = 0.0
        ty = 0.0
        ox, oz = jaw_origins[side, 0], jaw_origins[side, 1]
        for i in range(n):
            f = obstacle[i]
            if f < 0 or face_par[f, FP_JAW] != side:
                continue
            fx += forces[i, 0]
            fz += forces[i, 1]
            ty += (x[i, 1] - oz) * -forces[i, 0] - (x[i, 0] - ox) * -forces[i, 1]
            out[M_ANY_LEFT + side] = 1.0
        out[3 * side] = -fx
        out[3 * side + 1] = -fz
        out[3 * side + 2] = ty
    for i in range(n):
        f = obstacle[i]
        if f >= 0:
            normal_out[i] = forces[i, 0] * face_par[f, 0] + forces[i, 1] * face_par[f, 1]
            if face_par[f, FP_JAW] >= 0:  # each jaw's force along its faces' normals
                out[M_LEFT_N + np.int64(face_par[f, FP_JAW])] += normal_out[i]
    m_sum = 0.0
    for i in range(n):
        m_sum += masses[i]
    cx = cz = cvx = cvz = kin = 0.0
    for i in range(n):
        cx += masses[i] * x[i, 0]
        cz += masses[i] * x[i, 1]
        cvx += masses[i] * v[i, 0]
        cvz += masses[i] * v[i, 1]
        kin += masses[i] * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1])
    out[M_CX], out[M_CZ] = cx / m_sum, cz / m_sum
    out[M_CVX], out[M_CVZ] = cvx / m_sum, cvz / m_sum
    out[M_KINETIC] = 0.5 * kin
    if known:
        out[M_ELASTIC] = (energies[0] + energies[1]) + energies[2]
        out[M_GRAVITY] = energies[3]
    else:
        q = x.reshape(2 * n)
        no = np.bool_(False)
        grad = np.empty(2 * n)
        area_grad = np.empty(2 * n)
        band = np.empty((0, 1, 2, 2))
        pos = np.zeros(n, np.int64)
        elastic = ring_stretching(q, edges, spar, pos, no, grad, band)
        elastic += ring_bending(q, triples, bpar, pos, no, grad, band)
        vp, _c = ring_pressure(q, ring, press, pos, no, grad, band, area_grad)
        if flesh[0].shape[0] > 0:
            vp += neohookean_triangles(x, flesh[0], flesh[1], flesh[2], flesh[3][0],
                                       flesh[3][1], grad, grad, flesh[4], no)
        out[M_ELASTIC] = elastic + vp
        grav = 0.0
        for m in range(2 * n):
            grav += gravity_grad[m] * q[m]
        out[M_GRAVITY] = grav
    # deformation
    width, strain_max, peak = outline_measures(x, surface, skin_edges, rest_segments,
                                               normal_out, depth, pressure_out)
    out[M_WIDTH] = width
    out[M_MAX_STRAIN] = strain_max
    out[M_PEAK_PRESSURE] = peak
    out[M_CONTACT_LENGTH] = _jaw_contact_length(x, surface, obstacle, face_par, jaw_origins)


@njit(cache=True, error_model='numpy')
def _jaw_contact_length(x, surface, obstacle, face_par, jaw_origins):
    """m, the outline's contact length summed over the jaws' faces."""
    length = 0.0
    for f in range(face_par.shape[0]):
        if face_par[f, FP_JAW] < 0:
            continue
        side = np.int64(face_par[f, FP_JAW])
        length += face_contact_length_of(x, surface, obstacle, f, face_par[f, 0],
                                         face_par[f, 1],
                                         jaw_origins[side, 0] + face_par[f, FP_OFFSET_X],
                                         jaw_origins[side, 1] + face_par[f, FP_OFFSET_Z])
    return length


# ---------------------------------------------------------------------- damage
@njit(cache=True, error_model='numpy')
def damage_update(x, normal, obstacle, ring, groups, curvature, padded, rest_curvature,
                  bruise_pressure, rigid_modulus, pad_modulus, covered, node_pressure,
                  patches):
    """``damage.damage_patches`` for the faces of this module's steps (rigid faces, soft
    pads; no deformable finger): the per-step part of ``DamageTracker.update``.

    Args:
        x: (n, 2) m.  normal: (n,) N, normal reactions.  obstacle: (n,) holding obstacle.
        ring: (n_s,) outline nodes.  groups: (n_faces,) body id per obstacle.
        curvature: (n_faces,) 1/m.  padded: (n_faces,) 1.0 where a pad covers the face.
        rest_curvature: (n_s,) 1/m.  bruise_pressure, rigid_modulus, pad_modulus: Pa.
        covered: (n_s,) m, bruised length per outline position, updated in place.
        node_pressure: (n_s,) Pa, output.  patches: (n_s, P_SIZE) output rows.

    Returns:
        (number of patches, largest peak pressure Pa, bruised length sum(covered) m).
    """
    faces = np.zeros((groups.shape[0], FACE_SIZE))
    for f in range(groups.shape[0]):
        faces[f, FACE_BODY] = groups[f]
        faces[f, FACE_CURVATURE] = curvature[f]
        faces[f, FACE_PADDED] = padded[f]
    near = np.empty(ring.shape[0], np.int64)
    return damage_patches(x, normal, obstacle, ring, faces, rest_curvature, bruise_pressure,
                          rigid_modulus, pad_modulus, 1.0, covered, node_pressure, patches,
                          near)
