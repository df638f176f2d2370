"""Where a compiled 2D barrier Newton solve's time goes, by phase (a helper's tool).

Runs the Fin Ray grasp of ``bench_fin_ray.py`` (unwatched, after a warm-up); at the
chosen solves (default 300 and 600; after the solve returns, its problem at its
solution) times each phase's compiled call in a compiled loop, hot (us per call, the
best of three loops): the evaluation with and without the Hessian and its parts (the
table, each tabled energy, each barrier part, its terms with and without the PSD
projection and friction, the self-contact's quiet check, the step terms), the Newton
matrix's filtering (``factorise`` hook), the LDL^T factorisation, a direction (fresh,
kept factor), the step bound, one LDL^T solve (all of L's blocks; the kept nonzero
ones) and one CSC product; and each part's candidates. At the end the work counters
per solve over the grasp (Newton solves, evaluations with and without the Hessian,
factorise calls, directions). Prints figures; asserts nothing. The timed calls change
the problem's kept state, so the grasp after the first probe is not the bench's.

Usage::

    nice python bench/solve_phases.py [SOLVE_INDEX ...]
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

from gripper_sim.core import barrier_newton as bn  # noqa: E402
from gripper_sim.core import linear_solve, newton  # noqa: E402
from gripper_sim.core import energy_table as et  # noqa: E402
from gripper_sim.core.barrier_part import barrier_value, candidates, quiet  # noqa: E402
from gripper_sim.core.barrier_terms import barrier_terms  # noqa: E402
from gripper_sim.core.energies import kernels as ek  # noqa: E402
from gripper_sim.core.energy_table import inertia_and_energies  # noqa: E402
from gripper_sim.core.pcg_kernels import block_ldl_solve  # noqa: E402
from gripper_sim.core.solver_kernels import add_step_terms, csc_matvec  # noqa: E402


@njit
def t_evaluate(problem, x, hessian, grad, n):
    s = 0.0
    for _ in range(n):
        s += bn._evaluate(problem, x, hessian, grad)
    return s


@njit
def t_table(problem, x, hessian, grad, n):
    table_order, items, coefs, vectors, scratch_vectors, dq, hess_coefs = problem.table
    hdata, no_values = problem.pattern[2], problem.pattern[3]
    s = 0.0
    for _ in range(n):
        s += inertia_and_energies(x, problem.q_n, problem.v_n, problem.dt, problem.masses,
                                  problem.alpha, dq, grad, hessian,
                                  hdata if hessian else no_values, table_order, items,
                                  coefs, vectors if hessian else scratch_vectors)
    return s


@njit
def t_barriers(problem, x, hessian, grad, n):
    hdata = problem.pattern[2]
    s = 0.0
    empty_values, no_slots = np.zeros(0), np.zeros(0, np.int64)
    for _ in range(n):
        for part in problem.barriers:
            s += barrier_value(part, x, hessian, grad, hdata if hessian else empty_values,
                               part.slots if hessian else no_slots, problem.dt, True)
    return s


@njit
def t_step_terms(problem, x, hessian, grad, n):
    (indptr, indices, hdata, no_values, k_dq, blocks, diag_pos, diag_block_pos, _, _, _,
     _, _) = problem.pattern
    dq = problem.table[5]
    nodes, tangents, bounds, speed = problem.friction
    s = 0.0
    for _ in range(n):
        s += add_step_terms(0.0, hessian, x, problem.q_n, dq, problem.dt, problem.masses,
                            problem.alpha, problem.beta, indptr, indices, problem.stiffness,
                            k_dq, nodes, tangents, bounds, speed, problem.eps, diag_pos,
                            diag_block_pos, problem.work[1], problem.work[1], blocks, hdata)
    return s


@njit
def t_filter(problem, x, n):
    problem.flags[bn.F_KEPT] = -1
    for _ in range(n):
        newton.factorise(problem, x, 0.0)


@njit
def t_ldl(problem, n):
    matrices = problem.low[0]
    slot = problem.flags[bn.F_LAST]
    for _ in range(n):
        linear_solve.factorise(problem.linear, matrices[slot])


@njit
def t_direction(problem, g_f, dq, fresh, n):
    s = 0.0
    for _ in range(n):
        s += newton.direction(problem, g_f, dq, fresh)[1]
    return s


@njit
def t_step_bound(problem, x, dq, n):
    s = 0.0
    for _ in range(n):
        s += newton.step_bound(problem, x, dq)
    return s


def timed(fn, *args, n=2000):
    fn(*args, 1)
    best = np.inf
    for _ in range(3):
        start = time.perf_counter()
        fn(*args, n)
        best = min(best, time.perf_counter() - start)
    return best / n * 1e6


def probe(problem, flags, q):
    x = q.copy()
    n = x.size
    grad = np.empty(n)
    rows = {}
    rows['evaluate, Hessian'] = timed(t_evaluate, problem, x, True, grad)
    rows['  table (inertia, rods, pressure), Hessian'] = timed(t_table, problem, x, True, grad)
    rows['  barriers, Hessian'] = timed(t_barriers, problem, x, True, grad)
    rows['  step terms, Hessian'] = timed(t_step_terms, problem, x, True, grad)
    rows['evaluate, no Hessian'] = timed(t_evaluate, problem, x, False, grad)
    rows['  table, no Hessian'] = timed(t_table, problem, x, False, grad)
    rows['  barriers, no Hessian'] = timed(t_barriers, problem, x, False, grad)
    rows['  step terms, no Hessian'] = timed(t_step_terms, problem, x, False, grad)
    bn._evaluate(problem, x, True, grad)
    rows['factorise hook (filter_blocks, rank one)'] = timed(t_filter, problem, x)
    rows['LDL^T factorisation'] = timed(t_ldl, problem, n=500)
    g_f = grad.copy()
    dq = np.empty(n)
    rows['direction, fresh (factorise + CG)'] = timed(t_direction, problem, g_f, dq, True,
                                                     n=500)
    t_filter(problem, x, 1)
    t_ldl(problem, 1)
    flags[bn.F_KEPT] = flags[bn.F_LAST]
    rows['direction, kept factor (CG)'] = timed(t_direction, problem, g_f, dq, False)
    rows['step bound'] = timed(t_step_bound, problem, x, dq * 1e-3)
    rows.update(probe_more(problem, q))
    rows.update(probe_parts(problem, q))
    print('parts (candidates, project, friction, friction pairs, keys, n_v, self):',
          part_info(problem))
    return rows, None


@njit
def t_ldl_solve(problem, y, n):
    st = problem.linear
    for _ in range(n):
        block_ldl_solve(st.arrays, st.l_values, st.d_inv, y)


@njit
def t_ldl_solve_kept(problem, y, n):
    st = problem.linear
    for _ in range(n):
        block_ldl_solve(st.solve_arrays, st.l_solve, st.d_inv, y)


@njit
def t_matvec(problem, y, out, n):
    st = problem.linear
    matrices = problem.low[0]
    for _ in range(n):
        csc_matvec(st.indptr, st.indices, matrices[0], y, out)


def probe_more(problem, q):
    y = np.ones(q.size) * 1e-3
    out = np.empty(q.size)
    return {'LDL^T solve, all blocks': timed(t_ldl_solve, problem, y),
            'LDL^T solve, nonzero blocks (kept)': timed(t_ldl_solve_kept, problem, y),
            'CSC matvec': timed(t_matvec, problem, y, out)}


@njit
def part_info(problem):
    out = []
    for part in problem.barriers:
        out.append((part.pairs.shape[0], part.project, part.has_friction,
                    part.friction_pairs[0].shape[0], part.pattern_keys.shape[0],
                    part.dof_pairs.shape[0], part.self_contact))
    return out


@njit
def t_item(problem, q, slot, hessian, grad, n):
    items = problem.table[1]
    kind = problem.table[0][slot]
    index, a, b, scatter = items[slot]
    data = problem.pattern[2]
    x = q.reshape(-1, 2)
    ga = np.empty(q.shape[0])
    s = 0.0
    for _ in range(n):
        if kind == et.STRETCHING:
            s += ek.stretching(x, index, a, b, grad, data, scatter, hessian)
        elif kind == et.BENDING:
            s += ek.bending(x, index, a, b, grad, data, scatter, hessian)
        elif kind == et.PRESSURE:
            s += ek.enclosed_area_pressure(x, index[:, 0], a[0], a[1], a[2], a[3], grad, ga,
                                           data, scatter, hessian)[0]
    return s


@njit
def t_part(problem, x, k, hessian, grad, n):
    hdata = problem.pattern[2]
    part = problem.barriers[k]
    s = 0.0
    for _ in range(n):
        s += barrier_value(part, x, hessian, grad, hdata, part.slots, problem.dt, True)
    return s


@njit
def t_part_terms(problem, x, k, hessian, project, friction, grad, n):
    hdata = problem.pattern[2]
    part = problem.barriers[k]
    s = 0.0
    for _ in range(n):
        pairs = candidates(part, x)
        s += barrier_terms(
            x, part.dof_pairs, part.corners, part.edges, pairs, part.dhat, part.kappa,
            part.mesh_dofs, hessian, project, part.pattern_keys, part.slots, hdata,
            part.start, problem.dt, part.eps_v, part.friction_pairs, friction and part.has_friction,
            hessian and friction, part.barrier_gradient, part.friction_gradient, grad,
            friction)[0]
    return s


@njit
def t_quiet(problem, x, k, n):
    part = problem.barriers[k]
    s = 0
    for _ in range(n):
        s += quiet(part, x, np.zeros(0))
    return s


def probe_parts(problem, q):
    grad = np.empty(q.size)
    rows = {}
    for slot in range(6):
        for h in (True, False):
            rows[f'table item {slot} hessian={h}'] = timed(t_item, problem, q, slot, h, grad)
    for k in range(2):
        for h in (True, False):
            rows[f'part {k} hessian={h}'] = timed(t_part, problem, q, k, h, grad)
        rows[f'part {k} quiet check'] = timed(t_quiet, problem, q, k)
    for h, proj, fr in ((True, True, True), (True, False, True), (True, True, False),
                        (False, True, True), (False, True, False)):
        rows[f'part 1 terms hessian={h} project={proj} friction={fr}'] = timed(
            t_part_terms, problem, q, 1, h, proj, fr, grad)
    return rows


@njit
def _flags(problem):
    """The problem's flags (``barrier_newton.F_*``), the array it shares."""
    return problem.flags


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    wanted = {int(a) for a in argv} or {300, 600}
    from bench_soft_fingers import grasp

    run = bn.solve_from
    seen = [0]
    results = {}

    totals = np.zeros(newton.C_SIZE, np.int64)

    def probing_run(*args):
        problem, counts, q = args[0], args[14], args[-1]
        before = counts.copy()
        out = run(*args)
        totals[:] += counts - before
        seen[0] += 1
        if seen[0] in wanted:
            results[seen[0]] = probe(problem, _flags(problem), q)
        return out
    grasp('fin_ray', 4.0, (), False)  # warm-up
    bn.solve_from = probing_run
    try:
        grasp('fin_ray', 4.0, (), False)
    finally:
        bn.solve_from = run
    for index, (rows, stats) in sorted(results.items()):
        print(f'-- solve {index}')
        for label, us in rows.items():
            print(f'{label:45s} {us:8.2f} us')
    per = totals / max(totals[newton.C_SOLVES], 1)
    print(f"per solve ({totals[newton.C_SOLVES]} solves): {per[newton.C_HESSIAN_EVALS]:.2f} "
          f"evaluations with the Hessian, {per[newton.C_EVALS]:.2f} without, "
          f"{per[newton.C_FACTORS]:.2f} factorise calls, {per[newton.C_DIRECTIONS]:.2f} "
          f"directions")
    return 0


if __name__ == '__main__':
    sys.exit(main())
