"""Real-time factor of a 3D grasp-and-lift, and where the time goes.

    PYTHONPATH=. python bench/bench_3d.py [--quick] [--model shell|solid|both]

For each 3D model (the apple preset as a ~640-vertex shell, and as a ~2000-tetrahedron
solid) it runs the same grasp (close to a grip force of 2 mu N = 1.5 m g, settle, lift
2 cm, hold 0.3 s) at a reference step and at larger steps, keeps the largest step whose
peak grip force is within 2 % of the reference, and prints for it the simulated time
over the wall time (the real-time factor; >= 1 is real time) and a breakdown of the wall
time by part (energies and their Hessians, sparse assembly and filtering, LU solves,
contact bookkeeping, measures). Single thread; figures vary with the machine's load.
"""
from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core import make_simulation  # noqa: E402
from gripper_sim.core.grasp import GraspSequence, run_grasp  # noqa: E402

MODELS = {
    'shell': ['dimension=3', 'fruit.model=shell', 'fruit.mesh.subdivisions=8',
              'fruit.mesh.jaw_refinement=1'],
    'solid': ['dimension=3', 'fruit.model=solid', 'fruit.skin.enabled=false',
              'fruit.mesh.subdivisions=6', 'fruit.mesh.jaw_refinement=1',
              'fruit.mesh.max_tet_volume=1.5e-7'],
}

#: (function name suffix in the profile, part) for the time breakdown
PARTS = [
    ('evaluate', 'energies (value, gradient, Hessian)'),
    ('_solve_with_low_rank', 'LU factorisation and solves'),
    ('_constraints', 'contact: constraints'),
    ('_update_contacts', 'contact: update (stick/slip/release/detect)'),
    ('_measure', 'measures (wrenches, areas, damage)'),
]


def grasp(overrides: list[str], dt: float, profile: bool = False):
    config = load_config(overrides=overrides + [f'sim.dt={dt}',
                                                'contact.jaw.static_friction=0.5',
                                                'contact.jaw.kinetic_friction=0.5'])
    sim = make_simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    sequence = GraspSequence(sim, 1.5 * weight, lift_height=0.02, hold_time=0.3)
    profiler = cProfile.Profile() if profile else None
    start = time.perf_counter()
    if profiler:
        profiler.enable()
    summary = run_grasp(sim, sequence)
    if profiler:
        profiler.disable()
    wall = time.perf_counter() - start
    return sim, summary, wall, profiler


def breakdown(profiler, wall: float) -> list[tuple[str, float]]:
    stats = pstats.Stats(profiler).stats
    rows = []
    cum = {}
    for (filename, _, name), (_, _, _, cumtime, _) in stats.items():
        if 'gripper_sim' not in filename:
            continue
        cum.setdefault(name, 0.0)
        cum[name] = max(cum[name], cumtime)
    energies = sum(t for (f, _, n), (_, _, _, t, _) in stats.items()
                   if n == 'evaluate' and 'energies' in f)
    solver_eval = cum.get('_evaluate', 0.0)
    lu = cum.get('_solve_with_low_rank', 0.0)
    solve = cum.get('solve', 0.0)
    rows.append(('energies (value, gradient, Hessian)', energies))
    rows.append(('assembly: triplets -> sparse, friction, damping', solver_eval - energies))
    rows.append(('LU factorisation and solves (SuperLU)', lu))
    rows.append(('Newton rest (filters S K S, line search)', solve - solver_eval - lu))
    for name, label in PARTS[2:]:
        rows.append((label, cum.get(name, 0.0)))
    rows.append(('total wall (profiled)', wall))
    return rows


def bench(model: str, quick: bool) -> None:
    overrides = MODELS[model]
    reference_dt = 0.005 if quick else 0.0025
    candidates = (0.02, 0.01) if quick else (0.02, 0.01, 0.005)
    sim, ref, wall, _ = grasp(overrides, reference_dt)
    fruit = sim.fruit
    print(f'\n{model}: {fruit.n_nodes} vertices ({len(fruit.surface)} on the surface), '
          f'{len(fruit.tetrahedra)} tetrahedra, {fruit.total_mass * 1e3:.0f} g')
    print(f'  reference dt {reference_dt * 1e3:g} ms: outcome {ref["outcome"]}, peak grip '
          f'force {ref["max_grip_force"]:.4f} N, {sim.time:.2f} s simulated in {wall:.1f} s '
          f'(real-time factor {sim.time / wall:.3f})')
    chosen = None
    for dt in candidates:
        sim, summary, wall, _ = grasp(overrides, dt)
        dev = summary['max_grip_force'] / ref['max_grip_force'] - 1
        ok = abs(dev) <= 0.02 and summary['outcome'] == ref['outcome']
        print(f'  dt {dt * 1e3:g} ms: outcome {summary["outcome"]}, peak grip force '
              f'{summary["max_grip_force"]:.4f} N ({dev * 100:+.2f} % vs reference), '
              f'real-time factor {sim.time / wall:.3f}' + ('' if ok else '  (rejected)'))
        if ok:
            chosen = dt
            break
    if chosen is None:
        chosen = reference_dt
    sim, summary, wall, profiler = grasp(overrides, chosen, profile=True)
    steps = sim.last.step
    print(f'  -> dt {chosen * 1e3:g} ms: real-time factor {sim.time / wall:.3f} under the '
          f'profiler ({steps} steps, {wall / steps * 1e3:.1f} ms per step)')
    for label, seconds in breakdown(profiler, wall):
        print(f'     {label:50s} {seconds:7.2f} s  {seconds / wall * 100:5.1f} %')


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
