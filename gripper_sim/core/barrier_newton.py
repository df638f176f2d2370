"""The 2D barrier model's Newton solve as one compiled call (a prototype, off by default).

``fast_solver.PatternCachingSolver.solve`` runs ``newton.newton_iteration`` interpreted
on ``_NewtonProblem`` for the barrier model (``contact.model: ipc``): every hook is a
Python method calling a kernel. Here the same iteration runs compiled: its hooks are
overloads (``numba.extending.overload``) for ``BarrierProblemType``, a numba StructRef
(a StructRef and not a tuple: ``core.kernels`` registers its hooks for every tuple
type, and numba takes the first overload that types). The problem holds the solver's
arrays (energy table, CSC pattern and Hessian values, block LDL^T and Woodbury terms,
the two Newton matrix slots, work vectors) and one ``BarrierPart`` per barrier energy
(its collision mesh, candidates, lagged friction, quiet region, pattern slots); both
are made once per solver (``barrier_solve``, which runs a solve from Python) and a
solve sets only its own arrays (``solve``, ``set_part``: flat arguments, as numba
types a tuple argument in Python at ~2 ms for the problem's). Each hook calls the
kernels the interpreted route calls, in the same order on the same arrays, so a solve
gives the same iterates to the last bit
(``test/test_barrier_newton.py``: the ring, the membrane, the apple with friction and
the pressure's rank-one term, the Fin Ray grasp):

- ``evaluate``: ``energy_table.inertia_and_energies``; per barrier its quiet test
  (self-contact, ``barrier_kernels.relative_moves_within``), its candidates (kept while
  no vertex moves further than ``barrier.CANDIDATE_MARGIN`` from where they were sought,
  else sought again by ``barrier_search.edge_vertex_candidates``, as
  ``BarrierContact._candidate_pairs``), ``barrier_terms.barrier_terms``; then
  ``solver_kernels.add_step_terms``;
- ``factorise``: ``solver_kernels.filter_blocks`` into a matrix slot, the pressures'
  rank-one terms filtered;
- ``direction``: ``PatternCachingSolver.linear_solve``: ``pcg_kernels.preconditioned_cg``
  on the kept block LDL^T, refactorised by ``sparse_ldl.factor`` when stale, the
  Woodbury terms made with it, the refinement when CG fails on a fresh factor;
- ``step_bound``: per barrier ``barrier_kernels.kept_step_bound``, else the swept boxes'
  candidates and ``barrier_search.collision_free_step`` (``BarrierContact._step_bound``).

Nothing leaves the compiled loop: the candidates' refresh and the refactorisation are
compiled too. What the solve changes of the solver's and the barriers' state (the kept
LDL^T, Woodbury terms and staleness, the work counters, the candidates, the last
evaluation ``contact_forces`` reuses) is written back after the call
(``barrier_solve.run``). A Hessian entry outside a barrier's pattern (where it does not
drop them) is flagged and ``run`` raises AssertionError, as the interpreted route does
at once.

Covered (``barrier_solve.supports``): a 2D solver whose energies after the table are
one or two ``BarrierContact`` (the fruit's, with rigid faces or soft bodies; a
self-contact), and steps with no sliding nodes (the barrier model's steps; a sliding
node needs the line search's ``kink_step``). These run compiled by default
(``fast_solver.COMPILED_BARRIER_SOLVE``); the interpreted route serves the rest until this
one covers it too.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.experimental import structref
from numba.extending import overload

from gripper_sim.core import linear_solve, newton
from gripper_sim.core.barrier_kernels import (kept_step_bound, largest_move,
                                              relative_moves_within)
from gripper_sim.core.barrier_search import collision_free_step, edge_vertex_candidates
from gripper_sim.core.barrier_terms import barrier_terms
from gripper_sim.core.energy_table import inertia_and_energies
from gripper_sim.core.solver_kernels import add_step_terms, apply_filters, filter_blocks, max_abs

#: ``solve``'s status beyond ``newton``'s: a barrier Hessian entry outside its pattern
OUTSIDE_PATTERN = 100

#: flags (int64 array): the slot of the kept Newton matrix (-1: none), of the last
#: factorised one
F_KEPT, F_LAST, F_SIZE = range(3)
#: a barrier's flags (int64 array): its candidates (-1: none kept, 0: kept, 1: sought
#: again in this solve), its Hessian entries outside the pattern (not dropped), its last
#: finite evaluation (0: none in this solve (or quiet), 1: no pairs, 2: terms)
B_PAIRS, B_OUTSIDE, B_TERMS, B_SIZE = range(4)
#: the candidates where none are kept
NO_PAIRS = np.zeros((0, 2), np.int64)


@structref.register
class BarrierProblemType(types.StructRef):
    """The numba type of ``BarrierProblem``."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


