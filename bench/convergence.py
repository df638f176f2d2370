"""Convergence of a pick in the time step: the default 2D apple and the default 3D fruit.

Each fruit is picked (close, lift 5 cm, hold 1 s) at 1.1x, 1.5x and 3x its hold minimum
m g / (2 mu_s), at every dt of a ladder (2D: 2, 1, 0.5, 0.25, 0.125 ms; 3D: 20, 10, 5,
2.5 ms). Prints one row per run: outcome, slide (how far the jaw contacts slid: the
slip pick judges on, 0 for a held fruit whose contacts stick), centroid drop (the
centroid's largest drop relative to the jaws, elastic sag and ringing included), peak
grip force, the lowest grip force during lift and hold (relative to the command), solves
per step and process CPU time, then per force whether the outcome is the same at every
dt, the slide and the centroid drop each within max(0.2 mm, 20 %) of the finest dt's
and the peak grip force within 2 %.
With ``--forces``, instead: the pick_and_place scenario in force mode on the apple
from 0.5 N to 100 N, the peak grip force over the command in every phase (close,
squeeze, lift, transport, lower, open) and the lowest grip force during the lift.
``--set KEY=VALUE`` (repeatable) overrides the configuration of every run, e.g.
``--set fruit.damping.stiffness=2e-3`` (a damped flesh: the 2D centroid drop converges).
Run: ``nice python bench/convergence.py [--only 2d|3d] [--ratios 1.1 1.5 3] [--forces]
[--set KEY=VALUE ...]``.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from gripper_sim.configuration import load_config  # noqa: E402
from helpers import (converged, hold_minimum, pick_and_place_forces,  # noqa: E402
                     traced_pick)

FORCES = (0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0)
PHASES = ('close', 'squeeze', 'lift', 'transport', 'lower', 'open')
LADDERS = {'2d': (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4), '3d': (2e-2, 1e-2, 5e-3, 2.5e-3)}
OVERRIDES = {'2d': [], '3d': ['dimension=3']}


def force_table(fruit: str, overrides: list[str]) -> int:
    """Print the --forces table; 0 if every peak is within 2 % of its command and the
    lift never below 95 % of it."""
    print(f'pick_and_place, {fruit} (2D), force mode: peak grip force / command per phase')
    print('command N  outcome     ' + ''.join(f'{p:>10}' for p in PHASES)
          + '  lift min/cmd  cpu s')
    good = True
    for force in FORCES:
        summary, peaks, lift_min, cpu = pick_and_place_forces(fruit, force, *overrides)
        ratios = [peaks[p] / force if p in peaks else float('nan') for p in PHASES]
        print(f"{force:9.1f}  {summary['outcome']:10}  "
              + ''.join(f'{r:10.4f}' for r in ratios)
              + f'  {lift_min / force:12.4f}  {cpu:5.1f}', flush=True)
        good = good and max(peaks.values()) <= 1.02 * force and lift_min >= 0.95 * force
    return 0 if good else 1


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--only', choices=sorted(LADDERS), default=None)
    parser.add_argument('--fruit', default='apple', help='with --forces')
    parser.add_argument('--ratios', type=float, nargs='+', default=[1.1, 1.5, 3.0])
    parser.add_argument('--forces', action='store_true')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='a configuration override of every run (repeatable)')
    args = parser.parse_args(argv)
    if args.forces:
        return force_table(args.fruit, args.set)
    print('model  ratio  force N   dt ms  outcome  slide mm  drop mm  peak N  peak/cmd  '
          'lift min/cmd  solves/step  cpu s')
    verdicts = []
    for model in [args.only] if args.only else sorted(LADDERS):
        base = load_config(overrides=OVERRIDES[model] + args.set)
        minimum = hold_minimum(base)
        for ratio in args.ratios:
            force = ratio * minimum
            rows = []
            for dt in LADDERS[model]:
                config = load_config(overrides=OVERRIDES[model] + args.set + [f'sim.dt={dt}'])
                row = traced_pick(config, force)
                rows.append(row)
                print(f"{model:5}  {ratio:5.2f}  {force:7.3f}  {dt * 1e3:6.3f}  "
                      f"{row['outcome']:8}  {row['slip'] * 1e3:8.3f}  {row['drop'] * 1e3:7.3f}  "
                      f"{row['peak']:6.3f}  "
                      f"{row['peak'] / force:8.4f}  {row['lift_min'] / force:12.4f}  "
                      f"{row['solves']:11.2f}  {row['cpu']:6.1f}", flush=True)
            same, slide, peak = converged(rows)
            drop = converged([dict(row, slip=row['drop']) for row in rows])[1]
            verdicts.append((model, ratio, same, slide, drop, peak))
    print('\nmodel  ratio  same outcome  within max(0.2 mm, 20 %): slide  drop   '
          'peak within 2 %')
    for model, ratio, same, slide, drop, peak in verdicts:
        print(f'{model:5}  {ratio:5.2f}  {str(same):12}  {"":26}{str(slide):7}'
              f'{str(drop):7}{peak}')
    return 0 if all(all(v[2:]) for v in verdicts) else 1


if __name__ == '__main__':
    sys.exit(main())
