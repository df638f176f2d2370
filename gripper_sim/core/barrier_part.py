"""A 2D barrier's step state and its compiled evaluation, candidates and step bound: the
one implementation ``BarrierContact`` (2D) calls from Python and the compiled Newton
problem (``core.barrier_newton``) calls compiled.

``BarrierPart`` (a numba StructRef, one per 2D ``BarrierContact``, made with its
collision mesh) holds the barrier's fixed arrays and settings and the state of a step
(``set_step``, from ``BarrierContact.begin_step``): the faces' corners, the collision
mesh's start, the kept candidates and where they were sought, the lagged friction, the
quiet region of a self-contact; and what its evaluations keep: the candidates sought
again, the last evaluation (positions, values; its gradients in the barrier's buffers).

- ``quiet``: a self-contact with every vertex within its quiet region's reach
  (``barrier_kernels.relative_moves_within``);
- ``candidates``: the kept (edge, vertex) candidates, sought again
  (``barrier_search.edge_vertex_candidates``, boxes inflated by dhat / 2 + the margin)
  once a vertex moved further than the margin from where they were sought;
- ``barrier_value``: the barrier and lagged friction (``barrier_terms.barrier_terms``)
  over those candidates, gradients added, the Hessian into the solver's CSC values;
- ``kept_forces``: the last evaluation's forces, read at the positions it was made at;
- ``partners``: the body each outline node's nearest pair within dhat touches;
- ``start_clear``: whether the way to a start of the Newton solve is clear
  (``barrier_search.paths_clear``) over the kept candidates, else the swept boxes';
- ``max_step``: the CCD's step bound: ``barrier_kernels.kept_step_bound`` on the kept
  candidates, else the swept boxes' candidates and ``barrier_search.collision_free_step``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, types
from numba.experimental import structref

from gripper_sim.core.barrier_kernels import (balance_forces, kept_step_bound, largest_move,
                                              mark_sticking, mesh_vertices, nearest_faces,
                                              nearest_partners, normal_components,
                                              push_ahead, relative_moves_within,
                                              same_values)
from gripper_sim.core.barrier_search import (collision_free_step, edge_vertex_candidates,
                                             paths_clear)
from gripper_sim.core.barrier_terms import barrier_terms
from gripper_sim.core.friction_kernels import lagged_friction

#: a part's flags (int64 array): its candidates (-1: none kept, 0: sought at the step's
#: start (the faces' corners where they start), 1: sought since (where they end)), its
#: Hessian entries outside the pattern (an error, or left out with ``drop_outside``; the
#: reader clears it), its last finite evaluation (0: none this step, 1: no pairs, 2:
#: terms)
B_PAIRS, B_OUTSIDE, B_TERMS, B_SIZE = range(4)


@structref.register
class BarrierPartType(types.StructRef):
    """The numba type of ``BarrierPart``."""

    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


#: a part's fields: the barrier's fixed arrays and settings (``BarrierContact.part_fields``:
#: vertex dof pairs (n_v, 2), the mesh's edges and groups, self-contact, dhat m, kappa,
#: the mesh's dofs, whether to project the Hessian, the pattern's keys, eps_v m/s, the
#: candidate radius m, the swept radius m, the candidate margin m, the gradient buffers
#: (n_d,), whether entries outside the pattern are dropped, each vertex's body, the
#: bodies' count, the pattern's CSC slots (p,)), then a step's (``set_step``): the faces'
#: corners (c k, 2) m, the collision mesh's start (n_m, 2) m, the candidates' anchor
#: (n_v, 2) m and the candidates (k, 2), the lagged friction, the quiet region's anchor
#: and reach m (self-contact), the flags (``B_*``), the last evaluation's positions
#: (d n,) m and (barrier, friction) values J
PART_FIELDS = ('dof_pairs', 'edges', 'groups', 'self_contact', 'dhat', 'kappa',
               'mesh_dofs', 'project', 'pattern_keys', 'eps_v', 'radius', 'swept_radius',
               'margin', 'barrier_gradient', 'friction_gradient', 'drop_outside',
               'vertex_body', 'n_bodies', 'slots',
               'corners', 'start', 'anchor', 'pairs', 'friction_pairs', 'has_friction',
               'quiet_anchor', 'quiet_reach', 'has_quiet', 'flags', 'last_q', 'last_values')


class BarrierPart(structref.StructRefProxy):
    """One 2D barrier's arrays and step state (``PART_FIELDS``), made by ``new_part``."""


