"""A 2D finger of rods (the Fin Ray's beams and ribs) extruded over its width into shells.

Frame and slicing as ``core3d.finger_body3d``: the section's node i at (x, z) has a copy
in each of ``slices + 1`` equally spaced sections y_s in [-w/2, w/2]. Each rod edge
(a, b) of thickness t sweeps a strip of flat quads, one per slice, each cut into the
triangles (a_s, b_s, b_s+1) and (a_s, b_s+1, a_s+1): the members become thin plates
(their mid-surfaces), joined along the lines where members meet.

Why shells and not tetrahedra: a beam 1.2 mm thick bends as a plate; linear tetrahedra
a few across the thickness lock in bending (their stiffness converges from above, by
tens of percent at the element counts a grasp can afford), while a shell's hinges carry
the bending exactly for cylindrical bending with any element length, as the 2D rods do.

Energies (``energies.Membrane`` and ``energies.HingeBending``, the fruit skin's):
- membrane: St. Venant-Kirchhoff constant-strain triangles of the member's thickness;
- bending along the members (hinges on the extrusion edges (j_s, j_s+1)): for each 2D
  bending triple (i, j, k) and slice two hinges, (j_s, j_s+1; i_s, k_s) and
  (j_s, j_s+1; i_s+1, k_s+1), each half the stiffness: taking both wings' corners in the
  same section keeps a twist of the strip (w ~ x y) from changing the hinge's angle
  (a hinge across the mesh's own triangles, one wing's corner in section s and the
  other's in s + 1, couples the two, and the strip twisted under a tip load spread
  evenly across its width, 50 % softer with 6 slices). The pair's k (J per rad^2) is
  the triple's 2D energy per unit depth over the slice width |e|, EI / (2 l b) |e|,
  times 1 / (1 - nu^2): the members are plates as wide as the finger, bent
  cylindrically (plane strain across the width: a strip of width b and thickness t bent
  to radius R keeps its cross-section straight but for its edges when b^2 / (R t) >> 1,
  Searle's parameter; Timoshenko & Woinowsky-Krieger, Theory of Plates and Shells, ch. 1,
  bending of long plates to a cylindrical surface), so the stiffness per unit width is
  D = E t^3 / (12 (1 - nu^2)), not the 2D finger's E t^3 / 12 (plane stress). The rigid
  joints between members and the clamp on the base keep their 2D meaning
  (``core.fin_ray``: the joint triples' series stiffness);
- bending across the width and twist (hinges on the other inner edges of each strip: the
  edges (a_s, b_s) between slices and the quads' diagonals): the discrete-shell hinges
  with D = E t^3 / (12 (1 - nu^2)). A deformation the same in every slice leaves these
  flat, so under a load uniform across the width the body is the 2D finger with the plate
  modulus E / (1 - nu^2) in bending.
Triangles and hinges all of whose nodes are on the base (held by the jaw) are left out.

Contact: the front beam's strip (the section's ``surface_edges``), its mid-surface as the
2D finger's centre line. Masses as ``finger_body3d``: the 2D masses per unit depth times
the width each copy stands for.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core3d.finger_body3d import FingerBody3D
from gripper_sim.errors import ConfigError


def _slice_copies(section: FingerBody, width: float, slices: int):
    """((slices + 1) n, 3) positions, (slices + 1,) m the width of each copy."""
    n = section.n_nodes
    ys = np.linspace(-0.5 * width, 0.5 * width, slices + 1)
    x2 = section.rest_positions
    positions = np.vstack([np.column_stack([x2[:, 0], np.full(n, y), x2[:, 1]]) for y in ys])
    share = np.full(slices + 1, width / slices)
    share[[0, -1]] *= 0.5
    return positions, share


def _triangle_areas(x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    p = x[triangles]
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)


def plate_stiffness(youngs_modulus: float, poisson_ratio: float, thickness) -> np.ndarray:
    """D = E t^3 / (12 (1 - nu^2)), N m: a plate's bending stiffness per unit width."""
    return youngs_modulus * np.asarray(thickness, float) ** 3 / (12.0 * (1.0 - poisson_ratio ** 2))


