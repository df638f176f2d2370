"""The 2D barrier model's Newton solve as one compiled call.

``fast_solver.PatternCachingSolver.solve`` runs ``newton.newton_iteration``; where this
module covers the solve (``barrier_solve.supports``) it runs compiled, its hooks
overloads (``numba.extending.overload``) for ``BarrierProblemType``, a numba StructRef
(a StructRef and not a tuple: ``core.kernels`` registers its hooks for every tuple
type, and numba takes the first overload that types); elsewhere on the interpreted
``_NewtonProblem``. The two drivers call the same implementations: the Newton systems'
solve is ``core.linear_solve`` (the problem holds the solver's ``LinearSolveState``),
each barrier's evaluation, candidates and step bound are ``core.barrier_part`` (the
problem holds each barrier's own ``BarrierPart``), so a solve gives the same iterates
as the interpreted route to the last bit (``test/test_barrier_newton.py``: the ring,
the membrane, the apple with friction and the pressure's rank-one term, the Fin Ray
grasp). The problem (energy table, CSC pattern and Hessian values, the two Newton
matrix slots, work vectors) is made once per solver (``barrier_solve``, which runs a
solve from Python) and a solve sets only its own arrays (``solve``: flat arguments, as
numba types a tuple argument in Python at ~2 ms for the problem's):

- ``evaluate``: ``energy_table.inertia_and_energies``; per barrier
  ``barrier_part.barrier_value``; then ``solver_kernels.add_step_terms``
  (``PatternCachingSolver.evaluate_fast``'s sequence);
- ``factorise``: ``solver_kernels.filter_blocks`` into a matrix slot, the pressures'
  rank-one terms filtered;
- ``direction``: ``linear_solve.solve``;
- ``step_bound``: per barrier ``barrier_part.max_step``.

A Hessian entry outside a barrier's pattern (where it does not drop them) is flagged
in its part and ``barrier_solve.run`` raises AssertionError after the call, as the
interpreted route does at once.

Covered (``barrier_solve.supports``): a 2D solver whose energies after the table are
one or two ``BarrierContact`` (the fruit's - skin or solid flesh, whose energies the
table sums - with rigid faces or soft bodies; a self-contact), and steps with no
sliding nodes (the barrier model's steps; a sliding
node needs the line search's ``kink_step``). These run compiled by default
(``fast_solver.COMPILED_BARRIER_SOLVE``).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.experimental import structref
from numba.extending import overload

from gripper_sim.core import linear_solve, newton
from gripper_sim.core.barrier_kernels import same_values
from gripper_sim.core.barrier_part import barrier_value, max_step
from gripper_sim.core.energy_table import inertia_and_energies
from gripper_sim.core.solver_kernels import add_step_terms, apply_filters, filter_blocks, max_abs

#: ``solve``'s status beyond ``newton``'s: a barrier Hessian entry outside its pattern
OUTSIDE_PATTERN = 100

#: flags (int64 array): the slot of the kept Newton matrix (-1: none), of the last
#: factorised one
F_KEPT, F_LAST, F_SIZE = range(3)
#: ``solve_from``'s ``kept`` (float array): whether a solve may start with the last
#: solve's kept Newton matrix (1/0), the dt (s) it was made for, its age in solves
K_CARRY, K_DT, K_AGE, K_SIZE = range(4)


@structref.register
class BarrierProblemType(types.StructRef):
    """The numba type of ``BarrierProblem``."""

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


class BarrierProblem(structref.StructRefProxy):
    """The compiled Newton iteration's problem (``FIELDS``), made by ``new_problem``."""


structref.define_proxy(BarrierProblem, BarrierProblemType, list(FIELDS))


def _is_problem(problem):
    return isinstance(problem, BarrierProblemType)


# ---------------------------------------------------------------------- kernels
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
    empty_values, no_slots = np.zeros(0), np.zeros(0, np.int64)
    for part in problem.barriers:
        value = barrier_value(part, x, hessian, grad, hdata if hessian else empty_values,
                              part.slots if hessian else no_slots, problem.dt, True)
        if not math.isfinite(value):
            return np.inf
        phi += value
    nodes, tangents, bounds, speed = problem.friction
    return add_step_terms(phi, hessian, x, problem.q_n, dq, problem.dt, problem.masses,
                          problem.alpha, problem.beta, indptr, indices, problem.stiffness,
                          k_dq, nodes, tangents, bounds, speed, problem.eps, diag_pos,
                          diag_block_pos, grad, fric_grad, blocks, hdata)


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
            return problem.flags[F_KEPT] >= 0  # what ``solve_from`` left kept fits
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


@overload(newton.definite)
def _definite_hook(problem):
    if _is_problem(problem):
        def impl(problem):
            return linear_solve.not_known_indefinite(problem.linear)
        return impl


@overload(newton.step_bound)
def _step_bound_hook(problem, x, dq):
    if _is_problem(problem):
        def impl(problem, x, dq):
            bound = 1.0
            for part in problem.barriers:
                bound = min(bound, max_step(part, x, dq))
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
def solve(problem, q_n, v_n, dt, dt2, stiffness, filters, relative, error_limit, floor,
           q, alternative, tol, max_it, history, counts):
    """``newton.newton_iteration`` compiled on ``problem`` with this solve's arrays, from q
    or, if not empty and lower, ``alternative`` (``newton.lower_start``)."""
    problem.q_n = q_n
    problem.v_n = v_n
    problem.dt = dt
    problem.dt2 = dt2
    problem.stiffness = stiffness
    problem.filters = filters
    problem.cg = (relative, error_limit, floor)
    if alternative.shape[0]:
        newton.lower_start(problem, q, alternative, counts)
    return newton.newton_iteration(problem, q, dt, tol, max_it, history, counts)


