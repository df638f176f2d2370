"""Barrier contact (Incremental Potential Contact) of the fruit's surface with rigid faces.

The alternative to the modified mass method (``core.contact_passes``), selected by
``contact.model: ipc``. Following Li et al. 2020 ("Incremental Potential Contact",
ACM Trans. Graph. 39(4) 49), contact is an energy of the implicit Euler step:
- every pair of primitives of different bodies closer than ``dhat`` (2D: a vertex and an
  edge; 3D: a vertex and a triangle, or two edges) adds the
  barrier kappa b(d), b(d) = -(d - dhat)^2 ln(d / dhat) for 0 < d < dhat, 0 beyond;
  ipctk evaluates it on squared distances, b(d^2, dhat^2), and as its "physical"
  barrier divides it by dhat^3, so that kappa is a force (N): a vertex pressed with a
  force F settles at d ~ 2 kappa dhat / F, never at or below 0;
- friction is the lagged dissipative potential (their section 5): the normal forces and
  tangents of the start of the step, mu lambda f0(|v_t|) with f0 smoothed below the
  slip speed eps_v, added to the step as dt D(v) with v = (x - x_n) / dt;
- every Newton line search starts from the continuous-collision bound: the largest
  fraction of the step along which no primitive crosses another (their section 4).
In 3D the candidates (its sweep-and-prune broad phase), barrier, friction potential and
CCD are the IPC Toolkit's (``ipctk``, MIT). In 2D they are compiled: the barrier
(``core.barrier_kernels``) and the lagged friction (``core.friction_kernels``), each
equal to ipctk's to 1e-10, over the candidates of a compiled sort and sweep
(``core.barrier_search``), the barrier's kept while no vertex moves further than
``CANDIDATE_MARGIN``; the line search's bound is that module's additive CCD, and only a
start of step whose path it cannot clear goes to ipctk's exact CCD. The 2D barrier's
step state, evaluation, kept candidates and step bound live in one compiled part
(``core.barrier_part``) that the compiled Newton solve (``core.barrier_newton``) calls
too. One implementation
for both dimensions (``dimension`` d = 2 or 3). Its collision mesh holds the fruit's
surface: in 2D the outline (the surface nodes and skin edges), in 3D the surface nodes,
edges and triangles; and every rigid face: in
2D one segment per ``FlatFace`` (jaw faces, table, walls), in 3D two triangles per
``Plate`` (its rectangle), each moving with its face; infinite faces (table, walls)
become segments or squares ``INFINITE_FACE_LENGTH`` across. Only pairs of the fruit and
an obstacle collide (no self-contact of the surface yet), so the barrier's Hessian stays
on a fixed pattern: the node blocks of the skin edges (2D) or of the surface triangles
(3D), which hold every vertex-face, edge-edge and face-vertex pair with a rigid face.

Deformable bodies (``SoftBody``: the soft fingers, ``core.soft_fingers``) join the
collision mesh with their outlines, whose vertices are degrees of freedom too: the
contact is two-way, both bodies' nodes feel the barrier and the friction (soft-on-soft
contact). A pair may couple any node of the fruit's outline with any of a soft body's;
the Hessian's fixed pattern (the solver's fast path keeps one, as for rigid faces) holds
the outlines' edges and the likely pairs (``pairs``: in 2D those ``SoftFingers``
chooses), or by default every pair; a pair outside it keeps its exact gradient, its
coupling is left out of the Newton matrix. Only pairs with the fruit collide: the
fingers do not touch each other or the table. A finger's self-contact (its beams and
ribs against each other, ``FingerBody.self_contact``) is a second barrier of this class
(``self_contact``): each soft body against itself alone, no fruit, no faces, no
friction. In 3D a soft body's surface joins as triangles (``SoftBody.triangles``), and
its pairs with the fruit are those ``core3d.soft_barrier`` keeps in the pattern.
"""
from __future__ import annotations

import functools
import math
import operator
from dataclasses import dataclass
from typing import Callable

import ipctk
import numpy as np
from scipy.spatial import cKDTree

from gripper_sim.core import barrier_part as bp
from gripper_sim.core import contact as cm
from gripper_sim.core import soft_step_kernels as ssk
from gripper_sim.core.barrier_kernels import (balance_forces, largest_move,
                                              largest_relative_move, mark_sticking,
                                              mean_gap, mesh_vertices, nearest_faces,
                                              normal_components, push_ahead,
                                              relative_moves_within, same_values)
from gripper_sim.core.barrier_search import edge_vertex_candidates, smallest_distance
from gripper_sim.core.contact_passes import StepOutcome
from gripper_sim.core.energies.base import Energy, Evaluation, element_dofs
from gripper_sim.core.pattern_keys import sorted_unique
from gripper_sim.core.stepper import FRICTION_SMOOTHING, NewtonFailure, StepConstraints
from gripper_sim.errors import ConfigError

# ipctk runs its broad phase and its sums over the pairs in TBB threads, whose split of
# the work (and so the pairs' order and the round-off of every sum over them) changes from
# run to run: with one thread repeated runs are bit-identical (the 3D Fin Ray squeeze
# ended on 32 or 33 steps with two), and on a loaded 2-core machine cheaper in CPU time
ipctk.set_num_threads(1)

#: m, length of the segment (2D) or side of the square (3D) standing for an infinite
#: face (table, walls), centred on the face's origin
INFINITE_FACE_LENGTH = 4.0
#: a start of step whose pushed nodes would stop this fraction of dhat from a face
START_GAP_FRACTION = 0.5
#: no predicted start (``push_ahead``)
_NO_PREDICTION = np.zeros((0, 0))
#: the start's check: whether the straight paths cross at all (no conservative rescaling;
#: the line search's CCD stops short, at 0.8 of the time of impact, so that a Newton step
#: never lands on a face)
EXACT_CCD = ipctk.TightInclusionCCD(1e-9, 10 ** 7, 1.0)
#: the line search's CCD (3D, ``BarrierContact.line_search_ccd``): ipctk's default
#: rescaling, a tolerance of this fraction of dhat (ipctk's default 1e-6 m is dhat itself
#: at dhat = 1 um, and two of a 3D Fin Ray's members pressed 26 nm apart crossed within
#: it) and at most ``LINE_SEARCH_CCD_ITERATIONS`` (at the cap Tight Inclusion returns a
#: time of impact no later than the true one; ipctk's default cap, 1e7, made the 3D
#: solid pad's squeeze 2.5 times slower; see the README, *Contact models*), or
#: ``FRUIT_LINE_SEARCH_CCD_ITERATIONS`` between the fruit and the rest (1e6 took the 3D
#: solid pad's squeeze 10.2 s, this 7.9 s, the same steps and iterations; a finger's
#: self-contact keeps 1e6: its fold near buckling follows another path with 1e4)
LINE_SEARCH_CCD_TOLERANCE = 1e-2
LINE_SEARCH_CCD_ITERATIONS = 10 ** 6
FRUIT_LINE_SEARCH_CCD_ITERATIONS = 10 ** 5
#: the line search's step against a still infinite face (3D, ``_plane_step``) takes a
#: vertex this fraction of its way to the face's plane (Tight Inclusion's conservative
#: rescaling of the time of impact, which ipctk takes as its default)
PLANE_RESCALING = ipctk.TightInclusionCCD.DEFAULT_CONSERVATIVE_RESCALING
#: the candidates of a Newton step serve positions this fraction of dhat outside the box
#: each vertex sweeps along it (round-off of q + s dq), their boxes inflated by as much
SWEPT_MARGIN = 1e-2
#: m, how far apart a self-contact's primitives are sought at the start of a step
#: (``BarrierContact.quiet``): positions whose vertices, each body's mean move taken off,
#: stay within half the gap found, less dhat, of where it was sought have no pair within
#: dhat and skip the barrier's work
QUIET_SEARCH = 1e-3
#: a self-contact's quiet region serves the next steps too while their starts have used
#: at most this fraction of its reach (then it is sought again)
QUIET_KEEP = 0.5
#: a step that failed with pairs' couplings left out of the Hessian's pattern (soft
#: bodies and their self-contact, ``grow_pattern``) adds the node pairs within this many
#: of the collision mesh's longest edges of each other (a pair in contact couples a
#: vertex with both ends of an edge)
GROWTH_REACH_EDGES = 2.0
#: a soft-body step with no other collision-free start carries along with each finger
#: the fruit's outline nodes within this many of the collision mesh's longest edges of it
#: (``soft_body_step``), after those within dhat of it
CARRY_REACH_EDGES = 1.0
#: m, the compiled barrier's candidates (2D) are sought this much beyond dhat / 2 around
#: each primitive and serve while every vertex stays within it of where they were sought
CANDIDATE_MARGIN = 1e-4


#: ``barrier_terms``'s arguments when no Hessian is wanted or there is no friction
_NO_VALUES, _NO_SLOTS = np.zeros(0), np.zeros(0, np.int64)
_NO_STEP = np.zeros(0)  # ``quiet`` at q only
#: the compiled solve's empty (k, 2) corners or anchors and candidates
_NO_CORNERS, _NO_PAIRS = np.zeros((0, 2)), np.zeros((0, 2), np.int64)
#: no faces (a self-contact's step, ``soft_body_step``)
_NO_FACES = ()
#: no prescribed nodes (``set_up_starts``)
_NO_NODES = np.zeros(0, np.int64)
_NO_FRICTION = (np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 2)), np.zeros(0),
                np.zeros((0, 2)))


@dataclass(frozen=True)
class BarrierSettings:
    """Attributes:
        dhat: m, the barrier's activation distance (the largest gap still in contact).
        stiffness: N, the barrier stiffness kappa (a vertex pressed with F stays about
            2 kappa dhat / F from the face).
        friction_smoothing: m/s, eps_v, the slip speed below which friction is
            smoothed (static friction is approximated by slow creep).
    """

    dhat: float
    stiffness: float
    friction_smoothing: float = FRICTION_SMOOTHING

    @classmethod
    def from_config(cls, config) -> 'BarrierSettings':
        return cls(float(config['contact.ipc.dhat']), float(config['contact.ipc.stiffness']))


def check_supported(config, dimension: int, fast: bool | None) -> None:
    """ConfigError if ``contact.model: ipc`` is asked where it is not built yet."""
    if config['contact.model'] != 'ipc':
        return
    if config['gripper.finger.pad.enabled']:
        raise ConfigError("config key 'contact.model': ipc does not support soft pads yet "
                          '(gripper.finger.pad.enabled: false, or contact.model: mmm)')
    if config['contact.restitution'] > 0:
        raise ConfigError("config key 'contact.model': ipc has no restitution "
                          '(contact.restitution must be 0, or contact.model: mmm)')
    if fast:
        raise ConfigError("config key 'contact.model': ipc runs on the generic solver, not "
                          'the numba fast path (fast=True needs contact.model: mmm)')


