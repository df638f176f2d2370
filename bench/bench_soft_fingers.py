"""Benchmark of the deformable solid pad finger against the rigid flat finger: a 2D
grasp-and-lift of the default apple. Prints figures; asserts nothing.

CPU time of this process (``time.process_time``, the best of ``--repeat`` runs, of the
simulation's construction and the grasp: the configuration's loading and the probe
that finds where the fingers touch are left out; the machine's load average is
printed), side by side for ``gripper.finger.type`` flat and
solid_pad: the apple (shell model, 64 nodes) on the table, the jaws starting 1 mm from
it (from the fingers' fronts for the pad), closed in force mode to ``--force`` N, lifted
1 cm and held 0.2 s at dt = 1 ms (each finger's grasp run once untimed first, numba's
caches loaded); with the CPU time inside the barrier model's compiled Newton solves
(``in solves``, ``solve_timer``: what compiling the Python around them would leave), the
outcome, steps, solves, Newton iterations, and at the end the grip force, the contact
length (both jaws) and the peak damage pressure (Hertz estimate).
Each finger's grasp runs on two routes: ``watched``, a callback seeing every step (as the
ROS node and the recorders step: every step's result is built), and ``unwatched``,
``run_grasp`` without a callback (as ``pick``, ``window`` and studies run it: the flat
finger's steps at which the grasp decides nothing run many at a time in one compiled
call, ``Simulation.advance``; a deformable finger has no such route and steps one at a
time either way). The ratios are printed for both routes, and the two grasps' sizes'
(unknowns times Newton iterations, the deformable finger's over the flat finger's): the
CPU ratio at which both cost the same per unknown and iteration.
The flat finger takes its usual route (the modified mass method, the compiled whole
step); the solid pad two meshed blocks in the state and the barrier contact on the
Newton solver (its compiled energies on a fixed pattern).

``--baseline DIR`` compares with another checkout of the project (its kernels compiled
once): runs of this tree and of DIR alternate, each in a fresh process (this script on
the other tree, through the GRIPPER_SIM_TREE environment variable; each finger's grasp
run once untimed first, numba's caches loaded), and the table gives both (best of
``--repeat`` each). ``--set KEY=VALUE`` (repeatable) overrides a configuration key in
the deformable finger's grasp, the reference's left as it is (e.g.
``gripper.finger.fin_ray.element_length=0.004``), and ``--reference-set KEY=VALUE`` one
in the rigid finger's (e.g. ``contact.model=ipc``: the same contact model as the
deformable finger's); a bad key or value is a usage error.

Usage::

    nice python bench/bench_soft_fingers.py [--repeat N] [--force N] [--set KEY=VALUE]
        [--reference-set KEY=VALUE] [--baseline DIR]
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

from baseline import add_arguments, alternated, best_by_key, parse_checked  # noqa: E402
from solve_timer import solves_timed  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.simulation import Simulation  # noqa: E402
from gripper_sim.errors import ConfigError  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402

#: the fingers compared
FINGERS = ('flat', 'solid_pad')


def add_set_argument(parser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` option of the soft-finger benchmarks."""
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help=help_text)


def checked_config(parser, finger: str, settings: list, option: str = '--set'):
    """The configuration of ``finger`` with the ``option`` ``settings`` ('KEY=VALUE'); a
    bad key or value is the parser's usage error (exit 2)."""
    try:
        return load_config(overrides=[f'gripper.finger.type={finger}', *settings])
    except ConfigError as error:
        parser.error(f'{option}: {error}')


#: the routes a grasp is run on (see the module doc)
ROUTES = ('watched', 'unwatched')


def grasp(finger: str, force: float, overrides: tuple = (), watched: bool = True) -> dict:
    """One grasp-and-lift, the jaws starting 1 mm wider than where the fingers touch the
    apple, the configuration keys ``overrides`` ('KEY=VALUE') set, ``watched`` by a
    per-step callback or not; its CPU time (s: the simulation's construction and the
    grasp, not the configuration's loading nor the probe that finds where the fingers
    touch), of it inside the compiled barrier Newton solves (s, ``solve_timer``), and
    counts (Newton iterations only when watched: -1;
    ``unknowns`` the Newton solver's, the fruit's and any deformable finger's dofs)."""
    config = load_config(overrides=[f'gripper.finger.type={finger}', *overrides])
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    with solves_timed() as inside:
        start = time.process_time()
        sim = Simulation(config)
        iterations = []
        summary = run_grasp(sim, GraspSequence(sim, force, lift_height=0.01, hold_time=0.2),
                            on_step=(lambda result, phase: iterations.append(
                                result.newton_iterations)) if watched else None)
        cpu = time.process_time() - start
    return dict(cpu=cpu, solve_cpu=inside[0], outcome=summary['outcome'],
                steps=int(sim.last.step), solves=int(sim.gap_solves),
                newton=int(sum(iterations)) if watched else -1,
                unknowns=int(sim.solver.m.size),
                force=float(sim.last.grip_force),
                contact=float(sim.last.deformation.contact_length),
                pressure=float(sim.last.damage.peak_pressure))