structref.define_proxy(BarrierPart, BarrierPartType, list(PART_FIELDS))


@njit(cache=True)
def quiet(part, q, dq):
    """Whether the part is a self-contact within its quiet region at positions q (2 n,)
    m (and q + dq if dq (2 n,) m is not empty): no pair within dhat for certain."""
    if not part.has_quiet:
        return False
    return relative_moves_within(q, dq, part.dof_pairs, part.quiet_anchor, part.vertex_body,
                                 part.n_bodies, part.quiet_reach)


@njit(cache=True)
def candidates(part, q):
    """The (edge, vertex) candidates (k, 2) holding every pair closer than dhat at
    positions q (2 n,) m: the kept ones, sought again (boxes inflated by the candidate
    radius) once a vertex moved further than the margin from where they were sought
    (each side of a pair moved by at most the margin: the pair came at most twice it
    closer; the faces' corners stand still within a step)."""
    flags = part.flags
    if flags[B_PAIRS] < 0 or largest_move(q, part.dof_pairs, part.anchor) > part.margin:
        v = np.empty((part.dof_pairs.shape[0] + part.corners.shape[0], 2))
        mesh_vertices(q, part.dof_pairs, part.corners, v)
        part.pairs = edge_vertex_candidates(v, v, part.edges, part.groups, part.self_contact,
                                            part.radius)
        part.anchor[:] = v[:part.dof_pairs.shape[0]]
        flags[B_PAIRS] = 1
    return part.pairs


@njit(cache=True)
def barrier_value(part, x, hessian, grad, hdata, slots, dt, friction):
    """The barrier plus (with ``friction``) the lagged friction at positions x (2 n,) m
    over ``candidates``: value J (inf: a pair touches; nothing kept), the gradients
    added into grad (2 n,) N, with ``hessian`` the Hessians (the friction's with
    ``friction``) into hdata at the pattern keys' ``slots`` (p,). An entry outside the
    pattern (dropped with ``drop_outside``) sets the flag ``B_OUTSIDE``. Kept: x, the
    values, the gradients in the part's buffers (``B_TERMS``)."""
    if quiet(part, x, np.zeros(0)):
        return 0.0
    flags = part.flags
    pairs = candidates(part, x)
    if pairs.shape[0] or part.has_friction:
        barrier, friction_value, outside, friction_outside = barrier_terms(
            x, part.dof_pairs, part.corners, part.edges, pairs, part.dhat, part.kappa,
            part.mesh_dofs, hessian, part.project, part.pattern_keys, slots, hdata,
            part.start, dt, part.eps_v, part.friction_pairs, part.has_friction,
            hessian and friction, part.barrier_gradient, part.friction_gradient, grad,
            friction)
        if not math.isfinite(barrier):
            return np.inf
        if outside or friction_outside:
            flags[B_OUTSIDE] = 1
        flags[B_TERMS] = 2
    else:
        barrier = friction_value = 0.0
        flags[B_TERMS] = 1
    part.last_q[:] = x
    part.last_values[0] = barrier
    part.last_values[1] = friction_value
    return barrier + friction_value if friction else barrier


@njit(cache=True)
def kept_forces(part, q, friction, forces):
    """Whether the barrier's forces at positions q (2 n,) m are known without an
    evaluation (a quiet self-contact, or the last evaluation made at q); then sets
    ``forces`` (2 n,) N to minus the gradient of the barrier plus (with ``friction``) the
    lagged friction, as ``BarrierContact._terms`` adds them into zeros (minus zero where
    no vertex is)."""
    terms = part.flags[B_TERMS]
    if not quiet(part, q, np.zeros(0)) and (terms == 0 or not same_values(part.last_q, q)):
        return False
    forces[:] = -0.0
    if terms != 2 or quiet(part, q, np.zeros(0)):
        return True
    with_friction = friction and part.has_friction
    dof_pairs = part.dof_pairs
    for i in range(dof_pairs.shape[0]):
        for c in range(2):
            k = 2 * i + c
            gradient = 0.0 + part.barrier_gradient[k]
            if with_friction:
                gradient += part.friction_gradient[k]
            forces[dof_pairs[i, c]] = -gradient
    return True


