"""Deformable fingers in the 2D simulation: a ``FingerBody`` on each jaw, in the state.

A deformable finger type (``DEFORMABLE_FINGERS``: ``gripper.finger.type`` solid_pad,
fin_ray)
puts one copy of its ``FingerBody`` on the left jaw and its mirror image (x -> -x) on
the right one. The state vector holds the fruit's nodes, then the left finger's, then
the right finger's: q = [fruit (n), left (m), right (m)], x and z per node. Their
energies (neo-Hookean triangles, rods) index that global q. Each finger's
``base_nodes`` are prescribed (the modified mass method's zero filter) at the jaw's
backing plus their rest offset: for a deformable finger, the gap is the distance between
the two backings (the jaws' own stroke), so the fruit meets the fingers at a gap of its
width plus both fingers' thickness. Gravity acts on the fingers as on the fruit. The
fruit and the fingers touch through the barrier (``core.barrier``, ``SoftBody``), with
the jaws' friction coefficients (``contact.jaw.*``); the fruit and the table (and walls)
too.

The jaw feels the reaction at its finger's base nodes (``StepResult.left_wrench`` and
``right_wrench``): that is the grip force the jaw drive reads.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from gripper_sim.core.barrier import BarrierContact, BarrierSettings, SoftBody
from gripper_sim.core.energies import NeoHookeanTriangles
from gripper_sim.core.fin_ray import fin_ray_from_config
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.measures import numpy_sum, touching_length
from gripper_sim.core.results import FingerResult
from gripper_sim.core.solid_pad import solid_pad_body
from gripper_sim.errors import ConfigError

#: the deformable finger types and the builders of their bodies: (config, depth m) ->
#: FingerBody
DEFORMABLE_FINGERS = {'solid_pad': solid_pad_body, 'fin_ray': fin_ray_from_config}
#: the key that sets how far each deformable finger reaches in front of its jaw
THICKNESS_KEYS = {'solid_pad': 'gripper.finger.solid_pad.thickness',
                  'fin_ray': 'gripper.finger.fin_ray.base_width'}

#: the right finger is the left one mirrored in x
MIRROR = np.array([-1.0, 1.0])
#: the fruit-finger pairs the barrier's Hessian pattern holds (``BarrierContact``'s
#: ``pairs``): a fruit outline node and a finger surface node at most this many times
#: the sum of their node spacings apart in z at rest (the fingers close along x; a step
#: that fails with pairs outside it grows it: ``BarrierContact.grow_pattern``)
PAIR_REACH_SPACINGS = 2.0
#: ... the fruit's nodes within this fraction of its half-width of its side facing the
#: finger (the fruit compressed by half its width reaches no further)
PAIR_SIDE_DEPTH = 0.5


@njit(cache=True)
def base_pushes(reaction, touching, left_base, right_base, m):
    """(left, right) N, each jaw's force on the fruit along x through its finger: the sum
    (``measures.numpy_sum``) of the x reactions ``reaction`` (2 m, 2) N of its finger's
    base nodes (``left_base``, ``right_base`` (k,), indices into the fingers' state),
    the right one's negated; 0 for a finger none of whose m nodes touches the fruit
    (``touching`` (2 m,) bool)."""
    pushes = np.zeros(2)
    values = np.empty(max(left_base.shape[0], right_base.shape[0]))
    for side in range(2):
        base = left_base if side == 0 else right_base
        touches = False
        for i in range(side * m, (side + 1) * m):
            if touching[i]:
                touches = True
                break
        if not touches:
            continue
        for k in range(base.shape[0]):
            values[k] = reaction[base[k], 0]
        pushes[side] = numpy_sum(values, base.shape[0])
    return pushes[0], -pushes[1]


@dataclass(frozen=True)
class FingerState:
    """The deformable fingers' part of the state after a step (m = both fingers' nodes).

    Attributes:
        positions: (m, 2) m.  velocities: (m, 2) m/s.
        contact_forces: (m, 2) N, the fruit's force on each node.
        reaction: (m, 2) N, the force holding each base node on its jaw (0 elsewhere).
        touching: (m,) bool, the nodes in a barrier pair with the fruit.
    """

    positions: np.ndarray
    velocities: np.ndarray
    contact_forces: np.ndarray
    reaction: np.ndarray
    touching: np.ndarray


def is_deformable(config) -> bool:
    """Whether ``gripper.finger.type`` is a deformable finger."""
    return config['gripper.finger.type'] in DEFORMABLE_FINGERS


def check_soft_fingers(config, fast: bool | None) -> None:
    """ConfigError if a deformable finger is combined with what it does not support."""
    kind = config['gripper.finger.type']
    if config['gripper.finger.pad.enabled']:
        raise ConfigError(f"config key 'gripper.finger.pad.enabled': the {kind} finger is "
                          'itself soft; a pad layer on it is not modelled (set it false)')
    if config['contact.restitution'] > 0:
        raise ConfigError(f"config key 'contact.restitution': the {kind} finger's barrier "
                          'contact has no restitution (set it 0)')
    if fast:
        raise ConfigError(f"config key 'gripper.finger.type': the {kind} finger runs on the "
                          'generic solver, not the numba fast path (fast=True needs a rigid '
                          'finger)')


def finger_body(config, depth: float) -> FingerBody:
    """The FingerBody of the configured deformable finger, ``depth`` (m) deep."""
    return DEFORMABLE_FINGERS[config['gripper.finger.type']](config, depth)


class SoftFingers:
    """The two deformable fingers of a simulation (see the module docstring).

    Args:
        body: the left finger's body (the right one is its mirror image).
        first: index of the left finger's first node in the state (the fruit's nodes
            come before).
        static_friction, kinetic_friction: Coulomb coefficients fruit-finger.
        self_contact: the barrier settings of each finger's self-contact (its beams and
            ribs against each other, ``FingerBody.self_contact``); None: none.
    """

    #: (d,) the mirror taking the left finger's frame to the right one's
    mirror = MIRROR

    def __init__(self, body: FingerBody, first: int, static_friction: float,
                 kinetic_friction: float, self_contact: BarrierSettings | None = None):
        m = body.n_nodes
        self.body = body
        self.first = int(first)
        #: (m,) the global nodes of the left and of the right finger
        self.nodes = (self.first + np.arange(m), self.first + m + np.arange(m))
        #: (m, 2) m, each finger's rest positions in its jaw frame (world x direction)
        self.frames = (body.rest_positions, body.rest_positions * self.mirror)
        #: m, how far the finger reaches in front of its backing
        self.thickness = float(body.rest_positions[:, 0].max())
        self.masses = np.concatenate([body.masses, body.masses])
        #: (2 k,) global base nodes: the left finger's, then the right one's
        self.base = np.concatenate([side[body.base_nodes] for side in self.nodes])
        #: (k, d) m, each finger's base nodes at rest in its jaw frame (``base_targets``)
        self._base_frames = tuple(frame[body.base_nodes] for frame in self.frames)
        #: the fingers' self-contact barrier (each finger against itself), or None; its
        #: steps begin with the fruit's barrier's (``barrier.soft_body_step``)
        self.self_contact: BarrierContact | None = (
            body.self_contact(self_contact, self.nodes, self.first + 2 * m)
            if self_contact is not None else None)
        self.energies = self._energies() + ([self.self_contact] if self.self_contact else [])
        self.soft_bodies = self._soft_bodies(static_friction, kinetic_friction)
        #: per finger (left, right), its surface's elements as indices into both fingers'
        #: nodes: its outline's edges (2D) or triangles (3D) (``slip.surface_motion``)
        self.surface_elements = tuple(
            (body.edges if body.triangles is None else body.triangles) - self.first
            for body in self.soft_bodies)
        #: (2 e, 2) both fingers' outline edges (indices into their nodes, left then
        #: right; ``FingerResult.surface_edges``, read-only: every result shares it),
        #: built by the first ``result``
        self._surface_edges = None
        self._drawn_edges = None   # likewise, ``FingerResult.drawn_edges``

    def _soft_bodies(self, static_friction: float, kinetic_friction: float) -> tuple:
        """The two fingers' outlines in the barrier (``SoftBody``), left then right."""
        edges = self.body.surface_edges
        outline = np.unique(edges)
        return tuple(SoftBody(side[outline], side[edges], static_friction, kinetic_friction)
                     for side in self.nodes)

    @property
    def n_nodes(self) -> int:
        """Nodes of both fingers."""
        return 2 * self.body.n_nodes

    def _energies(self) -> list:
        """The fingers' elastic energies on the global state."""
        body, m = self.body, self.body.n_nodes
        rest = np.zeros((self.first + 2 * m, 2))
        rest[self.nodes[0]] = self.frames[0]
        rest[self.nodes[1]] = self.frames[1]
        energies = []
        if body.triangles.size:
            # mirroring reverses the winding: the right finger's triangles turn back
            triangles = np.vstack([self.nodes[0][body.triangles],
                                   self.nodes[1][body.triangles[:, [0, 2, 1]]]])
            energies.append(NeoHookeanTriangles(triangles, rest, body.youngs_modulus,
                                                body.poisson_ratio, body.depth))
        return energies + body.rod_energies(self.nodes, rest)

    def touching_gap(self, outline: np.ndarray) -> float:
        """m, the gap between the backings at which the two fingers at rest first touch
        the fruit's ``outline`` (n, 2) m, given relative to the jaws' centre: the fruit's
        points at the height of a finger's surface edges, against the surface's reach in
        front of its backing there (a solid pad: its thickness; a Fin Ray: its inclined
        front beam)."""
        x = self.body.rest_positions
        edges = self.body.surface_edges
        (x0, z0), (x1, z1) = x[edges[:, 0]].T, x[edges[:, 1]].T
        qx, qz = outline[:, :1], outline[:, 1:]
        low, high = np.minimum(z0, z1), np.maximum(z0, z1)
        rise = np.where(z1 != z0, z1 - z0, 1.0)
        along = np.where(z1 != z0, x0 + (qz - z0) / rise * (x1 - x0), np.maximum(x0, x1))
        reach = np.where((qz >= low) & (qz <= high), along, -np.inf)
        reach = reach.max(axis=1)                     # (n,) each point's finger in front
        level = np.isfinite(reach)
        if not np.any(level):
            return 0.0
        gaps = 2.0 * np.maximum(reach[level] - qx[level, 0], reach[level] + qx[level, 0])
        return float(max(gaps.max(), 0.0))

    def contact_pairs(self, surface: np.ndarray, outline: np.ndarray) -> np.ndarray:
        """(p, 2) the (fruit node, finger node) pairs of the barrier's Hessian pattern:
        the fruit's ``surface`` nodes (n_s,) at ``outline`` (n_s, 2) m, relative to the
        jaws' centre, on the side facing each finger (``PAIR_SIDE_DEPTH``), and that
        finger's surface nodes at rest within ``PAIR_REACH_SPACINGS`` times the sum of
        the two nodes' spacings of each other in z. A node's spacing: the distance to
        its nearest neighbour on its outline (m)."""
        x = self.body.rest_positions
        edges = self.body.surface_edges
        finger = np.unique(edges)
        finger_spacing = np.full(x.shape[0], np.inf)
        lengths = np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1)
        np.minimum.at(finger_spacing, edges.ravel(), np.repeat(lengths, 2))
        apart = np.linalg.norm(outline[:, None] - outline[None, :], axis=2)
        np.fill_diagonal(apart, np.inf)
        fruit_spacing = apart.min(axis=1)
        half_width = np.abs(outline[:, 0]).max()
        pairs = []
        for sign, nodes, frame in zip((-1.0, 1.0), self.nodes, self.frames):
            side = np.flatnonzero(sign * outline[:, 0] > (1.0 - PAIR_SIDE_DEPTH) * half_width)
            reach = PAIR_REACH_SPACINGS * (fruit_spacing[side, None]
                                           + finger_spacing[None, finger])
            i, j = np.nonzero(np.abs(outline[side, None, 1] - frame[None, finger, 1]) <= reach)
            pairs.append(np.column_stack([surface[side[i]], nodes[finger[j]]]))
        return np.vstack(pairs)

    def check_fit(self, config, open_gap: float, touching_gap: float,
                  fruit_width: float) -> None:
        """ConfigError unless both fingers fit in the jaws' stroke with room between them,
        and the fruit (``fruit_width`` m) fits between them at the open gap (m): the
        fingers touch it at ``touching_gap`` (m, ``touching_gap``)."""
        kind = config['gripper.finger.type']
        key = THICKNESS_KEYS.get(kind, 'gripper.finger.type')
        both = 2.0 * self.thickness
        stroke = config['gripper.max_gap']
        if both >= stroke:
            raise ConfigError(f"config key '{key}': two {kind} fingers "
                              f'{self.thickness * 1e3:.3g} mm thick fill the jaw stroke '
                              f"(gripper.max_gap = {stroke * 1e3:.3g} mm); make them thinner "
                              'or the stroke larger')
        if open_gap < both:
            raise ConfigError(f"config key 'gripper.initial_gap': the {kind} fingers, "
                              f'{self.thickness * 1e3:.3g} mm thick ({key}), overlap at the '
                              f'open gap ({open_gap * 1e3:.3g} mm); open the jaws to at least '
                              f'{both * 1e3:.3g} mm')
        if open_gap <= touching_gap:
            gap_key = ('gripper.initial_gap' if config['gripper.initial_gap'] is not None
                       else 'gripper.max_gap')
            raise ConfigError(f"config key '{gap_key}': the fruit ({fruit_width * 1e3:.3g} mm "
                              f'wide) does not fit between the {kind} fingers at the open gap '
                              f'({open_gap * 1e3:.3g} mm; they touch it at a gap of '
                              f'{touching_gap * 1e3:.3g} mm: fingers reaching '
                              f'{self.thickness * 1e3:.3g} mm in front of their jaws, {key}); '
                              'open the jaws wider or make the fingers thinner')

    # ------------------------------------------------------------------ placement
    def placed(self, left_origin: np.ndarray, right_origin: np.ndarray) -> np.ndarray:
        """(2 m, 2) m, both fingers at rest on jaws whose backings are centred at
        ``left_origin`` and ``right_origin`` (2,) m."""
        return np.vstack([left_origin + self.frames[0], right_origin + self.frames[1]])

    def at_rest(self, left_origin: np.ndarray, right_origin: np.ndarray) -> FingerState:
        """Both fingers at rest on jaws whose backings are centred at the origins (2,) m."""
        m = self.n_nodes
        return FingerState(self.placed(left_origin, right_origin), np.zeros((m, 2)),
                           np.zeros((m, 2)), np.zeros((m, 2)), np.zeros(m, bool))

    def base_targets(self, left_origin: np.ndarray, right_origin: np.ndarray) -> np.ndarray:
        """(2 k, 2) m, where the base nodes are held (``base`` order)."""
        left_rest, right_rest = self._base_frames
        return np.concatenate([left_origin + left_rest, right_origin + right_rest])

    def sides_of_base(self) -> tuple[np.ndarray, np.ndarray]:
        """(2 k,) bool each: the base nodes of the left and of the right finger."""
        k = self.body.base_nodes.size
        left = np.arange(2 * k) < k
        return left, ~left

    # ------------------------------------------------------------------ outputs
    def result(self, state: FingerState, left_origin: np.ndarray,
               right_origin: np.ndarray) -> FingerResult:
        """The fingers' outputs in ``state``, the backings centred at the origins (2,) m."""
        x, forces, touching = state.positions, state.contact_forces, state.touching
        m = self.body.n_nodes
        tip = self.body.tip_node
        tip_displacement = np.array([x[tip] - (left_origin + self.frames[0][tip]),
                                     (x[m + tip] - (right_origin + self.frames[1][tip]))
                                     * MIRROR])
        edges = self._surface_edges
        if edges is None:
            edges = np.vstack([self.body.surface_edges, m + self.body.surface_edges])
            edges.flags.writeable = False
            self._surface_edges = edges
            drawn = self.body.drawn_edges
            self._drawn_edges = np.vstack([drawn, m + drawn])
            self._drawn_edges.flags.writeable = False
        if np.any(touching):
            half = edges.shape[0] // 2
            lengths = [touching_length(x, side_edges, touching)
                       for side_edges in (edges[:half], edges[half:])]
        else:
            lengths = [0.0, 0.0]
        return FingerResult(positions=x.copy(), contact_forces=forces.copy(),
                            tip_displacement=tip_displacement,
                            contact_length=np.array(lengths), surface_edges=edges,
                            drawn_edges=self._drawn_edges)
