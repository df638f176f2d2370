"""The implicit Euler Newton solver of the simulations (2D and 3D) on a fixed pattern.

The fruit's meshes do not change, so neither do the positions of its energies' Hessian
entries: ``PatternCachingSolver`` finds the CSC pattern once. It is the one solver of
every set-up (the 2D whole-step kernel, ``core.kernels``, does the same step in band
storage); the triplet/SuperLU reference it is tested against is
``test/reference_solver.py``.

Every energy has an ``evaluate_into`` kernel. The solver runs the one Newton iteration
(``core.newton.newton_iteration``, interpreted, on ``_NewtonProblem``) with less work
per iteration:
- the energies add their gradients and Hessians straight into the CSC values through
  precomputed scatter indices (``core.energies.kernels``, ``core3d.kernels``); the
  inertia and the leading 2D rod energies, pressure and gravity are one call
  (``core.energy_table``), and
  S H S + (I - S) is one kernel over the d x d node blocks (``core.solver_kernels``), on
  the same pattern; kinetic friction is the Coulomb cone of the stepper, a 2D tangent
  being a cone with one tangent;
- each Newton system is solved by conjugate gradients (one compiled call,
  ``core.linear_solve``, which keeps the preconditioner) preconditioned with a block
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
  the directions the new filter leaves free); the iteration keeps the Newton matrix
  (its chord rule) after steps below ``KEEP_BELOW`` times the tolerance, within a solve,
  and a larger step's first line-search trial evaluates the Hessian with the gradient;
- the line search starts where a sliding node's slip velocity, turning round, comes
  nearest to zero (``kink_step``: past it the step overshoots the kink of the smoothed
  friction law and the search halves it again and again).
It follows the reference to the Newton tolerance over a grasp
(test/test_3d_energies.py::test_fast_solver_follows_the_numpy_reference_path).
"""
from __future__ import annotations

import math
import operator

import numpy as np
import scipy.sparse as sp

from gripper_sim.core import barrier_newton, barrier_solve, linear_solve, newton, sparse_ldl
from gripper_sim.core import solver_kernels as kernels
from gripper_sim.core.barrier_kernels import same_values
from gripper_sim.core.energies.base import Energy
from gripper_sim.core.energy_table import EnergyTable
from gripper_sim.core.pattern_keys import sorted_unique
from gripper_sim.core.stepper import (FRICTION_SMOOTHING, NEWTON_FAILURES, NewtonFailure,
                                      StepConstraints, StepProblem, StepSolution)

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
#: the Newton matrix is kept only after a step below this multiple of the tolerance
#: (near convergence the Hessian barely changes; farther, a new one pays)
KEEP_BELOW = 100.0
#: a sliding node's Newton step is cut at the kink of the friction law only if it
#: slips faster than this multiple of the smoothing speed (slower: inside the kink)
KINK_FACTOR = 10.0
#: a solve still converging at its iteration limit goes on from where it is, before its
#: step is halved: while its last PROGRESS_SPAN steps shrank by PROGRESS_FACTOR or more
#: (a linear convergence: pressed barrier pairs whose negative curvature the Newton
#: matrix leaves out), up to EXTENDED_LIMIT times the limit in all
PROGRESS_SPAN = 5
PROGRESS_FACTOR = 0.5
EXTENDED_LIMIT = 4
#: whether the 2D barrier model's Newton solves run compiled (``core.barrier_newton``)
#: where it covers them (``barrier_solve.supports``); the interpreted route serves the
#: rest (energies outside the energy table besides the barriers, steps with sliding
#: nodes, the mmm model's shared route, 3D). False: interpreted everywhere (the tests
#: compare the two)
COMPILED_BARRIER_SOLVE = True
#: whether a compiled barrier solve of a solver made with ``carry_newton_matrix`` (the
#: deformable fingers', ``SimulationFacade._make_solver``) starts with the Newton matrix
#: the last one kept, where it fits (``barrier_newton.solve_from``: the same dt and
#: filters, at most ``newton.MAX_FACTOR_AGE`` solves old): its first step a chord step.
#: The interpreted route makes a new matrix for each solve (False: the compiled route
#: too; the tests compare the two). The Fin Ray's grasp-and-lift at 4 N: 468 Hessian
#: evaluations instead of 1252 (15 N: 672, 1435), 1736 Newton systems instead of 1716,
#: ~11 % less time in its solves; its grip and peak pressure in the lift and hold the
#: same to 6 digits (the grip read off the fingers' bases). Rigid faces keep a new
#: matrix per solve: their grip is read off the barrier itself, and the chord steps'
#: looser last iterates let the ipc drive's grip swing further (the shell apple's lift
#: at 20 N: +3.1 % against +0.8 %)
CARRY_NEWTON_MATRIX = True
#: the stiffness damping's K_n without stiffness damping (beta = 0)
_NO_STIFFNESS = np.zeros(0)
#: no alternative start (``barrier_newton.solve_from``)
_NO_START = np.zeros(0)
#: the constants above as the compiled barrier solve takes them
_COMPILED_SETTINGS = barrier_solve.SolveSettings(
    KEEP_BELOW, CG_TOLERANCE, CG_ERROR_FRACTION, CG_RELATIVE_FLOOR)


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