@njit(cache=True)
def partners(part, q, vertex_nodes, owner, partner):
    """``barrier_kernels.nearest_partners`` at positions q (2 n,) m over ``candidates``,
    the faces' corners where they end: sets ``partner`` (n,) (``owner`` (n_m,) the body
    of each collision-mesh vertex, the deformable ones at ``vertex_nodes`` (n_v,))."""
    v = np.empty((part.dof_pairs.shape[0] + part.corners.shape[0], 2))
    mesh_vertices(q, part.dof_pairs, part.corners, v)
    nearest_partners(v, part.edges, candidates(part, q), part.dhat, vertex_nodes, owner,
                     partner)


@njit(cache=True)
def start_clear(part, q0, q1, faces_shift):
    """Whether ``barrier_search.paths_clear`` finds the straight motion from the step's
    start (positions q0 (2 n,) m, the faces' corners where they start: ``start``) to
    positions q1 (2 n,) m (the faces' corners where they end), whose corners move at most
    ``faces_shift`` m, free of crossings, every pair ending apart, for certain. Over the
    kept candidates if they hold every pair that comes within dhat along it: both ends
    within the margin of where they were sought (so is every point between), and the
    corners too (those of the start's candidates stand where the faces start, those
    sought since where they end); else over the candidates of the swept boxes."""
    v0 = part.start
    v1 = np.empty_like(v0)
    mesh_vertices(q1, part.dof_pairs, part.corners, v1)
    flags = part.flags
    if (flags[B_PAIRS] >= 0 and (flags[B_PAIRS] == 0 or faces_shift <= part.margin)
            and largest_move(q0, part.dof_pairs, part.anchor) <= part.margin
            and largest_move(q1, part.dof_pairs, part.anchor) <= part.margin):
        pairs = part.pairs
    else:
        pairs = edge_vertex_candidates(v0, v1, part.edges, part.groups, part.self_contact,
                                       part.swept_radius)
    return paths_clear(v0, v1, part.edges, pairs)