def extruded_rod_body(section: FingerBody, width: float, slices: int) -> FingerBody3D:
    """The 2D rod ``section`` extruded over y in [-width/2, width/2] (m) in ``slices``
    slices as thin shells (module docstring).

    Raises:
        ConfigError: the section has no rods, or no positive width.
        ValueError: a prestressed section (``rod_rest_lengths``), which the shells do not
            take.
    """
    if len(section.rod_rest_lengths):
        raise ValueError('a prestressed section (rod_rest_lengths) cannot be extruded: the '
                         "shells' rest shape is the section's drawn shape")
    if not len(section.rod_edges):
        raise ConfigError(f"config key 'gripper.finger.type' = {section.name}: only a "
                          'section of rods is extruded to shells')
    if not width > 0 or slices < 1:
        raise ConfigError(f'config key \'gripper.finger.fin_ray.depth\' must be positive for '
                          f'a 3D {section.name} finger')
    n, s = section.n_nodes, np.arange(slices)
    e_mod, nu, depth = section.youngs_modulus, section.poisson_ratio, section.depth
    positions, share = _slice_copies(section, width, slices)
    a, b = section.rod_edges[:, 0], section.rod_edges[:, 1]
    thickness = section.rod_axial_stiffness / (e_mod * depth)            # (r,) m
    # (r, slices) copies of the strip corners
    a0, b0 = a[:, None] + n * s, b[:, None] + n * s
    a1, b1 = a0 + n, b0 + n
    first = np.stack([a0, b0, b1], axis=-1)                               # (r, slices, 3)
    second = np.stack([a0, b1, a1], axis=-1)
    triangles = np.stack([first, second], axis=2).reshape(-1, 3)          # (r, slices, 2)
    triangle_thickness = np.repeat(thickness, 2 * slices)

    # bending along the members: the 2D triples, two hinges per slice
    i, j, k = section.bend_triples.T
    joint0, joint1 = j[:, None] + n * s, j[:, None] + n * (s + 1)
    along = np.stack([np.stack([joint0, joint1, i[:, None] + n * (s + c),
                                k[:, None] + n * (s + c)], axis=-1) for c in (0, 1)],
                     axis=2).reshape(-1, 4)
    lengths = (section.bend_lengths if len(section.bend_lengths) else 0.5 * (
        np.linalg.norm(section.rest_positions[j] - section.rest_positions[i], axis=1)
        + np.linalg.norm(section.rest_positions[k] - section.rest_positions[j], axis=1)))
    slice_width = width / slices
    along_k = np.repeat(0.25 * section.bend_stiffness / (lengths * depth) * slice_width
                        / (1.0 - nu ** 2), 2 * slices)
    # HingeBending's k = D |e|^2 / (2 A), A the two triangles' rest areas: D for that k
    pair_areas = (_triangle_areas(positions, along[:, [0, 1, 2]])
                  + _triangle_areas(positions, along[:, [1, 0, 3]]))
    along_d = 2.0 * along_k * pair_areas / slice_width ** 2

    # bending across the width: the edges (a_s, b_s) between slices and the diagonals
    between = np.stack([b0[:, 1:], a0[:, 1:], a0[:, :-1], b0[:, 1:] + n], axis=-1)
    diagonal = np.stack([b1, a0, b0, a1], axis=-1)
    across = np.vstack([between.reshape(-1, 4), diagonal.reshape(-1, 4)])
    across_t = np.concatenate([np.repeat(thickness, slices - 1), np.repeat(thickness, slices)])
    hinges = np.vstack([along, across])
    hinge_d = np.concatenate([along_d, plate_stiffness(e_mod, nu, across_t)])

    base = np.concatenate([section.base_nodes + n * c for c in range(slices + 1)])
    is_base = np.zeros(len(positions), bool)
    is_base[base] = True
    free_triangles = ~np.all(is_base[triangles], axis=1)
    free_hinges = ~np.all(is_base[hinges], axis=1)
    rod_keys = np.sort(section.rod_edges, axis=1) @ np.array([n, 1])
    surface_keys = np.sort(section.surface_edges, axis=1) @ np.array([n, 1])
    surface_rods = np.flatnonzero(np.isin(rod_keys, surface_keys))
    surface = triangles.reshape(-1, 2 * slices, 3)[surface_rods].reshape(-1, 3)
    middle = slices // 2
    return FingerBody3D(
        name=section.name, section=section, rest_positions=positions,
        masses=np.concatenate([section.masses / depth * w for w in share]),
        base_nodes=base, surface_triangles=surface,
        tip_node=int(section.tip_node + middle * n), width=float(width),
        tetrahedra=np.zeros((0, 4), np.int64), youngs_modulus=e_mod, poisson_ratio=nu,
        shell_triangles=triangles[free_triangles],
        shell_thickness=triangle_thickness[free_triangles],
        hinges=hinges[free_hinges], hinge_stiffness=hinge_d[free_hinges])
