"""Real-time factor of a 3D grasp-and-lift, and where the time goes.

    PYTHONPATH=. python bench/bench_3d.py [--quick] [--model shell|solid|both]
    PYTHONPATH=. python bench/bench_3d.py --against OTHER_TREE [--rounds 3]

For each 3D model (the apple preset as a ~640-vertex shell, and as a ~2000-tetrahedron
solid) it runs the same grasp (close to a grip force of 2 mu N = 1.5 m g, settle, lift
2 cm, hold 0.3 s) at a reference step and at larger steps, keeps the largest step whose
peak grip force is within 2 % of the reference, and prints for it the simulated time
over the wall time (the real-time factor; >= 1 is real time), the CPU time per step
(what the step costs on a quiet core), the linear algebra per step (Newton systems,
LDL^T factorisations, conjugate-gradient iterations) and a breakdown of the CPU time by
part (energy kernels, LDL^T factorisation, triangular solves, the rest of Newton, contact
bookkeeping, measures). Single thread; wall figures vary with the machine's load, which
is printed.

``--against DIR`` compares source trees side by side in one run (e.g. a checkout of an
older commit, ``git archive COMMIT | tar -x -C DIR``): the grasp at the 20 ms step runs
in a fresh process per tree (``GRIPPER_SIM_TREE``), the trees taking turns for
``--rounds`` rounds so that the machine's load falls on both alike; it prints the CPU
time per step and the real-time factor per core (simulated time over CPU time) of each.
"""
from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

from baseline import THIS_TREE, run_in_tree
#: the source tree whose gripper_sim the benchmark imports (the child processes of
#: ``--against`` set it)
sys.path.insert(0, os.environ.get('GRIPPER_SIM_TREE', str(THIS_TREE)))

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
    ('_measure', 'measures (wrenches, areas, damage)'),
]
#: the kept preconditioner's kernels (``core.sparse_ldl``): block LDL^T factorisation
#: and solve
_FACTOR = 'ldl_factor_3'
_TRISOLVE = 'ldl_solve_3'


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
            ('block LDL^T factorisation', factor),
            ('triangular solves (CG preconditioner, direct)', trisolve),
            ('Newton rest (filter S H S, CG, friction, search)',
             newton - energies - factor - trisolve)]
    rows.append(('contact passes (constraints, updates, end velocities)',
                 cum.get('contact_step', 0.0) - newton))
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
          + ('fast (numba kernels, CG on a kept LDL^T)' if getattr(sim.solver, 'fast', False)
             else 'numpy reference'))
    print(f'  reference dt {reference_dt * 1e3:g} ms: outcome {ref["outcome"]}, peak grip '
          f'force {ref["peak_grip_force"]:.4f} N, slip {ref["slip_distance"] * 1e3:.2f} mm, '
          f'{sim.time:.2f} s simulated in {wall:.1f} s (real-time factor {sim.time / wall:.3f})')
    chosen = None
    for dt in candidates:
        sim, summary, wall, cpu, _ = grasp(overrides, dt)
        dev = summary['peak_grip_force'] / ref['peak_grip_force'] - 1
        ok = abs(dev) <= 0.02 and summary['outcome'] == ref['outcome']
        print(f'  dt {dt * 1e3:g} ms: outcome {summary["outcome"]}, peak grip force '
              f'{summary["peak_grip_force"]:.4f} N ({dev * 100:+.2f} % vs reference), slip '
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
        print(f'     per step: {sim.gap_solves / steps:.2f} solves of the jaw drive (gaps), '
              + ', '.join(f'{stats[k] / steps:.2f} {label}' for k, label in (
                  ('passes', 'Newton solves (contact passes)'), ('systems', 'Newton systems'),
                  ('factorisations', 'LDL^T factorisations'), ('cg_iterations', 'CG iterations'))))
    sim, summary, wall, cpu, profiler = grasp(overrides, chosen, profile=True)
    print(f'     CPU time by part (under the profiler, {cpu / steps * 1e3:.1f} ms per step):')
    for label, seconds in breakdown(profiler, cpu):
        print(f'     {label:50s} {seconds:7.2f} s  {seconds / cpu * 100:5.1f} %')


#: the step of the side-by-side comparison (the 3D default, ``sim.dt``'s 3D default)
COMPARE_DT = 0.02


def one_grasp(model: str) -> dict:
    """The grasp of ``model`` at ``COMPARE_DT`` in this process: CPU s, steps, simulated
    s, outcome, peak grip force N."""
    sim, summary, _, cpu, _ = grasp(MODELS[model], COMPARE_DT)
    stats = getattr(sim.solver, 'stats', {})
    return dict(cpu=cpu, steps=sim.last.step, time=sim.time, outcome=summary['outcome'],
                peak=summary['peak_grip_force'], gap_solves=sim.gap_solves,
                passes=stats.get('passes', 0), systems=stats.get('systems', 0))


def side_by_side(models: list[str], trees: list[Path], rounds: int) -> None:
    """Print CPU per step and real-time factor per core of each tree, taking turns."""
    runs = {(model, tree): [] for model in models for tree in trees}
    loads = []
    for round_ in range(rounds + 1):   # round 0 warms numba's cache of each tree
        for model in models:
            for tree in trees:
                run = run_in_tree(Path(__file__), tree, ['--child', model])
                if round_ > 0:
                    runs[(model, tree)].append(run)
                    loads.append(os.getloadavg()[0])
    print(f'side by side at dt {COMPARE_DT * 1e3:g} ms, {rounds} rounds taking turns, load '
          f'{min(loads):.1f}-{max(loads):.1f} on {os.cpu_count()} cores; CPU time '
          '(time.process_time) of the grasp, per step; real-time factor = simulated s / CPU s')
    print(f'{"model":6} {"tree":40} {"outcome":8} {"peak N":>7} {"steps":>5} '
          f'{"CPU ms/step (median, min-max)":>30} {"real-time factor per core":>26}  '
          'per step: gap solves, contact passes, Newton systems')
    for model in models:
        for tree in trees:
            rows = runs[(model, tree)]
            per_step = [r['cpu'] / r['steps'] * 1e3 for r in rows]
            factors = [r['time'] / r['cpu'] for r in rows]
            print(f'{model:6} {str(tree)[-40:]:40} {rows[0]["outcome"]:8} '
                  f'{rows[0]["peak"]:7.4f} {rows[0]["steps"]:5d} '
                  f'{statistics.median(per_step):12.1f} ({min(per_step):.1f}-{max(per_step):.1f})'
                  f'{"":6} {statistics.median(factors):8.3f} '
                  f'({min(factors):.3f}-{max(factors):.3f})  '
                  + ', '.join(f'{rows[0].get(k, 0) / rows[0]["steps"]:.2f}'
                              for k in ('gap_solves', 'passes', 'systems')))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true',
                        help='reference dt 5 ms, candidates 20 and 10 ms')
    parser.add_argument('--model', choices=('shell', 'solid', 'both'), default='both')
    parser.add_argument('--against', type=Path, nargs='+', metavar='DIR',
                        help='other source trees to compare with this one, side by side')
    parser.add_argument('--rounds', type=int, default=3, help='with --against')
    parser.add_argument('--child', choices=tuple(MODELS), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(one_grasp(args.child)))
        return 0
    models = ['shell', 'solid'] if args.model == 'both' else [args.model]
    if args.against:
        side_by_side(models, [THIS_TREE] + [tree.resolve() for tree in args.against],
                     args.rounds)
        return 0
    for model in models:
        bench(model, args.quick)
    return 0


if __name__ == '__main__':
    sys.exit(main())
