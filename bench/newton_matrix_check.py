"""How well the Newton matrix of a Fin Ray close (3D, or a 2D pick trial) matches the
true Hessian of the step's potential, at every fresh Newton direction. Prints figures;
asserts nothing.

The default apple between 3D Fin Ray fingers, ``sim.dt`` 5 ms, closed in force mode to
``--force`` N. From the step whose grip passes ``--from-force`` N on, each fresh Newton
direction dq (solved from the assembled matrix A: A dq = -S g, S the node filters) is
checked against the potential's own curvature along it, by central differences of the
gradient g: ``mismatch = |S (g(q + e dq) - g(q - e dq)) / (2 e) + S g| / |S g|``, with e
such that the largest node moves ``--move`` m (1e-8 and 1e-9 agree where the potential
is smooth at that scale). 0 means the matrix is the Hessian along dq (Newton converges
fast); 0.1 to 1 means each Newton step removes only part of the residual (linear
convergence). ``--projection`` sets how the barrier's per-pair Hessians are made
positive semi-definite (ipctk's ``PSDProjectionMethod``: CLAMP, the default, or NONE,
the exact Hessian, or ABS). Each printed line is a step: grip force, sub-steps, and the
mismatch and step size (max |dq| / dt, m/s) of its fresh directions.

With ``--pick MODE`` (``hold`` or ``bruise``) it checks a 2D Fin Ray instead: the
window's trial of that mode at ``--force`` N (``workflows.window.evaluate_grasp``, the
scenario ``pick_and_place``, ``--fruit`` and ``--set`` applied), the solves
interpreted. At the last solve that failed, its last two fresh directions are broken
down by energy: the energy table's (the fruit's and fingers' elastic energies,
pressure, inertia and mass damping) and each barrier's with and without its friction, the Newton
matrix's product with dq against the central difference of that energy's gradient, at
the dofs of the largest residual. A pair of nodes whose coupling is missing from the
matrix shows as a barrier whose product is much larger than its difference (both nodes
moving together). The lagged friction is smooth only within eps_v dt of a slip (1.6 nm
at a 16 us sub-step): for its rows choose ``--move`` well below that.

Usage::

    nice python bench/newton_matrix_check.py [--force 45] [--from-force 30]
        [--projection CLAMP|NONE|ABS] [--move 1e-9] [--set KEY=VALUE ...]
    nice python bench/newton_matrix_check.py --pick hold --force 2.363 \
        --set fruit.nodes=256 --set gripper.finger.fin_ray.element_length=0.001
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import ipctk
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core import barrier, fast_solver  # noqa: E402
from gripper_sim.core.barrier_part import barrier_value  # noqa: E402
from gripper_sim.core.solver_kernels import add_inertia_diagonal, csc_matvec  # noqa: E402
from gripper_sim.core.stepper import NewtonFailure  # noqa: E402
from gripper_sim.core3d.simulation import Simulation3D  # noqa: E402
from gripper_sim.errors import ConvergenceError  # noqa: E402


class DirectionLog:
    """The fresh directions' (mismatch, max |dq| / dt (m/s)) of a step, kept while ``on``."""

    def __init__(self):
        self.on = False
        self.rows: list[tuple[float, float]] = []

    def __str__(self) -> str:
        return ' '.join(f'({m:.3f}, {v:.1e})' for m, v in self.rows)


def watch_directions(move: float, log: DirectionLog) -> None:
    """Wrap ``_NewtonProblem.direction`` and ``evaluate``: each fresh direction's
    mismatch (see the module) appended to ``log`` while it is on."""
    problem_class = fast_solver._NewtonProblem
    direction, evaluate = problem_class.direction, problem_class.evaluate
    last_hessian_point = {}

    def evaluate_watched(self, x, hessian, grad):
        if hessian:
            last_hessian_point['q'] = x.copy()
        return evaluate(self, x, hessian, grad)

    def direction_watched(self, g_f, dq, fresh):
        found, slope = direction(self, g_f, dq, fresh)
        if fresh and found and log.on:
            q = last_hessian_point['q']
            step = move / np.abs(dq).max()
            plus, minus = np.empty_like(q), np.empty_like(q)
            evaluate(self, q + step * dq, False, plus)
            evaluate(self, q - step * dq, False, minus)
            curvature = self.filtered((plus - minus) / (2.0 * step))
            log.rows.append((float(np.linalg.norm(curvature + g_f) / np.linalg.norm(g_f)),
                        float(np.abs(dq).max() / self.dt)))
        return found, slope

    problem_class.direction = direction_watched
    problem_class.evaluate = evaluate_watched


def energy_parts(solver, q, q_n, v_n, dt, hessian: bool) -> dict:
    """{name: (gradient (n,) N, Hessian CSC values (nnz,), rank-one terms)} of a 2D
    solver's energies at q: the energy table's, then each barrier's with its friction and
    without."""
    parts = {}
    grad, data = np.zeros(solver.n), np.zeros(solver._nnz)
    _, _, low_rank = solver._table.potential(q, q_n, v_n, dt, solver.m, solver.alpha,
                                             hessian, grad, data if hessian else np.zeros(1))
    if hessian:  # the inertia's and mass damping's diagonal (the solver adds it later)
        add_inertia_diagonal(data, solver._diag_pos, solver.m, dt, solver.alpha)
    parts['energy table'] = (grad, data, list(low_rank))
    for k, (energy, scatter) in enumerate(solver._untabled):
        part, slots = energy.compiled_part(scatter), energy.pattern_slots(scatter)
        for friction in (True, False):
            grad, data = np.zeros(solver.n), np.zeros(solver._nnz)
            barrier_value(part, q, hessian, grad, data if hessian else np.zeros(0),
                          slots if hessian else np.zeros(0, np.int64), dt, friction)
            name = f'barrier {k}' + ('' if friction else ' without friction')
            parts[name] = (grad, data, [])
    return parts