@njit(cache=True)
def begin_with_starts(part, x_n, v_n, dt, old_corners, new_corners, rubbing, mu_s, mu_k,
                      surface, origins, normals, tangents, half_extents, thickness, shifts,
                      fraction, fixed, targets, both):
    """A step of a barrier that is not a self-contact set up and its two starts made and
    checked in one call: what ``BarrierContact.begin_step``, ``pushed_starts`` with the
    predictor and ``reachable``'s compiled check of each start do one by one, in their
    order and arithmetic.

    Args:
        x_n, v_n: (n, 2) m, m/s at the step's start.  dt: s.
        old_corners, new_corners: (c k, 2) m, the faces' corners where they start and end.
        rubbing, mu_s, mu_k: as ``set_step``'s.
        surface, origins ... shifts, fraction: as ``barrier_kernels.push_ahead``'s (the
            faces where they start, and their shifts in the step).
        fixed: (k,) nodes prescribed at ``targets`` (k, 2) m in both starts (a soft
            body's base; may be empty).  both: check the way to x_n's start too (else
            only if the predictor's is not clear).

    Returns:
        (whether there is lagged friction, the collision mesh's start (n_m, 2) m, the
        largest corner shift m, the start x_n pushed (n, 2) m, the predictor x_n + dt v_n
        pushed (n, 2) m, whether ``start_clear`` clears the way to the predictor's, to
        x_n's (False where not checked), the largest coordinate difference between them m).
    """
    start_q = x_n.ravel()
    start = np.empty((part.dof_pairs.shape[0] + old_corners.shape[0], 2))
    mesh_vertices(start_q, part.dof_pairs, old_corners, start)
    faces_shift = 0.0  # no faces where the step starts (as ``BarrierContact._begin_part``)
    if old_corners.shape[0]:
        k = new_corners.shape[0]
        faces_shift = largest_move(new_corners.ravel(), np.arange(2 * k).reshape((k, 2)),
                                   old_corners)
    has_friction = set_step(part, new_corners, start, rubbing, faces_shift <= part.margin,
                            mu_s, mu_k, np.zeros((0, 2)), 0.0, False)
    plain = x_n.copy()
    predicted = np.empty_like(x_n)
    for i in range(x_n.shape[0]):
        for c in range(2):
            predicted[i, c] = x_n[i, c] + dt * v_n[i, c]
    push_ahead(x_n, surface, origins, normals, tangents, half_extents, thickness, shifts,
               part.dhat, fraction, plain, predicted)
    for j in range(fixed.shape[0]):
        for c in range(2):
            predicted[fixed[j], c] = plain[fixed[j], c] = targets[j, c]
    predicted_clear = start_clear(part, start_q, predicted.ravel(), faces_shift)
    plain_clear = False
    if both or not predicted_clear:
        plain_clear = start_clear(part, start_q, plain.ravel(), faces_shift)
    difference = 0.0
    for i in range(x_n.shape[0]):
        for c in range(2):
            difference = max(difference, abs(predicted[i, c] - plain[i, c]))
    return (has_friction, start, faces_shift, plain, predicted, predicted_clear,
            plain_clear, difference)


@njit(cache=True)
def step_outputs(part, q, x_n, dt, residual, origins, normals, tangents, half_extents,
                 velocities, smoothing, stick, slip, forces, v, holder, normal_force, mode):
    """A barrier step's outputs at its solution q (2 n,) m against rigid faces, in one call:
    what ``BarrierContact.contact_forces`` and ``held_contacts`` compute one by one, in
    their arithmetic, where the last evaluation was made at q (``kept_forces``); False
    (nothing written but ``forces``) where it was not.

    Args:
        x_n: (n, 2) m at the step's start.  dt: s.
        residual: (2 n,) N, the potential's gradient at q (``balance_forces``).
        origins, normals, tangents, half_extents, velocities: the faces at the step's
            end (``barrier_kernels.nearest_faces``' and ``mark_sticking``'s).
        smoothing: m/s, the friction smoothing speed.  stick, slip: the mode codes.
        forces: (2 n,) N, the barrier's and friction's force on each node, balanced
            (written; where False, not balanced).
        v: (n, 2) m/s, (x - x_n) / dt (written).
        holder: (n,) the face holding each node, -1 none (written); normal_force: (n,) N
            along its normal, mode: (n,) stick or slip, where held (zeros on entry).
    """
    if not kept_forces(part, q, True, forces):
        return False
    x = q.reshape(x_n.shape)
    on_nodes = forces.reshape(x_n.shape)
    balance_forces(on_nodes, residual.reshape(x_n.shape))
    for i in range(x_n.shape[0]):
        for c in range(2):
            v[i, c] = (x[i, c] - x_n[i, c]) / dt
    nearest_faces(x, on_nodes, origins, normals, tangents, half_extents, part.dhat, holder)
    normal_components(holder, on_nodes, normals, normal_force)
    mark_sticking(v, holder, normals, velocities, smoothing, stick, slip, mode)
    return True


@njit(cache=True)
def max_step(part, x, dq):
    """The CCD's largest fraction (0, 1] of the step dq (2 n,) m from x free of
    crossings (conservative: each pair keeps ``barrier_search.SEPARATION`` of its gap):
    on the kept candidates when both ends lie within the margin of where they were
    sought (``kept_step_bound``), else on the candidates of the boxes the vertices
    sweep (inflated by the swept radius)."""
    if quiet(part, x, dq):
        return 1.0
    bound = -1.0
    if part.flags[B_PAIRS] >= 0:
        bound = kept_step_bound(x, dq, part.dof_pairs, part.corners, part.edges, part.anchor,
                                part.pairs, part.margin)
    if bound >= 0.0:
        return bound
    n_m = part.dof_pairs.shape[0] + part.corners.shape[0]
    v0, v1 = np.empty((n_m, 2)), np.empty((n_m, 2))
    mesh_vertices(x, part.dof_pairs, part.corners, v0)
    mesh_vertices(x + dq, part.dof_pairs, part.corners, v1)
    swept = edge_vertex_candidates(v0, v1, part.edges, part.groups, part.self_contact,
                                   part.swept_radius)
    return collision_free_step(v0, v1, part.edges, swept)