@structref.register
class BarrierPartType(types.StructRef):
    """The numba type of ``BarrierPart``."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


#: the problem's fields. Kept with the solver (``barrier_solve``): masses (n,) kg per dof,
#: Rayleigh alpha 1/s and beta s, the friction smoothing m/s, the keep limit m/s, the
#: (empty) sliding nodes' arrays; ``table``: the energy table's order, items, pressure
#: coefficients and dA/dq (with and without the Hessian), dq, the coefficients of the
#: last Hessian; ``pattern``: the CSC indptr and indices, Hessian values, the no-Hessian
#: values, K_n dq, friction blocks, the diagonal's and the node blocks' positions
#: (``filter_blocks``' arrays); ``linear``: the solver's ``linear_solve.LinearSolveState``
#: (its kept preconditioner and work counters); ``barriers``: a tuple of ``BarrierPart``;
#: ``work``: see ``barrier_solve.CompiledSolve``; ``low``: two Newton matrix slots
#: (2, nnz), their filtered rank-one vectors (2, P, n), coefficients (2, P), counts
#: and shifts; ``flags`` (``F_*``). Set by ``solve``: q_n, v_n (n,), dt s, dt^2, K_n's
#: CSC values, the filters (n_nodes, 2, 2), CG's (relative, error limit m, floor m)
FIELDS = ('masses', 'alpha', 'beta', 'eps', 'keep_limit', 'friction',
          'table', 'pattern', 'linear', 'barriers', 'work', 'low', 'flags',
          'q_n', 'v_n', 'dt', 'dt2', 'stiffness', 'filters', 'cg')
#: a barrier's fields (one ``BarrierContact``): its fixed arrays and settings, then those
#: of a step, set by ``set_part``: the faces' corners (c k, 2) m, the collision mesh's
#: start (n_m, 2) m, the candidates and where they were sought, the lagged friction, the
#: quiet region (self-contact), its flags (``B_*``), its last evaluation's positions and
#: (barrier, friction) values J
PART_FIELDS = ('dof_pairs', 'edges', 'groups', 'self_contact', 'dhat', 'kappa',
               'mesh_dofs', 'project', 'pattern_keys', 'eps_v', 'radius', 'swept_radius',
               'margin', 'barrier_gradient', 'friction_gradient', 'drop_outside',
               'vertex_body', 'n_bodies', 'slots',
               'corners', 'start', 'anchor', 'pairs', 'friction_pairs', 'has_friction',
               'quiet_anchor', 'quiet_reach', 'has_quiet', 'flags', 'last_q', 'last_values')


class BarrierProblem(structref.StructRefProxy):
    """The compiled Newton iteration's problem (``FIELDS``), made by ``new_problem``."""


class BarrierPart(structref.StructRefProxy):
    """One barrier's arrays (``PART_FIELDS``), made by ``new_part``."""


structref.define_proxy(BarrierProblem, BarrierProblemType, list(FIELDS))
structref.define_proxy(BarrierPart, BarrierPartType, list(PART_FIELDS))


def _is_problem(problem):
    return isinstance(problem, BarrierProblemType)


