"""Benchmark of the barrier contact model (``contact.model: ipc``) against the modified
mass method (``mmm``) on rigid-finger cases. Prints figures; asserts nothing.

CPU time of this process (``time.process_time``, the best of ``--repeat`` runs; the
machine's load average is printed), for each case and model, with Newton iterations:

- ``hertz``: the solid disk (256 surface nodes) pressed to 1.5 N by flat jaws, 1.5 s of
  simulated time at dt = 10 ms. ``mmm`` runs the compiled whole step (``core.fast``,
  which now covers the solid fruit too), the barrier model the compiled energies on the
  fixed-pattern Newton solver (``core.fast_solver``).
- ``membrane``: the pressurised ring (256 nodes) squeezed by 10 % of its radius.
  ``mmm`` runs the whole step in one numba kernel (``core.fast``), which the barrier
  model does not have; ``mmm-numpy`` is the numpy reference path of the same method
  (``Simulation(config, fast=False)``).
- ``hertz3d``: the 3D solid sphere (linear tetrahedra, 922 nodes, 307 on the surface)
  pressed by D = 0.05 R between flat plates, 0.6 s at dt = 50 ms: the 3D model has one
  solver (the fixed-pattern Newton solver) for both contact models.
- ``pick``: the default apple gripped (2 mu N = 1.2 m g), lifted 2 cm and held 1 s,
  with the table, gravity and friction (``--pick`` to include it; about 10 s).

Usage::

    nice python bench/bench_barrier.py [--repeat N] [--pick]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))

from helpers import pick, quasi_static_sim  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

RADIUS = 0.03


def hertz(model: str, fast=None):
    sim = quasi_static_sim(RADIUS, 'fruit.model=solid', 'fruit.skin.enabled=false',
                           'fruit.nodes=256', 'fruit.flesh.youngs_modulus=1e6',
                           'fruit.flesh.poisson_ratio=0.3', f'contact.model={model}',
                           fast=fast)
    sim.command_force(1.5, speed=0.004)
    return sim, 1.5


def membrane(model: str, fast=None):
    sim = quasi_static_sim(RADIUS, 'fruit.skin.youngs_modulus=1e9', 'fruit.skin.thickness=1e-5',
                           'fruit.nodes=256', 'fruit.pressure.turgor=2e4',
                           'fruit.pressure.bulk_modulus=0', f'contact.model={model}',
                           fast=fast)
    approach = 0.1 * RADIUS
    sim.command_gap(2 * RADIUS - 2 * approach, speed=2 * approach / 0.5)
    return sim, 1.5


def hertz3d(model: str, fast=None):
    sim = make_simulation(load_config(overrides=[
        'dimension=3', 'world.gravity=0', 'world.table=false', 'fruit.density=50',
        'fruit.damping.mass=20', 'sim.dt=0.05', 'sim.max_contact_passes=30',
        f'fruit.shape.diameter={2 * RADIUS}', f'gripper.initial_gap={2 * RADIUS + 1e-4}',
        'fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.mesh.subdivisions=4',
        'fruit.mesh.jaw_refinement=0.4', 'fruit.mesh.order=1',
        'fruit.flesh.youngs_modulus=1e6', 'fruit.flesh.poisson_ratio=0.3',
        f'contact.model={model}']))
    sim.command_gap(sim.fruit.rest_width - 0.05 * RADIUS, 0.005 * RADIUS / 0.05)
    return sim, 0.6


def timed(case, model: str, fast=None):
    """(CPU s, Newton iterations, grip force N, contact length m) of one run."""
    start = time.process_time()
    if case == 'pick':
        sim, _ = pick(1.2, overrides=[f'contact.model={model}'])
        iterations = float('nan')
        result = sim.last
    else:
        sim, duration = case(model, fast)
        iterations = 0
        for _ in range(int(round(duration / sim.dt))):
            result = sim.step()
            iterations += result.newton_iterations
    return (time.process_time() - start, iterations, result.grip_force,
            result.deformation.contact_length)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=2)
    parser.add_argument('--pick', action='store_true', help='also the grasp-and-lift')
    args = parser.parse_args(argv)
    print(f'load average {os.getloadavg()[0]:.2f}; CPU seconds, best of {args.repeat}')
    runs = [('hertz', hertz, 'mmm', None), ('hertz', hertz, 'ipc', None),
            ('membrane', membrane, 'mmm', None), ('membrane', membrane, 'mmm-numpy', False),
            ('membrane', membrane, 'ipc', None),
            ('hertz3d', hertz3d, 'mmm', None), ('hertz3d', hertz3d, 'ipc', None)]
    if args.pick:
        runs += [('pick', 'pick', 'mmm', None), ('pick', 'pick', 'ipc', None)]
    print(f"{'case':10s} {'model':10s} {'CPU s':>8s} {'Newton':>7s} {'force N':>9s} "
          f"{'contact mm':>10s}")
    best = {}
    for name, case, label, fast in runs:
        model = label.split('-')[0]
        figures = min((timed(case, model, fast) for _ in range(args.repeat)),
                      key=lambda f: f[0])
        best[name, label] = figures[0]
        cpu, iterations, force, length = figures
        print(f'{name:10s} {label:10s} {cpu:8.2f} {iterations:7.0f} {force:9.4f} '
              f'{1e3 * length:10.3f}')
    for name in ('hertz', 'membrane', 'hertz3d', 'pick'):
        if (name, 'ipc') in best:
            print(f'{name}: ipc / mmm CPU time = {best[name, "ipc"] / best[name, "mmm"]:.2f}')
    print(f'membrane: ipc / mmm-numpy CPU time = '
          f'{best["membrane", "ipc"] / best["membrane", "mmm-numpy"]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
