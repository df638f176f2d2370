"""The Newton system's solve of ``fast_solver.PatternCachingSolver`` (2D and 3D), compiled,
with the preconditioner it keeps from system to system.

A system (A + u diag(c) u^T) dq = rhs, A the CSC values of the Newton matrix on the
solver's fixed pattern and u (n, k), c (k,) its rank-one terms (k may be 0), is solved
in the range of the node filters S (n_nodes, d, d) by conjugate gradients
(``pcg_kernels.preconditioned_cg``) preconditioned with a block LDL^T of an earlier
Newton matrix (``core.sparse_ldl``, d x d node blocks, the 3 x 3 kernels for d = 3) and
its rank-one terms by the Woodbury identity, (A + u C u^T)^-1 = A^-1 - A^-1 u (C^-1 +
u^T A^-1 u)^-1 u^T A^-1 (Golub & Van Loan, Matrix Computations, 4th ed., 2.1.4). A new
factorisation is made when the kept one is stale (CG took more than its stale
iterations last time), when asked (``fresh``), or when CG fails on the kept one; if CG
fails even on a fresh one (an indefinite matrix), the factor's own solution refined
against the matrix (``REFINEMENT_SWEEPS``) is the answer. The factor's solves skip
its blocks that are all zero (``_compact``; a contact pair's blocks while it is apart).
A system solved with a new factorisation also counts its matrix's negative eigenvalues
(``F_NEGATIVE``), for the Newton iteration's rule that a shifted matrix be positive
definite (``core.newton``):
D's blocks carry A's inertia (Sylvester's law of inertia; the factorisation has no
pivoting across blocks), and the rank-one terms change it by the capacitance matrix's
(Haynsworth's inertia additivity: In(A + u C u^T) = In(A) + In(C^-1 + u^T A^-1 u) -
In(C^-1), the bordered matrix [[A, u], [u^T, -C^-1]] reduced both ways).

``LinearSolveState`` (a numba StructRef, made once per solver by ``new_state``) holds
the pattern, the kept factor and its Woodbury terms, the flags and the work counters.
The solver's interpreted Newton problem calls ``solve`` from Python; the compiled 2D
barrier problem (``core.barrier_newton``) holds the same state and calls it compiled.
The flags and counters are arrays Python shares (``flags``, ``stats``).
"""
from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.experimental import structref

from gripper_sim.core.pcg_kernels import CONVERGED, block_ldl_solve, preconditioned_cg
from gripper_sim.core.solver_kernels import csc_matvec
from gripper_sim.core.sparse_ldl import factor, ldl_factor_3

#: flags (int64 array): whether a factor is kept, whether it is stale (a new one is due),
#: the columns of the Woodbury terms kept with it (-1: none), the negative eigenvalues of
#: the last system's matrix A + u diag(c) u^T if it was factorised afresh (-1: it was not)
F_HAS_FACTOR, F_STALE, F_WOODBURY, F_NEGATIVE, F_SIZE = range(5)
#: stats (int64 array): Newton systems, factorisations, CG iterations, factorisations of
#: an indefinite matrix
S_SYSTEMS, S_FACTORS, S_CG, S_INDEFINITE, S_SIZE = range(5)
#: iterative-refinement sweeps of the factor's solution when CG cannot be used
REFINEMENT_SWEEPS = 3