# ---------------------------------------------------------------------- kernels
@njit(cache=True)
def _vertices(q, part, out):
    """out (n_v + c k, 2) m: the barrier's deformable vertices at q, then the corners."""
    dof_pairs = part.dof_pairs
    n_v = dof_pairs.shape[0]
    for i in range(n_v):
        out[i, 0] = q[dof_pairs[i, 0]]
        out[i, 1] = q[dof_pairs[i, 1]]
    out[n_v:] = part.corners


@njit(cache=True)
def _quiet(part, q, dq):
    """``BarrierContact.quiet``: a self-contact in its quiet region at q (and q + dq if
    dq is not empty)."""
    if not part.has_quiet:
        return False
    return relative_moves_within(q, dq, part.dof_pairs, part.quiet_anchor, part.vertex_body,
                                 part.n_bodies, part.quiet_reach)


@njit(cache=True)
def _candidates(part, q):
    """The kept candidates (k, 2) for positions q, sought again (boxes inflated by the
    barrier's candidate radius) once a vertex moved further than the margin
    (``BarrierContact._candidate_pairs``)."""
    flags = part.flags
    if flags[B_PAIRS] < 0 or largest_move(q, part.dof_pairs, part.anchor) > part.margin:
        v = np.empty((part.dof_pairs.shape[0] + part.corners.shape[0], 2))
        _vertices(q, part, v)
        part.pairs = edge_vertex_candidates(v, v, part.edges, part.groups, part.self_contact,
                                            part.radius)
        part.anchor[:] = v[:part.dof_pairs.shape[0]]
        flags[B_PAIRS] = 1
    return part.pairs


@njit(cache=True)
def _barrier_value(part, x, hessian, grad, hdata, dt):
    """``BarrierContact.evaluate_into`` (2D): the barrier and friction value J (inf: a
    pair touches), gradients added into grad, Hessians into hdata."""
    if _quiet(part, x, np.zeros(0)):
        return 0.0
    flags = part.flags
    pairs = _candidates(part, x)
    if pairs.shape[0] or part.has_friction:
        slots = part.slots if hessian else np.zeros(0, np.int64)
        values = hdata if hessian else np.zeros(0)
        barrier_value, friction_value, outside, friction_outside = barrier_terms(
            x, part.dof_pairs, part.corners, part.edges, pairs, part.dhat, part.kappa,
            part.mesh_dofs, hessian, part.project, part.pattern_keys, slots, values,
            part.start, dt, part.eps_v, part.friction_pairs, part.has_friction, hessian,
            part.barrier_gradient, part.friction_gradient, grad, True)
        if not math.isfinite(barrier_value):
            return np.inf
        if (outside or friction_outside) and not part.drop_outside:
            flags[B_OUTSIDE] = 1
        flags[B_TERMS] = 2
    else:
        barrier_value = friction_value = 0.0
        flags[B_TERMS] = 1
    part.last_q[:] = x
    part.last_values[0] = barrier_value
    part.last_values[1] = friction_value
    return barrier_value + friction_value


@njit(cache=True)
def _evaluate(problem, x, hessian, grad):
    table_order, items, coefs, vectors, scratch_vectors, dq, hess_coefs = problem.table
    (indptr, indices, hdata, no_values, k_dq, blocks, diag_pos, diag_block_pos, _, _, _,
     _, _) = problem.pattern
    fric_grad = problem.work[1]
    data = hdata if hessian else no_values
    phi = inertia_and_energies(x, problem.q_n, problem.v_n, problem.dt, problem.masses,
                               problem.alpha, dq, grad, hessian, data, table_order, items,
                               coefs, vectors if hessian else scratch_vectors)
    if not math.isfinite(phi):
        return np.inf
    if hessian:
        hess_coefs[:] = coefs
    for part in problem.barriers:
        value = _barrier_value(part, x, hessian, grad, hdata, problem.dt)
        if not math.isfinite(value):
            return np.inf
        phi += value
    nodes, tangents, bounds, speed = problem.friction
    return add_step_terms(phi, hessian, x, problem.q_n, dq, problem.dt, problem.masses,
                          problem.alpha, problem.beta, indptr, indices, problem.stiffness,
                          k_dq, nodes, tangents, bounds, speed, problem.eps, diag_pos,
                          diag_block_pos, grad, fric_grad, blocks, hdata)


