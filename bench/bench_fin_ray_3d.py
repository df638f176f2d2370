"""Benchmark of the 3D deformable fingers: the CLI's squeeze of the default apple to a grip
force (``gripper-sim squeeze --set dimension=3 --set gripper.finger.type=... --to-force
2``) with the rigid flat finger, the solid pad and the Fin Ray, the Fin Ray also with the
1 um fruit contact gap it had before its own (``fin_ray_1um``). Prints figures; asserts
nothing.

CPU time of this process (``time.process_time``, the best of ``--repeat`` runs; the
machine's load average is printed), building the simulation included: the jaws close in
force mode until the grip is within 1 % of ``--force`` N, then hold 0.1 s; with the
steps, Newton iterations, the fingers' nodes, the fruit's contact area (both jaws), the
peak contact pressure and each finger's tip displacement towards the fruit.

``--ipctk-threads 2`` runs ipctk in two threads instead of the one ``core.barrier`` sets
(the baseline of that choice: the CPU time of both threads is counted, and the runs are
not repeatable bit for bit).

Usage::

    nice python bench/bench_fin_ray_3d.py [--repeat N] [--force N] [--ipctk-threads N]
                                          [--set key=value ...]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import ipctk  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core3d.simulation import Simulation3D  # noqa: E402

#: the runs compared, the reference first: (label, finger, its own overrides); the Fin Ray
#: with its fruit contact's gap (gripper.finger.fin_ray.contact_dhat, null: 0.1 mm) and
#: with the 1 um of contact.ipc.dhat it had before (the baseline)
FINGERS = (('flat', 'flat', ()), ('solid_pad', 'solid_pad', ()), ('fin_ray', 'fin_ray', ()),
           ('fin_ray_1um', 'fin_ray', ('gripper.finger.fin_ray.contact_dhat=1e-6',)))
#: s, held at the force once reached
SETTLE = 0.1


def squeeze(finger: str, force: float, overrides: list[str]) -> dict:
    """One squeeze to ``force`` N; its CPU time (s) and figures."""
    start = time.process_time()
    sim = Simulation3D(load_config(overrides=['dimension=3', f'gripper.finger.type={finger}',
                                              *overrides]))
    iterations = 0
    sim.command_force(force)
    for _ in range(200):
        result = sim.step()
        iterations += result.newton_iterations
        if abs(result.grip_force - force) < 0.01 * force and result.step > 5:
            break
    for _ in range(round(SETTLE / sim.dt)):
        result = sim.step()
        iterations += result.newton_iterations
    fingers = result.fingers
    return dict(cpu=time.process_time() - start, steps=result.step, newton=iterations,
                nodes=0 if fingers is None else len(fingers.positions),
                force=result.grip_force, area=result.deformation.contact_area,
                pressure=result.deformation.peak_contact_pressure,
                tip=None if fingers is None else fingers.tip_displacement[:, 0].mean())


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeat', type=int, default=1, help='runs per finger (best kept)')
    parser.add_argument('--force', type=float, default=2.0, help='grip force, N')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='a configuration override for every run (e.g. fruit.model=solid)')
    parser.add_argument('--ipctk-threads', type=int, default=None,
                        help="ipctk's threads (default: core.barrier's, 1)")
    args = parser.parse_args(argv)
    if args.ipctk_threads is not None:
        ipctk.set_num_threads(args.ipctk_threads)
    print(f'ipctk threads {ipctk.get_num_threads()}; load average {os.getloadavg()[0]:.2f}; CPU time (time.process_time), best of '
          f'{args.repeat}')
    print(f"{'finger':11s} {'CPU s':>7s} {'steps':>6s} {'Newton':>7s} {'nodes':>6s} "
          f"{'force N':>8s} {'area mm^2':>9s} {'peak kPa':>8s} {'tip mm':>7s}")
    rows = {}
    for label, finger, own in FINGERS:
        r = min((squeeze(finger, args.force, [*args.set, *own]) for _ in range(args.repeat)),
                key=lambda run: run['cpu'])
        rows[label] = r
        tip = '' if r['tip'] is None else f"{r['tip'] * 1e3:+7.3f}"
        print(f"{label:11s} {r['cpu']:7.1f} {r['steps']:6d} {r['newton']:7d} {r['nodes']:6d} "
              f"{r['force']:8.3f} {r['area'] * 1e6:9.1f} {r['pressure'] * 1e-3:8.1f} {tip:>7s}",
              flush=True)
    for label, _, _ in FINGERS[1:]:
        print(f"{label} / flat: {rows[label]['cpu'] / rows['flat']['cpu']:.1f}x")
    return 0


if __name__ == '__main__':
    sys.exit(main())