@dataclass(frozen=True)
class SoftBody:
    """A deformable body's outline in the collision mesh (beside the fruit's).

    Attributes:
        nodes: (k,) its outline's nodes (global node indices of the state).
        edges: (e, 2) its outline's edges (global node indices).
        static_friction, kinetic_friction: Coulomb coefficients against the fruit.
        triangles: (t, 3) its surface's outward triangles (global node indices), 3D
            only (``edges`` then holds every edge of them); None in 2D.
    """

    nodes: np.ndarray
    edges: np.ndarray
    static_friction: float
    kinetic_friction: float
    triangles: np.ndarray | None = None


#: (2^(d-1), d-1) the corners of a face in units of its half-extents along its tangents,
#: in order round the face, by dimension d
_CORNERS = {2: np.array([[-1.0], [1.0]]),
            3: np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])}
#: per dimension, (edges (e, 2), triangles (t, 3)) of a face's corners: a segment, or a
#: rectangle as two triangles (its diagonal among the edges)
_FACE_ELEMENTS = {2: (np.array([[0, 1]]), np.zeros((0, 3), np.int64)),
                  3: (np.array([[0, 1], [1, 2], [2, 3], [3, 0], [0, 2]]),
                      np.array([[0, 1, 2], [0, 2, 3]]))}


def _still_planes(faces) -> tuple:
    """(indices (p,), origins (p, 3) m, unit normals (p, 3)) of the ``faces`` (``Plate``)
    that are infinite (table, walls) and stand still."""
    planes = [k for k, face in enumerate(faces)
              if np.all(np.isinf(face.half_extents)) and not np.any(face.velocity)]
    return (np.array(planes, np.int64),
            np.array([faces[k].origin for k in planes], float).reshape(-1, 3),
            np.array([faces[k].normal for k in planes], float).reshape(-1, 3))


def _half_extents(face) -> np.ndarray:
    """(d - 1,) m, the face's half-extents, infinite ones cut to ``INFINITE_FACE_LENGTH``."""
    return np.minimum(np.asarray(face.half_extents, float), 0.5 * INFINITE_FACE_LENGTH)


def _same_faces(faces, kept_faces: tuple, kept_origins: tuple) -> bool:
    """Whether ``faces`` are the objects ``kept_faces``, each still with its origin array
    of ``kept_origins``."""
    return (len(faces) == len(kept_faces) and all(map(operator.is_, faces, kept_faces))
            and all(map(operator.is_, map(_origin, faces), kept_origins)))


_origin = operator.attrgetter('origin')
#: a face's (static, kinetic) friction coefficients
_friction_of = operator.attrgetter('static_friction', 'kinetic_friction')


def _shape_key(face) -> tuple:
    """What a face's normal, tangents, half-extents and thickness are made of: its type
    and those attributes' objects (a 2D face's tangent and half-extent come from its
    normal and half length), which a shallow copy of the face moved elsewhere
    (``faces_at``) shares."""
    attributes = face.__dict__
    return (type(face), attributes['normal'], attributes['thickness'],
            attributes.get('half_length'), attributes.get('tangents'),
            attributes.get('half_extents'))


def _same_shapes(shapes: tuple, kept: tuple) -> bool:
    """Whether two face lists' ``_shape_key``s hold the same objects."""
    return len(shapes) == len(kept) and all(
        all(map(operator.is_, a, b)) for a, b in zip(shapes, kept))


