"""A deformable finger body in 3D: a 2D finger body's section extruded over its width.

Frame: the finger's own jaw frame, as the 2D body's (``core.finger_body``) with y added:
x (m) from the jaw's rigid backing (x = 0) towards the fruit, y (m) along the jaw width,
z (m) up; the section y = 0 is the 2D body. The body is the 2D body's triangles (a solid
section: the solid pad) extruded over y in [-w/2, w/2] (w = ``gripper.jaw_width``, the
width the 3D rigid fingers are extruded over, ``core3d.fingers3d``) in ``slices`` equal
slices: every triangle spans a column of triangular prisms, each cut into three
tetrahedra by the layered mesher's rule (``layered_mesher.prism_tetrahedra``), so
neighbouring prisms conform. The material is the 2D body's, as neo-Hookean tetrahedra.
A section of rods (the Fin Ray's beams and ribs) is extruded into thin shells instead
(``core3d.rod_extrusion``): the body then holds shell triangles and hinges, no
tetrahedra.

Masses: the 2D body's lumped masses are its density times the section area per node
times its depth; divided by that depth they are per unit width, and each slice's copy of
a node takes the width it stands for (a slice, or half of one at the two ends).

Base nodes: every copy of a 2D base node (the backing face, bonded to the jaw). Surface:
the boundary triangles of the tetrahedra (each face of one tetrahedron only), outward,
but for the backing face (all three corners base nodes): the front, the top and bottom,
and the two side faces. Tip: the copy of the 2D tip node in the middle slice (its
nearest).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gripper_sim.core.barrier import BarrierContact, BarrierSettings
from gripper_sim.core.energies.base import Energy
from gripper_sim.core.finger_body import FingerBody, self_contact_barrier
from gripper_sim.core3d.energies import HingeBending, Membrane, NeoHookeanTets
from gripper_sim.core3d.layered_mesher import prism_tetrahedra
from gripper_sim.core3d.mesh_geometry import signed_volumes, surface_edges
from gripper_sim.errors import ConfigError

#: the four faces of a tetrahedron (a, b, c, d positively oriented), each outward
_TET_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


@dataclass(frozen=True)
class FingerBody3D:
    """Attributes:
        name: the finger type (``gripper.finger.type``), e.g. 'solid_pad'.
        section: the 2D body extruded (its section y = 0).
        rest_positions: (m, 3) m, in the finger frame (module docstring).
        masses: (m,) kg, lumped.
        base_nodes: (k,) nodes fixed to the jaw's backing.
        surface_triangles: (s, 3) the outward boundary triangles that may touch the fruit.
        tip_node: the node whose displacement is the finger's tip displacement.
        width: m, the extent along y.
        tetrahedra: (n_tet, 4) positively oriented (none for a shell body).
        youngs_modulus: Pa.  poisson_ratio: -.
        shell_triangles: (n_sh, 3) the thin shells' triangles (their mid-surface), with
            shell_thickness (n_sh,) m each (a membrane, ``energies.Membrane``).
        hinges: (n_h, 4) the shells' bending hinges (``energies.HingeBending``), with
            hinge_stiffness (n_h,) N m: the plate bending stiffness D each hinge's
            k = D |e|^2 / (2 A) is computed with (``core3d.rod_extrusion``).
        self_contact_settings: the barrier settings of the shells' self-contact
            (``self_contact``; ``contact.ipc.*``), None: none.
    """

    name: str
    section: FingerBody
    rest_positions: np.ndarray
    masses: np.ndarray
    base_nodes: np.ndarray
    surface_triangles: np.ndarray
    tip_node: int
    width: float
    tetrahedra: np.ndarray
    youngs_modulus: float
    poisson_ratio: float
    shell_triangles: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.int64))
    shell_thickness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    hinges: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), np.int64))
    hinge_stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    self_contact_settings: BarrierSettings | None = None

    @property
    def n_nodes(self) -> int:
        return len(self.masses)

    def elastic_energies(self, copies: tuple[np.ndarray, ...] | None = None,
                         rest_positions: np.ndarray | None = None,
                         mirrored: tuple[bool, ...] | None = None) -> list[Energy]:
        """The body's elastic energies: neo-Hookean tetrahedra, shell membranes and hinges.

        Args:
            copies: for a state holding several copies of the body (the two jaws'
                fingers), each copy's (n_nodes,) global node indices; None: the body
                alone, q of ``3 n_nodes``.
            rest_positions: (N, 3) m, the global rest positions (each copy's rest shape
                at its nodes); None with ``copies`` None.
            mirrored: per copy, whether its rest shape is the body's mirror image (its
                tetrahedra are turned back to positive volume); None: none is.
        """
        if copies is None:
            copies, rest_positions = (np.arange(self.n_nodes),), self.rest_positions
        if mirrored is None:
            mirrored = (False,) * len(copies)
        n = len(copies)
        energies: list[Energy] = []
        if len(self.tetrahedra):
            tets = np.vstack([nodes[self.tetrahedra[:, [0, 2, 1, 3]] if turned
                                    else self.tetrahedra]
                              for nodes, turned in zip(copies, mirrored)])
            energies.append(NeoHookeanTets(tets, rest_positions, self.youngs_modulus,
                                           self.poisson_ratio))
        if len(self.shell_triangles):
            energies.append(Membrane(np.vstack([nodes[self.shell_triangles] for nodes in copies]),
                                     rest_positions, self.youngs_modulus, self.poisson_ratio,
                                     np.tile(self.shell_thickness, n)))
        if len(self.hinges):
            energies.append(HingeBending(np.vstack([nodes[self.hinges] for nodes in copies]),
                                         rest_positions, np.tile(self.hinge_stiffness, n)))
        return energies


    def self_pairs(self) -> np.ndarray:
        """(p, 2) the node pairs of the shells' self-contact pattern: the section's
        (``FingerBody.self_pairs``: near at rest, joined by no rod element) within each
        slice and between neighbouring slices (a vertex meets a triangle of its own slice
        or of a neighbouring one when the members fold alike across the width)."""
        n = self.section.n_nodes
        copies = self.n_nodes // n
        pairs = self.section.self_pairs()
        both = np.vstack([pairs, pairs[:, ::-1]])
        within = [pairs + n * c for c in range(copies)]
        across = [both + n * np.array([c, c + 1]) for c in range(copies - 1)]
        return np.vstack(within + across)

    def self_contact(self, settings: BarrierSettings,
                     copies: tuple[np.ndarray, ...] | None = None,
                     n_nodes: int | None = None) -> BarrierContact | None:
        """The barrier between the body's own shell triangles (a vertex and a triangle,
        or two edges, that share no node; frictionless; ipctk's 3D pairs), so that its
        beams and ribs never cross: None for a body without shells. As
        ``FingerBody.self_contact`` in 2D (``core.finger_body.self_contact_barrier``).

        Args:
            settings: the barrier's dhat and stiffness.
            copies: for a state holding several copies of the body, each copy's
                (n_nodes,) global node indices (each copy touches only itself); None:
                the body alone.
            n_nodes: nodes of the state (None: the body's).
        """
        triangles = self.shell_triangles
        return self_contact_barrier(self.n_nodes, surface_edges(triangles), self.self_pairs,
                                    settings, copies, n_nodes, triangles=triangles)


def boundary_triangles(tetrahedra: np.ndarray) -> np.ndarray:
    """(s, 3) the faces of positively oriented ``tetrahedra`` (n_tet, 4) that belong to
    one tetrahedron only, wound outward."""
    faces = tetrahedra[:, _TET_FACES].reshape(-1, 3)
    key = np.sort(faces, axis=1)
    _, first, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    return faces[np.sort(first[counts == 1])]


def extruded_body(section: FingerBody, width: float, slices: int) -> FingerBody3D:
    """The 2D solid ``section`` extruded over y in [-width/2, width/2] (m) in ``slices``
    slices (module docstring).

    Raises:
        ConfigError: the section has no solid triangles (rods are not extruded), or no
            positive width.
    """
    if not section.triangles.size:
        raise ConfigError(f"config key 'gripper.finger.type' = {section.name}: only a solid "
                          'section (triangles) is extruded to 3D')
    if not width > 0 or slices < 1:
        raise ConfigError("config key 'gripper.jaw_width' must be positive for a 3D "
                          f'{section.name} finger')
    n = section.n_nodes
    ys = np.linspace(-0.5 * width, 0.5 * width, slices + 1)
    x2 = section.rest_positions
    positions = np.vstack([np.column_stack([x2[:, 0], np.full(n, y), x2[:, 1]]) for y in ys])
    tets = np.vstack([prism_tetrahedra(section.triangles, k * n, (k + 1) * n)
                      for k in range(slices)])
    negative = signed_volumes(positions, tets) < 0
    tets[negative] = tets[negative][:, [0, 2, 1, 3]]
    slice_width = np.full(slices + 1, width / slices)
    slice_width[[0, -1]] *= 0.5
    masses = np.concatenate([section.masses / section.depth * w for w in slice_width])
    base = np.concatenate([section.base_nodes + k * n for k in range(slices + 1)])
    is_base = np.zeros(len(positions), bool)
    is_base[base] = True
    faces = boundary_triangles(tets)
    surface = faces[~np.all(is_base[faces], axis=1)]
    middle = int(np.argmin(np.abs(ys)))
    return FingerBody3D(
        name=section.name, section=section, rest_positions=positions, masses=masses,
        base_nodes=base, surface_triangles=surface, tip_node=int(section.tip_node + middle * n),
        width=float(width), tetrahedra=tets, youngs_modulus=section.youngs_modulus,
        poisson_ratio=section.poisson_ratio)