def as_cone(con: StepConstraints) -> StepConstraints:
    """``con`` with 2D friction (one tangent (k, 2), speeds (k,)) written as a Coulomb
    cone with one tangent ((k, 1, 2), (k, 1)): the same potential, gradient and Hessian;
    its arrays contiguous, the nodes int64, the rest float (as the kernels take them)."""
    tangents, speed = con.friction_tangents, con.friction_obstacle_speed
    if tangents.ndim == 2:
        tangents, speed = tangents[:, None, :], speed[:, None]
    return StepConstraints(np.ascontiguousarray(con.filters, dtype=float),
                           np.ascontiguousarray(con.friction_nodes, dtype=np.int64),
                           np.ascontiguousarray(tangents, dtype=float),
                           np.ascontiguousarray(con.friction_bounds, dtype=float),
                           np.ascontiguousarray(speed, dtype=float))


def still_converging(steps: list) -> bool:
    """Whether a solve's Newton steps (max |dq| / dt of each, m/s) shrank by
    ``PROGRESS_FACTOR`` or more over the last ``PROGRESS_SPAN`` of them."""
    return (len(steps) > PROGRESS_SPAN
            and steps[-1] <= PROGRESS_FACTOR * steps[-1 - PROGRESS_SPAN])


class PatternCachingSolver:
    """The implicit Euler step's Newton solver (see the module docstring).

    Args:
        masses: (n_nodes,) kg.
        energies: internal and external potential energies, each with an
            ``evaluate_into`` kernel (``energies.base.KernelEnergy``).
        damping_mass: Rayleigh alpha (1/s).  damping_stiffness: Rayleigh beta (s),
            applied to the Hessian of the elastic energies.
        tolerance: m/s, stop when max |dq| / dt falls below it.
        max_iterations: Newton iterations before NewtonFailure.
        dim: 2 (planar) or 3, the coordinates per node.
        carry_newton_matrix: a compiled barrier solve starts with the Newton matrix the
            last one kept, where it fits (``CARRY_NEWTON_MATRIX``).
    """

    def __init__(self, masses: np.ndarray, energies: list[Energy], damping_mass: float = 0.0,
                 damping_stiffness: float = 0.0, tolerance: float = 1e-6,
                 max_iterations: int = 25, dim: int = 2, carry_newton_matrix: bool = False):
        self.dim = int(dim)
        self.carry_newton_matrix = carry_newton_matrix
        self.m = np.repeat(np.asarray(masses, dtype=float), self.dim)
        self.energies = list(energies)
        for energy in self.energies:
            if not hasattr(energy, 'evaluate_into'):
                raise TypeError(f'{type(energy).__name__} has no evaluate_into kernel: '
                                'every energy of the solver needs one')
        self.alpha = damping_mass
        self.beta = damping_stiffness
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.n = self.m.size
        self._passes = 0  # Newton solves (contact passes)
        #: the Newton iteration's work counters (``newton.C_*``)
        self.counts = np.zeros(newton.C_SIZE, np.int64)
        self._warm = None  # (q_n, dt, q) of the last solution, to start the next pass
        self._stiffness = None  # (q_n, K_n CSC values) of the stiffness damping
        self._compiled = None  # the compiled barrier solve (``compiled_arguments``)
        #: (constraints, their arrays, their ``as_cone``) of the last solve
        self._cone_kept = None
        self._build_fast_pattern()
        #: the Newton systems' solve with its kept preconditioner (``core.linear_solve``)
        self.linear = linear_solve.new_state(
            self._matvec_indptr, self._matvec_indices, self._perm, self._ldl_pattern,
            self._ldl_gather, CG_MAX_ITERATIONS, CG_STALE_ITERATIONS)
        self._linear_stats = self.linear.stats
        self._table = EnergyTable(self.energies, self._scatter, self.dim, self.n)
        #: the energies after the table's, with their scatter indices
        self._untabled = list(zip(self.energies[self._table.count:],
                                  self._scatter[self._table.count:]))
        #: ``evaluate_fast``'s arrays: the CSC values of its last Hessian, the values
        #: an evaluation without the Hessian is given, K_n dq (n_dof,) N, the sliding
        #: nodes' friction blocks (k, d, d) N/m
        self._hessian_values = np.empty(self._nnz)
        self._no_values = np.zeros(1)
        self._k_dq = np.empty(self.n)
        self._friction_blocks = np.empty((0, self.dim, self.dim))
        #: the energies that may bound a step (``max_step`` not the base's 1)
        self._step_bounding = [e for e in self.energies
                               if type(e).max_step is not Energy.max_step]
        #: whether the compiled barrier solve covers this solver's energies
        #: (``compiled_solve_covers``; they do not change)
        self._compiled_covers = barrier_solve.supports(
            self.dim, [e for e, _ in self._untabled], self._step_bounding)
        #: the Newton matrix's diagonal term without a shift (read only)
        self.no_shift = np.zeros(self.n)

    def load_kernels(self, q: np.ndarray, dt: float) -> None:
        """Run every kernel of the solver once, on one Newton solve from positions
        ``q`` (n_dof,) m at rest over ``dt`` (s) with a sliding node, and forget it: numba
        loads each kernel's compiled code from its cache on first use (about 10-20 ms
        each), which then happens here, when the simulation is built, and not in its
        first steps (a real-time loop would fall behind there)."""
        d = self.dim
        con = StepConstraints(np.tile(np.eye(d), (self.n // d, 1, 1)), np.zeros(1, np.int64),
                              np.eye(d)[None, 1:], np.zeros(1), np.zeros((1, d - 1)))
        try:
            self.solve(q, np.zeros(self.n), dt, q.copy(), con)
        except NewtonFailure:
            pass
        self.reset()
        self._passes = 0
        self._linear_stats[:] = 0
        self.counts[:] = 0

    @property
    def stats(self) -> dict:
        """Counts: Newton solves (contact passes), Newton systems, (LDL^T)
        factorisations, CG iterations."""
        s = self._linear_stats
        return dict(passes=self._passes, systems=int(s[linear_solve.S_SYSTEMS]),
                    factorisations=int(s[linear_solve.S_FACTORS]),
                    cg_iterations=int(s[linear_solve.S_CG]))

    def reset(self) -> None:
        """Forget the kept factorisation (a restarted simulation repeats its results)."""
        linear_solve.forget(self.linear)
        if self._compiled is not None:
            self._compiled.forget()
        self._warm = None
        self._stiffness = None

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The line search's first step: 1, or less where an energy bounds it (a contact
        barrier: the continuous-collision step, ``Energy.max_step``)."""
        return min([1.0] + [energy.max_step(q, dq) for energy in self._step_bounding])

    # ------------------------------------------------------------------ the pattern
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
        unique = sorted_unique(np.concatenate(key_sets))
        self._indices = (unique % n).astype(np.int32)
        self._indptr = np.searchsorted(unique // n, np.arange(n + 1)).astype(np.int32)
        self._nnz = unique.size
        self._scatter = [np.zeros((0, 0), np.int64) if keys is None else
                         np.searchsorted(unique, keys).astype(np.int64)
                         for keys in element_keys]
        col_node, row_node = unique // n // d, unique % n // d
        block_keys = sorted_unique(col_node * nodes + row_node)
        bcol, brow = block_keys // nodes, block_keys % nodes
        a = np.arange(d)
        keys = ((d * bcol[:, None, None] + a[None, None, :]) * n
                + d * brow[:, None, None] + a[None, :, None])  # [block, row a, col c]
        self._block_pos = np.searchsorted(unique, keys).astype(np.int64)
        self._block_nodes = np.stack([brow, bcol], axis=1).astype(np.int64)
        self._diag_block_pos = self._block_pos[brow == bcol][np.argsort(brow[brow == bcol])]
        # each node's blocks (as row or column, the diagonal once) in CSR, its diagonal one
        off = brow != bcol
        blocks = np.arange(brow.size)
        owner = np.concatenate([brow, bcol[off]])
        order = np.argsort(owner, kind='stable')
        self._node_blocks = np.concatenate([blocks, blocks[off]])[order]
        self._node_block_ptr = np.searchsorted(owner[order], np.arange(nodes + 1))
        self._diag_blocks = blocks[brow == bcol][np.argsort(brow[brow == bcol])]
        self._diag_pos = np.searchsorted(unique, np.arange(n) * n + np.arange(n))
        # the block LDL^T preconditioner in the nested-dissection order of the node graph
        # (dof by dof), and where its blocks come from in the CSC values
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

    def kink_step(self, q, q_n, dq, dt, con: StepConstraints) -> float:
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

    def step_stiffness(self, q_n: np.ndarray) -> np.ndarray:
        """K_n, the elastic energies' Hessian at the step's start ``q_n`` (n_dof,) m
        without their rank-one terms, as CSC values on the pattern (N/m): the matrix of
        the stiffness damping. Kept for the step (its contact passes share q_n)."""
        kept = self._stiffness
        if kept is not None and np.array_equal(kept[0], q_n):
            return kept[1]
        data = np.zeros(self._nnz)
        scratch = np.zeros(self.n)
        for energy, scatter in zip(self.energies, self._scatter):
            if energy.elastic:
                energy.evaluate_into(q_n, scratch, data, scatter, True)
        self._stiffness = (q_n.copy(), data)
        return data

    def evaluate_fast(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool,
                      grad=None, fric_grad=None):
        """The incremental potential Phi (J), its gradient (n_dof,) N, the friction part
        of the gradient (n_dof,) N, and, with ``hessian``, the Hessian parts: (CSC values
        on the fixed pattern, the energies' rank-one terms [(c, u)]; the solver's own
        arrays, valid until its next evaluation with the Hessian).
        ``grad`` and ``fric_grad`` (n_dof,), if given, are written instead of new arrays
        (the Newton iteration's own vectors); where Phi is inf they hold no result.

        Rayleigh stiffness damping (beta > 0) adds beta dq^T K_n dq / (2 dt), dq = q - q_n,
        K_n the elastic energies' Hessian at q_n (``step_stiffness``): a quadratic in q,
        so its gradient beta K_n dq / dt and Hessian beta K_n / dt are exact.
        Inertia, damping and friction are ``core.potential_terms``', as in the 2D
        whole-step kernel; the inertia and the leading 2D energies (rods, pressure,
        gravity) are one kernel call (``energy_table``), the other energies (the
        barrier, 3D ones) one call each, and the terms after the energies one call
        (``solver_kernels.add_step_terms``)."""
        if grad is None:
            grad = np.empty(self.n)
        if fric_grad is None:
            fric_grad = np.empty(self.n)
        data = self._hessian_values if hessian else self._no_values
        table = self._table
        phi, dq, low_rank = table.potential(q, q_n, v_n, dt, self.m, self.alpha, hessian,
                                            grad, data)
        if not math.isfinite(phi):
            return np.inf, None, None, None
        for energy, scatter in self._untabled:
            value, terms = energy.evaluate_into(q, grad, data, scatter, hessian)
            if not math.isfinite(value):
                return np.inf, None, None, None
            phi += value
            low_rank.extend(terms)
        stiffness = self.step_stiffness(q_n) if self.beta > 0 else _NO_STIFFNESS
        if con.friction_tangents.ndim == 2:
            con = as_cone(con)  # (``solve`` converts it once for its evaluations)
        k = con.friction_nodes
        blocks = self._friction_blocks
        if blocks.shape[0] != k.size:
            blocks = self._friction_blocks = np.empty((k.size, self.dim, self.dim))
        phi = kernels.add_step_terms(
            phi, hessian, q, q_n, dq, dt, self.m, self.alpha, self.beta,
            self._matvec_indptr, self._matvec_indices, stiffness, self._k_dq, k,
            con.friction_tangents, con.friction_bounds, con.friction_obstacle_speed,
            FRICTION_SMOOTHING, self._diag_pos, self._diag_block_pos, grad, fric_grad,
            blocks, data)
        return phi, grad, fric_grad, (data, low_rank) if hessian else None

    def newton_matrix(self, hdata: np.ndarray, filters: np.ndarray,
                      diagonal: np.ndarray) -> np.ndarray:
        """CSC values of S H S + (I - S) + diag(``diagonal`` (n_dof,)), H the CSC values
        ``hdata`` on the pattern, S the node filters (n_nodes, d, d)."""
        out = np.empty(self._nnz)
        kernels.filter_blocks(hdata, self._block_pos, self._block_nodes, self._node_block_ptr,
                              self._node_blocks, self._diag_blocks, filters, diagonal, out)
        return out

    def linear_solve(self, values: np.ndarray, rhs: np.ndarray, low_rank: tuple,
                     fresh: bool, dt: float, filters: np.ndarray) -> np.ndarray:
        """dq with (A + u diag(c) u^T) dq = rhs (A: CSC ``values`` on the pattern, the
        rank-one terms ``low_rank`` = (u (n, k), c (k,), u^T (k, n)), C order) in the
        range of the filters S (n_nodes, d, d), by ``core.linear_solve`` (its kept
        preconditioner factorised afresh if ``fresh``). Raises RuntimeError (singular)."""
        u, c, u_t = low_rank
        dq = np.empty(self.n)
        if not linear_solve.solve(self.linear, values, rhs, u, c, u_t, filters, CG_TOLERANCE,
                                  CG_ERROR_FRACTION * self.tolerance * dt,
                                  CG_RELATIVE_FLOOR * self.tolerance * dt, fresh, dq):
            raise RuntimeError('singular Newton matrix')
        return dq

    def solve(self, q_n: np.ndarray, v_n: np.ndarray, dt: float, q_start: np.ndarray,
              con: StepConstraints, alternative: np.ndarray | None = None) -> StepSolution:
        """One implicit Euler step: ``newton.newton_iteration`` on this solver's pattern
        (interpreted on a ``_NewtonProblem``, or compiled where ``compiled_arguments``
        covers the step: ``barrier_newton.solve_from``), from ``q_start`` (n_dof,) m or,
        where the incremental potential is lower there, ``alternative`` (n_dof,) m
        (``newton.lower_start``). A later contact pass of the same step starts from the
        last pass's solution in the directions the new filter leaves free. A solve still
        converging at ``max_iterations`` goes on (``PROGRESS_SPAN``).

        Raises:
            NewtonFailure: no convergence, no descent, or an infeasible start.
        """
        con = self._cone(con)
        self._passes += 1
        arguments = self.compiled_arguments(q_n, v_n, dt, con)
        if arguments is not None:
            q = np.empty(self.n)
            status, iterations, n_done = barrier_newton.solve_from(
                *arguments, q_start, _NO_START if alternative is None else alternative, q)
            done = arguments[-2][:n_done]  # (``solve_from``'s steps)
            reaction = self.compiled_finished(q_n, dt, q, status, iterations, done)
            return StepSolution(q, reaction.copy(), iterations, done.tolist())
        problem = _NewtonProblem(self, q_n, v_n, dt, con)
        history = np.zeros(self.max_iterations)
        warm = self._warm
        status = newton.INFEASIBLE_START
        if warm is not None and warm[1] == dt and same_values(warm[0], q_n):
            q = q_start + problem.filtered(warm[2] - q_start)
            status, iterations, n_hist = self._iterate(problem, q, history)
        if status == newton.INFEASIBLE_START:
            q = q_start.copy()
            status, iterations, n_hist = self._iterate(problem, q, history, alternative)
        done = history[:n_hist].tolist()
        while (status == newton.NO_CONVERGENCE and still_converging(done)
               and iterations < EXTENDED_LIMIT * self.max_iterations):
            status, more, n_hist = self._iterate(problem, q, history)
            iterations += more
            done += history[:n_hist].tolist()
        if status != newton.OK:
            raise NewtonFailure(NEWTON_FAILURES[status].format(iterations), done)
        self._warm = (q_n.copy(), dt, q)
        return StepSolution(q, problem.reaction, iterations, done)

    def compiled_arguments(self, q_n: np.ndarray, v_n: np.ndarray, dt: float,
                           con: StepConstraints) -> tuple | None:
        """Where the compiled barrier solve covers this solver and the step's constraints
        ``con`` (``as_cone``'s; ``compiled_solve_covers``): ``barrier_newton.solve_from``'s
        arguments up to its ``progress`` for a solve from positions ``q_n``, velocities
        ``v_n`` (n_dof,) over dt s (``barrier_solve.CompiledSolve.arguments``); after
        the call, ``compiled_finished``. Else None."""
        if not (COMPILED_BARRIER_SOLVE and self.compiled_solve_covers(con)):
            return None
        compiled = self._compiled
        if compiled is None or not compiled.fits(self._untabled):
            pattern = (self._matvec_indptr, self._matvec_indices, self._hessian_values,
                       self._no_values, self._k_dq, np.empty((0, 2, 2)), self._diag_pos,
                       self._diag_block_pos, self._block_pos, self._block_nodes,
                       self._node_block_ptr, self._node_blocks, self._diag_blocks)
            compiled = self._compiled = barrier_solve.CompiledSolve(
                _COMPILED_SETTINGS, self.m, self.alpha, self.beta, self.tolerance,
                self._table, pattern, self.linear, self._untabled)
        stiffness = self.step_stiffness(q_n) if self.beta > 0 else _NO_STIFFNESS
        warm = self._warm
        return compiled.arguments(q_n, v_n, dt, con, stiffness, self.max_iterations,
                                  self.counts, warm if warm is not None and warm[1] == dt
                                  else None, (PROGRESS_SPAN, PROGRESS_FACTOR, EXTENDED_LIMIT),
                                  CARRY_NEWTON_MATRIX and self.carry_newton_matrix)

    def compiled_finished(self, q_n: np.ndarray, dt: float, q: np.ndarray, status: int,
                          iterations: int, done: np.ndarray) -> np.ndarray:
        """After a ``barrier_newton.solve_from`` call from ``q_n`` over dt s with the
        ``compiled_arguments``, which wrote the solution ``q`` (n_dof,) m and returned
        ``status`` and ``iterations`` and the steps ``done`` (m/s): the solve's reaction
        (n_dof,) N (valid until the next solve), ``q`` the next solve's warm start.

        Raises:
            NewtonFailure: the status is not ``newton.OK``.
            AssertionError: a barrier's Hessian fell outside its pattern.
        """
        reaction = self._compiled.finished()
        if status != newton.OK:
            raise NewtonFailure(NEWTON_FAILURES[status].format(iterations), done.tolist())
        self._warm = (q_n.copy(), dt, q)
        return reaction

    def _cone(self, con: StepConstraints) -> StepConstraints:
        """``as_cone(con)``, kept while the same constraints come with the same arrays (a
        barrier step's are the same every step: ``barrier._free``, ``_prescribed``)."""
        arrays = (con.filters, con.friction_nodes, con.friction_tangents, con.friction_bounds,
                  con.friction_obstacle_speed)
        kept = self._cone_kept
        if (kept is None or kept[0] is not con
                or not all(map(operator.is_, arrays, kept[1]))):
            kept = self._cone_kept = (con, arrays, as_cone(con))
        return kept[2]

    def compiled_solve_covers(self, con: StepConstraints | None = None) -> bool:
        """Whether the compiled barrier solve (``barrier_solve``) covers this solver's
        problems (and the step's constraints ``con``: no sliding nodes)."""
        return self._compiled_covers and (con is None or not con.friction_nodes.size)

    def _iterate(self, problem, q: np.ndarray, history: np.ndarray,
                 alternative: np.ndarray | None = None):
        """``newton.newton_iteration`` interpreted on the ``_NewtonProblem`` ``problem``
        from ``q`` (overwritten; first set to ``alternative`` where the potential is
        lower, ``newton.lower_start``). (status, iterations, n_hist)."""
        if alternative is not None:
            newton.lower_start.py_func(problem, q, alternative, self.counts)
        return newton.newton_iteration_interpreted(problem, q, problem.dt, self.tolerance,
                                                   self.max_iterations, history, self.counts)


def _filtered(filters: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """S vec (n_dof,) with the filters S (n_nodes, d, d)."""
    out = np.empty(vec.size)
    kernels.apply_filters(filters, np.ascontiguousarray(vec), out)
    return out


class _NewtonProblem(StepProblem):
    """One ``PatternCachingSolver.solve``'s problem for ``newton.newton_iteration``: its
    hooks as methods (see ``core.newton``). The Newton matrix is the CSC values of
    S H S + (I - S) + shift S M / dt^2 with the energies' rank-one terms, solved by the
    solver's preconditioned CG (``linear_solve``, whose LDL^T preconditioner is kept
    from solve to solve). The kept Newton matrix serves this solve only, after steps
    below ``KEEP_BELOW`` times the tolerance: a solve's first step is far larger, and
    a matrix kept from the last solve took 15 % more Newton systems on the solid apple's
    grasp (bench_3d).

    Args:
        solver: the ``PatternCachingSolver``.
        q_n, v_n: (n_dof,) m, m/s at the start of the step.  dt: s.
        con: the step's constraints, 2D friction as a cone, arrays as the kernels take
            them (``as_cone``).
    """

    def __init__(self, solver: PatternCachingSolver, q_n: np.ndarray, v_n: np.ndarray,
                 dt: float, con: StepConstraints):
        super().__init__(solver, q_n, v_n, dt, con, solver.evaluate_fast)
        self.filters = con.filters
        self.fric_grad = np.empty(solver.n)  # the friction gradient of the last evaluation
        self._filtered = np.empty(solver.n)
        self.matrix = self.low = None
        self.shift = 0.0
        self.kept = None  # (CSC values, rank-one terms) of the kept Newton matrix

    def filtered(self, vec: np.ndarray) -> np.ndarray:
        """S vec (n_dof,)."""
        return _filtered(self.filters, vec)

    def evaluate(self, x, hessian, grad) -> float:
        """Phi at x (inf: infeasible), its gradient written into ``grad`` and the
        friction's into ``fric_grad`` by the solver itself (no copies)."""
        phi, _, _, parts = self.solver.evaluate_fast(x, self.q_n, self.v_n, self.dt,
                                                     self.con, bool(hessian), grad=grad,
                                                     fric_grad=self.fric_grad)
        if not math.isfinite(phi):
            return np.inf
        if hessian:
            self.parts = parts
        return phi

    def _filtered_low_rank(self, low_rank: list) -> tuple:
        """The rank-one terms [(c_j, u_j)] filtered and stacked once for every system with
        the matrix: (S u (n, k), c (k,), (S u)^T (k, n)), C order; k may be 0."""
        k, n = len(low_rank), self.solver.n
        u_t, c = np.empty((k, n)), np.empty(k)
        for j, (coef, vec) in enumerate(low_rank):
            c[j] = coef
            kernels.apply_filters(self.filters, vec, u_t[j])
        return np.ascontiguousarray(u_t.T), c, u_t

    def kept_fits(self) -> bool:
        return False  # a new solve: nothing kept (``keep``)

    def project(self, grad, g_f) -> None:
        kernels.apply_filters(self.filters, grad, g_f)

    def forget(self) -> None:
        self.kept = None

    def keep(self) -> None:
        self.kept = (self.matrix, self.low)

    def factorise(self, x, shift) -> bool:
        solver = self.solver
        hdata, low_rank = self.parts
        diagonal = solver.no_shift
        if shift:
            s_diag = np.einsum('naa->na', self.filters).ravel()
            diagonal = shift * s_diag * solver.m / self.dt ** 2
        self.matrix = solver.newton_matrix(hdata, self.filters, diagonal)
        self.low = self._filtered_low_rank(low_rank)
        self.shift = shift
        return True

    def direction(self, g_f, dq, fresh) -> tuple[bool, float]:
        if fresh:
            matrix, low, refactor = self.matrix, self.low, self.shift > 0
        else:
            (matrix, low), refactor = self.kept, False
        try:
            x = self.solver.linear_solve(matrix, -g_f, low, refactor, self.dt, self.filters)
        except RuntimeError:  # a singular factor
            return False, 0.0
        dq[:] = x
        slope = float(g_f @ x)
        return math.isfinite(slope), slope  # a non-finite entry of x makes the slope one

    def definite(self) -> bool:
        return linear_solve.not_known_indefinite(self.solver.linear)

    def step_bound(self, x, dq) -> float:
        return min(self.solver.max_step(x, dq),
                   self.solver.kink_step(x, self.q_n, dq, self.dt, self.con))

    def keep_limit(self) -> float:
        return KEEP_BELOW * self.solver.tolerance

    def filtered_max(self, g) -> float:
        kernels.apply_filters(self.filters, g, self._filtered)
        return kernels.max_abs(self._filtered)

    def finish(self, x, grad) -> None:
        self.reaction = grad - self.fric_grad
