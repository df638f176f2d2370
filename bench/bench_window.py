"""Time to compute a grasp window (``gripper-sim window``) for the default fruit.

Prints the window, the number of simulations and the wall time; no assertion (a
benchmark, not a test). Run: ``python bench/bench_window.py [--fruit NAME] [--finger NAME]``.
"""
from __future__ import annotations

import argparse
import math
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
    args = parser.parse_args()
    scenario = load_scenario(args.scenario)
    config = scenario_config(scenario, fruit=args.fruit, finger=args.finger)
    start = time.perf_counter()
    window = grasp_window(config, scenario, args.tolerance)
    wall = time.perf_counter() - start
    steps = len(window.trials)
    top = ('none up to gripper.max_force' if window.max_force == math.inf
           else 'none' if window.max_force is None else f'{window.max_force:.3g} N')
    low = 'none' if window.min_force is None else f'{window.min_force:.3g} N'
    print(f'grasp window, {window.fruit} / {window.finger} finger / {args.scenario}, '
          f'tolerance {args.tolerance:g}')
    print(f'  min force {low} (m g / 2 mu = {window.min_estimate:.3g} N), '
          f'max force {top} (Hertz {window.max_estimate:.3g} N)')
    print(f'  {steps} simulations, wall time {wall:.1f} s '
          f'({wall / max(steps, 1):.1f} s per simulation)')
    for trial in window.trials:
        print(f'    {trial.force:8.3f} N  {trial.outcome:8s} {trial.wall_time:6.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
