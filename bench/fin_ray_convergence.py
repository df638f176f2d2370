"""The Fin Ray's figures against its rod element length
(``gripper.finger.fin_ray.element_length``). Prints a table; asserts nothing.

For each ``--lengths`` (m) it runs, with the default apple (64 outline nodes):

- the grasp-and-lift of ``bench_fin_ray.py`` (4 N, lift 1 cm, hold 0.2 s; CPU time of
  one run after an untimed one): at its end the grip, the apple's contact length, each
  finger's contact length (the wrap), the tip's move towards the fruit, the Hertz
  estimate of the step and the largest of the run (the benchmark's ``Hertz kPa``);
- the quasi-static squeezes of ``test/test_fin_ray_grasp.py`` (no gravity, no table,
  the fingers 1 mm off the fruit, force mode to 2 and 8 N, 1.2 s): the same figures and
  the highest node's line pressure;
- the finger as a structure (``bench/fin_ray_structure.py``: 20 mm deep, base held,
  pressed along the front beam's normal over the middle third): the pressed point's
  travel and the tip's x at 1 and 6 N (``structure``: its equal shares on the nodes
  within 10 mm of mid-height; ``consistent``: the same load spread uniformly over that
  band and lumped by the nodes' hat functions, so that it does not move with the nodes);
- with ``--3d``, the 3D squeeze of ``bench_fin_ray_3d.py`` to 2 N: the fruit's contact
  area (both jaws), the peak contact pressure and the tips' mean move.

``patches`` counts the contact patches on the jaws (both): the damage estimate takes
each run of consecutive fruit nodes touching a jaw as one Hertz contact, so a finger
much coarser than the fruit's outline, whose contact falls apart into several runs,
reads a narrower, harder contact. ``--set KEY=VALUE`` (repeatable) overrides a key in
the 2D runs (e.g. ``fruit.nodes=128``).

Usage::

    nice python bench/fin_ray_convergence.py [--lengths 0.001 0.002 ...] [--3d]
        [--skip-2d] [--set KEY=VALUE]
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

from fin_ray_structure import pressed  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.fin_ray import fin_ray_body  # noqa: E402
from gripper_sim.core.finger_statics import static_equilibrium  # noqa: E402
from gripper_sim.core.simulation import Simulation  # noqa: E402
from gripper_sim.errors import ConfigError  # noqa: E402
from gripper_sim.geometry.fin_ray import FinRayGeometry  # noqa: E402
from gripper_sim.geometry.finger_materials import MATERIALS  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402

KEY = 'gripper.finger.fin_ray.element_length'
#: the quasi-static squeeze of test/test_fin_ray_grasp.py
SQUEEZE = ['world.gravity=0', 'world.table=false', 'fruit.damping.mass=20']
#: the user's --set overrides of the 2D runs
EXTRA: list[str] = []


def _figures(sim, result) -> dict:
    """What a user reads off a step's result: grip N, contact lengths m, tip m, pressures
    Pa."""
    patches = sum(1 for c in result.damage.contacts if c.body in (0, 1))
    return dict(nodes=sim._soft.body.n_nodes, force=float(result.grip_force), patches=patches,
                contact=float(result.deformation.contact_length),
                wrap=float(result.fingers.contact_length.mean()),
                tip=float(result.fingers.tip_displacement[:, 0].mean()),
                hertz=float(result.damage.pressure), hertz_peak=float(result.damage.peak_pressure),
                line=float(result.deformation.peak_contact_pressure))


def grasp(length: float, force: float = 4.0) -> dict:
    """The benchmark's grasp-and-lift (``bench_soft_fingers.grasp``) with ``length``."""
    overrides = ['gripper.finger.type=fin_ray', f'{KEY}={length}', *EXTRA]
    start = time.process_time()
    config = load_config(overrides=overrides)
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    sim = Simulation(config)
    summary = run_grasp(sim, GraspSequence(sim, force, lift_height=0.01, hold_time=0.2))
    return dict(_figures(sim, sim.last), cpu=time.process_time() - start,
                outcome=summary['outcome'])


def squeeze(length: float, force: float) -> dict:
    """The quasi-static squeeze of ``test_fin_ray_grasp._squeeze`` with ``length``."""
    overrides = ['gripper.finger.type=fin_ray', f'{KEY}={length}', *SQUEEZE, *EXTRA]
    touching = Simulation(load_config(overrides=overrides)).touching_gap
    sim = Simulation(load_config(overrides=overrides + [
        f'gripper.initial_gap={touching + 0.001}']))
    sim.command_force(force, 0.02)
    return _figures(sim, sim.run(1.2))


def structure(length: float) -> dict:
    """The default finger (20 mm deep) pressed over its middle third at 1 and 6 N: the
    pressed point's travel and the tip's x (m)."""
    config = load_config(overrides=['gripper.finger.type=fin_ray', f'{KEY}={length}'])
    body = fin_ray_body(FinRayGeometry.from_config(config, 0.02), MATERIALS['tpu'])
    out = {}
    for force in (1.0, 6.0):
        forces, mid, normal = pressed(body, force)
        moved = static_equilibrium(body, forces).positions - body.rest_positions
        out[force] = (float(-moved[mid] @ normal), float(moved[body.tip_node, 0]))
    return out


