"""The barrier contact of the 3D fruit with deformable 3D fingers (``core.barrier`` in 3D).

``core.barrier.BarrierContact`` holds the soft bodies' surface triangles in its collision
mesh (``SoftBody.triangles``); what differs in 3D is the Hessian's fixed pattern. In 2D
it holds every pair of a fruit outline node and a finger outline node; in 3D that is the
default apple's 642 surface nodes times a pad's ~800 surface nodes per finger, a dense
coupling block whose factorisation would dominate the step. The pattern here holds the
likely pairs only: a fruit surface node and a finger surface node whose rest positions in
the jaw frame (the fruit centred between the jaws, the finger on its jaw) lie within
``reach`` of each other across the closing axis (in y and z) on the finger's side of
the fruit: the fingers close along x, and in contact the two surfaces slide relative to
each other by far less than a mesh edge. Pairs outside the pattern (a fruit slipping far
along a finger) still add their exact barrier gradient; their coupling is left out of
the Newton matrix (``drop_outside_pattern``), which slows convergence but changes no
solution; a step that fails with couplings left out grows the pattern by the pairs near
contact and is taken again (``BarrierContact.grow_pattern``).

``partners`` (the body each node touches) is dimension-generic here: from each pair's
stencil (vertex-vertex, edge-vertex, edge-edge, face-vertex) and its distance.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.barrier import BarrierContact, BarrierSettings, SoftBody


class SoftBarrier3D(BarrierContact):
    """``BarrierContact`` of a 3D fruit and soft bodies (see the module docstring).

    Args:
        n_nodes: nodes of the state (the fruit's, then the soft bodies').
        surface: (n_s,) the fruit surface's nodes.  skin_edges: (n_e, 2) its edges.
        triangles: (n_t, 3) its outward triangles.
        settings: dhat, kappa, eps_v.
        bodies: the soft bodies, their ``triangles`` set.
        pairs: (p, 2) the (fruit surface node, soft body node) pairs the Hessian pattern
            holds (global node indices).
    """

    def __init__(self, n_nodes: int, surface: np.ndarray, skin_edges: np.ndarray,
                 triangles: np.ndarray, settings: BarrierSettings, bodies: tuple[SoftBody, ...],
                 pairs: np.ndarray):
        super().__init__(n_nodes, surface, skin_edges, settings, bodies, dimension=3,
                         triangles=triangles, pairs=pairs)

    def _pattern_elements(self) -> np.ndarray:
        """(n_elem, 3) the fruit's surface triangles, the soft bodies' and the pairs
        (``pattern_pairs``, their second node repeated: one element width)."""
        bodies = [self.vertex_nodes[t] for t in self.body_triangles]
        pairs = np.column_stack([self.pattern_pairs, self.pattern_pairs[:, 1]])
        return np.vstack([self.surface[self.fruit_triangles], *bodies, pairs])

    def partners(self, q: np.ndarray) -> np.ndarray:
        """(n,) int, for every node of an outline the body its nearest pair within dhat
        at ``q`` (3 n,) m touches: 0 the fruit, 1 + b soft body b, 1 + B + k face k (B
        soft bodies); -1 for the nodes in no pair."""
        v = self.vertices(q.reshape(-1, 3))
        collisions = self._collisions(v)
        n_v = self.vertex_nodes.size
        owner = np.concatenate([self.vertex_body, 1 + len(self.bodies)
                                + np.arange(v.shape[0] - n_v) // self.corners_per_face])
        mesh = self._mesh
        edges, faces = mesh.edges, mesh.faces
        stencils, distances = [], []
        for group in (collisions.vv_collisions, collisions.ev_collisions,
                      collisions.ee_collisions, collisions.fv_collisions):
            for collision in group:
                stencils.append(collision.vertex_ids(edges, faces))
                distances.append(collision.compute_distance(v, edges, faces))
        partner = -np.ones(self.n_dof // 3, np.int64)
        if not stencils:
            return partner
        ids = np.array(stencils, np.int64)                          # (p, 4), -1 padded
        present = ids >= 0
        body = np.where(present, owner[np.maximum(ids, 0)], -1)
        # each pair joins the fruit (0) and one other body: a vertex's partner is the other
        fruit_side = body == 0
        other = np.where(fruit_side, body.max(axis=1, keepdims=True), 0)
        keep = present & (ids < n_v)
        node = self.vertex_nodes[ids[keep]]
        other = other[keep]
        distance = np.broadcast_to(np.array(distances)[:, None], ids.shape)[keep]
        order = np.lexsort((distance, node))
        first = order[np.r_[True, node[order][1:] != node[order][:-1]]]
        partner[node[first]] = other[first]
        return partner
