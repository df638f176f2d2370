"""Preconditioned conjugate gradients of the fast Newton solver (``core.fast_solver``) in
one numba kernel, for 2D and 3D.

A Newton system (A + u diag(c) u^T) dq = rhs, A the CSC values of the Newton matrix on
the solver's fixed pattern, is solved in the range of the node filters S (n_nodes, d, d)
with the preconditioner S (L D L^T + u_w diag(.) u_w^T)^-1 S: the kept block LDL^T
(``core.sparse_ldl``, in the factor's dof order ``perm``) and its rank-one terms by the
Woodbury identity (A^-1 u_w and the inverse capacitance matrix, made with the
factorisation). The system lives in the range of S (its held directions are the
identity and the right-hand side is zero there), so the preconditioner S P^-1 S is
exact on them even when P was factorised with another contact set. The stopping rules
are ``fast_solver``'s (see its CG_* constants). The dot products go through BLAS as
numpy's do, so with one rank-one term the iterates equal a numpy loop over the same
kernels to the bit.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gripper_sim.core.solver_kernels import (apply_filters, cg_direction, cg_update,
                                             csc_matvec, filter_and_permute, max_abs,
                                             unpermute)
from gripper_sim.core.sparse_ldl import ldl_solve_3, solve

#: ``preconditioned_cg``'s outcomes
CONVERGED, FAILED = 0, 1


@njit(cache=True)
def block_ldl_solve(arrays, l_values, d_inv, x):
    """x <- (L D L^T)^-1 x in place, x (n_nodes b,) in the factor's position order:
    the 3 x 3 kernel for b = 3, else ``sparse_ldl.solve``.

    Args:
        arrays: the factor's ``SparsePattern.arrays``.
        l_values: (n_factor, b, b), d_inv: (n_nodes, b, b) the factors (C order).
    """
    if d_inv.shape[1] == 3:
        ldl_solve_3(arrays[4], arrays[5], l_values.reshape((l_values.shape[0], 9)),
                    d_inv.reshape((d_inv.shape[0], 9)), x)
    else:
        solve(arrays, l_values, d_inv, x)


@njit(cache=True)
def _add_product(out, sign, a, w):
    """out (n,) += sign a w, a (n, k), w (k,)."""
    for i in range(out.shape[0]):
        acc = 0.0
        for j in range(w.shape[0]):
            acc += a[i, j] * w[j]
        out[i] += sign * acc


@njit(cache=True)
def _transposed_product(u_t, x):
    """(k,) u^T x for u_t = u^T (k, n) (one BLAS dot product a column)."""
    out = np.empty(u_t.shape[0])
    for j in range(u_t.shape[0]):
        out[j] = np.dot(u_t[j], x)
    return out


@njit(cache=True)
def _precondition(filters, perm, arrays, l_values, d_inv, u_w_t, a_inv_u, small_inv, r,
                  work, y):
    """y (n,) = S (L D L^T + rank one)^-1 S r; work (n,) scratch."""
    filter_and_permute(filters, r, perm, work)
    block_ldl_solve(arrays, l_values, d_inv, work)
    unpermute(work, perm, y)
    k = u_w_t.shape[0]
    if k > 0:
        t = _transposed_product(u_w_t, y)
        v = np.zeros(k)
        _add_product(v, 1.0, small_inv, t)
        _add_product(y, -1.0, a_inv_u, v)
    apply_filters(filters, y, work)
    y[:] = work


@njit(cache=True)
def _apply(indptr, indices, values, u, u_t, c, x, out):
    """out (n,) = (A + u diag(c) u^T) x, u_t = u^T."""
    csc_matvec(indptr, indices, values, x, out)
    if c.shape[0] > 0:
        _add_product(out, 1.0, u, c * _transposed_product(u_t, x))


@njit(cache=True)
def _converges_in_time(reduction, target, iterations, max_iterations):
    """Whether CG, having reduced a norm by ``reduction`` in ``iterations``, reaches
    ``target`` (a reduction) within ``max_iterations`` at the same geometric rate."""
    if not 0.0 < reduction < 1.0:
        return False
    rate = math.log(reduction) / iterations
    return iterations + math.log(target / reduction) / rate <= max_iterations


@njit(cache=True)
def preconditioned_cg(indptr, indices, values, u, u_t, c, filters, perm, arrays, l_values,
                      d_inv, u_w_t, a_inv_u, small_inv, rhs, relative, error_limit, step_floor,
                      max_iterations, stale_iterations, x):
    """CG from zero on (A + u diag(c) u^T) x = rhs, preconditioned as the module says.

    Stops when the residual max |r| is below ``relative`` max |rhs| with max |x| at least
    ``step_floor`` (m), or when the preconditioned residual max |z| (the error estimate)
    is below ``error_limit`` (m); gives up on negative curvature, after
    ``max_iterations``, or at ``stale_iterations`` if neither test would pass in time at
    the rate so far.

    Args:
        indptr (n + 1,), indices (nnz,) int64, values (nnz,): A in CSC.
        u: (n, k), u_t: its transpose (k, n), c: (k,) the rank-one terms (k may be 0).
        filters: (n_nodes, d, d) S.  perm: (n,) the dofs in factor order.
        arrays, l_values, d_inv: the kept block LDL^T (``block_ldl_solve``).
        u_w_t: (k_w, n) u_w^T, a_inv_u: (n, k_w), small_inv: (k_w, k_w) the
            preconditioner's rank-one terms (k_w = 0: none).
        rhs: (n,).  x: (n,) the solution (written).

    Returns:
        (CONVERGED or FAILED, CG iterations).
    """
    n = rhs.shape[0]
    work = np.empty(n)
    ap = np.empty(n)
    z = np.empty(n)
    limit = relative * max_abs(rhs)
    x[:] = 0.0
    r = rhs.copy()
    _precondition(filters, perm, arrays, l_values, d_inv, u_w_t, a_inv_u, small_inv, r,
                  work, z)
    residual_0 = max_abs(r)
    error_0 = max_abs(z)
    p = z.copy()
    rz = np.dot(r, z)
    for it in range(1, max_iterations + 1):
        _apply(indptr, indices, values, u, u_t, c, p, ap)
        curvature = np.dot(p, ap)
        if not curvature > 0 or not math.isfinite(curvature):
            return FAILED, it
        residual, largest = cg_update(x, r, p, ap, rz / curvature)
        if residual <= limit and largest >= step_floor:
            return CONVERGED, it
        _precondition(filters, perm, arrays, l_values, d_inv, u_w_t, a_inv_u, small_inv,
                      r, work, z)
        error = max_abs(z)
        if error <= error_limit:
            return CONVERGED, it
        if it == stale_iterations and not (
                _converges_in_time(residual / residual_0, limit / residual_0, it,
                                   max_iterations)
                or _converges_in_time(error / error_0, error_limit / error_0, it,
                                      max_iterations)):
            return FAILED, it
        rz_new = np.dot(r, z)
        cg_direction(z, p, rz_new / rz)
        rz = rz_new
    return FAILED, max_iterations
