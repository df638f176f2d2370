"""Size, build time and quality of the 3D solid model's tetrahedral meshes.

    PYTHONPATH=. python bench/mesh_quality.py

For every fruit preset at the 3D defaults, and for the set-ups of the benchmark and of
the Hertz validation, it prints the surface vertices, the nodes and tetrahedra, the CPU
time to mesh, the smallest and largest dihedral angles and the largest aspect ratio
(longest edge over the inscribed sphere's diameter, 1 for a regular tetrahedron).
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.configuration import available_fruits, load_config  # noqa: E402
from gripper_sim.core3d import meshes  # noqa: E402
from gripper_sim.core3d.fruit import body_from_config  # noqa: E402

SOLID = ['dimension=3', 'fruit.model=solid']
SET_UPS = [(f'{fruit} (defaults)', fruit, []) for fruit in available_fruits()] + [
    ('benchmark solid', 'apple', ['fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=0.5',
                                  'fruit.mesh.max_tet_volume=0.01']),
    ('Hertz coarse', 'apple', ['fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=0.4',
                               'fruit.shape.diameter=0.06', 'fruit.mesh.order=2']),
    ('Hertz fine', 'apple', ['fruit.mesh.subdivisions=3', 'fruit.mesh.jaw_refinement=0.25',
                             'fruit.shape.diameter=0.06', 'fruit.mesh.order=2']),
]


def main() -> int:
    print(f'{"set-up":22s} {"surface":>7s} {"nodes":>6s} {"tets":>6s} {"CPU ms":>7s} '
          f'{"min dih":>7s} {"max dih":>7s} {"aspect":>6s}')
    for label, fruit, overrides in SET_UPS:
        config = load_config(fruit=fruit, overrides=SOLID + overrides)
        body = body_from_config(config)
        start = time.process_time()
        mesh = meshes.tetrahedralize(body, config['fruit.mesh.max_tet_volume'],
                                     order=config['fruit.mesh.order'])
        cpu = time.process_time() - start
        q = mesh.quality
        print(f'{label:22s} {len(body.positions):7d} {len(mesh.positions):6d} '
              f'{len(mesh.tetrahedra):6d} {cpu * 1e3:7.1f} {q.min_dihedral:7.1f} '
              f'{q.max_dihedral:7.1f} {q.max_aspect:6.1f}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
