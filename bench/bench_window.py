"""Time to compute a grasp window (``gripper-sim window``) for the default fruit.

Prints the window, the number of simulations and the wall time; no assertion (a
benchmark, not a test). Run: ``python bench/bench_window.py [--fruit NAME] [--finger NAME]
[--workers N [N ...]]``.

With several ``--workers`` counts the window is computed once per count, one after the
other in this process, and the table gives each one's wall time, the CPU time of this
process and of its worker processes (``resource.getrusage``), the trials run ahead that
the searches did not take, and whether its trials and bounds are the first count's to
the bit. Wall time is what more workers buy: run it on an otherwise idle machine (the
load average is printed).
"""
from __future__ import annotations

import argparse
import math
import os
import resource
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.configuration import DEFAULT_FRUIT  # noqa: E402
from gripper_sim.workflows.scenario import load_scenario, scenario_config  # noqa: E402
from gripper_sim.workflows.window import TOLERANCE, grasp_window  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--fruit', default=DEFAULT_FRUIT)
    parser.add_argument('--finger', default=None)
    parser.add_argument('--scenario', default='pick_and_place')
    parser.add_argument('--tolerance', type=float, default=TOLERANCE)
    parser.add_argument('--workers', type=int, nargs='+', default=None,
                        help='worker-process counts to compare (default: one process)')
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    config = scenario_config(scenario, fruit=args.fruit, finger=args.finger)
    if args.workers:
        return compare_workers(config, scenario, args)
    start, cpu = time.perf_counter(), time.process_time()
    window = grasp_window(config, scenario, args.tolerance)
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    steps = len(window.trials)
    top = ('none up to gripper.max_force' if window.max_force == math.inf
           else 'none' if window.max_force is None else f'{window.max_force:.3g} N')
    low = 'none' if window.min_force is None else f'{window.min_force:.3g} N'
    print(f'grasp window, {window.fruit} / {window.finger} finger / {args.scenario}, '
          f'tolerance {args.tolerance:g}')
    print(f'  min force {low} (slip < {window.max_slip * 1e3:g} mm; '
          f'm g / 2 mu = {window.min_estimate:.3g} N), '
          f'max force {top} (Hertz {window.max_estimate:.3g} N)')
    print(f'  {steps} simulations, wall time {wall:.1f} s, CPU time {cpu:.1f} s '
          f'({cpu / max(steps, 1):.2f} s of CPU per simulation)')
    for trial in window.trials:
        print(f'    {trial.kind:6s} {trial.force:8.3f} N  {trial.verdict:8s} slip '
              f'{trial.slip_distance * 1e3:6.3f} mm {trial.wall_time:6.1f} s')
    return 0


def compare_workers(config, scenario, args) -> int:
    """The window once per worker count in ``args.workers``; prints a table."""
    print(f'grasp window, {config["fruit.name"]} / {config["gripper.finger.name"]} finger '
          f'/ {args.scenario}, tolerance {args.tolerance:g}; load average '
          f'{os.getloadavg()[0]:.2f} at the start')
    print(f"{'workers':>7s} {'wall s':>8s} {'CPU s':>8s} {'trials':>6s} {'ahead':>5s} "
          f"{'min N':>8s} {'max N':>8s}  same as the first")
    first = None
    for workers in args.workers:
        own = resource.getrusage(resource.RUSAGE_SELF)
        children = resource.getrusage(resource.RUSAGE_CHILDREN)
        start = time.perf_counter()
        window = grasp_window(config, scenario, args.tolerance, workers=workers)
        wall = time.perf_counter() - start
        cpu = sum(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
                  for before, after in ((own, resource.getrusage(resource.RUSAGE_SELF)),
                                        (children,
                                         resource.getrusage(resource.RUSAGE_CHILDREN))))
        data = window.answer_dict()
        first = data if first is None else first
        print(f'{workers:7d} {wall:8.1f} {cpu:8.1f} {len(window.trials):6d} '
              f'{window.look_ahead_trials:5d} {window.min_force or math.nan:8.3f} '
              f'{window.max_force or math.nan:8.3f}  {data == first}')
    print(f'load average {os.getloadavg()[0]:.2f} at the end')
    return 0


if __name__ == '__main__':
    sys.exit(main())