@structref.register
class LinearSolveStateType(types.StructRef):
    """The numba type of ``LinearSolveState``."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


#: the state's fields: the CSC pattern (indptr (n + 1,), indices (nnz,) int64); the
#: factor's dof order perm (n,), its pattern (``SparsePattern.arrays``), the gather of
#: its blocks from the CSC values (target, source (m,)), its stored blocks' count, L
#: (n_factor, b, b) and D^-1 (n_nodes, b, b) kept and their scratch for a new factor;
#: the Woodbury terms kept with it (u (n, k), A^-1 u (n, k), inverse capacitance
#: (k, k)); ``flags`` (``F_*``), ``stats`` (``S_*``); CG's (max, stale) iterations;
#: the kept L's blocks that are not all zero, which its solves run on (``_compact``):
#: the pattern's arrays with their l_ptr, l_row, and those blocks (m, b, b)
FIELDS = ('indptr', 'indices', 'perm', 'arrays', 'target', 'source', 'n_blocks',
          'l_values', 'd_inv', 'l_new', 'd_new', 'w_u', 'w_a_inv_u', 'w_small_inv',
          'flags', 'stats', 'cg_iterations', 'solve_arrays', 'l_solve')


class LinearSolveState(structref.StructRefProxy):
    """The kept preconditioner and the pattern of one solver (``FIELDS``; ``new_state``).
    Its ``flags`` and ``stats`` are arrays Python shares (a compiled call each read:
    keep them)."""

    @property
    def flags(self) -> np.ndarray:
        return _flags(self)

    @property
    def stats(self) -> np.ndarray:
        return _stats(self)


structref.define_proxy(LinearSolveState, LinearSolveStateType, list(FIELDS))


@njit(cache=True)
def _flags(state):
    return state.flags


@njit(cache=True)
def _stats(state):
    return state.stats


@njit(cache=True)
def _new_state(fields):
    return LinearSolveState(*fields)


def new_state(indptr: np.ndarray, indices: np.ndarray, perm: np.ndarray, pattern,
              gather: tuple, max_iterations: int, stale_iterations: int) -> LinearSolveState:
    """The state of a solver: its CSC ``indptr``, ``indices`` (int64), the factor's dof
    order ``perm`` (n,), its ``sparse_ldl.SparsePattern``, ``gather`` = (target, source)
    its blocks from the CSC values, CG's iteration limits; no factor kept."""
    b = pattern.block
    n = perm.size
    l_shape, d_shape = (pattern.n_factor, b, b), (pattern.n_nodes, b, b)
    flags = np.zeros(F_SIZE, np.int64)
    flags[F_WOODBURY] = -1
    flags[F_NEGATIVE] = -1
    target, source = gather
    return _new_state((
        indptr, indices, perm, pattern.arrays, np.ascontiguousarray(target, dtype=np.int64),
        np.ascontiguousarray(source, dtype=np.int64), pattern.n_blocks,
        np.empty(l_shape), np.empty(d_shape), np.empty(l_shape), np.empty(d_shape),
        np.empty((n, 0)), np.empty((n, 0)), np.empty((0, 0)), flags,
        np.zeros(S_SIZE, np.int64), (int(max_iterations), int(stale_iterations)),
        pattern.arrays, np.empty(l_shape)))


def forget(state: LinearSolveState) -> None:
    """Forget the kept factor (the next system factorises afresh)."""
    flags = state.flags
    flags[:] = 0
    flags[F_WOODBURY] = -1
    flags[F_NEGATIVE] = -1


@njit(cache=True)
def ldl_solve(state, x, out):
    """out (n,) = (L D L^T)^-1 x (n,) by the kept factor."""
    perm = state.perm
    y = np.empty(x.shape[0])
    for m in range(perm.shape[0]):
        y[m] = x[perm[m]]
    block_ldl_solve(state.solve_arrays, state.l_solve, state.d_inv, y)
    for m in range(perm.shape[0]):
        out[perm[m]] = y[m]


@njit(cache=True)
def factorise(state, values):
    """The block LDL^T of the CSC ``values`` (nnz,) kept: the number of its pivot blocks
    that are not positive definite (0: the matrix is positive definite), or -1 if a pivot
    block is singular (the kept factor unchanged)."""
    state.stats[S_FACTORS] += 1
    b = state.d_inv.shape[1]
    blocks = np.zeros((state.n_blocks + 1, b, b))
    flat = blocks.reshape(-1)
    target, source = state.target, state.source
    for m in range(target.shape[0]):
        flat[target[m]] = values[source[m]]
    l_new, d_new = state.l_new, state.d_new
    if b == 3:
        status = ldl_factor_3(state.arrays, blocks.reshape((blocks.shape[0], 9)),
                              l_new.reshape((l_new.shape[0], 9)),
                              d_new.reshape((d_new.shape[0], 9)))
    else:
        status = factor(state.arrays, blocks, l_new, d_new)
    if status < 0:
        return -1
    state.l_values[:] = l_new
    state.d_inv[:] = d_new
    _compact(state)
    return status


