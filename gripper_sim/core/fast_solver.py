"""The implicit Euler Newton stepper of the simulations (2D and 3D) on a fixed pattern.

``ImplicitEulerSolver`` (``core.stepper``, the reference) turns the energies' IJV
triplets into a sparse matrix on every evaluation. The fruit's meshes do not change, so
neither do the triplets' positions: this subclass finds the CSC pattern once. Same
incremental potential, gradient and Hessian as the base class (up to round-off in the
summation order); without numba it sums each evaluation's triplets into the pattern
with one ``np.bincount``.

The fast path (numba installed, no stiffness damping, every energy with an
``evaluate_into`` kernel; ``GRIPPER_SIM_FAST=0`` turns it off) solves the same Newton
iteration (same line search, shifts and stopping rule) with less work:
- the energies add their gradients and Hessians straight into the CSC values through
  precomputed scatter indices (``core.energies.kernels``, ``core3d.kernels``), and
  S H S + (I - S) is one kernel over the d x d node blocks (``core.solver_kernels``), on
  the same pattern; kinetic friction is the Coulomb cone of the stepper, a 2D tangent
  being a cone with one tangent;
- each Newton system is solved by conjugate gradients preconditioned with a block
  LDL^T factorisation (``core.sparse_ldl``, d x d node blocks, no pivoting across
  blocks) kept from an earlier Newton iteration or step (the matrix changes little
  between them), its rank-one terms by the Woodbury identity and the whole projected
  by the step's filter S; a new factorisation is made only after CG needed more than
  ``CG_STALE_ITERATIONS`` (or would not converge in time), and CG runs after it too,
  so the precision of the solution is that of CG, not of the factors;
- CG is an inexact Newton solve (Dembo, Eisenstat & Steihaug 1982): it stops at a
  relative residual of ``CG_TOLERANCE`` while the step is large, and otherwise when its
  error estimate (the preconditioned residual) is below ``CG_ERROR_FRACTION`` of the
  Newton tolerance, so the step that ends the iteration is accurate;
- the factorisation is in METIS's nested-dissection order of the node graph, and for
  d = 3 by kernels written out for 3 x 3 blocks (``sparse_ldl.ldl_factor_3``,
  ``ldl_solve_3``): on the 3D fruits a factorisation takes 0.4 and a solve 0.5-0.7 of
  the time of the single-precision SuperLU used before, in double precision;
- a later contact pass of the same step starts from the previous pass's solution (in
  the directions the new filter leaves free), and after a Newton step below
  ``HESSIAN_REUSE`` times the tolerance the next iteration reuses the Newton matrix;
- the line search's first trial evaluates the Hessian with the gradient when a new
  Hessian follows (the full step is usually taken), and it stops where a sliding
  node's slip velocity, turning round, comes nearest to zero (``_kink_step``: past it
  the step overshoots the kink of the smoothed friction law and the search halves it
  again and again).
The fast path follows the reference path to the Newton tolerance over a grasp
(test/test_3d_energies.py::test_fast_solver_follows_the_numpy_reference_path).
"""
from __future__ import annotations

import math
import os

import numpy as np
import scipy.sparse as sp

from gripper_sim.core.stepper import (FRICTION_SMOOTHING, ImplicitEulerSolver, NewtonFailure,
                                      StepConstraints, StepSolution, descent_direction,
                                      line_search, stack_low_rank, woodbury_terms)

try:  # numba is optional: without it the numpy reference path runs
    from gripper_sim.core import solver_kernels as kernels
    from gripper_sim.core import sparse_ldl
except ImportError:  # pragma: no cover - depends on the environment
    kernels = sparse_ldl = None

#: SuperLU settings for the reference path's Newton systems (symmetric pattern:
#: minimum degree on A^T + A and diagonal pivots, about twice as fast as the defaults
#: for the 3D fruit)
SYMMETRIC_LU_OPTIONS = dict(permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                            options=dict(SymmetricMode=True))

