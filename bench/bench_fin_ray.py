"""Benchmark of the Fin Ray finger against the rigid flat finger: CPU time of a 2D
grasp-and-lift of the default apple. Prints figures; asserts nothing.

The same grasp as ``bench_soft_fingers.py`` (the jaws 1 mm from where the fingers touch
the apple, force mode to ``--force`` N, lifted 1 cm, held 0.2 s, dt = 1 ms), CPU time of
this process (``time.process_time``, the best of ``--repeat`` runs; the load average is
printed), side by side for ``gripper.finger.type`` flat and fin_ray.

Usage::

    nice python bench/bench_fin_ray.py [--repeat N] [--force N]
"""
from __future__ import annotations

import argparse
import os
import sys

from bench_soft_fingers import grasp


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=1, help='runs per finger (best kept)')
    parser.add_argument('--force', type=float, default=4.0, help='grip force, N')
    args = parser.parse_args(argv)
    print(f'load average {os.getloadavg()[0]:.2f}; CPU time (time.process_time), best of '
          f'{args.repeat}')
    rows = {finger: min((grasp(finger, args.force) for _ in range(args.repeat)),
                        key=lambda r: r['cpu'])
            for finger in ('flat', 'fin_ray')}
    print(f"{'finger':10s} {'CPU s':>8s} {'outcome':>8s} {'steps':>6s} {'solves':>7s} "
          f"{'Newton':>7s} {'force N':>8s}")
    for finger, r in rows.items():
        print(f"{finger:10s} {r['cpu']:8.2f} {r['outcome']:>8s} {r['steps']:6d} "
              f"{r['solves']:7d} {r['newton']:7d} {r['force']:8.3f}")
    print(f"fin_ray / flat: {rows['fin_ray']['cpu'] / rows['flat']['cpu']:.1f}x")
    return 0


if __name__ == '__main__':
    sys.exit(main())
