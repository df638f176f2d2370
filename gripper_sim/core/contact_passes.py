"""One implicit step with contact: the predictor-corrector passes, for 2D and 3D.

The modified mass method (Baraff & Witkin 1998) around the Newton solve of the implicit
Euler step (``core.stepper``): each pass prescribes the held nodes (z targets: a stuck
node moves with its obstacle, a sliding one and an IMPACT node keep their normal gap;
the S filter frees the rest), solves, and corrects the contact set
(``core.contact``): pulling nodes are released, stuck nodes whose tangential reaction
leaves the Coulomb cone |R_t| <= mu_s R_n slip, slipping nodes that stopped stick, a
held node pushed into a second face gets it as a frictionless secondary hold (a
corner), free surface nodes found inside a face are added (with restitution if they
arrive fast, at the first face and at the second of a corner alike: a node that hits a
floor and a wall in one step rebounds from both). The passes end when the set no longer
changes.

Restitution never adds energy: the outgoing velocity of a node that rebounds is capped so
that its kinetic energy after the step is at most its kinetic energy before plus the work
the fruit's forces (elastic, gravity, damping) did on it during the step. Backward Euler
with the obstacles' reactions R gives E_end - E_start <= sum R . dx (convex energies);
replacing a node's velocity dx / dt by v_out changes that node's part to
m |v_out|^2 / 2 - m |v_start|^2 / 2 - F . dx with F = m (dx / dt - v_start) / dt - R
the other forces on it, so with the cap no rebound raises the total energy.

Dimension is a parameter, not a copy: positions are (n, d), faces (``FlatFace`` in 2D,
``Plate`` in 3D) have a unit ``normal`` (d,) and ``tangents`` (d - 1, d), and kinetic
friction is the smoothed Coulomb cone of the stepper in the tangent space (one tangent
in 2D).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core import contact as cm
from gripper_sim.core.stepper import FRICTION_SMOOTHING, StepConstraints


@dataclass(frozen=True)
class ContactSettings:
    """Attributes:
        max_passes: predictor-corrector passes per step.
        max_correction_speed: m/s, fastest rate at which a penetration is undone.
        release_threshold: N, a held node is released when its normal reaction pulls
            by more than this.
        gravity: m/s^2, sets the slowest approach that bounces (5 g dt, at least 1 mm/s).
        deepest_first: a pass adds, of the free nodes inside a face, those at least this
            fraction of the deepest one's depth (0: all of them).
    """

    max_passes: int
    max_correction_speed: float
    release_threshold: float
    gravity: float
    deepest_first: float = 0.0

    @classmethod
    def from_config(cls, config, deepest_first: float = 0.0) -> 'ContactSettings':
        return cls(int(config['sim.max_contact_passes']),
                   float(config['contact.max_correction_speed']),
                   float(config['contact.release_threshold']), float(config['world.gravity']),
                   deepest_first)


@dataclass
class StepOutcome:
    """Attributes:
        x: (n, d) m, end positions.  v: (n, d) m/s, end velocities (held nodes with their
        obstacle's normal speed, stuck ones with its tangential speed too).
        forces: (n, d) N, the obstacles' reactions on the held nodes.
        contacts: the contact set at the end of the step.  iterations: Newton iterations.
        reaction: (n, d) N, the forces holding prescribed nodes (a soft finger's base,
        ``barrier.soft_body_step``), None where no node is prescribed.
    """

    x: np.ndarray
    v: np.ndarray
    forces: np.ndarray
    contacts: cm.ContactState
    iterations: int
    reaction: np.ndarray | None = None


def contact_step(solver, surface: np.ndarray, contacts: cm.ContactState, x_n: np.ndarray,
                 v_n: np.ndarray, old_faces: list, new_faces: list, dt: float,
                 settings: ContactSettings) -> StepOutcome:
    """One implicit step of ``dt`` from (x_n, v_n) (n, d) with the faces moving from
    ``old_faces`` to ``new_faces``; ``contacts`` is not modified.

    Raises:
        NewtonFailure: from the solver (the caller halves the step).
    """
    n, d = x_n.shape
    q_n = x_n.ravel()
    x_pred = x_n + dt * v_n
    contacts = contacts.copy()
    released = np.zeros(n, bool)
    slipped = np.zeros(n, bool)
    iterations = 0
    for _ in range(settings.max_passes):
        q_start, constraints = _constraints(contacts, x_n, x_pred, old_faces, new_faces, dt,
                                            settings)
        solution = solver.solve(q_n, v_n.ravel(), dt, q_start.ravel(), constraints)
        iterations += solution.iterations
        x = solution.q.reshape(-1, d)
        reaction = solution.reaction.reshape(-1, d)
        if not _update_contacts(contacts, x, x_n, v_n, reaction, old_faces, new_faces, dt,
                                released, slipped, surface, settings):
            break
    v = (x - x_n) / dt
    forces = np.zeros((n, d))
    rebound = np.zeros((n, d))  # (n, d) m/s, the restitution part of each velocity
    for _, face, nodes in _held_by_face(contacts, new_faces):
        nrm = face.normal
        stuck = contacts.mode[nodes] == cm.STICK
        v_t = v[nodes] - np.outer(v[nodes] @ nrm, nrm)
        v_t[stuck] = face.velocity - (face.velocity @ nrm) * nrm
        v_n_new = face.velocity @ nrm + contacts.bounce_speed[nodes]
        v[nodes] = v_t + v_n_new[:, None] * nrm
        rebound[nodes] += contacts.bounce_speed[nodes][:, None] * nrm
        forces[nodes] = reaction[nodes]
    for node in np.flatnonzero(contacts.secondary >= 0):
        face = new_faces[contacts.secondary[node]]
        bounce = contacts.secondary_bounce[node]
        v[node] += (face.velocity @ face.normal + bounce - v[node] @ face.normal) * face.normal
        rebound[node] += bounce * face.normal
    bouncing = np.flatnonzero(np.any(rebound != 0.0, axis=1))
    if bouncing.size:
        masses = solver.m[::d]
        v[bouncing] = capped_rebound(v[bouncing], rebound[bouncing], v_n[bouncing],
                                     x[bouncing] - x_n[bouncing], reaction[bouncing],
                                     masses[bouncing], dt)
    contacts.release(np.flatnonzero(contacts.mode == cm.IMPACT))
    contacts.release_secondary(np.flatnonzero(contacts.secondary_bounce > 0))
    return StepOutcome(x, v, forces, contacts, iterations)


def capped_rebound(v: np.ndarray, rebound: np.ndarray, v_start: np.ndarray, dx: np.ndarray,
                   reaction: np.ndarray, masses: np.ndarray, dt: float) -> np.ndarray:
    """The end velocities (k, d) m/s of k rebounding nodes with their rebound scaled down
    (by one factor s in [0, 1] per node) where it would add energy (see the module doc):
    |v - (1 - s) rebound|^2 <= |v_start|^2 + 2 F . dx / m.

    Args:
        v: (k, d) m/s, end velocities with the full rebound.  rebound: (k, d) m/s, its
        restitution part.  v_start: (k, d) m/s, velocities at the start of the step.
        dx: (k, d) m, displacements over the step.  reaction: (k, d) N, the obstacles'
        reactions.  masses: (k,) kg.
    """
    others = masses[:, None] * (dx / dt - v_start) / dt - reaction  # (k, d) N
    budget = (np.sum(v_start * v_start, axis=1)
              + 2.0 * np.sum(others * dx, axis=1) / masses)  # (m/s)^2
    base = v - rebound
    # |base + s rebound|^2 = bb + 2 s br + s^2 rr <= budget: the largest s in [0, 1]
    bb = np.sum(base * base, axis=1)
    br = np.sum(base * rebound, axis=1)
    rr = np.sum(rebound * rebound, axis=1)
    discriminant = br * br - rr * (bb - budget)
    with np.errstate(divide='ignore', invalid='ignore'):
        root = (-br + np.sqrt(np.maximum(discriminant, 0.0))) / rr
    scale = np.where((bb + 2.0 * br + rr <= budget) | (rr == 0.0), 1.0,
                     np.where(discriminant >= 0.0, np.clip(root, 0.0, 1.0), 0.0))
    return base + scale[:, None] * rebound


def _held_by_face(contacts: cm.ContactState, faces: list):
    """(index, face, the nodes (k,) it holds) of every face that holds nodes."""
    for index, face in enumerate(faces):
        nodes = np.flatnonzero(contacts.obstacle == index)
        if nodes.size:
            yield index, face, nodes


def _constraints(contacts: cm.ContactState, x_n, x_pred, old_faces, new_faces, dt: float,
                 settings: ContactSettings):
    """Start positions (n, d) with held nodes at their targets, and the step filters."""
    n, d = x_n.shape
    start = x_pred.copy()
    filters = np.tile(np.eye(d), (n, 1, 1))
    fr_nodes, fr_tangents, fr_bounds, fr_speed = [], [], [], []
    v_corr = settings.max_correction_speed
    for index, face, nodes in _held_by_face(contacts, new_faces):
        nrm, tan = face.normal, face.tangents
        mode = contacts.mode[nodes]
        penetration = np.maximum(0.0, -old_faces[index].gap(x_n[nodes]))
        target = -np.maximum(0.0, penetration - v_corr * dt)
        start[nodes] += (target - face.gap(start[nodes]))[:, None] * nrm
        stuck = mode == cm.STICK
        if np.any(stuck):
            held = nodes[stuck]
            along = x_n[held] @ tan.T + dt * (tan @ face.velocity)  # (k, d - 1)
            start[held] += (along - start[held] @ tan.T) @ tan
            filters[held] = 0.0
        filters[nodes[~stuck]] = np.eye(d) - np.outer(nrm, nrm)
        sliding = nodes[mode == cm.SLIP]
        if sliding.size and face.kinetic_friction > 0:
            fr_nodes.append(sliding)
            fr_tangents.append(np.broadcast_to(tan, (sliding.size, d - 1, d)))
            fr_bounds.append(face.kinetic_friction * np.maximum(
                contacts.normal_force[sliding], 0.0))
            fr_speed.append(np.broadcast_to(tan @ face.velocity, (sliding.size, d - 1)))
    for node in np.flatnonzero(contacts.secondary >= 0):
        # the second face's normal gap, set by a move that keeps the first one's gap
        # (along u = P n, P the node's filter); the filter stays a symmetric projector,
        # now also orthogonal to n (in 2D: the node is held at the corner point; in 3D
        # at a V's edge: on the edge line)
        face = new_faces[contacts.secondary[node]]
        u = filters[node] @ face.normal
        uu = float(u @ u)
        if uu < 1e-12:
            continue
        start[node] += (0.0 - face.gap(start[node][None])[0]) / uu * u
        filters[node] = filters[node] - np.outer(u, u) / uu
    if fr_nodes:
        con = StepConstraints(filters, np.concatenate(fr_nodes), np.concatenate(fr_tangents),
                              np.concatenate(fr_bounds), np.concatenate(fr_speed))
    else:
        con = StepConstraints.free(n, dim=d)
        con.filters = filters
    return start, con


def _update_contacts(contacts: cm.ContactState, x, x_n, v_n, reaction, old_faces, new_faces,
                     dt, released, slipped, surface, settings: ContactSettings) -> bool:
    """Correct the contact set after a solve; True if it changed (solve again)."""
    changed = False
    threshold = settings.release_threshold
    for index, face, nodes in _held_by_face(contacts, new_faces):
        nrm, tan = face.normal, face.tangents
        r_n = reaction[nodes] @ nrm
        r_t = np.linalg.norm(reaction[nodes] @ tan.T, axis=1)
        mode = contacts.mode[nodes]
        pulling = (r_n < -threshold) & (mode != cm.IMPACT)
        if np.any(pulling):
            contacts.release(nodes[pulling])
            released[nodes[pulling]] = True
            changed = True
        keep = ~pulling
        stuck = keep & (mode == cm.STICK)
        to_slip = stuck & (r_t > face.static_friction * r_n)
        if np.any(to_slip):
            contacts.mode[nodes[to_slip]] = cm.SLIP
            slipped[nodes[to_slip]] = True
            changed = True
        sliding = keep & (mode == cm.SLIP)
        if np.any(sliding):
            rel = np.linalg.norm(((x[nodes] - x_n[nodes]) / dt - face.velocity) @ tan.T,
                                 axis=1)
            to_stick = (sliding & (rel < 2 * FRICTION_SMOOTHING)
                        & ~slipped[nodes] & (face.static_friction > 0))
            if np.any(to_stick):
                contacts.mode[nodes[to_stick]] = cm.STICK
                changed = True
            lag = contacts.normal_force[nodes]
            stale = sliding & ~to_stick & (np.abs(r_n - lag) > 0.02 * np.abs(lag) + 1e-9)
            if np.any(stale) and face.kinetic_friction > 0:
                changed = True
        contacts.normal_force[nodes[keep]] = r_n[keep]
    for node in np.flatnonzero((contacts.secondary >= 0) & (contacts.secondary_bounce <= 0)):
        face = new_faces[contacts.secondary[node]]
        if reaction[node] @ face.normal < -threshold:
            contacts.release_secondary(node)
            changed = True
    if _add_corners(contacts, x, x_n, v_n, old_faces, new_faces, dt, settings):
        changed = True
    if _add_penetrating(contacts, x, x_n, v_n, old_faces, new_faces, dt, released, surface,
                        settings):
        changed = True
    return changed


def _add_corners(contacts: cm.ContactState, x, x_n, v_n, old_faces, new_faces, dt,
                 settings: ContactSettings) -> bool:
    """Held nodes pushed into a second face (a corner) get it as a secondary hold, with
    a rebound from it if they arrive faster than the bounce threshold and it has
    restitution."""
    held = np.flatnonzero((contacts.obstacle >= 0) & (contacts.secondary < 0))
    added = False
    for index, face in enumerate(new_faces):
        nodes = held[contacts.obstacle[held] != index]
        if not nodes.size:
            continue
        inside = nodes[face.covers(x[nodes]) & (face.gap(x[nodes]) < 0)]
        if inside.size:
            contacts.secondary[inside] = index
            contacts.mode[inside[contacts.mode[inside] == cm.STICK]] = cm.SLIP
            contacts.secondary_bounce[inside] = _rebound_speeds(
                face, old_faces[index], x_n[inside], v_n[inside], x[inside], dt, settings)
            held = np.setdiff1d(held, inside)
            added = True
    return added


def _rebound_speeds(face, old_face, x_n, v_n, x, dt: float,
                    settings: ContactSettings) -> np.ndarray:
    """Outgoing normal speeds (k,) m/s, relative to ``face``, of k nodes found inside it
    (0: no rebound): a node rebounds if it met the face faster than 5 g dt (at least
    1 mm/s) and the face has restitution e; it leaves with e times its speed at the moment
    it met the face (linear in time between the start and the solve's end).

    Args:
        face, old_face: the face at the end and at the start of the step.
        x_n, v_n: (k, d) m and m/s at the start of the step.  x: (k, d) m, the solve's end.
    """
    if face.restitution <= 0:
        return np.zeros(len(x))
    gap_start = old_face.gap(x_n)
    gap_end = face.gap(x)
    with np.errstate(divide='ignore', invalid='ignore'):
        tau = np.where(gap_start > 0, np.clip(gap_start / (gap_start - gap_end), 0, 1), 0.0)
    v_start = (v_n - face.velocity) @ face.normal
    v_end = ((x - x_n) / dt - face.velocity) @ face.normal
    approach = -(v_start + tau * (v_end - v_start))
    bouncing = approach > max(5.0 * settings.gravity * dt, 1e-3)
    return np.where(bouncing, face.restitution * approach, 0.0)


def _add_penetrating(contacts: cm.ContactState, x, x_n, v_n, old_faces, new_faces, dt,
                     released, surface, settings: ContactSettings) -> bool:
    """Free surface nodes inside a face are held by it (the deepest face of each), as
    IMPACT nodes if they arrive faster than the bounce threshold on a face with
    restitution; True if any was added."""
    candidates = surface[(contacts.obstacle[surface] < 0) & ~released[surface]]
    if not candidates.size:
        return False
    pts = x[candidates]
    low, high = pts.min(axis=0), pts.max(axis=0)
    depth = np.zeros(candidates.size)
    chosen = -np.ones(candidates.size, np.int64)
    for index, face in enumerate(new_faces):
        if not face.may_touch(low, high):  # broad phase
            continue
        gap = face.gap(pts)
        inside = face.covers(pts) & (gap < 0) & (-gap > depth)
        depth[inside] = -gap[inside]
        chosen[inside] = index
    hit = chosen >= 0
    if not np.any(hit):
        return False
    if settings.deepest_first > 0:
        for face_index in np.unique(chosen[hit]):
            # the deepest first: shallower nodes often come free once these are held
            on = chosen == face_index
            hit &= ~on | (depth >= settings.deepest_first * depth[on].max())
    nodes, index = candidates[hit], chosen[hit]
    contacts.obstacle[nodes] = index
    mu_s = np.array([f.static_friction for f in new_faces])
    contacts.mode[nodes] = np.where(mu_s[index] > 0, cm.STICK, cm.SLIP)
    contacts.normal_force[nodes] = 0.0
    for face_index in np.unique(index):
        sel = nodes[index == face_index]
        speed = _rebound_speeds(new_faces[face_index], old_faces[face_index], x_n[sel],
                                v_n[sel], x[sel], dt, settings)
        contacts.mode[sel[speed > 0]] = cm.IMPACT
        contacts.bounce_speed[sel] = speed
    return True
