"""Benchmark of the barrier contact model (``contact.model: ipc``) against the modified
mass method (``mmm``) on rigid-finger cases. Prints figures; asserts nothing.

CPU time of this process (``time.process_time``, the best of ``--repeat`` runs; the
machine's load average is printed), for each case and model, with Newton iterations and
(``solves s``) the CPU time inside the 2D barrier model's compiled Newton solves, the
part of the barrier model's time that compiling the Python around them would leave:

- ``hertz``: the solid disk (256 surface nodes) pressed to 1.5 N by flat jaws, 1.5 s of
  simulated time at dt = 10 ms. ``mmm`` runs the compiled whole step (``core.fast``,
  which now covers the solid fruit too), the barrier model the compiled energies on the
  fixed-pattern Newton solver (``core.fast_solver``).
- ``membrane``: the pressurised ring (256 nodes) squeezed by 10 % of its radius.
  ``mmm`` runs the whole step in one numba kernel (``core.fast``), which the barrier
  model does not have; ``mmm-shared`` is the same method on the route the barrier model
  takes (``Simulation(config, fast=False)``: the contact passes over the shared solver).
- ``hertz3d``: the 3D solid sphere (linear tetrahedra, 922 nodes, 307 on the surface)
  pressed by D = 0.05 R between flat plates, 0.6 s at dt = 50 ms: the 3D model has one
  solver (the fixed-pattern Newton solver) for both contact models.
- ``pick``: the default apple gripped (2 mu N = 1.2 m g), lifted 2 cm and held 1 s,
  with the table, gravity and friction (``--pick`` to include it; about 10 s).

``--baseline DIR`` compares with another checkout of the project (its kernels compiled
once, e.g. by a run of this script in it): runs of this tree and of DIR alternate, each
in a fresh process (this script on the other tree, through the GRIPPER_SIM_TREE
environment variable; every case run once untimed first, numba's caches loaded), and
the table gives both CPU times (best of ``--repeat`` each) with each run's figures.

Usage::

    nice python bench/bench_barrier.py [--repeat N] [--pick] [--baseline DIR]
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

#: the checkout whose gripper_sim is measured: this one, or GRIPPER_SIM_TREE (--baseline)
ROOT = Path(os.environ.get('GRIPPER_SIM_TREE') or Path(__file__).resolve().parents[1])
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))

from baseline import add_arguments, alternated, best_by_key, parse_checked  # noqa: E402
from helpers import pick, quasi_static_sim  # noqa: E402
from solve_timer import solves_timed  # noqa: E402

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
    """(CPU s, Newton iterations, grip force N, contact length m, CPU s inside the
    compiled 2D barrier solves, 0 where none ran: ``solve_timer``) of one run."""
    with solves_timed() as solves:
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
        cpu = time.process_time() - start
    return (cpu, iterations, result.grip_force, result.deformation.contact_length,
            solves[0])


def _runs(pick_too: bool) -> list:
    """(case name, case, label, fast) of the runs, in order."""
    runs = [('hertz', hertz, 'mmm', None), ('hertz', hertz, 'ipc', None),
            ('membrane', membrane, 'mmm', None), ('membrane', membrane, 'mmm-shared', False),
            ('membrane', membrane, 'ipc', None),
            ('hertz3d', hertz3d, 'mmm', None), ('hertz3d', hertz3d, 'ipc', None)]
    if pick_too:
        runs += [('pick', 'pick', 'mmm', None), ('pick', 'pick', 'ipc', None)]
    return runs


def measure(runs: list, repeat: int) -> dict:
    """(case name, label) -> the figures of ``timed`` with the least CPU time of
    ``repeat`` runs."""
    best = {}
    for name, case, label, fast in runs:
        model = label.split('-')[0]
        best[name, label] = min((timed(case, model, fast) for _ in range(repeat)),
                                key=lambda f: f[0])
    return best


def plain(runs: list) -> dict:
    """Each run once untimed (numba's caches loaded), then once timed: figures by
    'name label' (what --baseline runs in each tree)."""
    measure(runs, 1)
    return {f'{name} {label}': figures for (name, label), figures in measure(runs, 1).items()}


def compare(baseline: Path, pick_too: bool, repeat: int) -> dict:
    """The best figures of this tree and of ``baseline``, runs alternated in fresh
    processes: {'this': best, 'baseline': best} (see the module doc)."""
    outputs = alternated(Path(__file__).resolve(), baseline,
                         ['--plain'] + (['--pick'] if pick_too else []), repeat)
    return {label: {tuple(key.split()): figures
                    for key, figures in best_by_key(runs, lambda f: f[0]).items()}
            for label, runs in outputs.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=2)
    parser.add_argument('--pick', action='store_true', help='also the grasp-and-lift')
    add_arguments(parser, 'each run once after a warm-up, figures as JSON (what --baseline '
                          'runs)')
    args = parse_checked(parser, argv)
    runs = _runs(args.pick)
    if args.plain:
        print(json.dumps(plain(runs)))
        return 0
    if args.baseline is not None:
        tables = compare(args.baseline, args.pick, args.repeat)
        print(f'load average {os.getloadavg()[0]:.2f} at the end; CPU seconds, best of '
              f'{args.repeat} runs each, alternated: this tree and baseline '
              f'({args.baseline.resolve()})')
    else:
        print(f'load average {os.getloadavg()[0]:.2f}; CPU seconds, best of {args.repeat}')
        tables = {'this': measure(runs, args.repeat)}
    for tree, best in tables.items():
        if len(tables) > 1:
            print(f'-- {tree}')
        print(f"{'case':10s} {'model':10s} {'CPU s':>8s} {'Newton':>7s} {'force N':>9s} "
              f"{'contact mm':>10s} {'solves s':>9s}")
        for name, _, label, _ in runs:
            cpu, iterations, force, length, solves = best[name, label]
            print(f'{name:10s} {label:10s} {cpu:8.3f} {iterations:7.0f} {force:9.4f} '
                  f'{1e3 * length:10.3f} ' + (f'{solves:9.3f}' if solves else f"{'-':>9s}"))
        for name in ('hertz', 'membrane', 'hertz3d', 'pick'):
            if (name, 'ipc') in best:
                ipc, mmm = best[name, 'ipc'], best[name, 'mmm']
                print(f'{name}: ipc / mmm CPU time = {ipc[0] / mmm[0]:.2f}' + (
                    f'; its compiled solves alone / mmm = {ipc[4] / mmm[0]:.2f}'
                    if ipc[4] else ''))
        print(f'membrane: ipc / mmm-shared CPU time = '
              f'{best["membrane", "ipc"][0] / best["membrane", "mmm-shared"][0]:.2f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
