"""Whether a planar Fin Ray's front beam bends as a beam or as a plate in a grasp:
Searle's parameter b^2 / (R t) along it (b the finger's depth, t the beam's thickness,
1 / R the change of its curvature from rest), for a quasi-static squeeze of the apple
(no gravity, no table) held at each ``--force``. Well below 1 the strip curls freely
across its width (a beam, ``gripper.finger.fin_ray.section: beam``); well above 1 it
cannot (plane strain across the depth: ``plate``, 1 / (1 - nu^2) stiffer). Prints
figures; asserts nothing.

Usage::

    python bench/fin_ray_searle.py [--force N ...] [--set KEY=VALUE]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_soft_fingers import add_set_argument, checked_config  # noqa: E402
from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.simulation import Simulation  # noqa: E402
from gripper_sim.core.soft_fingers import finger_body  # noqa: E402

#: the squeeze holds its force once the jaws move slower than this (m/s), after
#: ``SETTLE_STEPS`` steps at least, for at most ``MAX_STEPS`` steps
SETTLED_SPEED, SETTLE_STEPS, MAX_STEPS = 1e-4, 400, 5000


def curvature_change(rest: np.ndarray, now: np.ndarray) -> np.ndarray:
    """1/m, the change of a polyline's turning angle at each interior node, per length
    (half its two edges), from ``rest`` to ``now`` (k, 2) m."""
    def headings(x):
        edges = np.diff(x, axis=0)
        return np.arctan2(edges[:, 1], edges[:, 0]), np.linalg.norm(edges, axis=1)
    (a0, _), (a1, lengths) = headings(rest), headings(now)
    turn = np.angle(np.exp(1j * (np.diff(a1) - np.diff(a0))))
    return np.abs(turn) / (0.5 * (lengths[1:] + lengths[:-1]))


def squeezed(overrides: list, force: float) -> tuple[float, np.ndarray, float, float]:
    """A squeeze of the apple by Fin Ray fingers held at ``force`` N: (grip N, the front
    beam's curvature change (k,) 1/m, its depth b m, its thickness t m)."""
    config = load_config(overrides=['gripper.finger.type=fin_ray', 'world.gravity=0',
                                    'world.table=false', *overrides])
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 1e-3})
    sim = Simulation(config)
    sim.command_force(force)
    for step in range(MAX_STEPS):
        result = sim.step()
        if (step >= SETTLE_STEPS and abs(result.grip_force - force) < 5e-3 * force
                and abs(result.jaw_velocity) < SETTLED_SPEED):
            break
    body = finger_body(config, sim.fruit.depth)   # the left finger at rest, its frame
    front = np.concatenate([body.surface_edges[:, 0], body.surface_edges[-1:, 1]])
    left = result.fingers.positions[:body.n_nodes]
    return (result.grip_force, curvature_change(body.rest_positions[front], left[front]),
            body.depth, config['gripper.finger.fin_ray.beam_thickness'])


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--force', type=float, nargs='+', default=[2.0, 4.0, 8.0],
                        help='grip forces held, N')
    add_set_argument(parser, 'override a configuration key (repeatable)')
    args = parser.parse_args(argv)
    if not all(np.isfinite(f) and f > 0 for f in args.force):
        parser.error('--force: every force must be a finite number > 0')
    checked_config(parser, 'fin_ray', args.set)
    print(f"{'grip N':>7s} {'R min mm':>9s} {'R median mm':>12s} {'Searle max':>11s} "
          f"{'median':>7s}   (b^2 / (R t) along the front beam)")
    for force in args.force:
        grip, change, depth, thickness = squeezed(args.set, force)
        searle = depth ** 2 * change / thickness
        print(f'{grip:7.2f} {1e3 / change.max():9.0f} {1e3 / np.median(change):12.0f} '
              f'{searle.max():11.1f} {np.median(searle):7.1f}   b {depth * 1e3:.1f} mm, '
              f't {thickness * 1e3:.2f} mm')
    return 0


if __name__ == '__main__':
    sys.exit(main())