#: relative residual (infinity norms) at which the preconditioned CG stops (0.1 took
#: 12 % more Newton systems on the solid apple's grasp: a fruit held at two nodes has a
#: soft mode that a loose residual leaves to the next Newton step)
CG_TOLERANCE = 1e-2
#: ... or when the preconditioned residual (the error estimate of dq) is below this
#: fraction of the Newton tolerance (times dt): the last Newton iterations, whose dq
#: are tiny, need no relative accuracy
CG_ERROR_FRACTION = 1e-2
#: ... the relative test only for a step this many times the Newton tolerance (times
#: dt) or more: a smaller one may end the Newton iteration and must be accurate
CG_RELATIVE_FLOOR = 10.0
#: CG iterations before the matrix is factorised afresh
CG_MAX_ITERATIONS = 20
#: a system that took more CG iterations than this gets a new factorisation next time
#: (a factorisation costs about 25 of the solid apple's CG iterations; 3 to 5 give the
#: same 3D grasp times, 3 the 2D Fin Ray grasp's best: 2.3 s against 2.4-2.8 s at 5)
CG_STALE_ITERATIONS = 3
#: iterative-refinement sweeps of the direct solve when CG cannot be used (indefinite)
REFINEMENT_SWEEPS = 3
#: after a Newton step below this multiple of the tolerance the next iteration reuses
#: the Newton matrix (a chord step: near convergence the Hessian barely changes, and
#: the step's size, which decides convergence, is as well estimated)
HESSIAN_REUSE = 100.0
#: a sliding node's Newton step is cut at the kink of the friction law only if it
#: slips faster than this multiple of the smoothing speed (slower: inside the kink)
KINK_FACTOR = 10.0


def nested_dissection(graph: sp.csr_matrix) -> np.ndarray:
    """Fill-reducing order (n,) of a graph's nodes: METIS's multilevel nested dissection
    (Karypis & Kumar 1998, SIAM J. Sci. Comput. 20(1)): on the 3D fruits' node graphs
    2-6 % fewer factor blocks than ``sparse_ldl.minimum_degree``."""
    import pymetis
    graph = sp.csr_matrix(graph)
    graph.setdiag(0)
    graph.eliminate_zeros()
    order, _ = pymetis.nested_dissection(pymetis.CSRAdjacency(graph.indptr, graph.indices))
    return np.asarray(order, dtype=np.int64)


class _BlockLDL:
    """A = L D L^T in d x d node blocks (``core.sparse_ldl``) standing for A^-1 as the
    preconditioner, in the nested-dissection order of the node graph: x[perm] =
    (L D L^T)^-1 b[perm], perm (n,) the dofs in factor order.

    Args:
        pattern: the ``sparse_ldl.SparsePattern`` of the Newton matrix.
        gather: (target (m,) into the flat block values, source (m,) into the CSC
            values): the matrix's stored blocks taken from its CSC values.
        perm: (n,) dofs in the factor's position order.
    """

    def __init__(self, pattern, gather: tuple, perm: np.ndarray):
        self.pattern, self.gather, self.perm = pattern, gather, perm
        b = pattern.block
        self.l_values = np.empty((pattern.n_factor, b, b))
        self.d_inv = np.empty((pattern.n_nodes, b, b))
        self._rhs = np.empty(perm.size)

    def factorise(self, data: np.ndarray) -> None:
        """Factorise the matrix of CSC values ``data``. Raises RuntimeError (a singular
        pivot block)."""
        values = self.pattern.new_values()
        target, source = self.gather
        values.reshape(-1)[target] = data[source]
        if self.pattern.block == 3:
            status = sparse_ldl.ldl_factor_3(self.pattern.arrays, values.reshape(-1, 9),
                                          self.l_values.reshape(-1, 9),
                                          self.d_inv.reshape(-1, 9))
        else:
            status = sparse_ldl.factor(self.pattern.arrays, values, self.l_values, self.d_inv)
        if status < 0:
            raise RuntimeError('singular Newton matrix')

    def _solve_in_place(self, x: np.ndarray) -> None:
        if self.pattern.block == 3:
            sparse_ldl.ldl_solve_3(self.pattern.l_ptr, self.pattern.l_row,
                                self.l_values.reshape(-1, 9), self.d_inv.reshape(-1, 9), x)
        else:
            sparse_ldl.solve(self.pattern.arrays, self.l_values, self.d_inv, x)

    def solve(self, b: np.ndarray) -> np.ndarray:
        """A^-1 b for b (n,) or (n, k)."""
        columns = b.reshape(b.shape[0], -1)
        out = np.empty(columns.shape)
        for c in range(columns.shape[1]):
            x = np.ascontiguousarray(columns[self.perm, c], dtype=float)
            self._solve_in_place(x)
            out[self.perm, c] = x
        return out.reshape(b.shape)

    def solve_filtered(self, filters: np.ndarray, b: np.ndarray) -> np.ndarray:
        """A^-1 S b (n,), S the node filters (n_nodes, d, d)."""
        kernels.filter_and_permute(filters, b, self.perm, self._rhs)
        self._solve_in_place(self._rhs)
        x = np.empty(b.shape)
        kernels.unpermute(self._rhs, self.perm, x)
        return x