@njit(cache=True)
def _solve_appended(problem, q_n, v_n, dt, dt2, stiffness, filters, cg, tol, max_it, q,
                    alternative, history, counts, done, n_done, carried):
    """One ``solve`` from q, its steps appended to ``done`` after the first ``n_done``:
    (status, iterations, the steps now in ``done``). Without ``carried`` nothing is kept
    from before (the flags of the kept matrices reset)."""
    if not carried:
        problem.flags[F_KEPT] = -1
        problem.flags[F_LAST] = -1
    status, iterations, n_hist = solve(problem, q_n, v_n, dt, dt2, stiffness, filters,
                                       cg[0], cg[1], cg[2], q, alternative, tol, max_it,
                                       history, counts)
    for k in range(n_hist):
        done[n_done + k] = history[k]
    return status, iterations, n_done + n_hist


@njit(cache=True)
def _still_converging(done, n_done, progress):
    """``fast_solver.still_converging`` of the first ``n_done`` steps of ``done``,
    ``progress`` (span, factor, limit) its constants."""
    span = int(progress[0])
    return n_done > span and done[n_done - 1] <= progress[1] * done[n_done - 1 - span]


@njit(cache=True)
def _kept_fits(problem, kept, kept_filters, filters, dt):
    """Whether the Newton matrix the last solve kept serves this one (``kept``
    (K_SIZE,)): carrying it is on, it was made for this dt and these ``filters`` (their
    values, ``kept_filters``), and it is younger than ``newton.MAX_FACTOR_AGE`` solves."""
    if (kept[K_CARRY] == 0.0 or problem.flags[F_KEPT] < 0 or kept[K_DT] != dt
            or kept[K_AGE] >= newton.MAX_FACTOR_AGE):
        return False
    flat, kept_flat = filters.ravel(), kept_filters.ravel()
    for k in range(flat.shape[0]):
        if flat[k] != kept_flat[k]:
            return False
    return True


@njit(cache=True)
def solve_from(problem, q_n, v_n, dt, dt2, stiffness, filters, cg, tol, max_it, warm,
               warm_q_n, warm_q, history, counts, done, progress, kept, kept_filters,
               q_start, alternative, q):
    """``fast_solver.PatternCachingSolver.solve`` on the compiled route, in one call:
    from the last solve's solution ``warm_q`` in the free directions (if ``warm``, made
    with the same dt, and its start ``warm_q_n`` is q_n), else (or if that start is
    infeasible) from ``q_start`` (n_dof,) m, or ``alternative`` (if not empty) where the
    potential is lower there (dt2: dt^2 s^2); a solve still converging at ``max_it``
    goes on (``progress``: (span, factor, limit), ``fast_solver.PROGRESS_SPAN``,
    ``PROGRESS_FACTOR``, ``EXTENDED_LIMIT``). ``cg``: (relative, error limit, floor) as
    ``solve`` takes them. The Newton matrix kept at the last solve's end starts this
    one where it fits (``_kept_fits``; ``kept`` (K_SIZE,) and ``kept_filters`` (n_nodes,
    2, 2) updated for the next solve): its first step a chord step, taken where it cuts
    the potential, else made again with a new matrix (``newton.newton_iteration``).
    Writes the solution into ``q`` (n_dof,) m, the steps (m/s) into ``done`` (progress
    limit + 1 times max_it,); the reaction is ``work[4]``. Returns (status, iterations,
    the steps in ``done``)."""
    status = newton.INFEASIBLE_START
    iterations = n_done = 0
    carried = _kept_fits(problem, kept, kept_filters, filters, dt)
    factors = counts[newton.C_FACTORS]
    if warm and same_values(warm_q_n, q_n):
        difference = np.ascontiguousarray(warm_q - q_start)
        apply_filters(filters, difference, q)
        q += q_start
        status, iterations, n_done = _solve_appended(
            problem, q_n, v_n, dt, dt2, stiffness, filters, cg, tol, max_it, q, np.zeros(0),
            history, counts, done, 0, carried)
    if status == newton.INFEASIBLE_START:
        q[:] = q_start
        status, iterations, n_done = _solve_appended(
            problem, q_n, v_n, dt, dt2, stiffness, filters, cg, tol, max_it, q, alternative,
            history, counts, done, 0, carried)
    carry = kept[K_CARRY] != 0.0
    while (status == newton.NO_CONVERGENCE and _still_converging(done, n_done, progress)
           and iterations < progress[2] * max_it):
        status, more, n_done = _solve_appended(
            problem, q_n, v_n, dt, dt2, stiffness, filters, cg, tol, max_it, q, np.zeros(0),
            history, counts, done, n_done, carry)
        iterations += more
    if counts[newton.C_FACTORS] != factors:  # a new matrix: made for this step
        kept[K_DT] = dt
        kept[K_AGE] = 0.0
        kept_filters[:] = filters
    else:
        kept[K_AGE] += 1.0
    return status, iterations, n_done
