"""How well the Newton matrix of a 3D Fin Ray close matches the true Hessian of the step's
potential, at every fresh Newton direction. Prints figures; asserts nothing.

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

Usage::

    nice python bench/newton_matrix_check.py [--force 45] [--from-force 30]
        [--projection CLAMP|NONE|ABS] [--move 1e-9] [--set KEY=VALUE ...]
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


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--force', type=float, default=45.0)
    parser.add_argument('--from-force', type=float, default=30.0)
    parser.add_argument('--projection', default='CLAMP', choices=('CLAMP', 'NONE', 'ABS'))
    parser.add_argument('--move', type=float, default=1e-9)
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE')
    args = parser.parse_args(argv)
    barrier.BarrierContact.projection = getattr(ipctk.PSDProjectionMethod, args.projection)
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
