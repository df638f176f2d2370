"""How the barrier model's Newton solves converge in the 2D Fin Ray grasp-and-lift of
``bench_fin_ray.py``: the solves by their iterations, and for the solves of three
iterations the norms of their steps (infinity norm of dq / dt, m/s, the quantity the
tolerance ``sim.newton_tolerance`` bounds) and the ratios that tell quadratic
convergence (dq2 / dq1^2 steady, s/m) from linear (dq2 / dq1 steady). Prints figures;
asserts nothing.

Usage::

    nice python bench/newton_rates.py [--set KEY=VALUE]
"""
from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

from bench_soft_fingers import add_set_argument, checked_config, grasp  # noqa: E402

from gripper_sim.core import fast_solver  # noqa: E402

#: percentiles printed
PERCENTILES = (5, 25, 50, 75, 95)


def histories(overrides: tuple) -> list[list[float]]:
    """Each Newton solve's step norms (m/s) in one Fin Ray grasp-and-lift."""
    kept: list[list[float]] = []
    solve = fast_solver.PatternCachingSolver.solve

    def recording(self, *args, **kwargs):
        solution = solve(self, *args, **kwargs)
        kept.append(list(solution.history))
        return solution
    fast_solver.PatternCachingSolver.solve = recording
    try:
        grasp('fin_ray', 4.0, overrides)
    finally:
        fast_solver.PatternCachingSolver.solve = solve
    return kept


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_set_argument(parser, 'override a configuration key of the grasp (repeatable)')
    args = parser.parse_args(argv)
    config = checked_config(parser, 'fin_ray', args.set)
    runs = histories(tuple(args.set))
    counts = collections.Counter(len(run) for run in runs)
    print(f'{len(runs)} solves, {sum(map(len, runs))} Newton iterations; tolerance '
          f"{config['sim.newton_tolerance']:g} m/s")
    print('iterations: ' + ', '.join(f'{k}: {counts[k]}' for k in sorted(counts)))
    three = np.array([run for run in runs if len(run) == 3])
    if not three.size:
        return 0
    rows = (('dq1 m/s', three[:, 0]), ('dq2 m/s', three[:, 1]),
            ('dq2 / dq1', three[:, 1] / three[:, 0]),
            ('dq2 / dq1^2 s/m', three[:, 1] / three[:, 0] ** 2),
            ('dq3 / dq2', three[:, 2] / three[:, 1]))
    print(f'the {len(three)} solves of 3 iterations, percentiles '
          + ' '.join(f'{p:>9d}' for p in PERCENTILES))
    for label, values in rows:
        print(f'  {label:16s}' + ' '.join(f'{v:9.2e}' for v in np.percentile(values,
                                                                            PERCENTILES)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
