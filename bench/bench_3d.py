"""Real-time factor of a 3D grasp-and-lift, and where the time goes.

    PYTHONPATH=. python bench/bench_3d.py [--quick] [--model shell|solid|both]

For each 3D model (the apple preset as a ~640-vertex shell, and as a ~2000-tetrahedron
solid) it runs the same grasp (close to a grip force of 2 mu N = 1.5 m g, settle, lift
2 cm, hold 0.3 s) at a reference step and at larger steps, keeps the largest step whose
peak grip force is within 2 % of the reference, and prints for it the simulated time
over the wall time (the real-time factor; >= 1 is real time), the CPU time per step
(what the step costs on a quiet core), the linear algebra per step (Newton systems,
LU factorisations, conjugate-gradient iterations) and a breakdown of the CPU time by
part (energy kernels, LU factorisation, triangular solves, the rest of Newton, contact
bookkeeping, measures). Single thread; wall figures vary with the machine's load, which
is printed. ``GRIPPER_SIM_FAST=0`` runs the numpy reference path instead.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402

MODELS = {
    'shell': ['dimension=3', 'fruit.model=shell', 'fruit.mesh.subdivisions=8',
              'fruit.mesh.jaw_refinement=1'],
    # one layer of prisms below a 259-vertex surface: 519 nodes, 2056 tetrahedra (the
    # size of the TetGen mesh this benchmark used before, 542 nodes and 2089 tetrahedra)
    'solid': ['dimension=3', 'fruit.model=solid', 'fruit.skin.enabled=false',
              'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=0.5',
              'fruit.mesh.max_tet_volume=0.01'],
}

#: (function name in the profile, part) for the time breakdown
PARTS = [
    ('_constraints', 'contact: constraints'),
    ('_update_contacts', 'contact: update (stick/slip/release/detect)'),
    ('_measure', 'measures (wrenches, areas, damage)'),
]
_FACTOR = '<built-in method scipy.sparse.linalg._dsolve._superlu.gstrf>'
_TRISOLVE = "<method 'solve' of 'SuperLU' objects>"


def grasp(overrides: list[str], dt: float, profile: bool = False):
    """Run the grasp; (simulation, summary, wall s, CPU s, profiler or None)."""
    config = load_config(overrides=overrides + [f'sim.dt={dt}',
                                                'contact.jaw.static_friction=0.5',
                                                'contact.jaw.kinetic_friction=0.5'])
    sim = make_simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    sequence = GraspSequence(sim, 1.5 * weight, lift_height=0.02, hold_time=0.3)
    profiler = cProfile.Profile(time.process_time) if profile else None
    start, cpu = time.perf_counter(), time.process_time()
    if profiler:
        profiler.enable()
    summary = run_grasp(sim, sequence)
    if profiler:
        profiler.disable()
    return (sim, summary, time.perf_counter() - start, time.process_time() - cpu, profiler)


def breakdown(profiler, total: float) -> list[tuple[str, float]]:
    """(part, CPU s) of a profiled run whose CPU time was ``total``."""
    stats = pstats.Stats(profiler).stats
    cum: dict[str, float] = {}
    own: dict[str, float] = {}
    energies = 0.0
    for (filename, _, name), (_, _, tottime, cumtime, _) in stats.items():
        own[name] = own.get(name, 0.0) + tottime
        if 'gripper_sim' in filename:
            cum[name] = max(cum.get(name, 0.0), cumtime)
            if name in ('evaluate', 'evaluate_into') and 'energies' in filename:
                energies += cumtime
    factor = own.get(_FACTOR, 0.0)
    trisolve = own.get(_TRISOLVE, 0.0)
    newton = cum.get('solve', 0.0)
    rows = [('energy kernels (value, gradient, Hessian)', energies),
            ('sparse LU factorisation (SuperLU)', factor),
            ('triangular solves (CG preconditioner, direct)', trisolve),
            ('Newton rest (filter S H S, CG, friction, search)',
             newton - energies - factor - trisolve)]
    for name, label in PARTS:
        rows.append((label, cum.get(name, 0.0)))
    rows.append(('total CPU (profiled)', total))
    return rows


def bench(model: str, quick: bool) -> None:
    overrides = MODELS[model]
    reference_dt = 0.005 if quick else 0.0025
    candidates = (0.02, 0.01) if quick else (0.02, 0.01, 0.005)
    sim, ref, wall, cpu, _ = grasp(overrides, reference_dt)
    fruit = sim.fruit
    print(f'\n{model}: {fruit.n_nodes} vertices ({len(fruit.surface)} on the surface), '
          f'{len(fruit.tetrahedra)} tetrahedra, {fruit.total_mass * 1e3:.0f} g; solver: '
          + ('fast (numba kernels, CG on a kept LU)' if getattr(sim.solver, 'fast', False)
             else 'numpy reference'))
    print(f'  reference dt {reference_dt * 1e3:g} ms: outcome {ref["outcome"]}, peak grip '
          f'force {ref["max_grip_force"]:.4f} N, slip {ref["slip_distance"] * 1e3:.2f} mm, '
          f'{sim.time:.2f} s simulated in {wall:.1f} s (real-time factor {sim.time / wall:.3f})')
    chosen = None
    for dt in candidates:
        sim, summary, wall, cpu, _ = grasp(overrides, dt)
        dev = summary['max_grip_force'] / ref['max_grip_force'] - 1
        ok = abs(dev) <= 0.02 and summary['outcome'] == ref['outcome']
        print(f'  dt {dt * 1e3:g} ms: outcome {summary["outcome"]}, peak grip force '
              f'{summary["max_grip_force"]:.4f} N ({dev * 100:+.2f} % vs reference), slip '
              f'{summary["slip_distance"] * 1e3:.2f} mm, real-time factor {sim.time / wall:.3f} '
              f'(CPU {sim.time / cpu:.3f})' + ('' if ok else '  (rejected)'))
        if ok:
            chosen = dt
            break
    if chosen is None:
        chosen = reference_dt
    sim, summary, wall, cpu, _ = grasp(overrides, chosen)
    steps = sim.last.step
    load = os.getloadavg()[0]
    print(f'  -> dt {chosen * 1e3:g} ms: real-time factor {sim.time / wall:.3f} '
          f'({wall / steps * 1e3:.1f} ms wall per step at load {load:.1f} on '
          f'{os.cpu_count()} cores); CPU {cpu / steps * 1e3:.1f} ms per step, i.e. '
          f'{sim.time / cpu:.3f} x real time on a quiet core')
    stats = getattr(sim.solver, 'stats', None)
    if stats and stats.get('systems'):
        print('     per step: ' + ', '.join(f'{stats[k] / steps:.2f} {label}' for k, label in (
            ('passes', 'Newton solves (contact passes)'), ('systems', 'Newton systems'),
            ('factorisations', 'LU factorisations'), ('cg_iterations', 'CG iterations'))))
    sim, summary, wall, cpu, profiler = grasp(overrides, chosen, profile=True)
    print(f'     CPU time by part (under the profiler, {cpu / steps * 1e3:.1f} ms per step):')
    for label, seconds in breakdown(profiler, cpu):
        print(f'     {label:50s} {seconds:7.2f} s  {seconds / cpu * 100:5.1f} %')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='reference dt 5 ms, candidates 20 and 10 ms')
    parser.add_argument('--model', choices=('shell', 'solid', 'both'), default='both')
    args = parser.parse_args(argv)
    for model in ('shell', 'solid') if args.model == 'both' else (args.model,):
        bench(model, args.quick)
    return 0


if __name__ == '__main__':
    sys.exit(main())