class BarrierContact(Energy):
    """The barrier and friction potentials of one step (``begin_step`` sets it up).

    Args:
        n_nodes: nodes of the state (the fruit's, then any soft bodies').
        surface: (n_s,) the fruit surface's nodes.
        skin_edges: (n_e, 2) the surface's edges (node indices), may be empty in 2D; in 3D
            every edge of ``triangles``.
        settings: dhat, kappa, eps_v.
        bodies: the soft bodies (``SoftBody``) whose outlines touch the fruit (2D).
        dimension: d, 2 or 3.
        triangles: (n_t, 3) the surface's triangles (node indices, outward), 3D only.
        pairs: (p, 2) the node pairs the Hessian's pattern holds (2D; ``pattern_pairs``):
            the likely ones; the coupling of a pair outside them is left out of the
            Newton matrix (``drop_outside_pattern``). None: every pair of a fruit outline
            node and a soft body's outline node.
        self_contact: the soft bodies' self-contact instead (2D): each body's outline
            against itself (a vertex and an edge of the same body that do not share a
            node), no fruit (``surface`` and ``skin_edges`` empty), no faces.
    """

    elastic = False
    #: how each pair's Hessian is made positive semi-definite (CLAMP: its negative
    #: eigenvalues set to 0, so that Newton descends; NONE: the exact Hessian)
    projection = ipctk.PSDProjectionMethod.CLAMP
    #: whether Hessian entries outside the fixed pattern are left out of the Newton matrix
    #: (a pattern of the likely pairs only, ``core3d.soft_barrier``) instead of an error
    drop_outside_pattern = False

    def __init__(self, n_nodes: int, surface: np.ndarray, skin_edges: np.ndarray,
                 settings: BarrierSettings, bodies: tuple = (), dimension: int = 2,
                 triangles: np.ndarray | None = None, pairs: np.ndarray | None = None,
                 self_contact: bool = False):
        self.dimension = d = dimension
        self.self_contact = bool(self_contact)
        #: (p, 2) the node pairs whose coupling the Hessian's pattern holds (2D): (fruit
        #: node, soft body node), or with ``self_contact`` two nodes of one body; None:
        #: every pair of a fruit outline node and a soft body's outline node
        self.pattern_pairs = (None if pairs is None
                              else np.asarray(pairs, np.int64).reshape(-1, 2))
        #: the pairs given (``restore_pattern``)
        self._given_pairs = self.pattern_pairs
        #: whether Hessian entries fell outside the pattern (left out of the Newton
        #: matrix) since the pattern last changed (``grow_pattern``)
        self.left_out = False
        if pairs is not None:
            self.drop_outside_pattern = True
        self.n_dof = d * n_nodes
        self.surface = np.asarray(surface, dtype=np.int64)
        self.bodies = tuple(bodies)
        #: (n_v,) the node of each deformable vertex of the collision mesh: the fruit's
        #: outline first, then each soft body's
        self.vertex_nodes = np.concatenate(
            [self.surface] + [np.asarray(b.nodes, np.int64) for b in self.bodies])
        local = -np.ones(n_nodes, np.int64)
        local[self.vertex_nodes] = np.arange(self.vertex_nodes.size)
        self.fruit_edges = local[np.asarray(skin_edges, dtype=np.int64).reshape(-1, 2)]
        self.body_edges = [local[np.asarray(b.edges, np.int64).reshape(-1, 2)]
                           for b in self.bodies]
        self.fruit_triangles = (local[np.asarray(triangles, np.int64).reshape(-1, 3)]
                                if triangles is not None else np.zeros((0, 3), np.int64))
        self.body_triangles = [local[np.asarray(b.triangles, np.int64).reshape(-1, 3)]
                               for b in self.bodies if b.triangles is not None]
        #: (n_v,) 0 for the fruit's vertices, 1 + b for soft body b's
        self.vertex_body = np.concatenate(
            [np.zeros(self.surface.size, np.int64)]
            + [np.full(len(b.nodes), 1 + k, np.int64) for k, b in enumerate(self.bodies)])
        self.settings = settings
        self.potential = ipctk.BarrierPotential(settings.dhat, settings.stiffness, True)
        iterations = (LINE_SEARCH_CCD_ITERATIONS if self.self_contact
                      else FRUIT_LINE_SEARCH_CCD_ITERATIONS)
        self.line_search_ccd = ipctk.TightInclusionCCD(
            LINE_SEARCH_CCD_TOLERANCE * settings.dhat, iterations,
            ipctk.TightInclusionCCD.DEFAULT_CONSERVATIVE_RESCALING)
        self.friction = ipctk.FrictionPotential(settings.friction_smoothing)
        n_v = self.vertex_nodes.size
        self.vertex_dofs = element_dofs(self.vertex_nodes[:, None], d).ravel()
        self._vertex_dof_pairs = self.vertex_dofs.reshape(-1, d)
        #: (n_elem, m) the dofs of the elements that span the barrier's Hessian pattern
        #: (solvers that keep one sparsity pattern read it): the fruit's surface triangles
        #: (3D) or skin edges (2D; or its lone surface nodes), and with soft bodies their
        #: outlines' edges and every pair of a fruit outline node and a soft body's
        #: outline node
        self.dofs = element_dofs(self._pattern_elements(), d)
        self._pattern_keys = self._hessian_pattern()
        self._mesh = None
        self._n_faces = -1
        self._dt = 1.0
        self._obstacles_end = np.zeros((0, d))
        #: m, the largest move of a face's corner in the step (2D, ``begin_step``)
        self._faces_shift = 0.0
        #: ``_face_geometry``'s last three answers: (faces, their origins, the arrays),
        #: the newest first
        self._geometry_kept = []
        #: (the faces' ``_shape_key``s, their normals, tangents, half-extents, thicknesses,
        #: corners' offsets from their origins), or None
        self._shapes_kept = None
        self._start = np.zeros((n_v, d))
        #: (d n,) m, the positions of the step's start (``begin_step``)
        self._start_q = np.zeros(d * n_nodes)
        self._rest = None  # (n_v, d) m, the surface's first start: the mesh's rest shape
        self._tangential = ipctk.TangentialCollisions()  # the lagged friction's pairs (3D)
        #: whether the step has lagged friction pairs (2D, ``barrier_part.set_step``)
        self._has_friction = False
        #: the broad phase of every candidate search (the meshes are small: sorting the
        #: boxes along an axis beats the default hash grid 2-3x)
        self._broad_phase = ipctk.SweepAndPrune()
        #: the last collision set: (the vertices it was built at (n_v + c k, d) m, it)
        self._last_collisions = None
        #: the last potentials' evaluation: (q (d n,) m, value of the barrier J, of the
        #: friction J, the barrier's gradient and the friction's (n_d,) N over
        #: ``vertex_dofs``), for the outputs read at the solution (``contact_forces``,
        #: ``normal_forces``)
        self._last_terms = None
        #: (n_d,) N, the compiled evaluation's barrier and friction gradients (2D)
        self._gradient_buffers = (np.empty(self.vertex_dofs.size),
                                  np.empty(self.vertex_dofs.size))
        self._positions = None  # (scatter, CSC position of each pattern key)
        #: the last Newton step's candidates: (lowest, highest (n_v, d) m corners of the
        #: box each deformable vertex swept, ipctk.Candidates), see ``max_step``
        self._swept = None
        #: 3D: the step's infinite faces standing still (table, walls): (their indices
        #: among the faces, origins (p, 3) m, unit normals (p, 3)), see ``_plane_step``
        self._planes = (np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
        #: per Hessian part, its last CSC structure and ``_locate``'s answer for it
        self._entry_cache = {}
        #: self-contact only: (the deformable vertices where the gaps were sought (n_v, d)
        #: m, how far m each may move from there, its body's mean move taken off, with no
        #: pair coming within dhat), or None
        self._quiet = None
        #: (the faces' (static, kinetic) coefficients, ``_coefficients``'s answer), or None
        self._friction_coefficients = None
        #: (n_m,) the body of each collision-mesh vertex as ``partners`` numbers them
        self._owners = None
        #: 2D: the step state, kept candidates, last evaluation and compiled kernels
        #: (``barrier_part``; made with the collision mesh), its arrays Python reads
        #: (``barrier_part.shared_arrays``), the slots and projection last set in it;
        #: else None
        self._part = None
        self._part_arrays = None
        self._part_slots = None
        self._part_project = None
        self._part_projection = None  # the ``projection`` last compared (``_synced_part``)

    # ------------------------------------------------------------------ set-up
    def _pattern_elements(self) -> np.ndarray:
        """(n_elem, k) node elements spanning the Hessian's pattern (see ``dofs``)."""
        if self.fruit_triangles.size:
            return self.surface[self.fruit_triangles]
        if not self.bodies:
            return (self.surface[self.fruit_edges] if self.fruit_edges.size
                    else self.surface[:, None])
        fruit = (self.surface[self.fruit_edges] if self.fruit_edges.size
                 else np.stack([self.surface, self.surface], axis=1))
        nodes = [fruit] + [self.vertex_nodes[edges] for edges in self.body_edges]
        if self.pattern_pairs is not None:
            nodes.append(self.pattern_pairs)
        else:
            for body in self.bodies:
                outline = np.asarray(body.nodes, np.int64)
                nodes.append(np.stack([np.repeat(self.surface, outline.size),
                                       np.tile(outline, self.surface.size)], axis=1))
        return np.vstack(nodes)

    def _hessian_pattern(self) -> np.ndarray:
        """Sorted keys col * n_dof + row of the fixed Hessian pattern: the entries of the
        elements ``dofs``."""
        m = self.dofs.shape[1]
        keys = np.tile(self.dofs, (1, m)) * self.n_dof + np.repeat(self.dofs, m, axis=1)
        return sorted_unique(keys)

    @property
    def corners_per_face(self) -> int:
        """Collision-mesh vertices of one rigid face: 2 (a segment) or 4 (a rectangle)."""
        return _CORNERS[self.dimension].shape[0]

    def _build_mesh(self, obstacles: np.ndarray) -> None:
        """The collision mesh of the surface at rest (``_rest``) and the faces' corners
        ``obstacles`` (c k, d) m."""
        n_v = self.vertex_nodes.size
        c = self.corners_per_face
        k = obstacles.shape[0] // c
        offsets = n_v + c * np.arange(k)[:, None, None]
        face_edges, face_triangles = _FACE_ELEMENTS[self.dimension]
        edges = np.vstack([self.fruit_edges, *self.body_edges,
                           (offsets + face_edges).reshape(-1, 2)]).astype(np.int32)
        rest = np.asfortranarray(np.vstack([self._rest, obstacles]))
        if self.dimension == 2:
            self._mesh = ipctk.CollisionMesh(rest, np.asfortranarray(edges))
        else:
            triangles = np.vstack([self.fruit_triangles, *self.body_triangles,
                                   (offsets + face_triangles).reshape(-1, 3)]).astype(np.int32)
            self._mesh = ipctk.CollisionMesh(rest, np.asfortranarray(edges),
                                             np.asfortranarray(triangles))
        if self.self_contact:
            # a body's vertices with its own edges only (ipctk skips an edge's own ends)
            self._mesh_groups = self.vertex_body.astype(np.int64)
            self._mesh.can_collide = ~ipctk.make_vertex_patches_filter(
                self._mesh_groups.astype(np.int32))
        else:
            # the fruit against everything else: soft bodies and faces share one patch
            self._mesh_groups = np.concatenate([(self.vertex_body > 0).astype(np.int64),
                                                np.ones(c * k, np.int64)])
            self._mesh.can_collide = ipctk.make_vertex_patches_filter(
                self._mesh_groups.astype(np.int32))
        self._n_faces = k
        #: the collision mesh's triangles and edges (the faces' last, per face in order)
        self._mesh_sizes = (len(triangles) if self.dimension == 3 else 0, len(edges))
        self._last_collisions = None
        #: the mesh's edges (n_e, 2) and each vertex's state dofs (n_v + c k, d), -1 for
        #: the faces' corners (for the compiled barrier)
        self._mesh_edges = edges.astype(np.int64)
        self._mesh_dofs = -np.ones((rest.shape[0], self.dimension), np.int64)
        self._mesh_dofs[:self.vertex_nodes.size] = self.vertex_dofs.reshape(-1, self.dimension)
        if self.dimension == 2:
            self._part = bp.new_part(self._part_fields())
            self._part_arrays = bp.shared_arrays(self._part)
            self._part_slots = None
            self._part_project = self.projection == ipctk.PSDProjectionMethod.CLAMP

    def _corners(self, faces) -> np.ndarray:
        """(c k, d) m, the corners of the k ``faces`` (``FlatFace`` or ``Plate``), c =
        2^(d-1) rows per face: a segment's two ends, a rectangle's four corners in order
        round it (``_face_geometry``'s, kept: not to be written)."""
        return self._face_geometry(faces)[6]

    def vertices(self, positions: np.ndarray, obstacles: np.ndarray | None = None) -> np.ndarray:
        """(n_v + c k, d) m, the collision mesh's vertices: the surfaces (the fruit's, the
        soft bodies') of ``positions`` (n, d) and the faces' corners (default: where
        they are at the end of this step)."""
        ends = self._obstacles_end if obstacles is None else obstacles
        v = np.empty((self.vertex_nodes.size + ends.shape[0], self.dimension), order='F')
        mesh_vertices(positions.ravel(), self._vertex_dof_pairs, ends, v)
        return v

    def begin_step(self, x_n: np.ndarray, old_faces, new_faces, dt: float) -> None:
        """Set up a step of ``dt`` (s) from positions ``x_n`` (n, d) m with the faces moving
        from ``old_faces`` to ``new_faces`` (the same object: faces that stand still): the
        lagged friction of the start state."""
        old = self._corners(old_faces)
        new = old if new_faces is old_faces else self._corners(new_faces)
        mu_s, mu_k, rubbing = self._begin_faces(x_n, old, new, new_faces, dt)
        start = self.vertices(x_n, old)
        self._start = start
        if self.dimension == 2:
            self._begin_part(x_n, start, new, mu_s, mu_k, rubbing)
            return
        if self.self_contact:
            self._quiet = self._quiet_region(x_n, start)
        if len(self._tangential):  # ipctk's lagged friction (3D): the last step's
            self._tangential = ipctk.TangentialCollisions()
        if rubbing:
            collisions = ipctk.NormalCollisions()
            collisions.build(self._mesh, start, self.settings.dhat,
                             broad_phase=self._broad_phase)
            if len(collisions):
                self._tangential.build(self._mesh, start, collisions, self.potential, mu_s,
                                       mu_k, max)

    def _begin_faces(self, x_n: np.ndarray, old: np.ndarray, new: np.ndarray, new_faces,
                     dt: float) -> tuple:
        """``begin_step``'s set-up of the faces and the step (all but the collision mesh's
        start and the 2D part's or 3D friction's state), the faces' corners where they
        start and end ``old``, ``new`` (c k, d) m: ``_coefficients(new_faces)``."""
        if self._rest is None:
            # the mollifier of nearly parallel edges (3D) scales with their rest lengths
            self._rest = x_n[self.vertex_nodes].copy()
        if self._mesh is None or self._n_faces != len(new_faces):
            self._build_mesh(new)
        self._obstacles_start, self._obstacles_end = old, new
        self._swept = None
        if self.dimension == 3:
            self._planes = _still_planes(new_faces)
        self._last_terms = None
        self._dt = dt
        self._start_q = x_n.ravel().copy()
        return self._coefficients(new_faces)

    def begin_with_starts(self, x_n: np.ndarray, v_n: np.ndarray, old_faces, new_faces,
                          dt: float) -> tuple[list, float]:
        """``begin_step``, then ``pushed_starts`` of x_n and of the predictor
        x_n + dt v_n, each checked as ``reachable`` does, the compiled parts in one call
        (``set_up_starts``): for a 2D barrier of rigid faces only, not a self-contact.
        Positions ``x_n`` (n, 2) m, velocities ``v_n`` (n, 2) m/s.

        Returns:
            (the reachable starts (n, 2) m, the predictor's first; the largest coordinate
            difference m between the two starts).
        """
        plain, predicted, predicted_clear, plain_clear, difference = self.set_up_starts(
            x_n, v_n, old_faces, new_faces, dt, _NO_NODES, _NO_CORNERS, True)
        starts = [start for start, clear in ((predicted, predicted_clear),
                                             (plain, plain_clear))
                  if clear or self.exactly_reachable(start)]
        return starts, difference

    def set_up_starts(self, x_n: np.ndarray, v_n: np.ndarray, old_faces, new_faces,
                      dt: float, fixed: np.ndarray, targets: np.ndarray,
                      both: bool) -> tuple:
        """``begin_step`` and ``pushed_starts`` of x_n and of the predictor x_n + dt v_n
        (positions (n, 2) m, velocities (n, 2) m/s) in one compiled call
        (``barrier_part.begin_with_starts``), nodes ``fixed`` (k,) at ``targets`` (k, 2) m
        in both, with ``reachable``'s compiled check (``barrier_part.start_clear``) of the
        predictor's and, with ``both`` or if that is not clear, of x_n's: 2D, not a
        self-contact.

        Returns:
            (x_n's start, the predictor's (n, 2) m, whether the compiled check clears the
            way to the predictor's, to x_n's (False where not checked), the largest
            coordinate difference m between them).
        """
        faces = self._starts_arguments(x_n, old_faces, new_faces, dt)  # (makes the part)
        (has_friction, start, faces_shift, plain, predicted, predicted_clear, plain_clear,
         difference) = bp.begin_with_starts(self._part, x_n, v_n, dt, *faces,
                                            START_GAP_FRACTION, fixed, targets, both)
        self.took_starts(has_friction, start, faces_shift)
        return plain, predicted, bool(predicted_clear), bool(plain_clear), float(difference)

    def _starts_arguments(self, x_n: np.ndarray, old_faces, new_faces, dt: float) -> tuple:
        """The faces set up for a step of ``dt`` s from positions ``x_n`` (n, 2) m
        (``_begin_faces``): ``barrier_part.begin_with_starts``' arguments from
        ``old_corners`` to ``shifts``."""
        origins, normals, tangents, half_extents, _, thickness, old = self._face_geometry(
            old_faces)
        new_geometry = self._face_geometry(new_faces)
        new_origins, new = new_geometry[0], new_geometry[6]
        mu_s, mu_k, rubbing = self._begin_faces(x_n, old, new, new_faces, dt)
        return (old, new, rubbing, mu_s, mu_k, self.surface, origins, normals, tangents,
                half_extents, thickness, new_origins - origins)

    def took_starts(self, has_friction: bool, start: np.ndarray, faces_shift: float) -> None:
        """What ``barrier_part.begin_with_starts`` (or ``soft_step_kernels.begin``) set
        up in the part, as this barrier keeps it: whether there is lagged friction, the
        collision mesh's start (n_m, 2) m, the faces' largest shift m."""
        self._start, self._faces_shift = start, faces_shift
        self._has_friction = bool(has_friction)

    def begin_soft_step(self, x_n: np.ndarray, v_start: np.ndarray, old_faces, new_faces,
                        dt: float, fixed: np.ndarray, targets: np.ndarray,
                        self_contact: 'BarrierContact | None') -> tuple | None:
        """``set_up_starts`` (nodes ``fixed`` (k,) at ``targets`` (k, 2) m, the predictor
        x_n + dt v_start) and the ``self_contact``'s ``begin_step`` (if given; no faces)
        in one compiled call (``soft_step_kernels.begin``), where the self-contact keeps
        its quiet region: 2D, this barrier not a self-contact.

        Returns:
            (x_n's start, the predictor's (n, 2) m, whether the compiled check clears the
            way to the predictor's, to x_n's (False where not checked), whether the way
            to the predictor's is clear of the self-contact too), or None where the
            self-contact's quiet region must be sought again (nothing set up: the
            caller's ``set_up_starts`` and ``begin_step`` do it).
        """
        faces = self._starts_arguments(x_n, old_faces, new_faces, dt)  # (makes the part)
        has_self = self_contact is not None
        if has_self:
            self_rubbing, self_mu_s, self_mu_k = self_contact.quiet_step_arguments(x_n, dt)
            self_part = self_contact.part
        else:
            self_rubbing, self_mu_s, self_mu_k = False, _NO_VALUES, _NO_VALUES
            self_part = self._part
        (status, has_friction, start, faces_shift, plain, predicted, predicted_clear,
         plain_clear, self_start, self_friction, clear) = ssk.begin(
            self._part, x_n, v_start, dt, *faces, START_GAP_FRACTION, fixed, targets,
            self_part, has_self, QUIET_KEEP, self_rubbing, self_mu_s, self_mu_k)
        if status == ssk.SEEK_QUIET:
            return None
        self.took_starts(has_friction, start, faces_shift)
        if has_self:
            self_contact.took_starts(self_friction, self_start, 0.0)
        return plain, predicted, bool(predicted_clear), bool(plain_clear), bool(clear)

    def quiet_step_arguments(self, x_n: np.ndarray, dt: float) -> tuple:
        """A self-contact's faces (none) set up for a step of ``dt`` s from positions
        ``x_n`` (n, 2) m, as ``begin_step`` sets them up: (whether a friction coefficient
        is positive, the static and kinetic ones (n_m,))."""
        none = self._corners(_NO_FACES)
        mu_s, mu_k, rubbing = self._begin_faces(x_n, none, none, _NO_FACES, dt)
        return rubbing, mu_s, mu_k

    def soft_outputs(self, q: np.ndarray, x_n: np.ndarray, dt: float,
                     solved_reaction: np.ndarray, fixed_dofs: np.ndarray) -> tuple:
        """A soft-body step's outputs at its solution ``q`` (2 n,) m from positions ``x_n``
        (n, 2) m over ``dt`` s (``soft_step_kernels.outputs``): (the velocities (n, 2)
        m/s, the solve's reaction ``solved_reaction`` (2 n,) N on ``fixed_dofs`` (k,), 0
        elsewhere, (n, 2), ``partners`` (n,), ``contact_forces`` (n, 2) N). 2D."""
        size = q.shape[0]
        v, reaction, forces = np.empty(size), np.empty(size), np.empty(size)
        partner = np.empty(size // 2, np.int64)
        if not ssk.outputs(self._part, q, x_n, dt, solved_reaction, fixed_dofs,
                           self.vertex_nodes, self._owner(), v, reaction, partner, forces):
            forces = self.contact_forces(q)
        return v.reshape(-1, 2), reaction.reshape(-1, 2), partner, forces.reshape(-1, 2)

    def _begin_part(self, x_n: np.ndarray, start: np.ndarray, new: np.ndarray,
                    mu_s: np.ndarray, mu_k: np.ndarray, rubbing: bool) -> None:
        """``begin_step``'s 2D part: the step from positions ``x_n`` (n, 2) m, the collision
        mesh's vertices ``start`` (n_m, 2) m, to the faces' corners ``new`` (c k, 2) m
        where they end, with the coefficients ``_coefficients`` gives: the candidates at
        the start (kept while no corner moves further than ``CANDIDATE_MARGIN``), the
        lagged friction's pairs (``barrier_part.set_step``), a self-contact's quiet
        region."""
        start_c = np.ascontiguousarray(start)
        old = self._obstacles_start
        self._faces_shift = 0.0 if not old.size or old is new else _largest_shift(old, new)
        if self.self_contact:
            self._quiet = self._quiet_region(x_n, start_c)
        quiet = self._quiet
        self._has_friction = bool(bp.set_step(
            self._part, new, start_c, rubbing, self._faces_shift <= CANDIDATE_MARGIN, mu_s,
            mu_k, quiet[0] if quiet is not None else _NO_CORNERS,
            quiet[1] if quiet is not None else 0.0, quiet is not None))

    def _coefficients(self, faces) -> tuple[np.ndarray, np.ndarray, bool]:
        """Each collision-mesh vertex's static and kinetic friction coefficients (n_m,)
        with the ``faces`` (a pair takes the larger one: the face's or the soft body's,
        the fruit's being 0), and whether any is positive; kept while the faces'
        coefficients stay."""
        key = tuple(map(_friction_of, faces))
        if self._friction_coefficients is None or self._friction_coefficients[0] != key:
            body_mu_s = np.array([0.0] + [b.static_friction for b in self.bodies])
            body_mu_k = np.array([0.0] + [b.kinetic_friction for b in self.bodies])
            face_mu = np.array(key, float).reshape(-1, 2)
            c = self.corners_per_face
            mu_s = np.concatenate([body_mu_s[self.vertex_body], np.repeat(face_mu[:, 0], c)])
            mu_k = np.concatenate([body_mu_k[self.vertex_body], np.repeat(face_mu[:, 1], c)])
            rubbing = bool(np.any(mu_s > 0) or np.any(mu_k > 0))
            self._friction_coefficients = (key, mu_s, mu_k, rubbing)
        return self._friction_coefficients[1:]

    def _quiet_region(self, x_n: np.ndarray, start: np.ndarray):
        """The self-contact's quiet region (``_quiet``) for a step from positions ``x_n``
        (n, d) m, the collision mesh's vertices ``start``: the last one while the step
        starts well inside it (``QUIET_KEEP``), else sought again; None if a pair is
        within 2 dhat."""
        kept = self._quiet
        if kept is not None and self._relative_move(x_n.ravel(), kept[0]) <= QUIET_KEEP * kept[1]:
            return kept
        gap = self._nearest(start, QUIET_SEARCH)
        if gap > 2.0 * self.settings.dhat:
            return start[:self.vertex_nodes.size].copy(), 0.5 * (gap - self.settings.dhat)
        return None

    def _relative_move(self, q: np.ndarray, anchor: np.ndarray) -> float:
        """m, how far a vertex at positions ``q`` (n d,) moved from ``anchor`` (n_v, d) m
        besides its body's mean move (``largest_relative_move``)."""
        return largest_relative_move(q, self._vertex_dof_pairs, anchor, self.vertex_body,
                                     len(self.bodies) + 1)

    def _check_outside(self, outside: int) -> None:
        """AssertionError if compiled Hessian entries fell outside the pattern, unless
        ``drop_outside_pattern`` (then ``left_out`` is set)."""
        if outside and not self.drop_outside_pattern:
            raise AssertionError('barrier Hessian entry outside its pattern')
        self.left_out = self.left_out or bool(outside)

    def grow_pattern(self, x: np.ndarray) -> bool:
        """Add to the Hessian's pattern (``pattern_pairs`` given) the node pairs that may
        touch (``_near_pairs``) within ``GROWTH_REACH_EDGES`` times the collision mesh's
        longest edge of each other at positions ``x`` (n, d) m, if entries fell outside
        the pattern since it last changed (``left_out``). True if it grew: a solver must
        then be made anew over ``dofs``."""
        if not self.left_out or self.pattern_pairs is None:
            return False
        self.left_out = False
        v = x[self.vertex_nodes]
        near = self._near_pairs(v, GROWTH_REACH_EDGES * self.longest_edge(x))
        known = self.pattern_pairs[:, 0] * self.n_dof + self.pattern_pairs[:, 1]
        new = near[~np.isin(near[:, 0] * self.n_dof + near[:, 1], known)]
        if not new.size:
            return False
        self._set_pattern(np.vstack([self.pattern_pairs, new]))
        return True

    def longest_edge(self, x: np.ndarray) -> float:
        """m, the collision mesh's longest outline edge (the fruit's and the soft
        bodies') at positions ``x`` (n, d) m."""
        v = x[self.vertex_nodes]
        edges = np.vstack([self.fruit_edges, *self.body_edges])
        return float(np.linalg.norm(v[edges[:, 1]] - v[edges[:, 0]], axis=1).max())

    def bodies_gap(self, x: np.ndarray) -> float:
        """m, the smallest distance between outline vertices of two different soft bodies
        at positions ``x`` (n, d) m (inf with fewer than two bodies)."""
        v = x[self.vertex_nodes]
        outlines = [v[self.vertex_body == 1 + b] for b in range(len(self.bodies))]
        return min((float(cKDTree(first).query(second)[0].min())
                    for k, first in enumerate(outlines) for second in outlines[k + 1:]),
                   default=math.inf)

    def _near_pairs(self, v: np.ndarray, reach: float) -> np.ndarray:
        """(p, 2) the node pairs whose vertices at ``v`` (n_v, d) m lie within ``reach``
        (m) of each other and may touch: a fruit outline node and a soft body's (in that
        order), or with ``self_contact`` two nodes of one body (the lower first), sorted."""
        if self.self_contact:
            found = []
            for body in range(1, len(self.bodies) + 1):
                mine = np.flatnonzero(self.vertex_body == body)
                pairs = cKDTree(v[mine]).query_pairs(reach, output_type='ndarray')
                found.append(np.sort(self.vertex_nodes[mine][pairs], axis=1))
            near = np.vstack(found) if found else np.zeros((0, 2), np.int64)
        else:
            fruit = np.flatnonzero(self.vertex_body == 0)
            body = np.flatnonzero(self.vertex_body != 0)
            close = cKDTree(v[fruit]).sparse_distance_matrix(
                cKDTree(v[body]), reach, output_type='ndarray')
            near = np.column_stack([self.vertex_nodes[fruit][close['i']],
                                    self.vertex_nodes[body][close['j']]])
        return near[np.lexsort((near[:, 1], near[:, 0]))].astype(np.int64)

    def restore_pattern(self) -> bool:
        """Back to the pattern of the pairs given (a restarted run repeats its results);
        True if it had grown (a solver must then be made anew over ``dofs``)."""
        self.left_out = False
        if self.pattern_pairs is self._given_pairs:
            return False
        self._set_pattern(self._given_pairs)
        return True

    def _set_pattern(self, pairs: np.ndarray) -> None:
        """The Hessian's pattern of the pairs (p, 2), and what depends on it."""
        self.pattern_pairs = pairs
        self.dofs = element_dofs(self._pattern_elements(), self.dimension)
        self._pattern_keys = self._hessian_pattern()
        self._positions = None
        self._entry_cache = {}
        if self._part is not None:
            bp.set_pattern(self._part, self._pattern_keys)
            self._part_slots = None

    def quiet(self, q: np.ndarray, dq: np.ndarray = _NO_STEP) -> bool:
        """Whether no pair is within dhat at positions ``q`` (n d,) m for certain (and, with
        ``dq`` (n d,) m, at q + dq too; one kernel call, ``relative_moves_within``): a
        self-contact whose vertices all lie within the quiet region's reach of where it
        was sought, each body's mean move taken off (each vertex and edge moved by at most
        that reach against its body: their gap shrank by at most twice it;
        ``barrier_part.quiet`` in 2D). Always False for the fruit's barrier."""
        if self._quiet is None:  # (the 2D part's region is this one: ``begin_step``)
            return False
        if self.dimension == 2:
            return bool(bp.quiet(self._part, q, dq))
        anchor, reach = self._quiet
        return bool(relative_moves_within(q, dq, self._vertex_dof_pairs, anchor,
                                          self.vertex_body, len(self.bodies) + 1, reach))

    # ------------------------------------------------------------------ the energy
    def _terms(self, q: np.ndarray, gradient: np.ndarray, into=None,
               friction: bool = True) -> float:
        """Barrier plus lagged friction (if ``friction``) at positions ``q`` (d n,) m: adds
        the gradient (N) into ``gradient`` and, if ``into`` = (values, slots (p,)) is
        given, the Hessian (N/m) into ``values``, each entry of the pattern's sorted keys
        k at ``slots[k]``; returns the value J. Without the Hessian, the values and
        gradients of the last evaluation are reused when ``q`` is the same."""
        if self.quiet(q):
            return 0.0
        last = self._part_terms() if self.dimension == 2 else self._last_terms
        parts, scales = [], []  # the Hessians (scipy CSC) and their factors
        if into is None and last is not None and same_values(last[0], q):
            _, barrier_value, friction_value, barrier_gradient, friction_gradient = last
        elif self.dimension == 2:
            # the kernel adds the gradients into ``gradient`` itself
            values, slots = into if into is not None else (_NO_VALUES, _NO_SLOTS)
            value = bp.barrier_value(self._synced_part(), q, into is not None, gradient,
                                     values, slots, self._dt, friction)
            self.check_compiled()
            return value
        else:
            mesh = self._mesh
            v = self.vertices(q.reshape(-1, self.dimension))
            n_d = self.vertex_dofs.size
            barrier_value = friction_value = 0.0
            barrier_gradient = friction_gradient = None
            if len(collisions := self._collisions(v)):
                barrier_value = float(self.potential(collisions, mesh, v))
                if not np.isfinite(barrier_value):
                    return np.inf
                barrier_gradient = self.potential.gradient(collisions, mesh, v)[:n_d]
                if into is not None:
                    parts.append(self.potential.hessian(collisions, mesh, v, self.projection))
                    scales.append(1.0)
            if len(self._tangential):
                velocity = np.asfortranarray((v - self._start) / self._dt)
                friction_value = self._dt * float(self.friction(self._tangential, mesh,
                                                                velocity))
                friction_gradient = self.friction.gradient(self._tangential, mesh,
                                                           velocity)[:n_d]
                if into is not None and friction:
                    parts.append(self.friction.hessian(self._tangential, mesh, velocity,
                                                       self.projection))
                    scales.append(1.0 / self._dt)
            self._last_terms = (q.copy(), barrier_value, friction_value, barrier_gradient,
                                friction_gradient)
        value = barrier_value
        if barrier_gradient is not None:
            gradient[self.vertex_dofs] += barrier_gradient
        if friction:
            value += friction_value
            if friction_gradient is not None:
                gradient[self.vertex_dofs] += friction_gradient
        if parts:
            where, vals = self._pattern_entries(parts, scales)
            np.add.at(into[0], into[1][where], vals)
        return value

    def check_compiled(self) -> None:
        """AssertionError if a compiled evaluation (2D) put Hessian entries outside the
        pattern (unless ``drop_outside_pattern``; the part flags it, cleared here)."""
        flags = self._part_arrays[0]
        if flags[bp.B_OUTSIDE]:
            flags[bp.B_OUTSIDE] = 0
            self._check_outside(1)

    def _part_terms(self):
        """The 2D part's last evaluation as ``_last_terms`` (q, barrier value J, friction
        value J, barrier and friction gradients (n_d,) N over ``vertex_dofs`` or None),
        None if there is none this step."""
        flags, last_q, values, _ = self._part_arrays
        terms = flags[bp.B_TERMS]
        if not terms:
            return None
        gradients = ((None, None) if terms == 1 else
                     (self._gradient_buffers[0],
                      self._gradient_buffers[1] if self._has_friction else None))
        return last_q, float(values[0]), float(values[1]), *gradients

    def _pattern_entries(self, parts: list, scales: list) -> tuple[np.ndarray, np.ndarray]:
        """The entries of the Hessians ``parts`` (scipy CSC over the collision mesh's
        dofs, each times its ``scales`` factor) on the deformable vertices: (their indices
        in the pattern's sorted keys, their values N/m), duplicates not summed."""
        n_d = self.vertex_dofs.size
        where, vals = [], []
        for slot, (matrix, scale) in enumerate(zip(parts, scales)):
            end = matrix.indptr[n_d]
            indptr, rows = matrix.indptr[:n_d + 1], matrix.indices[:end]
            kept = self._entry_cache.get(slot)
            if kept is None or not (np.array_equal(kept[0], indptr)
                                    and np.array_equal(kept[1], rows)):
                kept = (indptr.copy(), rows.copy(), *self._locate(indptr, rows))
                self._entry_cache[slot] = kept
            self.left_out = self.left_out or kept[4]
            where.append(kept[2])
            vals.append(scale * matrix.data[:end][kept[3]])
        if not where:
            return np.zeros(0, np.int64), np.zeros(0)
        return np.concatenate(where), np.concatenate(vals)

    def _locate(self, indptr: np.ndarray,
                rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, bool]:
        """For a Hessian's CSC structure over the deformable vertices' dofs (``indptr``
        (n_d + 1,), row ``indices``): (the pattern's key index of each entry among the
        deformable vertices, bool mask of those entries, whether entries fell outside the
        pattern and were left out)."""
        n_d = self.vertex_dofs.size
        cols = np.repeat(np.arange(n_d), np.diff(indptr))
        inside = rows < n_d
        keys = self.vertex_dofs[cols[inside]] * self.n_dof + self.vertex_dofs[rows[inside]]
        last = self._pattern_keys.size - 1
        index = np.minimum(np.searchsorted(self._pattern_keys, keys), last)
        found = self._pattern_keys[index] == keys
        left_out = not np.all(found)
        if left_out:
            if not self.drop_outside_pattern:
                raise AssertionError('barrier Hessian entry outside its pattern')
            inside[inside] = found
            index = index[found]
        return index, inside, left_out

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        """Barrier plus lagged friction at fruit positions ``q`` (d n,) m."""
        gradient = np.zeros(self.n_dof)
        if not hessian:
            return Evaluation(self._terms(q, gradient), gradient, *_no_triplets())
        vals = np.zeros(self._pattern_keys.size)
        value = self._terms(q, gradient, (vals, np.arange(vals.size)))
        cols, rows = np.divmod(self._pattern_keys, self.n_dof)
        return Evaluation(value, gradient, rows, cols, vals)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """As ``evaluate``, adding the gradient (N) into ``grad`` and the Hessian (N/m)
        into the solver's CSC values ``data`` at ``scatter`` (n_elem, m * m), the
        positions of the entries of ``dofs``; returns (value J, no low-rank terms)."""
        into = (data, self.pattern_slots(scatter)) if hessian else None
        return self._terms(q, grad, into), []

    @property
    def part(self):
        """The 2D barrier's ``barrier_part.BarrierPart`` (its step state and last
        evaluation), for compiled readers of its forces (``soft_step_kernels``)."""
        return self._part

    def compiled_part(self, scatter: np.ndarray):
        """The 2D barrier's ``barrier_part.BarrierPart`` (a new one when the collision
        mesh is built anew), its Hessian going into the solver's CSC values at
        ``scatter`` (``evaluate_into``'s)."""
        slots = self.pattern_slots(scatter)
        if self._part_slots is not slots:
            bp.set_slots(self._part, slots)
            self._part_slots = slots
        return self._synced_part()

    def _synced_part(self):
        """The 2D part with this barrier's ``projection`` (which may be set on the
        instance)."""
        projection = self.projection
        if projection is not self._part_projection:  # (ipctk's enum values are singletons)
            project = projection == ipctk.PSDProjectionMethod.CLAMP
            if project != self._part_project:
                bp.set_project(self._part, project)
                self._part_project = project
            self._part_projection = projection
        return self._part

    def pattern_slots(self, scatter: np.ndarray) -> np.ndarray:
        """(p,) the solver's CSC position of each of the pattern's sorted keys, from the
        positions ``scatter`` (n_elem, m * m) of the entries of ``dofs``; kept for the
        same scatter array."""
        if self._positions is None or self._positions[0] is not scatter:
            m = self.dofs.shape[1]
            keys = np.tile(self.dofs, (1, m)) * self.n_dof + np.repeat(self.dofs, m, axis=1)
            first = np.unique(keys.ravel(), return_index=True)[1]
            self._positions = (scatter, scatter.ravel()[first])
        return self._positions[1]

    def _part_fields(self) -> tuple:
        """The fields of this 2D barrier's ``barrier_part.BarrierPart``, the step's
        empty (``begin_step`` sets them), no pattern slots yet (``compiled_part``)."""
        contact = self.settings
        return (self._vertex_dof_pairs, self._mesh_edges, self._mesh_groups,
                self.self_contact, contact.dhat, contact.stiffness, self._mesh_dofs,
                self.projection == ipctk.PSDProjectionMethod.CLAMP, self._pattern_keys,
                contact.friction_smoothing, 0.5 * contact.dhat + CANDIDATE_MARGIN,
                (0.5 + SWEPT_MARGIN) * contact.dhat, CANDIDATE_MARGIN,
                *self._gradient_buffers, self.drop_outside_pattern, self.vertex_body,
                len(self.bodies) + 1, _NO_SLOTS,
                _NO_CORNERS, _NO_CORNERS, np.zeros((self.vertex_nodes.size, 2)),
                _NO_PAIRS, _NO_FRICTION, False, _NO_CORNERS, 0.0, False,
                np.zeros(bp.B_SIZE, np.int64), np.empty(self.n_dof), np.empty(2))

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The largest fraction (0, 1] of the step ``dq`` (d n,) m from ``q`` along which no
        primitive of the surface crosses a face's and no face's crosses the surface's
        (CCD: in 2D compiled, ``barrier_part.max_step``; in 3D ipctk's, keeping the step's collision
        candidates for the line search along it)."""
        if self.dimension == 2:
            return float(bp.max_step(self._part, q, dq))
        if self.quiet(q, dq):
            return 1.0
        end = q + dq
        v0 = self.vertices(q.reshape(-1, self.dimension))
        v1 = self.vertices(end.reshape(-1, self.dimension))
        candidates = ipctk.Candidates()
        candidates.build(self._mesh, v0, v1, (0.5 + SWEPT_MARGIN) * self.settings.dhat,
                         self._broad_phase)
        n_v = self.vertex_nodes.size
        self._swept = (np.minimum(v0[:n_v], v1[:n_v]), np.maximum(v0[:n_v], v1[:n_v]),
                       candidates)
        bound, others = self._plane_step(candidates, v0, v1)
        if others.empty():
            return bound
        return min(bound, float(others.compute_collision_free_stepsize(
            self._mesh, v0, v1, narrow_phase_ccd=self.line_search_ccd)))

    def _plane_step(self, candidates: ipctk.Candidates, v0: np.ndarray,
                    v1: np.ndarray) -> tuple[float, ipctk.Candidates]:
        """3D: the line search's largest step fraction (0, 1] against the infinite faces
        standing still (``_planes``) in closed form, and the ``candidates`` left to the
        CCD (those of no such face). The collision mesh's vertices move from ``v0`` to
        ``v1`` (n_m, 3) m in straight lines. A face all of whose deformable vertices
        start in front of it bounds the step where the first of them would have come
        ``PLANE_RESCALING`` of its way to its plane (as Tight Inclusion's conservative
        rescaling of the time of impact): its plane holds its rectangle and, each edge
        lying in front of it, an edge meets it first at an end. (Tight Inclusion runs to
        its iteration cap on a vertex falling onto the table at the 1 um gap's tolerance,
        1e-8 m: the first 3D step onto the table took 6 s.) A face with a vertex at or
        behind it is left to the CCD."""
        faces, origins, normals = self._planes
        if not faces.size:
            return 1.0, candidates
        n_v = self.vertex_nodes.size
        start = (v0[:n_v] - origins[:, None, :]) @ normals[:, :, None]  # (p, n_v, 1) m
        end = (v1[:n_v] - origins[:, None, :]) @ normals[:, :, None]
        in_front = start.min(axis=(1, 2)) > 0.0
        faces = faces[in_front]
        if not faces.size:
            return 1.0, candidates
        start, end = start[in_front], end[in_front]
        closing = end < start
        times = PLANE_RESCALING * start[closing] / (start[closing] - end[closing])
        bound = float(times.min(initial=1.0))
        triangles, edges = self._mesh_sizes
        face_edges, face_triangles = (len(e) for e in _FACE_ELEMENTS[3])
        k = self._n_faces
        drop_triangles = set((triangles - face_triangles * (k - faces[:, None])
                              + np.arange(face_triangles)).ravel().tolist())
        drop_edges = set((edges - face_edges * (k - faces[:, None])
                          + np.arange(face_edges)).ravel().tolist())
        others = ipctk.Candidates()
        others.fv_candidates = [c for c in candidates.fv_candidates
                                if c.face_id not in drop_triangles]
        others.ee_candidates = [c for c in candidates.ee_candidates
                                if c.edge0_id not in drop_edges
                                and c.edge1_id not in drop_edges]
        others.ev_candidates = candidates.ev_candidates
        others.vv_candidates = candidates.vv_candidates
        return bound, others

    def _collisions(self, v: np.ndarray) -> ipctk.NormalCollisions:
        """The pairs closer than dhat at the collision mesh's vertices ``v`` (``vertices``):
        from the last Newton step's candidates when every deformable vertex lies in the
        box it swept along that step (the faces stand still within a step), else from a
        new broad phase. Boxes inflated by dhat / 2 each meet for every pair closer
        than dhat, so the candidates hold every such pair. The set of the same ``v`` as
        the last call is that call's."""
        last = self._last_collisions
        if last is not None and np.array_equal(last[0], v):
            return last[1]
        collisions = ipctk.NormalCollisions()
        collisions.build(self._candidates(v), self._mesh, v, self.settings.dhat)
        self._last_collisions = (v.copy(), collisions)
        return collisions

    def _candidates(self, v: np.ndarray) -> ipctk.Candidates:
        """The candidates (ipctk) holding every pair closer than dhat at the collision
        mesh's vertices ``v``: the last Newton step's when every deformable vertex lies in
        the box it swept along that step (the faces stand still within a step), else
        those of a new broad phase. Boxes inflated by dhat / 2 each meet for every pair
        closer than dhat."""
        swept = self._swept
        if swept is not None:
            low, high, kept = swept
            slack = SWEPT_MARGIN * self.settings.dhat
            inside = v[:low.shape[0]]
            if np.all(inside >= low - slack) and np.all(inside <= high + slack):
                return kept
        candidates = ipctk.Candidates()
        candidates.build(self._mesh, v, 0.5 * self.settings.dhat, self._broad_phase)
        return candidates

    def _static_candidates(self, v: np.ndarray, radius: float) -> np.ndarray:
        """(k, 2) the (edge, vertex) pairs of the collision mesh's vertices ``v`` (2D) whose
        boxes inflated by ``radius`` (m) meet (``barrier_search``)."""
        return edge_vertex_candidates(v, v, self._mesh_edges, self._mesh_groups,
                                      self.self_contact, radius)

    def _nearest(self, v: np.ndarray, reach: float, beyond: float | None = None) -> float:
        """m, the smallest distance of a pair of the collision mesh's vertices ``v``, or
        ``beyond`` (default ``reach``) if none is nearer than ``reach`` (m)."""
        if self.dimension == 3:
            pairs = ipctk.NormalCollisions()
            pairs.build(self._mesh, v, reach, broad_phase=self._broad_phase)
            distance = (min(np.sqrt(pairs.compute_minimum_distance(self._mesh, v)), reach)
                        if len(pairs) else reach)
        else:
            pairs = self._static_candidates(v, 0.5 * reach)
            distance = smallest_distance(v, self._mesh_edges, pairs, reach)
        return float(distance) if distance < reach or beyond is None else beyond

    # ------------------------------------------------------------------ the start
    def pushed_starts(self, x_n: np.ndarray, old_faces, new_faces,
                      predicted: np.ndarray | None = None) -> tuple:
        """The step's starts, not checked for crossings (``reachable``): (n, d) m x_n with
        the outline nodes that a moving face covers at x_n and would come closer than
        dhat / 2 to pushed ahead of it (one already within dhat of it moved with it, its
        gap kept, where the face recedes too), and ``predicted`` (n, d) m (the predictor
        x_n + dt v_n; None: none) with them pushed ahead of it as far as their own moves
        leave that to do (None if none)."""
        plain = x_n.copy()
        ahead = _NO_PREDICTION if predicted is None else predicted.copy()
        origins, normals, tangents, half_extents, _, thickness, _ = self._face_geometry(
            old_faces)
        shifts = self._face_geometry(new_faces)[0] - origins
        push_ahead(x_n, self.surface, origins, normals, tangents, half_extents, thickness,
                   shifts, self.settings.dhat, START_GAP_FRACTION, plain, ahead)
        return plain, (None if predicted is None else ahead)

    def reachable(self, start: np.ndarray) -> bool:
        """Whether the straight paths from the step's start (``begin_step``'s positions,
        the faces at the start of the step) to ``start`` (n, d) m (the faces at its end)
        cross nothing and end apart."""
        q = start.ravel()
        if self.quiet(q):
            return True
        # in 2D the compiled (conservative) check clears most paths, and with them their
        # ends (it clears no pair that ends touching; the others' boxes stay apart); the
        # exact CCD decides the others; nothing that stands still crosses anything
        if self.dimension == 2 and bp.start_clear(self._part, self._start_q, q,
                                                  self._faces_shift):
            return True
        return self.exactly_reachable(start)

    def carried_by_faces(self, x_n: np.ndarray, old_faces: list,
                         new_faces: list) -> np.ndarray | None:
        """(n, d) m, x_n with each fruit surface node within ``CARRY_REACH_EDGES`` of the
        outline's longest edges of a moving face (of its extent, not its plane) moved by
        that face's shift (the nearest one's): a fallback start for a step whose pushed
        starts cross something (``_begin``), as where a fruit squeezed flat along a jaw
        wraps round its corner and the corner would cross an outline edge that no single
        node's push keeps ahead of it; None if no face moves."""
        origins, _, tangents, half_extents, _, _, _ = self._face_geometry(old_faces)
        shifts = self._face_geometry(new_faces)[0] - origins
        moving = np.flatnonzero(np.any(shifts != 0.0, axis=1))
        if not moving.size:
            return None
        nodes = self.surface
        offsets = x_n[nodes][None, :, :] - origins[moving][:, None, :]   # (m, s, d)
        distances = np.empty((moving.size, nodes.size))
        for row, k in enumerate(moving):
            along = np.clip(offsets[row] @ tangents[k].T, -half_extents[k], half_extents[k])
            distances[row] = np.linalg.norm(offsets[row] - along @ tangents[k], axis=1)
        near = distances.min(axis=0) <= CARRY_REACH_EDGES * self.longest_edge(x_n)
        start = x_n.copy()
        start[nodes[near]] += shifts[moving[distances.argmin(axis=0)[near]]]
        return start

    def exactly_reachable(self, start: np.ndarray) -> bool:
        """``reachable``'s exact check (ipctk's CCD, then the ends' distance) of the paths
        to ``start`` (n, d) m."""
        v0 = self._start
        v1 = self.vertices(start)
        if not np.array_equal(v0, v1):
            exact = float(ipctk.compute_collision_free_stepsize(
                self._mesh, v0, v1, broad_phase=self._broad_phase, narrow_phase_ccd=EXACT_CCD))
            if exact < 1.0:
                return False
        return self.min_distance(start) > 0.0

    # ------------------------------------------------------------------ outputs
    def contact_forces(self, q: np.ndarray) -> np.ndarray:
        """(n, d) N, the faces' force on each node at ``q`` (d n,) m: barrier + friction."""
        return self._forces(q, True)

    def normal_forces(self, q: np.ndarray) -> np.ndarray:
        """(n, d) N, the barrier's (normal) part of ``contact_forces``, no friction."""
        return self._forces(q, False)

    def _forces(self, q: np.ndarray, friction: bool) -> np.ndarray:
        """(n, d) N, minus the gradient of the barrier plus (with ``friction``) the lagged
        friction at ``q`` (d n,) m: in 2D the last evaluation's when it was at ``q``
        (``barrier_part.kept_forces``), else ``_terms``'s."""
        if self.dimension == 2:
            forces = np.empty(self.n_dof)
            if bp.kept_forces(self._part, q, friction, forces):
                return forces.reshape(-1, 2)
        gradient = np.zeros(self.n_dof)
        self._terms(q, gradient, friction=friction)
        return -gradient.reshape(-1, self.dimension)

    def partners(self, q: np.ndarray) -> np.ndarray:
        """(n,) int, for every node of an outline the body its nearest pair within dhat
        at ``q`` (2 n,) m touches: 0 the fruit, 1 + b soft body b, 1 + B + k face k (B
        soft bodies); -1 for the nodes in no pair. 2D."""
        partner = np.empty(self.n_dof // 2, np.int64)
        bp.partners(self._part, q, self.vertex_nodes, self._owner(), partner)
        return partner

    def _owner(self) -> np.ndarray:
        """(n_m,) the body of every collision-mesh vertex (``partners``' numbers: the
        outlines', then the faces' end points'), kept."""
        n_v = self.vertex_nodes.size
        n_m = n_v + self._obstacles_end.shape[0]
        owner = self._owners
        if owner is None or owner.size != n_m:
            owner = self._owners = np.concatenate(
                [self.vertex_body, 1 + len(self.bodies)
                 + np.arange(n_m - n_v) // self.corners_per_face])
        return owner

    def holders(self, x: np.ndarray, faces, forces: np.ndarray) -> np.ndarray:
        """(n,) the face (index) each node with a contact force touches (its nearest face
        within dhat), -1 for the others; positions ``x`` and ``forces`` (n, d)."""
        holder = np.empty(x.shape[0], np.int64)
        nearest_faces(np.ascontiguousarray(x), np.ascontiguousarray(forces),
                      *self._face_geometry(faces)[:4], self.settings.dhat, holder)
        return holder

    def step_outputs(self, q: np.ndarray, x_n: np.ndarray, dt: float, faces,
                     residual: np.ndarray) -> tuple[np.ndarray, np.ndarray, cm.ContactState]:
        """A step's outputs at its solution ``q`` (d n,) m from positions ``x_n`` (n, d) m over
        ``dt`` (s), ``faces`` (rigid) at its end: (the velocities (x - x_n) / dt (n, d)
        m/s, ``contact_forces`` (n, d) N balanced by the solve's ``residual`` (d n,) N
        (``barrier_kernels.balance_forces``), ``held_contacts``); in 2D in one compiled
        call (``barrier_part.step_outputs``) where the last evaluation was made at q."""
        n, d = x_n.shape
        if d == 2:
            forces, v, holder = np.empty(2 * n), np.empty((n, 2)), np.empty(n, np.int64)
            contacts = cm.ContactState.held_by(holder)
            origins, normals, tangents, half_extents, velocities, _, _ = (
                self._face_geometry(faces))
            if bp.step_outputs(self._part, q, x_n, dt, residual, origins, normals, tangents,
                               half_extents, velocities, self.settings.friction_smoothing,
                               cm.STICK, cm.SLIP, forces, v, holder, contacts.normal_force,
                               contacts.mode):
                return v, forces.reshape(n, 2), contacts
        forces = self.contact_forces(q)
        balance_forces(forces, residual.reshape(n, d))
        x = q.reshape(-1, d)
        v = (x - x_n) / dt
        return v, forces, self.held_contacts(x, v, faces, forces)

    def held_contacts(self, x: np.ndarray, v: np.ndarray, faces,
                      forces: np.ndarray) -> cm.ContactState:
        """The contact set of positions ``x``, velocities ``v`` and contact ``forces`` (n, d)
        against ``faces``: each node held by its ``holders`` face, with its normal force
        (N, along the face's normal) and its mode, STICK below the friction smoothing
        speed along the face (relative to it), else SLIP."""
        contacts = cm.ContactState.held_by(self.holders(x, faces, forces))
        _, normals, _, _, velocities, _, _ = self._face_geometry(faces)
        normal_components(contacts.obstacle, np.ascontiguousarray(forces), normals,
                          contacts.normal_force)
        mark_sticking(np.ascontiguousarray(v), contacts.obstacle, normals, velocities,
                      self.settings.friction_smoothing, cm.STICK, cm.SLIP, contacts.mode)
        return contacts

    def _face_geometry(self, faces) -> tuple:
        """The faces' origins and unit normals (k, d), tangents (k, d - 1, d), half-extents
        (k, d - 1) m (as ``nearest_faces`` takes them), velocities (k, d) m/s,
        thicknesses (k,) m and corners (``_corners``); kept for the last three face lists
        while each face and its origin array are the same objects (a facade hands the
        same faces for the same gripper state, ``faces_at``; faces are not changed in
        place: a moved face is a copy with a new origin). The parts that do not move
        with a face are kept apart, while the faces' shapes are made of the same objects
        (``_shape_key``): a face list of a new gripper state makes only its
        origins, velocities and corners."""
        for kept_faces, kept_origins, geometry in self._geometry_kept:
            if _same_faces(faces, kept_faces, kept_origins):
                return geometry
        d = self.dimension
        shapes = tuple(map(_shape_key, faces))
        kept_shapes = self._shapes_kept
        if kept_shapes is not None and _same_shapes(shapes, kept_shapes[0]):
            normals, tangents, half_extents, thickness, corner_offsets = kept_shapes[1]
        else:
            tangents = np.array([f.tangents for f in faces], float).reshape(-1, d - 1, d)
            half_extents = np.array([_half_extents(f) for f in faces]).reshape(-1, d - 1)
            corner_offsets = (_CORNERS[d] * half_extents[:, None, :]) @ tangents
            normals = np.array([f.normal for f in faces], float).reshape(-1, d)
            thickness = np.array([f.thickness for f in faces], float)
            self._shapes_kept = (shapes, (normals, tangents, half_extents, thickness,
                                          corner_offsets))
        origins = np.array([f.origin for f in faces], float).reshape(-1, d)
        corners = (origins[:, None, :] + corner_offsets).reshape(-1, d)
        geometry = (origins, normals, tangents, half_extents,
                    np.array([f.velocity for f in faces], float).reshape(-1, d),
                    thickness, corners)
        self._geometry_kept = ([(tuple(faces), tuple(f.origin for f in faces), geometry)]
                               + self._geometry_kept[:2])
        return geometry

    def touching_faces(self, faces, x: np.ndarray, holder: np.ndarray) -> list:
        """The faces moved out along their normals by their ``touching_gaps``: the surfaces
        the outline lies on, for the measures that read gaps from a face."""
        moved = []
        for face, gap in zip(faces, self.touching_gaps(faces, x, holder)):
            if gap:
                face = face.moved(face.origin + gap * face.normal)
            moved.append(face)
        return moved

    @staticmethod
    def touching_gaps(faces, x: np.ndarray, holder: np.ndarray) -> list[float]:
        """m, each face's mean gap to the nodes it holds (``holder`` (n,), positions ``x``
        (n, d) m; 0.0 for a face that holds none): how far out the outline lies on it (the
        contact length's edges are read from a face there)."""
        x = np.ascontiguousarray(x, dtype=float)
        return [mean_gap(x, holder, k, face.origin, face.normal)
                for k, face in enumerate(faces)]

    def min_distance(self, x: np.ndarray) -> float:
        """m, the smallest distance between the surface and a face at positions (n, d)
        (inf when none is within dhat)."""
        v = self.vertices(x)
        if self.dimension == 2:
            return self._nearest(v, self.settings.dhat, np.inf)
        collisions = self._collisions(v)
        if not len(collisions):
            return np.inf
        return float(np.sqrt(collisions.compute_minimum_distance(self._mesh, v)))


def _largest_shift(a: np.ndarray, b: np.ndarray) -> float:
    """m, the largest distance between matching rows of points ``a`` and ``b`` (k, 2)."""
    return float(largest_move(np.ravel(b), _row_dofs(b.shape[0]), a))


@functools.lru_cache(maxsize=8)
def _row_dofs(rows: int) -> np.ndarray:
    """(rows, 2) the flat index of each coordinate of a (rows, 2) C-order array."""
    return np.arange(2 * rows, dtype=np.int64).reshape(rows, 2)


def _no_triplets():
    empty = np.zeros(0, dtype=np.int64)
    return empty, empty, np.zeros(0)


def _begin(barrier: BarrierContact, x_n: np.ndarray, v_n: np.ndarray, old_faces: list,
           new_faces: list, dt: float, resolution: float,
           v_predicted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Set up the barrier's step; its starts (n, d) m: x_n pushed ahead of moving faces
    (``pushed_starts``), and the predictor x_n + dt v pushed ahead of them too (v:
    ``v_predicted`` (n, d) m/s where given, ``barrier_step``'s, else v_n): in 2D always,
    in 3D only with ``v_predicted`` (the jaws carry the fruit), and then alone where it
    is reached;
    those the way to which crosses nothing: (the start, the other start or None; the
    solve takes the one of lower incremental potential, ``newton.lower_start``). Two
    starts no coordinate of which differs by ``resolution`` m (the Newton tolerance's
    step) or more are one. NewtonFailure if none.

    The predictor halves the ring squeeze's Newton iterations (``bench_barrier.py``: 256
    against 556; from x_n a moving jaw pushes outline nodes into its barrier that the
    solution lifts off it, and Newton frees them a few iterations each), and the
    potential keeps x_n where the predictor is worse (the Hertz disk ringing after its
    load: 250 iterations, 362 from x_n, 300 from the predictor). In 3D the check of a
    second start (ipctk's CCD) and the two potentials cost more than the iterations they
    save (the Hertz sphere: 35 against 38 iterations, 0.75 against 0.67 s)."""
    v = v_n if v_predicted is None else v_predicted
    if barrier.dimension == 2 and not barrier.self_contact:
        starts, difference = barrier.begin_with_starts(x_n, v, old_faces, new_faces, dt)
    else:
        barrier.begin_step(x_n, old_faces, new_faces, dt)
        plain, predicted = barrier.pushed_starts(
            x_n, old_faces, new_faces,
            x_n + dt * v if barrier.dimension == 2 or v_predicted is not None else None)
        candidates = [start for start in (predicted, plain) if start is not None]
        if barrier.dimension == 3:  # one start, the first reached (its CCD is ipctk's)
            starts = next(([start] for start in candidates if barrier.reachable(start)), [])
        else:
            starts = [start for start in candidates if barrier.reachable(start)]
        difference = np.abs(starts[0] - starts[1]).max() if len(starts) == 2 else 0.0
    if not starts:
        carried = barrier.carried_by_faces(x_n, old_faces, new_faces)
        if carried is None or not barrier.exactly_reachable(carried):
            raise NewtonFailure('no collision-free start for the barrier step', [])
        starts = [carried]
    if len(starts) == 1 or difference < resolution:
        return starts[0], None
    return starts[0], starts[1].ravel()


def barrier_step(solver, barrier: BarrierContact, x_n: np.ndarray, v_n: np.ndarray,
                 old_faces: list, new_faces: list, dt: float,
                 v_predicted: np.ndarray | None = None) -> StepOutcome:
    """One implicit step of ``dt`` (s) from (x_n, v_n) (n, d) with the barrier model: one
    Newton solve of the incremental potential with the barrier among its energies (the
    solver holds ``barrier``), no contact passes. The predicted start (``_begin``) is
    x_n + dt ``v_predicted`` (n, d) m/s, given where the jaws hold the fruit (in 2D,
    else x_n + dt v_n; in 3D, else none); it sets only where Newton starts.

    Raises:
        NewtonFailure: no feasible start or no convergence (the caller halves the step).
    """
    n, d = x_n.shape
    start, alternative = _begin(barrier, x_n, v_n, old_faces, new_faces, dt,
                                solver.tolerance * dt, v_predicted)
    solution = solver.solve(x_n.ravel(), v_n.ravel(), dt, start.ravel(), _free(n, d),
                            alternative)
    v, forces, contacts = barrier.step_outputs(solution.q, x_n, dt, new_faces,
                                               solution.reaction)
    return StepOutcome(solution.q.reshape(-1, d), v, forces, contacts, solution.iterations)


#: the last ``_free`` constraints: ((n, d), them), or None
_kept_free: tuple | None = None


def _free(n: int, d: int) -> StepConstraints:
    """The constraints of a step of n free nodes in d dimensions (identity filters), kept
    for the same (n, d): a barrier step's are the same every step and nothing writes
    them (writable, unlike ``_prescribed``'s: the interpreted solves' kernels are
    compiled for writable filters)."""
    global _kept_free
    if _kept_free is None or _kept_free[0] != (n, d):
        _kept_free = ((n, d), StepConstraints.free(n, dim=d))
    return _kept_free[1]


#: the last ``_prescribed`` answer: ((n, d, the fixed nodes' array), (the constraints,
#: the fixed nodes' dofs)), or None
_kept_constraints: tuple | None = None


class NoCollisionFreeStart(NewtonFailure):
    """A soft-body step found no start whose way from the step's start crosses nothing
    (``soft_body_step``; the caller halves the step)."""

    def __init__(self):
        super().__init__("no collision-free start for the soft bodies' step", [])


def _carried_start(barrier: BarrierContact, x_n: np.ndarray, pushed: np.ndarray,
                   carried: list, reach: float | None = None) -> np.ndarray:
    """(n, d) m, ``pushed`` with each soft body's nodes and the fruit's outline nodes
    near it at ``x_n`` moved by its base's shift (``soft_body_step``): those within dhat
    of it (``partners``), or with ``reach`` (m) those within ``reach`` of its outline's
    vertices and nearer it than any other body's."""
    start = pushed.copy()
    fruit = barrier.vertex_nodes[barrier.vertex_body == 0]
    if reach is None:
        partner = barrier.partners(x_n.ravel())
        owner = partner[fruit]
    else:
        apart = np.array([cKDTree(x_n[barrier.vertex_nodes[barrier.vertex_body == 1 + b]])
                          .query(x_n[fruit])[0] for b in range(len(carried))])
        owner = np.where(apart.min(axis=0) <= reach, 1 + apart.argmin(axis=0), -1)
    for body, (nodes, shift) in enumerate(carried):
        start[nodes] = x_n[nodes] + shift
        touching = fruit[owner == 1 + body]
        start[touching] = x_n[touching] + shift
    return start


def _carried_starts(barrier: BarrierContact, x_n: np.ndarray, pushed: np.ndarray,
                    carried: Callable[[], list] | None,
                    reachable: Callable[[np.ndarray], bool]) -> np.ndarray:
    """The first ``reachable`` of the carried starts (``_carried_start``): the fruit's
    nodes within dhat of a soft body carried with it, else those within
    ``CARRY_REACH_EDGES`` of the collision mesh's longest edges of it (a fruit edge whose
    ends lie closer to a finger than its move may cross it unless both are carried).

    Raises:
        NoCollisionFreeStart: neither is (or no ``carried``).
    """
    if carried is not None:
        moves = carried()
        for reach in (None, CARRY_REACH_EDGES * barrier.longest_edge(x_n)):
            start = _carried_start(barrier, x_n, pushed, moves, reach)
            if reachable(start):
                return start
    raise NoCollisionFreeStart()


def _prescribed(n: int, d: int, fixed: np.ndarray) -> tuple[StepConstraints, np.ndarray]:
    """(the constraints of a step of n nodes in d dimensions with nodes ``fixed`` (k,)
    prescribed (zero filters), the rest free, the fixed nodes' dofs (k d,)); read only,
    kept for the same fixed array (a soft body step's are the same every step)."""
    global _kept_constraints
    kept = _kept_constraints
    if kept is None or kept[0][:2] != (n, d) or kept[0][2] is not fixed:
        constraints = StepConstraints.free(n, dim=d)
        constraints.filters[fixed] = 0.0
        constraints.filters.flags.writeable = False
        dofs = element_dofs(fixed[:, None], d).ravel()
        dofs.flags.writeable = False
        kept = _kept_constraints = ((n, d, fixed), (constraints, dofs))
    return kept[1]


def soft_body_step(solver, barrier: BarrierContact, x_n: np.ndarray, v_n: np.ndarray,
                   fixed: np.ndarray, fixed_targets: np.ndarray, old_faces: list,
                   new_faces: list, dt: float,
                   self_contact: BarrierContact | None = None,
                   carried: Callable[[], list] | None = None,
                   v_predicted: np.ndarray | None = None) -> StepOutcome:
    """One implicit step of ``dt`` (s) from (x_n, v_n) (n, d) of the fruit and the soft
    bodies in the barrier (``barrier.bodies``), nodes ``fixed`` (k,) prescribed at
    ``fixed_targets`` (k, d) m (a finger's base on its jaw: zero filters, the modified
    mass method), the faces moving from ``old_faces`` to ``new_faces``; with the soft
    bodies' ``self_contact`` barrier (among the solver's energies too) if given.

    The Newton solve starts from the predictor x_n + dt v (v: ``v_predicted`` (n, d) m/s
    where given, else v_n) if the way there crosses nothing, else from x_n (each with
    the fixed nodes at their targets and the outline pushed ahead of moving faces,
    ``pushed_starts``), else, with ``carried`` (a function giving per soft body in
    ``barrier.bodies`` order (its nodes (k,), the shift (d,) m its base makes in the
    step); called only then), from x_n with each soft body moved by its base's shift and
    the fruit's nodes near it moved along with it (within dhat, else within
    ``CARRY_REACH_EDGES`` longest edges: ``_carried_starts``): where a fruit pressed hard
    on a finger lies closer to it than the base's move, moving the base alone would
    cross the fruit.

    Returns:
        The outcome; ``forces`` (n, d) N the barrier's and friction's force on every node
        (both bodies of a pair), ``reaction`` (n, d) N the force holding each fixed node
        at its target (0 elsewhere), ``contacts.obstacle`` (n,) the body each outline node
        touches as ``partners`` numbers them (0 the fruit, 1 + b soft body b, then the
        faces; -1 none).

    Raises:
        NewtonFailure: no convergence, or ``NoCollisionFreeStart`` (the caller halves
            the step).
    """
    n, d = x_n.shape
    v = v_n if v_predicted is None else v_predicted
    set_up = None
    if d == 2:
        set_up = barrier.begin_soft_step(x_n, v, old_faces, new_faces, dt, fixed,
                                         fixed_targets, self_contact)
    if set_up is not None:
        pushed, start, clear, pushed_clear, chosen = set_up
    else:
        chosen = False
        if d == 2:
            pushed, start, clear, pushed_clear, _ = barrier.set_up_starts(
                x_n, v, old_faces, new_faces, dt, fixed, fixed_targets, False)
        else:
            barrier.begin_step(x_n, old_faces, new_faces, dt)
            pushed, start = barrier.pushed_starts(x_n, old_faces, new_faces, x_n + dt * v)
            clear = pushed_clear = None
        if self_contact is not None:
            self_contact.begin_step(x_n, _NO_FACES, _NO_FACES, dt)

    def reachable(start: np.ndarray, compiled_clear: bool | None = None) -> bool:
        """Whether the way to ``start`` (its fixed nodes set here, or by the compiled
        set-up (2D), which made the barrier's check if ``compiled_clear`` is given)
        crosses nothing."""
        if compiled_clear is None:
            start[fixed] = fixed_targets
            crosses_nothing = barrier.reachable(start)
        else:
            crosses_nothing = compiled_clear or barrier.exactly_reachable(start)
        return crosses_nothing and (self_contact is None or self_contact.reachable(start))

    if not chosen and not reachable(start, clear):
        start = pushed  # its own array
        # the predictor's way may be clear of the fruit and not of the self-contact: then
        # x_n's was not checked (the compiled call checks it only where the predictor's
        # is not clear)
        if not reachable(start, pushed_clear if not clear else None):
            start = _carried_starts(barrier, x_n, pushed, carried, reachable)
    constraints, fixed_dofs = _prescribed(n, d, fixed)
    solution = solver.solve(x_n.ravel(), v_n.ravel(), dt, start.ravel(), constraints)
    if d == 2:
        velocities, reaction, partner, forces = barrier.soft_outputs(
            solution.q, x_n, dt, solution.reaction, fixed_dofs)
        return StepOutcome(solution.q.reshape(-1, 2), velocities, forces,
                           cm.ContactState.held_by(partner), solution.iterations, reaction)
    x = solution.q.reshape(-1, d)
    reaction = np.zeros(n * d)
    reaction[fixed_dofs] = solution.reaction[fixed_dofs]
    reaction = reaction.reshape(n, d)
    contacts = cm.ContactState.held_by(barrier.partners(solution.q))
    return StepOutcome(x, (x - x_n) / dt, barrier.contact_forces(solution.q), contacts,
                       solution.iterations, reaction)