def _baseline_rows(script: Path, baseline: Path, fingers: tuple, force: float,
                   overrides: list, reference_overrides: list, repeat: int) -> dict:
    """{'this': rows, 'baseline': rows}, rows the best grasp per finger of each tree, runs
    alternated in fresh processes (see the module doc)."""
    settings = [word for option, items in (('--set', overrides),
                                           ('--reference-set', reference_overrides))
                for item in items for word in (option, item)]
    outputs = alternated(script, baseline, ['--plain', '--force', str(force), *settings],
                         repeat)
    return {label: best_by_key(runs, lambda row: row['cpu']) for label, runs in outputs.items()}


def row_key(finger: str, route: str) -> str:
    """The key of a grasp's row: the finger's name for the watched route (as before the
    routes), '<finger> unwatched' for the other."""
    return finger if route == 'watched' else f'{finger} {route}'


def _print_rows(rows: dict, fingers: tuple) -> None:
    print(f"{'finger':10s} {'route':>9s} {'CPU s':>8s} {'in solves':>9s} {'outcome':>8s} "
          f"{'steps':>6s} {'solves':>7s} {'Newton':>7s} {'force N':>8s} {'contact mm':>10s} "
          f"{'Hertz kPa':>9s}")
    for finger in fingers:
        for route in ROUTES:
            r = rows[row_key(finger, route)]
            inside = f"{r['solve_cpu']:9.3f}" if r['solve_cpu'] else f"{'-':>9s}"
            newton = f"{r['newton']:7d}" if r['newton'] >= 0 else f"{'-':>7s}"
            print(f"{finger:10s} {route:>9s} {r['cpu']:8.3f} {inside} {r['outcome']:>8s} "
                  f"{r['steps']:6d} {r['solves']:7d} {newton} {r['force']:8.3f} "
                  f"{r['contact'] * 1e3:10.1f} {r['pressure'] * 1e-3:9.0f}")
    reference, other = fingers
    for route in ROUTES:
        mine, theirs = rows[row_key(other, route)], rows[row_key(reference, route)]
        ratio = mine['cpu'] / theirs['cpu']
        solves_alone = mine['solve_cpu'] / theirs['cpu']
        print(f"{route}: {other} / {reference}: {ratio:.1f}x" + (
            f"; {other}'s compiled solves alone / {reference}: {solves_alone:.1f}x"
            if solves_alone else ''))
    mine, theirs = rows[other], rows[reference]
    if 'unknowns' in mine and 'unknowns' in theirs and min(mine['newton'], theirs['newton']) > 0:
        work = mine['unknowns'] * mine['newton'] / (theirs['unknowns'] * theirs['newton'])
        print(f"size: {other} {mine['unknowns']} unknowns x {mine['newton']} Newton "
              f"iterations / {reference} {theirs['unknowns']} x {theirs['newton']}: "
              f'{work:.1f}x (the CPU ratio at equal cost per unknown and iteration)')


def _runs(fingers: tuple, force: float, overrides: dict) -> dict:
    """Each finger's grasp on each route once ({row_key: row})."""
    return {row_key(finger, route): grasp(finger, force, overrides[finger],
                                          route == 'watched')
            for finger in fingers for route in ROUTES}


def compare(fingers: tuple[str, str], description: str, argv=None) -> int:
    """The grasp with each of ``fingers`` (the reference first); prints a table (two with
    ``--baseline``)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument('--repeat', type=int, default=1, help='runs per finger (best kept)')
    parser.add_argument('--force', type=float, default=4.0, help='grip force, N')
    add_set_argument(parser, "override a configuration key in the deformable finger's "
                     'grasp (repeatable)')
    parser.add_argument('--reference-set', action='append', default=[], metavar='KEY=VALUE',
                        help="override a configuration key in the rigid finger's grasp "
                        '(repeatable; e.g. contact.model=ipc)')
    add_arguments(parser, 'each grasp once after a warm-up, as JSON (what --baseline runs)')
    args = parse_checked(parser, argv)
    reference, deformable = fingers
    checked_config(parser, deformable, args.set)
    checked_config(parser, reference, args.reference_set, '--reference-set')
    overrides = {reference: tuple(args.reference_set), deformable: tuple(args.set)}
    if args.plain:
        _runs(fingers, args.force, overrides)  # untimed: numba's caches loaded
        print(json.dumps(_runs(fingers, args.force, overrides)))
        return 0
    if args.baseline is not None:
        script = Path(sys.modules['__main__'].__file__).resolve()
        tables = _baseline_rows(script, args.baseline, fingers, args.force, args.set,
                                args.reference_set, args.repeat)
        print(f'load average {os.getloadavg()[0]:.2f} at the end; CPU time '
              f'(time.process_time), best of {args.repeat} runs each, alternated: this tree '
              f'and baseline ({args.baseline.resolve()})')
        for label, rows in tables.items():
            print(f'-- {label}')
            _print_rows(rows, fingers)
        return 0
    print(f'load average {os.getloadavg()[0]:.2f}; CPU time (time.process_time), best of '
          f'{args.repeat}' + ''.join(f'; {deformable}: {item}' for item in args.set)
          + ''.join(f'; {reference}: {item}' for item in args.reference_set))
    _runs(fingers, args.force, overrides)  # untimed: numba's caches loaded
    runs = [_runs(fingers, args.force, overrides) for _ in range(args.repeat)]
    _print_rows({key: min((run[key] for run in runs), key=lambda r: r['cpu'])
                 for key in runs[0]}, fingers)
    return 0


def main(argv=None) -> int:
    return compare(FINGERS, __doc__.splitlines()[0], argv)


if __name__ == '__main__':
    sys.exit(main())
