"""The compiled barrier solve (``core.barrier_newton``) run from Python: which solvers it
covers (``supports``), the problem and its barriers' parts made once per solver and
kept with it (``_Kept``), and one solve (``run``): the solver's and the barriers' state
handed in, the compiled ``newton.newton_iteration`` called, the state it changed written
back (the kept LDL^T and Woodbury terms, staleness, work counters, candidates, the
barrier's last evaluation).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core import barrier_newton as bn
from gripper_sim.core import newton

#: the candidates' anchor where none are kept; K_n where there is no stiffness damping
_NO_ANCHOR, _NO_STIFFNESS = np.zeros((0, 2)), np.zeros(0)


def supports(solver) -> bool:
    """Whether ``run`` covers the solver's problems (see the module)."""
    from gripper_sim.core.barrier import BarrierContact
    barriers = [energy for energy, _ in solver._untabled]
    return (solver.dim == 2 and 0 < len(barriers) <= 2
            and all(type(b) is BarrierContact and b.dimension == 2 for b in barriers)
            and solver._step_bounding == barriers)


def _part(barrier, scatter):
    """A ``BarrierPart`` of a 2D ``BarrierContact`` and its scatter into the solver's CSC
    values (its per-step fields empty: ``set_part`` sets them)."""
    from gripper_sim.core import barrier as barrier_module

    contact = barrier.settings
    n_v = barrier.vertex_nodes.size
    return bn.new_part((
        barrier._vertex_dof_pairs, barrier._mesh_edges, barrier._mesh_groups,
        barrier.self_contact, contact.dhat, contact.stiffness, barrier._mesh_dofs,
        barrier.projection == barrier_module.ipctk.PSDProjectionMethod.CLAMP,
        barrier._pattern_keys, contact.friction_smoothing,
        0.5 * contact.dhat + barrier_module.CANDIDATE_MARGIN,
        (0.5 + barrier_module.SWEPT_MARGIN) * contact.dhat, barrier_module.CANDIDATE_MARGIN,
        *barrier._gradient_buffers, barrier.drop_outside_pattern, barrier.vertex_body,
        len(barrier.bodies) + 1, barrier.pattern_slots(scatter),
        np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((n_v, 2)), bn.NO_PAIRS,
        barrier_module._NO_FRICTION, False, np.zeros((0, 2)), 0.0, False,
        np.zeros(bn.B_SIZE, np.int64), np.empty(barrier.n_dof), np.empty(2)))


