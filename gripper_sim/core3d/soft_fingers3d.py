"""Deformable fingers in the 3D simulation: the 2D soft fingers extruded, on both jaws.

As in 2D (``core.soft_fingers``, whose ``SoftFingers`` this extends): the left jaw
carries the body, the right one its mirror image (x -> -x); the state holds the fruit's
nodes, then the left finger's, then the right finger's, x, y, z per node; each finger's
base nodes are prescribed on its jaw's backing; the fruit and the fingers touch through
the barrier (``core3d.soft_barrier``) with the jaws' friction coefficients; the jaw feels
the reaction at its finger's base nodes (the grip force). The bodies are the 2D ones
extruded over the jaw width (``core3d.finger_body3d``), neo-Hookean tetrahedra (the
solid fruit's energy, ``core3d.energies.NeoHookeanTets``).

Built: ``solid_pad`` and ``fin_ray``. The pad's section is the 2D pad's block
(``core.solid_pad.block_body``: ``gripper.finger.solid_pad.layers`` cells across the
thickness t); along the height and the width its cells are ``IN_PLANE_CELL_RATIO`` t
long (and no more than ``MAX_IN_PLANE_CELLS`` along either), coarser than in 2D, where
cells are square: the fruit's 3D surface mesh is itself a few mm coarse, and the
contact needs no finer face than that.

The Fin Ray's section is the 2D finger of rods (``core.fin_ray``), as wide as
``gripper.finger.fin_ray.depth`` (null: ``gripper.jaw_width``), extruded into thin shells
(``core3d.rod_extrusion``) in slices about ``WIDTH_CELL_RATIO`` rod elements wide (at
least 2, at most ``MAX_IN_PLANE_CELLS``). Each Fin Ray has its self-contact, as in 2D:
the barrier (``contact.ipc.dhat``, ``contact.ipc.stiffness``) between its own shell
triangles (``FingerBody3D.self_contact``), so that its members never cross. Its fruit
contact acts within ``FIN_RAY_CONTACT_DHAT`` (``fruit_barrier_settings``).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from gripper_sim.core.barrier import BarrierSettings, SoftBody
from gripper_sim.core.fin_ray import fin_ray_from_config
from gripper_sim.core.results import FingerResult
from gripper_sim.core.soft_fingers import FingerState, SoftFingers
from gripper_sim.core.solid_pad import block_body
from gripper_sim.core3d import meshes
from gripper_sim.core3d.finger_body3d import FingerBody3D, extruded_body
from gripper_sim.core3d.layered_mesher import vertex_edge_lengths
from gripper_sim.core3d.rod_extrusion import extruded_rod_body
from gripper_sim.core3d.mesh_geometry import surface_edges
from gripper_sim.errors import ConfigError
from gripper_sim.geometry.fin_ray import element_length

#: the right finger is the left one mirrored in x
MIRROR = np.array([-1.0, 1.0, 1.0])
#: a 3D pad's cells along the height and width, over its thickness
IN_PLANE_CELL_RATIO = 0.5
#: ... but no more cells than this along the height or the width
MAX_IN_PLANE_CELLS = 16
#: a 3D Fin Ray's slices across its width, in rod elements (``element_length``)
WIDTH_CELL_RATIO = 2.0
#: the pairs the barrier's pattern holds (``core3d.soft_barrier``): a fruit surface node
#: and a finger surface node at most this many times the sum of their mean surface edge
#: lengths apart across the closing axis (y, z) at rest
PAIR_REACH_EDGES = 1.5
#: ... the fruit's nodes within this fraction of its half-width of its surface facing the
#: finger (the fruit compressed by half its width reaches no further)
PAIR_CAP_DEPTH = 0.5


def solid_pad_body3d(config) -> FingerBody3D:
    """The 3D solid pad of ``config`` (see the module docstring)."""
    thickness = float(config['gripper.finger.solid_pad.thickness'])
    height = float(config['gripper.jaw_height'])
    width = float(config['gripper.jaw_width'])
    cell = IN_PLANE_CELL_RATIO * thickness
    rows = min(MAX_IN_PLANE_CELLS, max(2, int(round(height / cell))))
    slices = min(MAX_IN_PLANE_CELLS, max(2, int(round(width / cell))))
    section = block_body('solid_pad', thickness, height,
                         int(config['gripper.finger.solid_pad.layers']), rows, width,
                         float(config['gripper.finger.solid_pad.youngs_modulus']),
                         float(config['gripper.finger.solid_pad.poisson_ratio']),
                         float(config['gripper.finger.solid_pad.density']))
    return extruded_body(section, width, slices)


def fin_ray_body3d(config) -> FingerBody3D:
    """The 3D Fin Ray of ``config`` (see the module docstring)."""
    depth = config['gripper.finger.fin_ray.depth']
    width = float(config['gripper.jaw_width'] if depth is None else depth)
    cell = WIDTH_CELL_RATIO * element_length(config)
    slices = min(MAX_IN_PLANE_CELLS, max(2, int(round(width / cell))))
    # the section as beams: the shells add the plates' 1 / (1 - nu^2) themselves
    section = fin_ray_from_config(config, width, 'beam')
    return dataclasses.replace(extruded_rod_body(section, width, slices),
                               self_contact_settings=BarrierSettings.from_config(config))


#: m, the 3D Fin Ray's fruit contact dhat unless set (``gripper.finger.fin_ray.contact_dhat``):
#: a Newton step of the front beam wrapping or sliding on the fruit moves the surfaces by
#: tens of micrometres, and pairs further apart than dhat are not in the Newton matrix:
#: with ``contact.ipc.dhat`` (1 um) every iteration's collision-free bound cut the step to
#: a few per cent. 0.1 mm (IPC's usual 1e-3 of the scene, the fruit) lies well within the
#: beam's half thickness, the contact acting on its mid-surface.
FIN_RAY_CONTACT_DHAT = 1e-4


def fruit_barrier_settings(config) -> BarrierSettings:
    """The settings of the barrier of the fruit with the deformable fingers (and the
    table): ``contact.ipc.*``, with the Fin Ray's dhat ``gripper.finger.fin_ray.contact_dhat``
    (null: ``FIN_RAY_CONTACT_DHAT``)."""
    settings = BarrierSettings.from_config(config)
    if config['gripper.finger.type'] != 'fin_ray':
        return settings
    dhat = config['gripper.finger.fin_ray.contact_dhat']
    return dataclasses.replace(settings,
                               dhat=FIN_RAY_CONTACT_DHAT if dhat is None else float(dhat))


#: the deformable finger types built in 3D and their builders: config -> FingerBody3D
DEFORMABLE_FINGERS_3D = {'solid_pad': solid_pad_body3d, 'fin_ray': fin_ray_body3d}


def finger_body3d(config) -> FingerBody3D:
    """The FingerBody3D of the configured deformable finger.

    Raises:
        ConfigError: a deformable finger not built in 3D yet.
    """
    kind = config['gripper.finger.type']
    if kind not in DEFORMABLE_FINGERS_3D:
        raise ConfigError(f"config key 'gripper.finger.type' = {kind}: not built in 3D yet "
                          f"(dimension 3 takes {', '.join(DEFORMABLE_FINGERS_3D)} among the "
                          'deformable fingers)')
    return DEFORMABLE_FINGERS_3D[kind](config)


class SoftFingers3D(SoftFingers):
    """The two deformable fingers of a 3D simulation (see the module docstring).

    Args:
        body: the left finger's body (the right one is its mirror image); with its
            ``self_contact_settings`` each finger has its self-contact.
        first: index of the left finger's first node in the state.
        static_friction, kinetic_friction: Coulomb coefficients fruit-finger.
    """

    mirror = MIRROR

    def __init__(self, body: FingerBody3D, first: int, static_friction: float,
                 kinetic_friction: float):
        super().__init__(body, first, static_friction, kinetic_friction,
                         body.self_contact_settings)
        #: the 2D fingers of the section, whose outline gives the touching gap
        self._section = SoftFingers(body.section, 0, static_friction, kinetic_friction)

    def _soft_bodies(self, static_friction: float, kinetic_friction: float) -> tuple:
        """The two fingers' surfaces in the barrier, with their triangles (``SoftBody``);
        sets ``surface_triangles`` (2 s, 3), both fingers' (indices into their nodes)."""
        m = self.body.n_nodes
        # mirroring reverses the winding: the right finger's triangles turn back
        windings = (self.body.surface_triangles, self.body.surface_triangles[:, [0, 2, 1]])
        self.surface_triangles = np.vstack([side * m + t for side, t in enumerate(windings)])
        return tuple(SoftBody(nodes[np.unique(t)], nodes[surface_edges(t)], static_friction,
                              kinetic_friction, triangles=nodes[t])
                     for nodes, t in zip(self.nodes, windings))

    def _energies(self) -> list:
        m = self.body.n_nodes
        rest = np.zeros((self.first + 2 * m, 3))
        rest[self.nodes[0]] = self.frames[0]
        rest[self.nodes[1]] = self.frames[1]
        return self.body.elastic_energies(self.nodes, rest, mirrored=(False, True))

    def touching_gap(self, outline: np.ndarray) -> float:
        """m, the gap between the backings at which the fingers at rest first touch the
        fruit's surface points ``outline`` (n, 3) m (relative to the jaws' centre): the
        section's (``SoftFingers.touching_gap``) over the points across the finger's
        width."""
        across = np.abs(outline[:, 1]) <= 0.5 * self.body.width
        return self._section.touching_gap(outline[across][:, [0, 2]])

    def contact_pairs(self, surface: np.ndarray, outline: np.ndarray,
                      spacing: np.ndarray) -> np.ndarray:
        """(p, 2) the (fruit node, finger node) pairs of the barrier's pattern
        (``core3d.soft_barrier``), from the fruit's ``surface`` nodes (n_s,) at ``outline``
        (n_s, 3) m relative to the jaws' centre, their mean surface edge lengths
        ``spacing`` (n_s,) m: on each finger's side, the fruit nodes of the cap facing it
        (``PAIR_CAP_DEPTH``) and the finger's surface nodes within ``PAIR_REACH_EDGES``
        times the sum of the two nodes' mean edge lengths of each other in y and z, with
        the fruit's middle height (the middle of the outline's extent in z) at the jaws'
        centre: the height at which the jaws grasp it, wherever they start (a pick starts
        them above it, ``approach.height``; pairs from there would miss the grasp)."""
        outline = outline - np.array([0.0, 0.0, 0.5 * (outline[:, 2].max()
                                                         + outline[:, 2].min())])
        x = self.body.rest_positions
        outline_nodes = np.unique(self.body.surface_triangles)
        with np.errstate(invalid='ignore'):  # the inner nodes have no surface edge
            finger_spacing = vertex_edge_lengths(x, self.body.surface_triangles)[outline_nodes]
        half_width = np.abs(outline[:, 0]).max()
        pairs = []
        for sign, nodes, frame in zip((-1.0, 1.0), self.nodes, self.frames):
            cap = np.flatnonzero(sign * outline[:, 0] > (1.0 - PAIR_CAP_DEPTH) * half_width)
            reach = PAIR_REACH_EDGES * (spacing[cap, None] + finger_spacing[None, :])
            apart = np.abs(outline[cap, None, 1:] - frame[None, outline_nodes, 1:])
            i, j = np.nonzero(np.all(apart <= reach[:, :, None], axis=2))
            pairs.append(np.column_stack([surface[cap[i]], nodes[outline_nodes[j]]]))
        return np.vstack(pairs)

    def at_rest(self, left_origin: np.ndarray, right_origin: np.ndarray) -> FingerState:
        """Both fingers at rest on jaws whose backings are centred at the origins (3,) m."""
        m = self.n_nodes
        return FingerState(self.placed(left_origin, right_origin), np.zeros((m, 3)),
                           np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m, bool))

    def result(self, state: FingerState, left_origin: np.ndarray,
               right_origin: np.ndarray) -> FingerResult:
        """The fingers' outputs in ``state``, the backings centred at the origins (3,) m;
        contact area per finger: the vertex areas (a third of each adjacent surface
        triangle) of its nodes touching the fruit; contact length: the diameter of the
        circle of that area, 2 sqrt(A / pi)."""
        x, touching = state.positions, state.touching
        m = self.body.n_nodes
        moved = x - self.placed(left_origin, right_origin)
        tip = self.body.tip_node
        areas = meshes.vertex_areas(x, self.surface_triangles, 2 * m)
        area = np.array([areas[:m][touching[:m]].sum(), areas[m:][touching[m:]].sum()])
        return FingerResult(positions=x.copy(), contact_forces=state.contact_forces.copy(),
                            tip_displacement=np.array([moved[tip], moved[m + tip] * MIRROR]),
                            contact_length=2.0 * np.sqrt(area / math.pi),
                            surface_edges=surface_edges(self.surface_triangles),
                            contact_area=area)