def consistent_press(body, force: float, spread: float = 0.01):
    """((n, 2) N, the front beam's nodes in order along it, their arc lengths m, the arc
    length of mid-height, the inward normal): ``force`` N spread uniformly over the front
    beam within ``spread`` m of mid-height (z) and lumped to its nodes by their linear hat
    functions, so that the load does not change with the nodes (``pressed`` puts equal
    shares on the nodes inside the band, whose number and extent move with the spacing)."""
    x0 = body.rest_positions
    ends = x0[body.surface_edges[[0, -1], [0, 1]]]
    along = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    normal = np.array([along[1], -along[0]])
    front = np.unique(body.surface_edges)
    arc = (x0[front] - ends[0]) @ along
    order = np.argsort(arc)
    front, arc = front[order], arc[order]
    band = np.sort([(z - ends[0][1]) / along[1] for z in (-spread, spread)])
    grid = np.linspace(band[0], band[1], 20001)
    weights = np.array([np.trapezoid(np.interp(grid, arc, np.eye(len(arc))[k]), grid)
                        for k in range(len(arc))])
    forces = np.zeros_like(x0)
    forces[front] = -force * (weights / weights.sum())[:, None] * normal
    return forces, front, arc, -ends[0][1] / along[1], normal


def structure_consistent(length: float) -> dict:
    """``structure`` with ``consistent_press``: the travel at mid-height (interpolated
    along the beam) and the tip's x (m) at 1 and 6 N."""
    config = load_config(overrides=['gripper.finger.type=fin_ray', f'{KEY}={length}'])
    body = fin_ray_body(FinRayGeometry.from_config(config, 0.02), MATERIALS['tpu'])
    out = {}
    for force in (1.0, 6.0):
        forces, front, arc, mid, normal = consistent_press(body, force)
        moved = static_equilibrium(body, forces).positions - body.rest_positions
        out[force] = (float(np.interp(mid, arc, -(moved[front] @ normal))),
                      float(moved[body.tip_node, 0]))
    return out


def squeeze3d(length: float, force: float = 2.0) -> dict:
    """The 3D squeeze of ``bench_fin_ray_3d.py`` with ``length``."""
    from bench_fin_ray_3d import squeeze as squeeze_3d
    return squeeze_3d('fin_ray', force, [f'{KEY}={length}'])


def _row(label: str, length: float, r: dict) -> str:
    return (f"{label:9s} {length * 1e3:4.0f} {r['nodes']:6d} {r['force']:7.3f} "
            f"{r['contact'] * 1e3:8.2f} {r['wrap'] * 1e3:8.2f} {r['tip'] * 1e3:+8.4f} "
            f"{r['hertz'] * 1e-3:8.1f} {r['hertz_peak'] * 1e-3:8.1f} {r['line'] * 1e-3:8.2f} "
            f"{r['patches']:7d}")


def _check(parser, option: str, overrides: list) -> None:
    """The parser's usage error (exit 2) naming ``option`` if the Fin Ray's configuration
    with ``overrides`` ('KEY=VALUE') is refused."""
    try:
        load_config(overrides=['gripper.finger.type=fin_ray', *overrides])
    except ConfigError as error:
        parser.error(f'{option}: {error}')


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--lengths', type=float, nargs='+',
                        default=[0.001, 0.002, 0.003, 0.004, 0.005])
    parser.add_argument('--3d', dest='three_d', action='store_true', help='the 3D squeeze too')
    parser.add_argument('--skip-2d', action='store_true', help='only the 3D squeeze')
    parser.add_argument('--set', action='append', default=[], metavar='KEY=VALUE',
                        help='a configuration override of the 2D runs (repeatable)')
    args = parser.parse_args(argv)
    _check(parser, '--set', args.set)  # a bad setting or length: a usage error, before any run
    for length in args.lengths:
        _check(parser, '--lengths', [f'{KEY}={length}', *args.set])
    EXTRA[:] = args.set
    print(f'load average {os.getloadavg()[0]:.2f}' + ''.join(f'; {item}' for item in args.set))
    if not args.skip_2d:
        print('run       L mm  nodes  grip N apple mm  wrap mm   tip mm Hertz kPa peak kPa '
              'line kPa patches')
        print('  (nodes: one finger; apple: its contact length; wrap: a finger\'s contact '
              'length; Hertz: the step\'s damage estimate, peak: the run\'s largest; line: '
              'the highest node\'s line pressure)')
        for length in args.lengths:
            grasp(length)  # untimed: numba's caches loaded
            r = grasp(length)
            print(_row('lift 4 N', length, r) + f"   CPU {r['cpu']:.3f} s, {r['outcome']}",
                  flush=True)
            for force in (2.0, 8.0):
                print(_row(f'squeeze {force:g}', length, squeeze(length, force)), flush=True)
            for label, press in (('structure', structure), ('consistent', structure_consistent)):
                s = press(length)
                print(f"{label:10s}{length * 1e3:4.0f}  press at 1 N {s[1.0][0] * 1e3:.4f} mm, "
                      f"tip {s[1.0][1] * 1e3:+.4f} mm; at 6 N {s[6.0][0] * 1e3:.4f} mm, tip "
                      f"{s[6.0][1] * 1e3:+.4f} mm", flush=True)
    if args.three_d or args.skip_2d:
        print('3D squeeze to 2 N: L mm, CPU s, steps, Newton, nodes, grip N, area mm^2, '
              'peak kPa, tip mm')
        for length in args.lengths:
            r = squeeze3d(length)
            print(f"3D {length * 1e3:4.0f} {r['cpu']:7.1f} {r['steps']:4d} {r['newton']:5d} "
                  f"{r['nodes']:6d} {r['force']:7.3f} {r['area'] * 1e6:8.1f} "
                  f"{r['pressure'] * 1e-3:7.1f} {r['tip'] * 1e3:+7.3f}", flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
