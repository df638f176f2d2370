"""A deformable finger body (2D): the geometry and material a soft finger is made of.

Frame: the finger's own jaw frame. x (m) points from the jaw's rigid backing towards the
fruit, the backing being the line x = 0; z (m) points up, z = 0 at the jaw's centre
height. The left jaw carries the body as given, the right jaw its mirror image (x -> -x).

A body is rods (elastic beams: stretching edges and bending triples, e.g. a Fin Ray
finger's front and back beams and its ribs), triangles (plane-strain elastic solid, e.g.
a thick pad), or both. Its ``base_nodes`` move with the jaw; the rest is free and touches
the fruit through ``surface_edges``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from gripper_sim.core.barrier import BarrierContact, BarrierSettings, SoftBody
from gripper_sim.core.energies import Energy, RodBending, Stretching

#: the node pairs of a finger whose coupling its self-contact's Hessian pattern holds:
#: those this many rod element lengths (the longest) apart or closer at rest (pairs
#: further apart still feel their exact barrier force, ``BarrierContact.pattern_pairs``)
SELF_PAIR_REACH_ELEMENTS = 2.0


def _ints(shape) -> np.ndarray:
    return np.zeros(shape, np.int64)


@dataclass(frozen=True)
class FingerBody:
    """Attributes:
        name: the finger type (``gripper.finger.type``), e.g. 'fin_ray'.
        rest_positions: (m, 2) m, in the finger frame (module docstring).
        masses: (m,) kg, lumped.
        base_nodes: (k,) nodes fixed to the jaw's backing.
        surface_edges: (e, 2) the edges of the outline that may touch the fruit.
        tip_node: the node whose displacement is the finger's tip displacement.
        depth: m, out-of-plane depth (the finger's width along the jaw).
        rod_edges: (r, 2) rod segments; rod_axial_stiffness: (r,) EA, N;
            rod_rest_lengths: (r,) m, their rest lengths (empty: their lengths in
            ``rest_positions``; shorter or longer: the body is prestressed as drawn).
        bend_triples: (t, 3) node triples (i, j, k) bent at j; bend_stiffness: (t,) EI,
            N m^2 (rest angle: that of ``rest_positions``); bend_lengths: (t,) m, the rod
            length each triple's curvature stands for (empty: the mean of its two rest
            edge lengths; see ``RodBending``).
        triangles: (n_tri, 3) counter-clockwise solid triangles; youngs_modulus: Pa;
            poisson_ratio: -: the material of the triangles, and of the rods' surface
            (the contact modulus of the damage estimate).
    """

    name: str
    rest_positions: np.ndarray
    masses: np.ndarray
    base_nodes: np.ndarray
    surface_edges: np.ndarray
    tip_node: int
    depth: float
    rod_edges: np.ndarray = field(default_factory=lambda: _ints((0, 2)))
    rod_axial_stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rod_rest_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bend_triples: np.ndarray = field(default_factory=lambda: _ints((0, 3)))
    bend_stiffness: np.ndarray = field(default_factory=lambda: np.zeros(0))
    bend_lengths: np.ndarray = field(default_factory=lambda: np.zeros(0))
    triangles: np.ndarray = field(default_factory=lambda: _ints((0, 3)))
    youngs_modulus: float = 0.0
    poisson_ratio: float = 0.0

    @property
    def n_nodes(self) -> int:
        return len(self.masses)

    @cached_property
    def drawn_edges(self) -> np.ndarray:
        """(k, 2) the edges that draw the whole body: its rod segments and the boundary
        of its triangles (the edges of one triangle only)."""
        sides = np.sort(self.triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        unique, counts = np.unique(sides, axis=0, return_counts=True)
        return np.vstack([self.rod_edges, unique[counts == 1]]).astype(np.int64)

    def rod_energies(self, copies: tuple[np.ndarray, ...] | None = None,
                     rest_positions: np.ndarray | None = None) -> list[Energy]:
        """The stretching and bending energies of the rods (empty for a body without).

        Args:
            copies: for a state holding several copies of the body (the two jaws'
                fingers), each copy's (n_nodes,) global node indices; None: the body
                alone, q of ``2 n_nodes``.
            rest_positions: (N, 2) m, the global rest positions (each copy's rest shape
                at its nodes, e.g. mirrored); None with ``copies`` None.
        """
        if not len(self.rod_edges):
            return []
        if copies is None:
            copies, rest_positions = (np.arange(self.n_nodes),), self.rest_positions
        n = len(copies)
        edges = np.vstack([nodes[self.rod_edges] for nodes in copies])
        if len(self.rod_rest_lengths):
            rest = np.tile(self.rod_rest_lengths, n)
        else:
            rest = np.linalg.norm(rest_positions[edges[:, 1]] - rest_positions[edges[:, 0]],
                                  axis=1)
        energies: list[Energy] = [Stretching(edges, rest,
                                             np.tile(self.rod_axial_stiffness, n))]
        if len(self.bend_triples):
            lengths = np.tile(self.bend_lengths, n) if len(self.bend_lengths) else None
            energies.append(RodBending(np.vstack([nodes[self.bend_triples] for nodes in copies]),
                                       rest_positions, np.tile(self.bend_stiffness, n),
                                       lengths))
        return energies

    def self_pairs(self) -> np.ndarray:
        """(p, 2) the node pairs (i < j) of the body's self-contact pattern: nodes at
        most ``SELF_PAIR_REACH_ELEMENTS`` rod element lengths apart at rest that no rod
        element joins."""
        x = self.rest_positions
        lengths = np.linalg.norm(x[self.rod_edges[:, 1]] - x[self.rod_edges[:, 0]], axis=1)
        reach = SELF_PAIR_REACH_ELEMENTS * (lengths.max() if lengths.size else 0.0)
        apart = np.linalg.norm(x[:, None] - x[None, :], axis=2)
        near = np.triu(apart <= reach, 1)
        near[tuple(np.sort(self.rod_edges, axis=1).T)] = False
        return np.argwhere(near)

    def self_contact(self, settings: BarrierSettings,
                     copies: tuple[np.ndarray, ...] | None = None,
                     n_nodes: int | None = None) -> BarrierContact | None:
        """The barrier between the body's own rod elements (a vertex and an element that
        do not share a node; frictionless), so that its beams and ribs never cross:
        None for a body without rods (``self_contact_barrier`` over ``rod_edges``).

        Args:
            settings: the barrier's dhat and stiffness.
            copies: for a state holding several copies of the body, each copy's
                (n_nodes,) global node indices (each copy touches only itself); None:
                the body alone.
            n_nodes: nodes of the state (None: the body's).
        """
        return self_contact_barrier(self.n_nodes, self.rod_edges, self.self_pairs, settings,
                                    copies, n_nodes)


def self_contact_barrier(body_nodes: int, edges: np.ndarray, self_pairs,
                         settings: BarrierSettings,
                         copies: tuple[np.ndarray, ...] | None = None,
                         n_nodes: int | None = None,
                         triangles: np.ndarray | None = None) -> BarrierContact | None:
    """A finger body's self-contact: the frictionless barrier between its own elements
    that share no node, each copy of the body touching only itself; None for a body
    without elements. The element kind: rod ``edges`` (2D, a vertex and an edge), or
    with ``triangles`` shell triangles (3D, ipctk's vertex-triangle and edge-edge pairs).

    Args:
        body_nodes: the body's node count.
        edges: (e, 2) the touching elements' edges (body node indices): the rod edges, or
            every edge of ``triangles``.
        self_pairs: () -> (p, 2) the body node pairs whose coupling the barrier's Hessian
            pattern holds (called for a body with elements only).
        settings: the barrier's dhat and stiffness.
        copies: for a state holding several copies of the body, each copy's (body_nodes,)
            global node indices; None: the body alone.
        n_nodes: nodes of the state (None: the body's).
        triangles: (t, 3) the shell triangles (body node indices), 3D; None in 2D.
    """
    elements = edges if triangles is None else triangles
    if not len(elements):
        return None
    if copies is None:
        copies, n_nodes = (np.arange(body_nodes),), body_nodes
    nodes = np.unique(elements)
    pairs = self_pairs()
    bodies = tuple(SoftBody(copy[nodes], copy[edges], 0.0, 0.0,
                            triangles=None if triangles is None else copy[triangles])
                   for copy in copies)
    no_fruit = np.zeros(0, np.int64)
    return BarrierContact(n_nodes, no_fruit, no_fruit.reshape(0, 2), settings, bodies,
                          dimension=2 if triangles is None else 3,
                          pairs=np.vstack([copy[pairs] for copy in copies]),
                          self_contact=True)