class _Kept:
    """What ``run`` keeps with a solver: the problem (``BarrierProblem``), its barriers'
    parts (``BarrierPart``) and the arrays they share with Python."""

    def __init__(self, solver, settings: 'SolveSettings'):
        from gripper_sim.core.stepper import FRICTION_SMOOTHING

        #: what the problem was made for: each barrier, its scatter, its collision mesh
        self.key = self.key_of(solver)
        n = solver.n
        table = solver._table
        p = table.pressures
        self.lu = solver.empty_factor()
        self.woodbury = (np.empty((n, p)), np.empty((n, p)), np.empty((p, p)))
        #: the solver's Woodbury terms as the last solve left them (their values are those
        #: of ``woodbury``), and the last read-only filters with their copy
        self.woodbury_out = None
        self.filters = (None, None)
        self.parts = tuple(_part(barrier, scatter) for barrier, scatter in solver._untabled)
        #: each part's flags, last positions and values (shared with the part)
        self.part_arrays = tuple(bn.shared_arrays(part) for part in self.parts)
        #: the loop's vectors (5, n), the friction gradient, CG's solution, S g, the
        #: reaction
        self.work = (np.empty((5, n)), np.empty(n), np.empty(n), np.empty(n), np.empty(n))
        self.flags = np.zeros(bn.F_SIZE, np.int64)
        self.stats = np.zeros(bn.S_SIZE, np.int64)
        lu = self.lu
        self.problem = bn.new_problem((
            solver.m, solver.alpha, solver.beta, FRICTION_SMOOTHING,
            settings.keep_below * solver.tolerance,
            (np.zeros(0, np.int64), np.zeros((0, 1, 2)), np.zeros(0), np.zeros((0, 1))),
            (settings.cg_max_iterations, settings.cg_stale_iterations),
            (table.order, table.items, table._coefs, table._vectors, table._scratch_vectors,
             table._dq, np.zeros(p)),
            (solver._matvec_indptr, solver._matvec_indices, solver._hessian_values,
             solver._no_values, solver._k_dq, np.empty((0, 2, 2)), solver._diag_pos,
             solver._diag_block_pos, solver._block_pos, solver._block_nodes,
             solver._node_block_ptr, solver._node_blocks, solver._diag_blocks),
            (solver._perm, lu.arrays, solver._ldl_gather[0], solver._ldl_gather[1],
             lu.l_values, lu.d_inv, np.empty_like(lu.l_values), np.empty_like(lu.d_inv),
             solver._ldl_pattern.n_blocks, *self.woodbury),
            self.parts, self.work,
            (np.empty((2, solver._nnz)), np.empty((2, p, n)), np.empty((2, p)),
             np.zeros(2, np.int64), np.zeros(2)),
            self.flags, self.stats,
            np.zeros(n), np.zeros(n), 1.0, 1.0, np.zeros(0), np.zeros((n // 2, 2, 2)),
            (0.0, 0.0, 0.0)))

    @staticmethod
    def key_of(solver) -> tuple:
        return tuple(x for barrier, scatter in solver._untabled
                     for x in (barrier, scatter, barrier._mesh_edges))


@dataclass(frozen=True)
class SolveSettings:
    """The solver's constants (``fast_solver``'s of the same names in capitals)."""

    keep_below: float
    cg_tolerance: float
    cg_error_fraction: float
    cg_relative_floor: float
    cg_max_iterations: int
    cg_stale_iterations: int


def _set_barrier(part, barrier) -> None:
    """The part's arrays of this step and solve from the barrier's state."""
    from gripper_sim.core.barrier import _NO_FRICTION

    pairs = barrier._pairs
    friction = barrier._friction_pairs
    quiet = barrier._quiet
    bn.set_part(part, barrier._obstacles_end, np.ascontiguousarray(barrier._start),
                pairs[0] if pairs is not None else _NO_ANCHOR, pairs is not None,
                pairs[1] if pairs is not None else bn.NO_PAIRS,
                *(friction if friction is not None else _NO_FRICTION), friction is not None,
                quiet[0] if quiet is not None else _NO_ANCHOR,
                quiet[1] if quiet is not None else 0.0, quiet is not None)


def _read_back(part, arrays, barrier) -> None:
    """The barrier's state after a solve: its candidates if sought again, its last
    evaluation (as ``BarrierContact._terms`` keeps it, for the outputs read at the
    solution)."""
    flags, last_q, (barrier_value, friction_value), anchor = arrays
    if flags[bn.B_PAIRS] == 1:
        barrier._pairs = (anchor.copy(), bn.candidates_of(part), barrier._obstacles_end)
    if flags[bn.B_TERMS]:
        gradients = ((None, None) if flags[bn.B_TERMS] == 1 else
                     (barrier._gradient_buffers[0],
                      barrier._gradient_buffers[1] if barrier._friction_pairs is not None
                      else None))
        barrier._last_terms = (last_q.copy(), float(barrier_value), float(friction_value),
                               *gradients)
    if flags[bn.B_OUTSIDE]:
        raise AssertionError('barrier Hessian entry outside its pattern')


def run(solver, settings: SolveSettings, q_n, v_n, dt, con, q, history):
    """One Newton solve of ``solver`` (``supports``) compiled: (status, iterations,
    len(history), reaction (n_dof,) N or None); ``q`` (n_dof,) m, the start, overwritten
    with the solution. The solver's kept LDL^T, its state and the barriers' candidates
    are read and written back; ``con`` as ``fast_solver.as_cone`` makes it, no sliding
    nodes. Raises AssertionError where a barrier's Hessian falls outside its pattern
    (as the interpreted route does)."""
    kept = getattr(solver, '_compiled_solve', None)
    key = _Kept.key_of(solver)
    if kept is None or len(kept.key) != len(key) or any(
            a is not b for a, b in zip(kept.key, key)):
        kept = solver._compiled_solve = _Kept(solver, settings)
    flags, lu = kept.flags, kept.lu
    flags[:] = 0
    flags[bn.F_KEPT] = flags[bn.F_LAST] = -1
    flags[bn.F_WOODBURY] = -1
    kept.stats[:] = 0
    if solver._lu is not None:
        if solver._lu is not lu:
            lu.l_values[:] = solver._lu.l_values
            lu.d_inv[:] = solver._lu.d_inv
        flags[bn.F_HAS_LU] = 1
        if solver._woodbury is not None:
            if solver._woodbury is not kept.woodbury_out:  # else they hold its values
                for mine, theirs in zip(kept.woodbury, solver._woodbury):
                    mine[:theirs.shape[0], :theirs.shape[1]] = theirs
            flags[bn.F_WOODBURY] = solver._woodbury[0].shape[1]
    flags[bn.F_STALE] = int(solver._stale)
    barriers = [barrier for barrier, _ in solver._untabled]
    for part, barrier in zip(kept.parts, barriers):
        _set_barrier(part, barrier)
    tol = solver.tolerance
    filters = con.filters
    if not filters.flags.writeable:  # a read-only array is typed apart: a copy, kept
        if kept.filters[0] is not filters:
            kept.filters = (filters, filters.copy())
        filters = kept.filters[1]
    stiffness = solver.step_stiffness(q_n) if solver.beta > 0 else _NO_STIFFNESS
    status, iterations, n_hist = bn.solve(
        kept.problem, q_n, v_n, dt, dt ** 2, stiffness, filters, settings.cg_tolerance,
        settings.cg_error_fraction * tol * dt, settings.cg_relative_floor * tol * dt,
        q, tol, solver.max_iterations, history, solver.counts)
    stats = kept.stats
    solver.stats['systems'] += int(stats[bn.S_SYSTEMS])
    solver.stats['factorisations'] += int(stats[bn.S_FACTORS])
    solver.stats['cg_iterations'] += int(stats[bn.S_CG])
    solver._stale = bool(flags[bn.F_STALE])
    if stats[bn.S_FACTORS]:  # the factor and its Woodbury terms are new
        solver._lu = lu
        k = int(flags[bn.F_WOODBURY])
        w_u, w_a_inv_u, w_small_inv = kept.woodbury
        kept.woodbury_out = solver._woodbury = (
            None if k < 0 else
            (w_u[:, :k].copy(), w_a_inv_u[:, :k].copy(), w_small_inv[:k, :k].copy()))
    for part, arrays, barrier in zip(kept.parts, kept.part_arrays, barriers):
        _read_back(part, arrays, barrier)
    reaction = kept.work[4].copy() if status == newton.OK else None
    return status, iterations, n_hist, reaction