@njit(cache=True)
def new_part(fields):
    """A ``BarrierPart`` of the fields' tuple (``PART_FIELDS``)."""
    return BarrierPart(*fields)


@njit(cache=True)
def set_slots(part, slots):
    """The pattern keys' CSC slots (p,) of the solver the part's Hessian goes to."""
    part.slots = slots


@njit(cache=True)
def set_pattern(part, pattern_keys):
    """The sorted keys (p,) of the barrier's Hessian pattern (its slots set anew after:
    ``set_slots``)."""
    part.pattern_keys = pattern_keys


@njit(cache=True)
def set_project(part, project):
    """Whether each pair's Hessian is made positive semi-definite (clamped)."""
    part.project = project


@njit(cache=True)
def set_step(part, corners, start, rubbing, keep, mu_s, mu_k, quiet_anchor, quiet_reach,
             has_quiet):
    """A step's state (``PART_FIELDS``), no evaluation kept: the faces' corners where
    they end (c k, 2) m, the collision mesh's start (n_m, 2) m (C order; the faces'
    corners where they start); with ``rubbing`` (a friction coefficient is positive)
    the candidates at the start (``edge_vertex_candidates``, boxes inflated by the
    candidate radius: every pair within dhat), kept if ``keep`` (no corner moves further
    than the margin in the step), and the lagged friction of those within dhat
    (``friction_kernels.lagged_friction``, each vertex's coefficients ``mu_s``, ``mu_k``
    (n_m,)); a self-contact's quiet region (anchor (n_v, 2) m, reach m) if
    ``has_quiet``. Returns whether there is lagged friction."""
    part.corners = corners
    part.start = start
    pairs = np.zeros((0, 2), np.int64)
    has_pairs = has_friction = False
    ids, weights = np.zeros((0, 3), np.int64), np.zeros((0, 3))
    tangents, forces, coefficients = np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2))
    if rubbing:
        found = edge_vertex_candidates(start, start, part.edges, part.groups,
                                       part.self_contact, part.radius)
        k = found.shape[0]
        if k:
            all_ids, all_weights = np.empty((k, 3), np.int64), np.empty((k, 3))
            all_tangents, all_forces, all_coefficients = (np.empty((k, 2)), np.empty(k),
                                                          np.empty((k, 2)))
            count = lagged_friction(start, part.edges, found, part.dhat, part.kappa, mu_s,
                                    mu_k, all_ids, all_weights, all_tangents, all_forces,
                                    all_coefficients)
            if count:
                has_friction = True
                ids, weights = all_ids[:count].copy(), all_weights[:count].copy()
                tangents, forces = all_tangents[:count].copy(), all_forces[:count].copy()
                coefficients = all_coefficients[:count].copy()
        if keep:
            has_pairs = True
            pairs = found
            part.anchor[:] = start[:part.dof_pairs.shape[0]]
    part.pairs = pairs
    part.friction_pairs = (ids, weights, tangents, forces, coefficients)
    part.has_friction = has_friction
    part.quiet_anchor = quiet_anchor
    part.quiet_reach = quiet_reach
    part.has_quiet = has_quiet
    part.flags[:] = 0
    part.flags[B_PAIRS] = 0 if has_pairs else -1
    return has_friction


@njit(cache=True)
def shared_arrays(part):
    """The part's arrays Python reads: flags, the last evaluation's positions and
    values, the candidates' anchor."""
    return part.flags, part.last_q, part.last_values, part.anchor
