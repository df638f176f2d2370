"""Benchmark of the deformable solid pad finger against the rigid flat finger: a 2D
grasp-and-lift of the default apple. Prints figures; asserts nothing.

CPU time of this process (``time.process_time``, the best of ``--repeat`` runs; the
machine's load average is printed), side by side for ``gripper.finger.type`` flat and
solid_pad: the apple (shell model, 64 nodes) on the table, the jaws starting 1 mm from
it (from the fingers' fronts for the pad), closed in force mode to ``--force`` N, lifted
1 cm and held 0.2 s at dt = 1 ms (each finger's grasp run once untimed first, numba's
caches loaded); with the CPU time inside the barrier model's compiled Newton solves
(``in solves``, ``solve_timer``: what compiling the Python around them would leave), the
outcome, steps, solves, Newton iterations, and at the end the grip force, the contact
length (both jaws) and the peak damage pressure (Hertz estimate).
The flat finger takes its usual route (the modified mass method, the compiled whole
step); the solid pad two meshed blocks in the state and the barrier contact on the
Newton solver (its compiled energies on a fixed pattern).

``--baseline DIR`` compares with another checkout of the project (its kernels compiled
once): runs of this tree and of DIR alternate, each in a fresh process (this script on
the other tree, through the GRIPPER_SIM_TREE environment variable; each finger's grasp
run once untimed first, numba's caches loaded), and the table gives both (best of
``--repeat`` each). ``--set KEY=VALUE`` (repeatable) overrides a configuration key in
the deformable finger's grasp, the reference's left as it is (e.g.
``gripper.finger.fin_ray.element_length=0.004``); a bad key or value is a usage error.

Usage::

    nice python bench/bench_soft_fingers.py [--repeat N] [--force N] [--set KEY=VALUE]
        [--baseline DIR]
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


def checked_config(parser, finger: str, settings: list):
    """The configuration of ``finger`` with the ``--set`` ``settings`` ('KEY=VALUE'); a
    bad key or value is the parser's usage error (exit 2)."""
    try:
        return load_config(overrides=[f'gripper.finger.type={finger}', *settings])
    except ConfigError as error:
        parser.error(f'--set: {error}')


def grasp(finger: str, force: float, overrides: tuple = ()) -> dict:
    """One grasp-and-lift, the jaws starting 1 mm wider than where the fingers touch the
    apple, the configuration keys ``overrides`` ('KEY=VALUE') set; its CPU time (s), of it
    inside the compiled barrier Newton solves (s, ``solve_timer``), and counts."""
    with solves_timed() as inside:
        start = time.process_time()
        config = load_config(overrides=[f'gripper.finger.type={finger}', *overrides])
        config = config.replaced(
            {'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
        sim = Simulation(config)
        iterations = []
        summary = run_grasp(sim, GraspSequence(sim, force, lift_height=0.01, hold_time=0.2),
                            on_step=lambda result, phase: iterations.append(
                                result.newton_iterations))
        cpu = time.process_time() - start
    return dict(cpu=cpu, solve_cpu=inside[0], outcome=summary['outcome'],
                steps=int(sim.last.step), solves=int(sim.gap_solves),
                newton=int(sum(iterations)), force=float(sim.last.grip_force),
                contact=float(sim.last.deformation.contact_length),
                pressure=float(sim.last.damage.peak_pressure))


def _baseline_rows(script: Path, baseline: Path, fingers: tuple, force: float,
                   overrides: list, repeat: int) -> dict:
    """{'this': rows, 'baseline': rows}, rows the best grasp per finger of each tree, runs
    alternated in fresh processes (see the module doc)."""
    settings = [word for item in overrides for word in ('--set', item)]
    outputs = alternated(script, baseline, ['--plain', '--force', str(force), *settings],
                         repeat)
    return {label: best_by_key(runs, lambda row: row['cpu']) for label, runs in outputs.items()}


def _print_rows(rows: dict, fingers: tuple) -> None:
    print(f"{'finger':10s} {'CPU s':>8s} {'in solves':>9s} {'outcome':>8s} {'steps':>6s} "
          f"{'solves':>7s} {'Newton':>7s} {'force N':>8s} {'contact mm':>10s} "
          f"{'Hertz kPa':>9s}")
    for finger, r in rows.items():
        inside = f"{r['solve_cpu']:9.3f}" if r['solve_cpu'] else f"{'-':>9s}"
        print(f"{finger:10s} {r['cpu']:8.3f} {inside} {r['outcome']:>8s} {r['steps']:6d} "
              f"{r['solves']:7d} {r['newton']:7d} {r['force']:8.3f} "
              f"{r['contact'] * 1e3:10.1f} {r['pressure'] * 1e-3:9.0f}")
    reference, other = fingers
    ratio = rows[other]['cpu'] / rows[reference]['cpu']
    solves_alone = rows[other]['solve_cpu'] / rows[reference]['cpu']
    print(f"{other} / {reference}: {ratio:.1f}x" + (
        f"; {other}'s compiled solves alone / {reference}: {solves_alone:.1f}x"
        if solves_alone else ''))


def compare(fingers: tuple[str, str], description: str, argv=None) -> int:
    """The grasp with each of ``fingers`` (the reference first); prints a table (two with
    ``--baseline``)."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument('--repeat', type=int, default=1, help='runs per finger (best kept)')
    parser.add_argument('--force', type=float, default=4.0, help='grip force, N')
    add_set_argument(parser, "override a configuration key in the deformable finger's "
                     'grasp (repeatable)')
    add_arguments(parser, 'each grasp once after a warm-up, as JSON (what --baseline runs)')
    args = parse_checked(parser, argv)
    reference, deformable = fingers
    checked_config(parser, deformable, args.set)
    overrides = {reference: (), deformable: tuple(args.set)}
    if args.plain:
        for finger in fingers:
            grasp(finger, args.force, overrides[finger])
        print(json.dumps({finger: grasp(finger, args.force, overrides[finger])
                          for finger in fingers}))
        return 0
    if args.baseline is not None:
        script = Path(sys.modules['__main__'].__file__).resolve()
        tables = _baseline_rows(script, args.baseline, fingers, args.force, args.set,
                                args.repeat)
        print(f'load average {os.getloadavg()[0]:.2f} at the end; CPU time '
              f'(time.process_time), best of {args.repeat} runs each, alternated: this tree '
              f'and baseline ({args.baseline.resolve()})')
        for label, rows in tables.items():
            print(f'-- {label}')
            _print_rows(rows, fingers)
        return 0
    print(f'load average {os.getloadavg()[0]:.2f}; CPU time (time.process_time), best of '
          f'{args.repeat}' + ''.join(f'; {deformable}: {item}' for item in args.set))
    rows = {}
    for finger in fingers:
        grasp(finger, args.force, overrides[finger])  # untimed: numba's caches loaded
        runs = [grasp(finger, args.force, overrides[finger]) for _ in range(args.repeat)]
        rows[finger] = min(runs, key=lambda r: r['cpu'])
    _print_rows(rows, fingers)
    return 0


def main(argv=None) -> int:
    return compare(FINGERS, __doc__.splitlines()[0], argv)


if __name__ == '__main__':
    sys.exit(main())
