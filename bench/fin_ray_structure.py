"""The Fin Ray finger as a structure: force against displacement of its front beam at
mid-height, the tip's motion (the Fin Ray effect), the linear Euler-Bernoulli frame it
must match at small loads, and CPU times. Writes ``docs/fin_ray_structure.png``.

    python bench/fin_ray_structure.py [--out docs/fin_ray_structure.png]

The finger is the default (``config/fingers/fin_ray.yaml``, 20 mm deep), its base held;
the load presses the front beam along its normal over the middle third of its height,
as a fruit would. CPU time by ``time.process_time``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

from frame_reference import frame_displacements  # noqa: E402
from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.fin_ray import fin_ray_body  # noqa: E402
from gripper_sim.core.finger_statics import static_equilibrium  # noqa: E402
from gripper_sim.geometry.fin_ray import FinRayGeometry, layout  # noqa: E402
from gripper_sim.geometry.finger_materials import MATERIALS  # noqa: E402

FORCES = (0.25, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0)


def pressed(body, force, spread=0.01):
    """(n, 2) N over the front nodes within ``spread`` m of mid-height, and the mid node."""
    x0 = body.rest_positions
    front = np.unique(body.surface_edges)
    mid = int(front[np.argmin(np.abs(x0[front, 1]))])
    ends = x0[body.surface_edges[[0, -1], [0, 1]]]
    t = (ends[1] - ends[0]) / np.linalg.norm(ends[1] - ends[0])
    normal = np.array([t[1], -t[0]])
    loaded = front[np.abs(x0[front, 1]) <= spread]
    forces = np.zeros_like(x0)
    forces[loaded] = -force / len(loaded) * normal
    return forces, mid, normal


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--out', default=str(ROOT / 'docs' / 'fin_ray_structure.png'))
    args = parser.parse_args(argv)
    config = load_config(overrides=['gripper.finger.type=fin_ray'])
    geometry = FinRayGeometry.from_config(config, 0.02)
    material = MATERIALS['tpu']
    body = fin_ray_body(geometry, material)
    plan = layout(geometry)
    e, b = material.youngs_modulus, geometry.depth
    print(f'Fin Ray: {body.n_nodes} nodes, {len(body.rod_edges)} rods, '
          f'{len(body.bend_triples)} bending triples; E = {e / 1e6:.4g} MPa')
    unit, mid, normal = pressed(body, 1.0)
    frame = frame_displacements(body.rest_positions, [m.nodes for m in plan.members],
                                [e * m.thickness * b for m in plan.members],
                                [e * m.thickness ** 3 * b / 12 for m in plan.members],
                                plan.base_nodes, unit)
    frame_travel = -frame[mid] @ normal
    print(f'linear frame: {frame_travel * 1e3:.4g} mm/N at mid-height, tip x '
          f'{frame[body.tip_node, 0] * 1e3:+.4g} mm/N')
    print(' force N | press mm (ours, frame) | tip x mm | tip z mm | CPU s')
    rows, shapes = [], {}
    for force in FORCES:
        forces, _, _ = pressed(body, force)
        start = time.process_time()
        state = static_equilibrium(body, forces)
        cpu = time.process_time() - start
        moved = state.positions - body.rest_positions
        travel = -moved[mid] @ normal
        rows.append((force, travel, moved[body.tip_node, 0]))
        if force in (2.0, 4.0, 6.0):
            shapes[force] = state.positions
        print(f'{force:8.3g} | {travel * 1e3:7.3f} {force * frame_travel * 1e3:7.3f}      | '
              f'{moved[body.tip_node, 0] * 1e3:+8.3f} | {moved[body.tip_node, 1] * 1e3:+8.3f} '
              f'| {cpu:.3f}')
    rib_free = fin_ray_body(dataclasses.replace(geometry, rib_count=0), material)
    forces, rf_mid, _ = pressed(rib_free, 1.0)
    moved = static_equilibrium(rib_free, forces).positions - rib_free.rest_positions
    print(f'rib-free frame at 1 N: {-moved[rf_mid] @ normal * 1e3:.3f} mm at mid-height '
          f'(with ribs {rows[2][1] * 1e3:.3f} mm)')
    _figure(body, rows, frame_travel, shapes, args.out)
    print(f'wrote {args.out}')
    return 0


def _figure(body, rows, frame_travel, shapes, out):
    force, travel, tip = (np.array(column) for column in zip(*rows))
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.4))
    left.plot(travel * 1e3, force, 'o-', label='rod model (large deflection)')
    left.plot(force * frame_travel * 1e3, force, '--', label='linear Euler-Bernoulli frame')
    left.plot(tip * 1e3, force, 's-', label='tip x (+: towards the fruit)')
    left.axvline(0.0, color='0.7', lw=0.8)
    left.set_xlabel('displacement (mm)')
    left.set_ylabel('press on the front beam (N)')
    left.set_title('force against displacement at mid-height')
    left.legend(fontsize=8)
    x0 = body.rest_positions
    for edges, style in ((body.rod_edges, 'k-'),):
        for a, c in edges:
            right.plot(x0[[a, c], 0] * 1e3, x0[[a, c], 1] * 1e3, style, lw=0.8, alpha=0.35)
    for (force, x), colour in zip(sorted(shapes.items()), ('C0', 'C1', 'C3')):
        for a, c in body.rod_edges:
            right.plot(x[[a, c], 0] * 1e3, x[[a, c], 1] * 1e3, '-', color=colour, lw=1.0)
        right.plot([], [], '-', color=colour, label=f'{force:g} N')
    right.set_aspect('equal')
    right.set_xlabel('x (mm), fruit to the right')
    right.set_ylabel('z (mm)')
    right.set_title('shapes (grey: rest; base on the jaw at the top)')
    right.legend(fontsize=8)
    fig.tight_layout()
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)


if __name__ == '__main__':
    sys.exit(main())