@njit(cache=True)
def _compact(state):
    """The kept L's blocks that are not all zero (with a contact pair's Hessian blocks
    in the pattern, most of them are zero while the pair is apart: the Fin Ray grasp's
    factor has 803 of its 1445), with their columns' pointers and rows, for its solves
    (``solve_arrays``, ``l_solve``): a zero block subtracts zero, so the solves give the
    same values (but for the sign of an exact zero) for less work."""
    arrays, l_values = state.arrays, state.l_values
    l_ptr, l_row = arrays[4], arrays[5]
    b = l_values.shape[1]
    n_nodes = l_ptr.shape[0] - 1
    ptr = np.empty(n_nodes + 1, np.int64)
    rows = np.empty(l_row.shape[0], np.int64)
    kept = np.empty(l_row.shape[0], np.int64)
    count = 0
    for i in range(n_nodes):
        ptr[i] = count
        for p in range(l_ptr[i], l_ptr[i + 1]):
            nonzero = False
            for r in range(b):
                for c in range(b):
                    if l_values[p, r, c] != 0.0:  # NaN too
                        nonzero = True
            if nonzero:
                rows[count] = l_row[p]
                kept[count] = p
                count += 1
    ptr[n_nodes] = count
    compact = np.empty((count, b, b))
    for m in range(count):
        compact[m] = l_values[kept[m]]
    state.solve_arrays = arrays[:4] + (ptr, rows[:count].copy()) + arrays[6:]
    state.l_solve = compact


@njit(cache=True)
def not_known_indefinite(state):
    """False if the last system's matrix was factorised afresh and found indefinite
    (``F_NEGATIVE`` > 0); True if positive definite or not counted."""
    return state.flags[F_NEGATIVE] <= 0


@njit(cache=True)
def _negative_eigenvalues(state, indefinite_blocks, c, small_inv):
    """The negative eigenvalues of A + u diag(c) u^T, A the kept factor's matrix with
    ``indefinite_blocks`` pivot blocks not positive definite, c (k,), ``small_inv`` the
    inverse capacitance matrix (k, k) (see the module's docstring)."""
    negative = 0
    if indefinite_blocks:
        for block in state.d_inv:
            for value in np.linalg.eigvalsh(0.5 * (block + block.T)):
                if value < 0.0:
                    negative += 1
    k = c.shape[0]
    if k:
        for value in np.linalg.eigvalsh(0.5 * (small_inv + small_inv.T)):
            if value > 0.0:
                negative += 1
        for j in range(k):
            if c[j] > 0.0:
                negative -= 1
    return negative


@njit(cache=True)
def _woodbury(state, u, c):
    """The preconditioner's rank-one terms for u (n, k), c (k,) by the kept factor:
    (a copy of u, A^-1 u (n, k), the inverse capacitance matrix
    (diag(1/c) + u^T A^-1 u)^-1 (k, k))."""
    n, k = u.shape
    columns = np.empty((k, n))
    solved = np.empty((k, n))
    a_inv_u = np.empty((n, k))
    for j in range(k):
        columns[j] = u[:, j]
        ldl_solve(state, columns[j], solved[j])
        a_inv_u[:, j] = solved[j]
    capacitance = np.zeros((k, k))
    for i in range(k):
        capacitance[i, i] = 1.0 / c[i]
        for j in range(k):
            capacitance[i, j] += np.dot(columns[i], solved[j])
    return u.copy(), a_inv_u, np.ascontiguousarray(np.linalg.inv(capacitance))


@njit(cache=True)
def _woodbury_terms(state, u, c):
    """The rank-one terms for u, c: those kept with the factor if they have as many
    columns, else made now (not kept); none (k_w = 0) if k = 0."""
    k = c.shape[0]
    if k and state.flags[F_WOODBURY] == k:
        return state.w_u, state.w_a_inv_u, state.w_small_inv
    if k:
        return _woodbury(state, u, c)
    n = u.shape[0]
    return np.zeros((n, 0)), np.zeros((n, 0)), np.zeros((0, 0))


