"""A thick solid pad (``gripper.finger.type: solid_pad``): an elastic block on the jaw.

The pad is the rectangle 0 <= x <= t, -h/2 <= z <= h/2 of the finger frame
(``core.finger_body``: x from the jaw's rigid backing towards the fruit), t =
``gripper.finger.solid_pad.thickness``, h = ``gripper.jaw_height``, meshed as a
plane-strain neo-Hookean solid (E, nu = ``gripper.finger.solid_pad.youngs_modulus``,
``.poisson_ratio``) on a structured grid of ``gripper.finger.solid_pad.layers`` cells
across the thickness and square-ish cells along the height, each cell split into two
triangles along alternating diagonals (no preferred shear direction). Its nodes on the
backing (x = 0) are bonded to the jaw; the others are free. The outline that can touch
the fruit is the front face and the top and bottom faces but for their cells at the
backing. Its tip is the front face's top corner. The depth is the fruit's (the planar
model's b: the pad is as wide as the slice of fruit it holds).
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.finger_body import FingerBody
from gripper_sim.geometry.solid_pad import row_count


def solid_pad_body(config, depth: float) -> FingerBody:
    """The solid pad the flat configuration ``config`` describes, ``depth`` (m) deep."""
    thickness = float(config['gripper.finger.solid_pad.thickness'])
    height = float(config['gripper.jaw_height'])
    layers = int(config['gripper.finger.solid_pad.layers'])
    return block_body('solid_pad', thickness, height, layers,
                      row_count(thickness, height, layers), depth,
                      float(config['gripper.finger.solid_pad.youngs_modulus']),
                      float(config['gripper.finger.solid_pad.poisson_ratio']),
                      float(config['gripper.finger.solid_pad.density']))


def block_body(name: str, thickness: float, height: float, layers: int, rows: int,
               depth: float, youngs_modulus: float, poisson_ratio: float,
               density: float) -> FingerBody:
    """A rectangular block [0, thickness] x [-height/2, height/2] (m) meshed with
    ``layers`` x ``rows`` cells, two triangles each (see the module docstring)."""
    xs = np.linspace(0.0, thickness, layers + 1)
    zs = np.linspace(-0.5 * height, 0.5 * height, rows + 1)
    column = rows + 1
    positions = np.array([[x, z] for x in xs for z in zs])

    def node(i, j):
        return i * column + j
    triangles = []
    for i in range(layers):
        for j in range(rows):
            a, b, c, d = node(i, j), node(i + 1, j), node(i + 1, j + 1), node(i, j + 1)
            if (i + j) % 2 == 0:
                triangles += [(a, b, c), (a, c, d)]
            else:
                triangles += [(a, b, d), (b, c, d)]
    triangles = np.array(triangles, np.int64)
    p = positions[triangles]
    area = 0.5 * ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
                  - (p[:, 1, 1] - p[:, 0, 1]) * (p[:, 2, 0] - p[:, 0, 0]))
    masses = np.zeros(len(positions))
    np.add.at(masses, triangles.ravel(), np.repeat(density * area * depth / 3.0, 3))
    front = [(node(layers, j), node(layers, j + 1)) for j in range(rows)]
    sides = [(node(i, j), node(i + 1, j)) for j in (0, rows) for i in range(1, layers)]
    return FingerBody(
        name=name, rest_positions=positions, masses=masses,
        base_nodes=np.array([node(0, j) for j in range(column)], np.int64),
        surface_edges=np.array(front + sides, np.int64).reshape(-1, 2),
        tip_node=node(layers, rows), depth=depth, triangles=triangles,
        youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio)