def _converges_in_time(reduction: float, target: float, iterations: int) -> bool:
    """Whether CG, having reduced a norm by ``reduction`` in ``iterations``, reaches
    ``target`` (a reduction) within ``CG_MAX_ITERATIONS`` at the same geometric rate."""
    if not 0.0 < reduction < 1.0:
        return False
    rate = math.log(reduction) / iterations
    return iterations + math.log(target / reduction) / rate <= CG_MAX_ITERATIONS


def fast_available() -> bool:
    """Whether the numba kernels can be used (numba installed, GRIPPER_SIM_FAST != 0)."""
    return kernels is not None and os.environ.get('GRIPPER_SIM_FAST', '1') != '0'


def as_cone(con: StepConstraints) -> StepConstraints:
    """``con`` with 2D friction (one tangent (k, 2), speeds (k,)) written as a Coulomb
    cone with one tangent ((k, 1, 2), (k, 1)): the same potential, gradient and Hessian."""
    if con.friction_tangents.ndim == 3:
        return con
    return StepConstraints(con.filters, con.friction_nodes, con.friction_tangents[:, None, :],
                           con.friction_bounds, con.friction_obstacle_speed[:, None])


class PatternCachingSolver(ImplicitEulerSolver):
    """``ImplicitEulerSolver`` whose energy Hessians keep one sparsity pattern."""

    def __init__(self, *args, fast: bool | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self._pattern = None  # (signature, inverse, indices, indptr, nnz)
        if fast is None:
            fast = fast_available()
        self.fast = bool(fast and kernels is not None and self.beta == 0
                         and all(hasattr(e, 'evaluate_into') for e in self.energies))
        #: counts of the fast path: Newton solves (contact passes), Newton systems,
        #: (LDL^T) factorisations, CG iterations
        self.stats = dict(passes=0, systems=0, factorisations=0, cg_iterations=0)
        self._lu = None
        self._woodbury = None  # (u, A^-1 u, (C^-1 + u^T A^-1 u)^-1) at the factorisation
        self._stale = False
        self._warm = None  # (q_n, dt, q) of the last solution, to start the next pass
        if self.fast:
            self._build_fast_pattern()

    def load_kernels(self, q: np.ndarray, dt: float) -> None:
        """Run every kernel of the fast path once, on one Newton solve from positions
        ``q`` (n_dof,) m at rest over ``dt`` (s) with a sliding node, and forget it: numba
        loads each kernel's compiled code from its cache on first use (about 10-20 ms
        each), which then happens here, when the simulation is built, and not in its
        first steps (a real-time loop would fall behind there)."""
        if not self.fast:
            return
        d = self.dim
        con = StepConstraints(np.tile(np.eye(d), (self.n // d, 1, 1)), np.zeros(1, np.int64),
                              np.eye(d)[None, 1:], np.zeros(1), np.zeros((1, d - 1)))
        try:
            self.solve(q, np.zeros(self.n), dt, q.copy(), con)
        except NewtonFailure:
            pass
        kernels.cg_direction(np.zeros(1), np.zeros(1), 0.0)  # CG ended in one iteration
        self.reset()
        self.stats = dict.fromkeys(self.stats, 0)

    def reset(self) -> None:
        """Forget the kept factorisation (a restarted simulation repeats its results)."""
        self._lu = None
        self._woodbury = None
        self._warm = None

    def _assemble(self, rows: list, cols: list, vals: list) -> sp.csc_matrix:
        signature = tuple(r.size for r in rows)
        if self._pattern is None or self._pattern[0] != signature:
            r = np.concatenate(rows)
            c = np.concatenate(cols)
            keys = c.astype(np.int64) * self.n + r
            unique, inverse = np.unique(keys, return_inverse=True)
            indices = (unique % self.n).astype(np.int32)
            indptr = np.searchsorted(unique // self.n, np.arange(self.n + 1)).astype(np.int32)
            self._pattern = (signature, inverse.ravel(), indices, indptr, unique.size)
        _, inverse, indices, indptr, nnz = self._pattern
        data = np.bincount(inverse, weights=np.concatenate(vals), minlength=nnz)
        return sp.csc_matrix((data, indices, indptr), shape=(self.n, self.n))

    def _evaluate(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool):
        inertia = q - q_n - dt * v_n
        phi = 0.5 * float(np.sum(self.m * inertia ** 2)) / dt ** 2
        grad = self.m * inertia / dt ** 2
        need = hessian or self.beta > 0
        rows, cols, vals, low_rank = [], [], [], []
        elastic_rows, elastic_cols, elastic_vals = [], [], []
        for energy in self.energies:
            ev = energy.evaluate(q, hessian=need)
            if not np.isfinite(ev.value):
                return np.inf, None, None, None
            phi += ev.value
            grad += ev.gradient
            if need and ev.rows.size:
                rows.append(ev.rows)
                cols.append(ev.cols)
                vals.append(ev.vals)
                if energy.elastic:
                    elastic_rows.append(ev.rows)
                    elastic_cols.append(ev.cols)
                    elastic_vals.append(ev.vals)
            if need:
                low_rank.extend(ev.low_rank)
        dq = q - q_n
        phi += self._mass_damping(dq, dt, grad)
        stiffness = self._assemble(rows, cols, vals) if need and rows else None
        if self.beta > 0 and elastic_rows:
            damping = (stiffness if len(elastic_rows) == len(rows) else
                       sp.coo_matrix((np.concatenate(elastic_vals),
                                      (np.concatenate(elastic_rows),
                                       np.concatenate(elastic_cols))),
                                     shape=(self.n, self.n)).tocsc())
            cdq = damping @ dq
            phi += 0.5 * self.beta * float(dq @ cdq) / dt
            grad += self.beta * cdq / dt
        phi_f, fric_grad, blocks = self._friction(q, q_n, dt, con, grad)
        phi += phi_f
        if not hessian:
            return phi, grad, fric_grad, None
        diag = self.m / dt ** 2 + (self.alpha * self.m / dt if self.alpha > 0 else 0.0)
        hess = sp.diags(np.broadcast_to(diag, (self.n,)).astype(float), format='csc')
        if stiffness is not None:
            hess = hess + stiffness
            if self.beta > 0 and elastic_rows:
                hess = hess + (self.beta / dt) * damping
        k = con.friction_nodes
        if k.size:
            d = self.dim
            dofs = d * k[:, None] + np.arange(d)[None, :]
            hess = hess + sp.csc_matrix(
                (blocks.ravel(), (np.repeat(dofs, d, axis=1).ravel(),
                                  np.tile(dofs, (1, d)).ravel())), shape=(self.n, self.n))
        return phi, grad, fric_grad, (hess.tocsc(), low_rank)

    def _mass_damping(self, dq: np.ndarray, dt: float, grad: np.ndarray) -> float:
        """Rayleigh mass damping alpha M dq^2 / (2 dt) (J); its gradient added to grad."""
        if self.alpha <= 0:
            return 0.0
        grad += self.alpha * self.m * dq / dt
        return 0.5 * self.alpha * float(np.sum(self.m * dq ** 2)) / dt

    def _friction(self, q, q_n, dt: float, con: StepConstraints, grad: np.ndarray):
        """Kinetic friction of the sliding nodes: (potential J, its gradient (n_dof,) N,
        also added to grad, its (k, d, d) Hessian blocks N/m or None)."""
        fric_grad = np.zeros(self.n)
        if not con.friction_nodes.size:
            return 0.0, fric_grad, None
        phi_f, blocks = self._cone_friction(q, q_n, dt, con, fric_grad)
        grad += fric_grad
        return phi_f, fric_grad, blocks

    # ------------------------------------------------------------------ fast path
    def _build_fast_pattern(self) -> None:
        """CSC pattern of every energy's elements plus the diagonal node blocks, the
        scatter index of each energy, and the positions of the d x d node blocks."""
        n = self.n
        d = self.dim
        nodes = n // d
        diag = (d * np.arange(nodes))[:, None] + np.arange(d)[None, :]
        key_sets = [(np.tile(diag, (1, d)) * n + np.repeat(diag, d, axis=1)).ravel()]
        element_keys = []
        for energy in self.energies:
            if energy.dofs is None:
                element_keys.append(None)
                continue
            m = energy.dofs.shape[1]
            keys = np.tile(energy.dofs, (1, m)) * n + np.repeat(energy.dofs, m, axis=1)
            element_keys.append(keys)
            key_sets.append(keys.ravel())
        unique = np.unique(np.concatenate(key_sets))
        self._indices = (unique % n).astype(np.int32)
        self._indptr = np.searchsorted(unique // n, np.arange(n + 1)).astype(np.int32)
        self._nnz = unique.size
        self._scatter = [np.zeros((0, 0), np.int64) if keys is None else
                         np.searchsorted(unique, keys).astype(np.int64)
                         for keys in element_keys]
        col_node, row_node = unique // n // d, unique % n // d
        block_keys = np.unique(col_node * nodes + row_node)
        bcol, brow = block_keys // nodes, block_keys % nodes
        a = np.arange(d)
        keys = ((d * bcol[:, None, None] + a[None, None, :]) * n
                + d * brow[:, None, None] + a[None, :, None])  # [block, row a, col c]
        self._block_pos = np.searchsorted(unique, keys).astype(np.int64)
        self._block_nodes = np.stack([brow, bcol], axis=1).astype(np.int64)
        self._diag_block_pos = self._block_pos[brow == bcol][np.argsort(brow[brow == bcol])]
        self._diag_pos = np.searchsorted(unique, np.arange(n) * n + np.arange(n))
        # the block LDL^T preconditioner in the nested-dissection order of the node graph
        # (dof by dof), and where its blocks come from in the CSC values
        off = brow != bcol
        graph = sp.csr_matrix((np.ones(len(bcol)), (brow, bcol)), shape=(nodes, nodes))
        node_order = nested_dissection(graph)
        self._ldl_pattern = sparse_ldl.analyse(
            nodes, np.stack([brow[off], bcol[off]], axis=1), d, order=node_order)
        index, transposed = self._ldl_pattern.block_index(brow, bcol)
        stored = ~transposed
        target = (d * d * index[stored])[:, None, None] + d * a[:, None] + a[None, :]
        self._ldl_gather = (target.ravel(), self._block_pos[stored].ravel())
        self._perm = (d * node_order[:, None] + a[None, :]).ravel()
        self._matvec_indptr = self._indptr.astype(np.int64)
        self._matvec_indices = self._indices.astype(np.int64)

    def _kink_step(self, q, q_n, dq, dt, con: StepConstraints) -> float:
        """The line search's first step for sliding nodes: a Newton step that turns a
        node's slip velocity s around (s . ds < 0) past the point nearest to zero
        overshoots the kink of the smoothed friction law (its curvature along s is
        eps^2 / |s|^3, next to nothing while |s| >> eps): stop there first."""
        k = con.friction_nodes
        if not k.size:
            return 1.0
        d = self.dim
        t = con.friction_tangents
        s0 = (np.einsum('kad,kd->ka', t, q.reshape(-1, d)[k] - q_n.reshape(-1, d)[k]) / dt
              - con.friction_obstacle_speed)
        ds = np.einsum('kad,kd->ka', t, dq.reshape(-1, d)[k]) / dt
        along = np.sum(s0 * ds, axis=1)
        size = np.sum(ds * ds, axis=1)
        fast = np.sum(s0 * s0, axis=1) > (KINK_FACTOR * FRICTION_SMOOTHING) ** 2
        turning = (along < 0) & (size > 0) & fast
        if not np.any(turning):
            return 1.0
        nearest = -along[turning] / size[turning]
        return float(min(1.0, nearest.min()))

    def _csc(self, data: np.ndarray) -> sp.csc_matrix:
        return sp.csc_matrix((data, self._indices, self._indptr), shape=(self.n, self.n))

    def _evaluate_fast(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool):
        """As ``_evaluate``, with the Hessian as CSC values on the fixed pattern."""
        inertia = q - q_n - dt * v_n
        phi = 0.5 * float(np.sum(self.m * inertia ** 2)) / dt ** 2
        grad = self.m * inertia / dt ** 2
        data = np.zeros(self._nnz if hessian else 1)
        low_rank = []
        for energy, scatter in zip(self.energies, self._scatter):
            value, terms = energy.evaluate_into(q, grad, data, scatter, hessian)
            if not np.isfinite(value):
                return np.inf, None, None, None
            phi += value
            low_rank.extend(terms)
        phi += self._mass_damping(q - q_n, dt, grad)
        k = con.friction_nodes
        fric_grad = np.zeros(self.n)
        if k.size:
            blocks = np.empty((k.size, self.dim, self.dim))
            phi += kernels.cone_friction(
                q.reshape(-1, self.dim), q_n.reshape(-1, self.dim), k.astype(np.int64),
                np.ascontiguousarray(con.friction_tangents, dtype=float),
                np.ascontiguousarray(con.friction_bounds, dtype=float),
                np.ascontiguousarray(con.friction_obstacle_speed, dtype=float), dt,
                FRICTION_SMOOTHING, fric_grad, blocks)
            grad += fric_grad
        if not hessian:
            return phi, grad, fric_grad, None
        diag = self.m / dt ** 2 + (self.alpha * self.m / dt if self.alpha > 0 else 0.0)
        kernels.add_diagonal(data, self._diag_pos, np.ascontiguousarray(diag, dtype=float))
        if k.size:
            kernels.add_node_blocks(data, self._diag_block_pos, k.astype(np.int64),
                                    np.ascontiguousarray(blocks))
        return phi, grad, fric_grad, (data, low_rank)

    def _factorise(self, values: np.ndarray) -> _BlockLDL:
        """The block LDL^T of A (CSC ``values`` on the pattern). Raises RuntimeError
        (singular)."""
        self.stats['factorisations'] += 1
        ldl = _BlockLDL(self._ldl_pattern, self._ldl_gather, self._perm)
        ldl.factorise(values)
        return ldl

    def _linear_solve(self, values: np.ndarray, rhs: np.ndarray, low_rank, fresh: bool,
                      dt: float, filters: np.ndarray):
        """dq with (A + sum c u u^T) dq = rhs (A: CSC ``values`` on the pattern) by
        conjugate gradients preconditioned with the kept LDL^T, factorised afresh when CG
        does not converge fast (or ``fresh``), in the range of the filters S (n_nodes, d,
        d). Raises RuntimeError (singular)."""
        self.stats['systems'] += 1
        u, c = stack_low_rank(low_rank, self.n)
        if self._lu is not None and not fresh and not self._stale:
            dq = self._pcg(values, rhs, u, c, dt, filters)
            if dq is not None:
                return dq
        self._stale = False
        self._lu = self._factorise(values)
        self._woodbury = None
        if c.size:
            # the preconditioner keeps these rank-one terms with the factorisation
            a_inv_u, capacitance = woodbury_terms(self._lu.solve, u, c)
            self._woodbury = (u, a_inv_u, np.linalg.inv(capacitance))
        dq = self._pcg(values, rhs, u, c, dt, filters)
        if dq is not None:
            return dq
        # CG failed even on a fresh factorisation (negative curvature: an indefinite
        # matrix): the factorisation's own solution, refined against the matrix
        precondition = self._preconditioner(u, c)
        dq = precondition(rhs)
        for _ in range(REFINEMENT_SWEEPS):
            dq += precondition(rhs - self._apply(values, u, c, dq))
        return dq

    def _preconditioner(self, u: np.ndarray, c: np.ndarray, filters: np.ndarray | None = None):
        """r -> (kept LDL^T + rank-one terms)^-1 r, projected by the filters S (n_nodes,
        d, d) if given: S (LDL^T + ...)^-1 S r."""
        lu = self._lu
        kept = self._woodbury
        if kept is not None and kept[0].shape[1] == c.size:
            u_w, a_inv_u, small_inv = kept
        elif c.size:
            a_inv_u, capacitance = woodbury_terms(lu.solve, u, c)
            u_w, small_inv = u, np.linalg.inv(capacitance)
        else:
            u_w = None
        if filters is None:
            solve = lu.solve
        else:
            # the system lives in the range of S (its held directions are the identity
            # and the right-hand side is zero there): the preconditioner S P^-1 S is exact
            # on them even when P was factorised with another contact set
            def solve(r):
                return lu.solve_filtered(filters, r)

        def precondition(r):
            y = solve(r)
            if u_w is not None:
                y -= a_inv_u @ (small_inv @ (u_w.T @ y))
            if filters is not None:
                kernels.apply_filters(filters, y.copy(), y)
            return y
        return precondition

    def _apply(self, values: np.ndarray, u: np.ndarray, c: np.ndarray,
               x: np.ndarray) -> np.ndarray:
        """(A + u diag(c) u^T) x, A the CSC ``values`` on the pattern."""
        ax = np.empty(self.n)
        kernels.csc_matvec(self._matvec_indptr, self._matvec_indices, values, x, ax)
        if c.size:
            ax += u @ (c * (u.T @ x))
        return ax

    def _pcg(self, values, rhs, u, c, dt, filters):
        """Preconditioned CG from zero; None if it fails to converge in time."""
        precondition = self._preconditioner(u, c, filters)
        max_abs = kernels.max_abs
        limit = CG_TOLERANCE * max_abs(rhs)
        error_limit = CG_ERROR_FRACTION * self.tolerance * dt
        step_floor = CG_RELATIVE_FLOOR * self.tolerance * dt
        x = np.zeros_like(rhs)
        r = rhs.copy()
        z = precondition(r)
        residual_0, error_0 = max_abs(r), max_abs(z)
        p = z.copy()
        rz = float(r @ z)
        for it in range(1, CG_MAX_ITERATIONS + 1):
            ap = self._apply(values, u, c, p)
            curvature = float(p @ ap)
            if not curvature > 0 or not np.isfinite(curvature):
                self.stats['cg_iterations'] += it
                return None
            residual, largest = kernels.cg_update(x, r, p, ap, rz / curvature)
            if residual <= limit and largest >= step_floor:
                self.stats['cg_iterations'] += it
                self._stale = it > CG_STALE_ITERATIONS
                return x
            z = precondition(r)
            error = max_abs(z)
            if error <= error_limit:
                self.stats['cg_iterations'] += it
                self._stale = it > CG_STALE_ITERATIONS
                return x
            if it == CG_STALE_ITERATIONS and not (
                    _converges_in_time(residual / residual_0, limit / residual_0, it)
                    or _converges_in_time(error / error_0, error_limit / error_0, it)):
                # at this rate neither test would pass in time: factorise now
                self.stats['cg_iterations'] += it
                return None
            rz_new = float(r @ z)
            kernels.cg_direction(z, p, rz_new / rz)
            rz = rz_new
        self.stats['cg_iterations'] += CG_MAX_ITERATIONS
        return None

    def solve(self, q_n: np.ndarray, v_n: np.ndarray, dt: float, q_start: np.ndarray,
              con: StepConstraints) -> StepSolution:
        """``ImplicitEulerSolver.solve`` (same Newton iteration, line search and
        shifts), on the fast path when it applies."""
        con = as_cone(con)
        if not self.fast:
            return super().solve(q_n, v_n, dt, q_start, con)
        self.stats['passes'] += 1
        filters = np.ascontiguousarray(con.filters, dtype=float)
        s_diag = np.einsum('naa->na', filters).ravel()

        def filtered(vec):
            out = np.empty(self.n)
            kernels.apply_filters(filters, np.ascontiguousarray(vec), out)
            return out

        q = q_start.copy()
        history: list[float] = []
        phi = np.inf
        warm = self._warm
        if warm is not None and warm[1] == dt and np.array_equal(warm[0], q_n):
            # another contact pass of the same step: start from the last pass's solution
            # in the free directions, the prescribed values in the held ones
            q = q_start + filtered(warm[2] - q_start)
            phi, grad, _, parts = self._evaluate_fast(q, q_n, v_n, dt, con, hessian=True)
        if not np.isfinite(phi):
            q = q_start.copy()
            phi, grad, _, parts = self._evaluate_fast(q, q_n, v_n, dt, con, hessian=True)
        if not np.isfinite(phi):
            raise NewtonFailure('start of step is infeasible (inverted element)', history)
        out = np.empty(self._nnz)
        reuse = False
        matrix = low = None
        for iteration in range(1, self.max_iterations + 1):
            g_f = filtered(grad)
            if not reuse:
                hdata, low_rank = parts
                low = [(coef, filtered(vec)) for coef, vec in low_rank]

            def solve_shifted(shift):
                nonlocal matrix
                if not (reuse and shift == 0.0):
                    kernels.filter_blocks(hdata, self._block_pos, self._block_nodes,
                                          filters, shift * s_diag * self.m / dt ** 2, out)
                    matrix = out.copy()
                return self._linear_solve(matrix, -g_f, low, shift > 0, dt, filters)

            dq, slope = descent_direction(solve_shifted, g_f, history)
            if kernels.max_abs(dq) / dt < self.tolerance:
                q = q + dq
                _, grad, fric_grad, _ = self._evaluate_fast(q, q_n, v_n, dt, con, False)
                history.append(kernels.max_abs(dq) / dt)
                self._warm = (q_n.copy(), dt, q)
                return StepSolution(q, grad - fric_grad, iteration, history)
            # a full step this large is followed by a new Hessian: the line search's
            # first trial (usually taken) evaluates it with the gradient
            full_step_hessian = (reuse or
                                 kernels.max_abs(dq) / dt >= HESSIAN_REUSE * self.tolerance)
            first_trial = []

            def evaluate(x):
                if full_step_hessian and not first_trial:
                    phi_x, grad_x, _, parts_x = self._evaluate_fast(x, q_n, v_n, dt, con, True)
                    first_trial.append(parts_x)
                    return phi_x, grad_x
                return self._evaluate_fast(x, q_n, v_n, dt, con, False)[:2]

            q, phi, grad, step = line_search(evaluate, q, dq, phi, slope,
                                             kernels.max_abs(g_f), filtered, history,
                                             first_step=min(self.max_step(q, dq),
                                                            self._kink_step(q, q_n, dq, dt,
                                                                            con)))
            norm = step * kernels.max_abs(dq) / dt
            history.append(norm)
            if norm < self.tolerance:
                _, grad, fric_grad, _ = self._evaluate_fast(q, q_n, v_n, dt, con, False)
                self._warm = (q_n.copy(), dt, q)
                return StepSolution(q, grad - fric_grad, iteration, history)
            reuse = not reuse and norm < HESSIAN_REUSE * self.tolerance
            if not reuse:
                if step == 1.0 and first_trial:
                    parts = first_trial[0]
                else:
                    phi, grad, _, parts = self._evaluate_fast(q, q_n, v_n, dt, con, True)
        raise NewtonFailure(f'no convergence in {self.max_iterations} iterations', history)