@njit(cache=True)
def _pcg(state, values, rhs, u, c, u_t, filters, relative, error_limit, floor, x):
    """CG on the kept factor (``pcg_kernels.preconditioned_cg``): True if it converged
    (x written; the factor marked stale if it took more than the stale iterations)."""
    u_w, a_inv_u, small_inv = _woodbury_terms(state, u, c)
    max_iterations, stale_iterations = state.cg_iterations
    status, iterations = preconditioned_cg(
        state.indptr, state.indices, values, u, u_t, c, filters, state.perm,
        state.solve_arrays, state.l_solve, state.d_inv, np.ascontiguousarray(u_w.T),
        a_inv_u, small_inv, rhs,
        relative, error_limit, floor, max_iterations, stale_iterations, x)
    state.stats[S_CG] += iterations
    if status != CONVERGED:
        return False
    state.flags[F_STALE] = 1 if iterations > stale_iterations else 0
    return True


@njit(cache=True)
def _precondition(state, u, c, r, out):
    """out = (kept LDL^T + rank-one terms)^-1 r."""
    ldl_solve(state, r, out)
    u_w, a_inv_u, small_inv = _woodbury_terms(state, u, c)
    k = u_w.shape[1]
    if k:
        t = np.empty(k)
        column = np.empty(out.shape[0])
        for j in range(k):
            column[:] = u_w[:, j]
            t[j] = np.dot(column, out)
        for i in range(k):
            s = 0.0
            for j in range(k):
                s += small_inv[i, j] * t[j]
            for m in range(out.shape[0]):
                out[m] -= a_inv_u[m, i] * s


@njit(cache=True)
def solve(state, values, rhs, u, c, u_t, filters, relative, error_limit, floor, fresh, x):
    """x (n,) with (A + u diag(c) u^T) x = rhs (n,) in the range of the filters S
    (n_nodes, d, d): A the CSC ``values`` (nnz,), u (n, k), c (k,), u_t = u^T (k, n)
    C order; CG's stopping rules ``relative``, ``error_limit`` m and ``floor`` m
    (``pcg_kernels.preconditioned_cg``); ``fresh``: factorise first. False if the
    factorisation is singular (x not written)."""
    flags = state.flags
    state.stats[S_SYSTEMS] += 1
    flags[F_NEGATIVE] = -1
    if flags[F_HAS_FACTOR] and not fresh and not flags[F_STALE]:
        if _pcg(state, values, rhs, u, c, u_t, filters, relative, error_limit, floor, x):
            return True
    flags[F_STALE] = 0
    indefinite_blocks = factorise(state, values)
    if indefinite_blocks < 0:
        return False
    flags[F_HAS_FACTOR] = 1
    flags[F_WOODBURY] = -1
    k = c.shape[0]
    if k:
        state.w_u, state.w_a_inv_u, state.w_small_inv = _woodbury(state, u, c)
        flags[F_WOODBURY] = k
    flags[F_NEGATIVE] = _negative_eigenvalues(state, indefinite_blocks, c, state.w_small_inv)
    if flags[F_NEGATIVE]:
        state.stats[S_INDEFINITE] += 1
    if _pcg(state, values, rhs, u, c, u_t, filters, relative, error_limit, floor, x):
        return True
    # CG failed on a fresh factorisation (negative curvature: an indefinite matrix)
    n = rhs.shape[0]
    _precondition(state, u, c, rhs, x)
    residual, correction = np.empty(n), np.empty(n)
    for _ in range(REFINEMENT_SWEEPS):
        csc_matvec(state.indptr, state.indices, values, x, residual)
        if k:
            column = np.empty(n)
            for j in range(k):
                column[:] = u[:, j]
                s = c[j] * np.dot(column, x)
                for m in range(n):
                    residual[m] += u[m, j] * s
        for m in range(n):
            residual[m] = rhs[m] - residual[m]
        _precondition(state, u, c, residual, correction)
        for m in range(n):
            x[m] += correction[m]
    return True