@njit(cache=True)
def _max_step(part, x, dq):
    """``BarrierContact.max_step`` (2D): the CCD's largest fraction (0, 1] of dq."""
    if _quiet(part, x, dq):
        return 1.0
    bound = -1.0
    if part.flags[B_PAIRS] >= 0:
        bound = kept_step_bound(x, dq, part.dof_pairs, part.corners, part.edges, part.anchor,
                                part.pairs, part.margin)
    if bound >= 0.0:
        return bound
    n_m = part.dof_pairs.shape[0] + part.corners.shape[0]
    v0, v1 = np.empty((n_m, 2)), np.empty((n_m, 2))
    _vertices(x, part, v0)
    _vertices(x + dq, part, v1)
    swept = edge_vertex_candidates(v0, v1, part.edges, part.groups, part.self_contact,
                                   part.swept_radius)
    return collision_free_step(v0, v1, part.edges, swept)


# ---------------------------------------------------------------------- the hooks
@overload(newton.vectors)
def _vectors_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            vectors = problem.work[0]
            return vectors[0], vectors[1], vectors[2], vectors[3], vectors[4]
        return impl


@overload(newton.kept_fits)
def _kept_fits_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return False  # a new solve: nothing kept
        return impl


@overload(newton.evaluate)
def _evaluate_hook(problem, x, hessian, grad):
    if _is_problem(problem):
        def impl(problem, x, hessian, grad):
            return _evaluate(problem, x, hessian, grad)
        return impl


@overload(newton.project)
def _project_hook(problem, grad, g_f):
    if _is_problem(problem):
        def impl(problem, grad, g_f):
            apply_filters(problem.filters, grad, g_f)
        return impl


@overload(newton.forget)
def _forget_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            problem.flags[F_KEPT] = -1
        return impl


@overload(newton.keep)
def _keep_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            problem.flags[F_KEPT] = problem.flags[F_LAST]
        return impl


@overload(newton.factorise)
def _factorise_hook(problem, x, shift):
    if _is_problem(problem):
        def impl(problem, x, shift):
            (indptr, indices, hdata, _, _, _, _, _, block_pos, block_nodes, node_ptr,
             node_blocks, diag_blocks) = problem.pattern
            matrices, u_ts, cs, ks, shifts = problem.low
            flags = problem.flags
            slot = 1 if flags[F_KEPT] == 0 else 0
            filters = problem.filters
            n = problem.masses.shape[0]
            diagonal = np.zeros(n)
            if shift:
                for i in range(filters.shape[0]):
                    for a in range(2):
                        m = 2 * i + a
                        diagonal[m] = shift * filters[i, a, a] * problem.masses[m] / problem.dt2
            filter_blocks(hdata, block_pos, block_nodes, node_ptr, node_blocks, diag_blocks,
                          filters, diagonal, matrices[slot])
            vectors, hess_coefs = problem.table[3], problem.table[6]
            k = 0
            for p in range(hess_coefs.shape[0]):
                if hess_coefs[p] != 0.0:
                    apply_filters(filters, vectors[p], u_ts[slot, k])
                    cs[slot, k] = hess_coefs[p]
                    k += 1
            ks[slot] = k
            shifts[slot] = shift
            flags[F_LAST] = slot
            return True
        return impl