def watch_energies(move: float, directions: list, context: dict) -> None:
    """Wrap ``_NewtonProblem.direction`` and ``evaluate``: each fresh direction's
    (|S g| (n,), {energy: (S difference, S product) (n,)}) appended to ``directions``
    (the solver and the step's q_n, v_n, dt from ``context``)."""
    problem_class = fast_solver._NewtonProblem
    direction, evaluate = problem_class.direction, problem_class.evaluate
    last = {}

    def evaluate_watched(self, x, hessian, grad):
        if hessian:
            last['q'] = x.copy()
        return evaluate(self, x, hessian, grad)

    def direction_watched(self, g_f, dq, fresh):
        found, slope = direction(self, g_f, dq, fresh)
        if fresh and found:
            solver, q = context['solver'], last['q']
            step = move / np.abs(dq).max()
            state = (context['q_n'], context['v_n'], context['dt'])
            at = energy_parts(solver, q, *state, True)
            plus = energy_parts(solver, q + step * dq, *state, False)
            minus = energy_parts(solver, q - step * dq, *state, False)
            rows = {}
            for name, (_, data, low_rank) in at.items():
                product = np.zeros(solver.n)
                csc_matvec(solver._matvec_indptr, solver._matvec_indices, data, dq, product)
                for c, u in low_rank:
                    product += c * u * np.dot(u, dq)
                difference = (plus[name][0] - minus[name][0]) / (2.0 * step)
                rows[name] = (self.filtered(difference), self.filtered(product))
            directions.append((np.abs(g_f), rows))
            evaluate(self, q, True, np.empty_like(q))  # the matrix's point again
        return found, slope

    problem_class.direction = direction_watched
    problem_class.evaluate = evaluate_watched


def check_pick(args) -> int:
    """The 2D pick trial of ``args.pick`` at ``args.force`` (see the module)."""
    from gripper_sim.workflows.scenario import load_scenario, scenario_config
    from gripper_sim.workflows.window import evaluate_grasp, trial_setup
    fast_solver.COMPILED_BARRIER_SOLVE = False
    directions, context, failed = [], {}, []
    watch_energies(args.move, directions, context)
    solve = fast_solver.PatternCachingSolver.solve

    def solve_watched(self, q_n, v_n, dt, *rest):
        directions.clear()
        context.update(solver=self, q_n=q_n, v_n=v_n, dt=dt)
        try:
            return solve(self, q_n, v_n, dt, *rest)
        except NewtonFailure as error:
            failed[:] = [(dt, str(error), list(directions))]
            raise

    fast_solver.PatternCachingSolver.solve = solve_watched
    scenario = load_scenario('pick_and_place')
    config, base = trial_setup(scenario_config(
        scenario, fruit=args.fruit, finger='fin_ray', overrides=args.set), scenario)
    evaluation = evaluate_grasp(config, base, args.force, args.pick)
    print(f'{args.pick} trial at {args.force} N: {evaluation.outcome}, peak grip force '
          f'{evaluation.peak_grip_force:.2f} N')
    if not failed:
        print('no solve failed')
        return 0
    dt, message, rows = failed[0]
    print(f'last failed solve (dt {dt:.3g} s): {message}')
    for residual, energies in rows[-2:]:
        top = np.argsort(residual)[::-1][:4]
        print('  fresh direction; largest |S g| (N) at dofs',
              ', '.join(f'{d}: {residual[d]:.2e}' for d in top))
        for name, (difference, product) in energies.items():
            print(f'    {name:26s}', '  '.join(
                f'{d}: {difference[d]:+.2e} / {product[d]:+.2e}' for d in top),
                '  (difference / matrix product, N)')
    return 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--force', type=float, default=45.0)
    parser.add_argument('--from-force', type=float, default=30.0)
    parser.add_argument('--projection', default='CLAMP', choices=('CLAMP', 'NONE', 'ABS'))
    parser.add_argument('--move', type=float, default=1e-9)
    parser.add_argument('--pick', choices=('hold', 'bruise'), default=None,
                        help='the 2D Fin Ray pick trial of this mode instead')
    parser.add_argument('--fruit', default=None, help="the pick trial's fruit preset")
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    args = parser.parse_args(argv)
    barrier.BarrierContact.projection = getattr(ipctk.PSDProjectionMethod, args.projection)
    if args.pick:
        return check_pick(args)
    log = DirectionLog()
    watch_directions(args.move, log)
    sim = Simulation3D(load_config(overrides=['dimension=3', 'gripper.finger.type=fin_ray',
                                              'sim.dt=0.005', *args.set]))
    sim.command_force(args.force)
    start = time.process_time()
    grip = 0.0
    for step in range(4000):
        log.on, log.rows = grip >= args.from_force, []
        try:
            result = sim.step()
        except ConvergenceError as error:
            print(f'step {step}: {error}')
            print('  directions of the failed step:', log)
            return 0
        grip = result.grip_force
        print(f'step {step}: grip {grip:.2f} N, {result.substeps} sub-step(s), '
              f'CPU {time.process_time() - start:.1f} s', flush=True)
        if log.on:
            print('  directions (mismatch, m/s):', log)
        if abs(grip - args.force) < 0.01 * args.force:
            print(f'reached {grip:.2f} N')
            return 0
    return 0


if __name__ == '__main__':
    sys.exit(main())