@overload(newton.direction)
def _direction_hook(problem, g_f, dq, fresh):
    if _is_problem(problem):
        def impl(problem, g_f, dq, fresh):
            matrices, u_ts, cs, ks, shifts = problem.low
            flags = problem.flags
            if fresh:
                slot = flags[F_LAST]
                refactor = shifts[slot] > 0
            else:
                slot = flags[F_KEPT]
                refactor = False
            k = ks[slot]
            u_t = np.ascontiguousarray(u_ts[slot, :k])
            u = np.ascontiguousarray(u_t.T)
            c = np.ascontiguousarray(cs[slot, :k])
            n = g_f.shape[0]
            rhs = np.empty(n)
            for m in range(n):
                rhs[m] = -g_f[m]
            x = problem.work[2]
            relative, error_limit, floor = problem.cg
            if not linear_solve.solve(problem.linear, matrices[slot], rhs, u, c, u_t,
                                      problem.filters, relative, error_limit, floor,
                                      refactor, x):
                return False, 0.0
            dq[:] = x
            slope = np.dot(g_f, x)
            return math.isfinite(slope), slope
        return impl


@overload(newton.step_bound)
def _step_bound_hook(problem, x, dq):
    if _is_problem(problem):
        def impl(problem, x, dq):
            bound = 1.0
            for part in problem.barriers:
                bound = min(bound, _max_step(part, x, dq))
            return min(bound, 1.0)
        return impl


@overload(newton.keep_limit)
def _keep_limit_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return problem.keep_limit
        return impl


@overload(newton.filtered_max)
def _filtered_max_hook(problem, g):
    if _is_problem(problem):
        def impl(problem, g):
            filtered = problem.work[3]
            apply_filters(problem.filters, g, filtered)
            return max_abs(filtered)
        return impl


@overload(newton.finish)
def _finish_hook(problem, x, grad):
    if _is_problem(problem):
        def impl(problem, x, grad):
            reaction, fric_grad = problem.work[4], problem.work[1]
            for m in range(x.shape[0]):
                reaction[m] = grad[m] - fric_grad[m]
        return impl


# ---------------------------------------------------------------------- the entry
@njit(cache=True)
def new_problem(fields):
    """A ``BarrierProblem`` of the fields' tuple (once per solver: ``_Kept``)."""
    return BarrierProblem(*fields)


@njit(cache=True)
def new_part(fields):
    """A ``BarrierPart`` of the fields' tuple (once per barrier: ``_Kept``)."""
    return BarrierPart(*fields)


@njit(cache=True)
def set_part(part, corners, start, anchor, has_pairs, pairs, friction_ids,
              friction_weights, friction_tangents, friction_forces, friction_coefficients,
              has_friction, quiet_anchor, quiet_reach, has_quiet):
    """A barrier's arrays of this step and solve (``PART_FIELDS``; flat arguments: numba
    types a tuple argument in Python, slowly)."""
    part.corners = corners
    part.start = start
    if has_pairs:
        part.anchor[:] = anchor
    part.pairs = pairs
    part.friction_pairs = (friction_ids, friction_weights, friction_tangents,
                           friction_forces, friction_coefficients)
    part.has_friction = has_friction
    part.quiet_anchor = quiet_anchor
    part.quiet_reach = quiet_reach
    part.has_quiet = has_quiet
    part.flags[:] = 0
    part.flags[B_PAIRS] = 0 if has_pairs else -1


@njit(cache=True)
def candidates_of(part):
    """The part's candidates (k, 2)."""
    return part.pairs


@njit(cache=True)
def shared_arrays(part):
    """The part's arrays Python reads: flags, the last evaluation's positions and
    values, the candidates' anchor."""
    return part.flags, part.last_q, part.last_values, part.anchor


@njit(cache=True)
def solve(problem, q_n, v_n, dt, dt2, stiffness, filters, relative, error_limit, floor,
           q, tol, max_it, history, counts):
    """``newton.newton_iteration`` compiled on ``problem`` with this solve's arrays."""
    problem.q_n = q_n
    problem.v_n = v_n
    problem.dt = dt
    problem.dt2 = dt2
    problem.stiffness = stiffness
    problem.filters = filters
    problem.cg = (relative, error_limit, floor)
    return newton.newton_iteration(problem, q, dt, tol, max_it, history, counts)
