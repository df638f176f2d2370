"""Compiled contact passes of the modified mass method, one implementation for 2D and 3D.

The per-node logic of the predictor-corrector passes (the method and its rules are
described in ``core.contact_passes`` and ``core.contact``), as numba kernels on arrays
with the dimension d a parameter (positions (n, d)). One driver calls them around a
Newton solve, ``contact_passes.contact_passes``: run by Python in ``contact_step``
(every set-up, around the solver object) and compiled in the 2D whole-step kernel
``kernels.substep`` (around its compiled Newton solve). Per pass: ``constraints`` (z targets, S filters, the sliding nodes' kinetic friction),
the solve, ``update`` (release, stick/slip, corners, newly caught nodes); after the last
pass ``finish`` (end velocities with restitution capped so it adds no energy, the
contact forces, the one-step holds let go). Every function here is inlined into its
compiled callers (the 2D kernel, and each other), so that no arrays are handed over
(and reference-counted) node by node.

Faces are a tuple ``faces`` of arrays, F flat faces translating during the step:
    normal (F, d): unit normals towards the fruit side;
    tangents (F, d - 1, d): orthonormal tangents spanning each face;
    half_extents (F, d - 1) m: half sizes along the tangents (inf: unbounded);
    props (F, 4): [thickness m behind the face still in contact, static friction,
        kinetic friction, restitution] (columns ``THICKNESS`` .. ``RESTITUTION``);
    origin_start, origin_end (F, d) m: a point of each face at the start and at the end
        of the step;
    velocity (F, d) m/s.
The contact state is a tuple ``state`` of (n,) arrays (obstacle, mode, normal_force,
bounce_speed, secondary, secondary_bounce), the fields of ``contact.ContactState``,
updated in place.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from gripper_sim.core.contact import FREE, IMPACT, SLIP, STICK
from gripper_sim.core.stepper import FRICTION_SMOOTHING

#: columns of a face's ``props`` row
THICKNESS, STATIC_FRICTION, KINETIC_FRICTION, RESTITUTION = range(4)

#: squared length (of S n) below which a corner's second face adds no constraint: the
#: first face's filter already holds the node in every direction
_NO_FREE_DIRECTION = 1e-12


def face_arrays(old_faces: list, new_faces: list, dim: int) -> tuple:
    """The ``faces`` tuple (see the module doc) of faces that translate from
    ``old_faces`` to ``new_faces`` (``obstacles.FlatFace`` in 2D, ``Plate`` in 3D: a
    unit ``normal``, ``tangents`` (d - 1, d), ``half_extents`` (d - 1,), ``origin``,
    ``velocity``, ``thickness``, friction and restitution coefficients)."""
    count = len(new_faces)
    normal = np.empty((count, dim))
    tangents = np.empty((count, dim - 1, dim))
    half_extents = np.empty((count, dim - 1))
    props = np.empty((count, 4))
    origin_start = np.empty((count, dim))
    origin_end = np.empty((count, dim))
    velocity = np.empty((count, dim))
    for f, (old, new) in enumerate(zip(old_faces, new_faces)):
        normal[f] = new.normal
        tangents[f] = new.tangents
        half_extents[f] = new.half_extents
        props[f] = (new.thickness, new.static_friction, new.kinetic_friction,
                    new.restitution)
        origin_start[f] = old.origin
        origin_end[f] = new.origin
        velocity[f] = new.velocity
    return normal, tangents, half_extents, props, origin_start, origin_end, velocity


@njit(cache=True, error_model='numpy', inline='always')
def _gap(origin, normal, f, x, i):
    """Signed distance (m) of point i of x (n, d) from the plane of face f through
    ``origin[f]``; < 0 inside."""
    gap = 0.0
    for c in range(x.shape[1]):
        gap += (x[i, c] - origin[f, c]) * normal[f, c]
    return gap


@njit(cache=True, error_model='numpy', inline='always')
def _along(vector, tangents, f, a):
    """Component of ``vector`` (d,) along tangent a of face f."""
    total = 0.0
    for c in range(vector.shape[0]):
        total += vector[c] * tangents[f, a, c]
    return total


@njit(cache=True, error_model='numpy', inline='always')
def _covers(faces, f, x, i):
    """Whether point i of x (n, d) is within face f's extent at the end of the step and
    not beyond its back."""
    normal, tangents, half_extents, props, _, origin, _ = faces
    d = x.shape[1]
    for a in range(d - 1):
        along = 0.0
        for c in range(d):
            along += (x[i, c] - origin[f, c]) * tangents[f, a, c]
        if abs(along) > half_extents[f, a]:
            return False
    return _gap(origin, normal, f, x, i) > -props[f, THICKNESS]


@njit(cache=True, error_model='numpy', inline='always')
def release(state, i):
    """Node i is free (no face, no corner, no rebound)."""
    obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce = state
    obstacle[i] = -1
    mode[i] = FREE
    normal_force[i] = 0.0
    bounce_speed[i] = 0.0
    secondary[i] = -1
    secondary_bounce[i] = 0.0


@njit(cache=True, error_model='numpy', inline='always')
def constraints(state, faces, x_n, x_pred, dt, v_corr, start, filters, fr_nodes, fr_t,
                fr_bound, fr_speed):
    """The start positions of a solve with the held nodes at their targets, the step
    filters and the kinetic friction of the sliding nodes.

    A held node's normal gap target undoes a penetration at ``v_corr`` at most; a stuck
    node moves with its face; a node held by a second face too (a corner) reaches that
    face's plane along its free directions (u = S n), and its filter, still a symmetric
    projector, loses u (in 2D it is held at the corner point, in 3D on a V's edge).

    Args:
        state, faces: see the module doc.
        x_n, x_pred: (n, d) m, positions at the start of the step and predicted.
        dt: s.  v_corr: m/s, the fastest rate at which a penetration is undone.
        Outputs: start (n, d) m, filters (n, d, d), fr_nodes (n,) int64, fr_t
        (n, d - 1, d) their faces' tangents, fr_bound (n,) N mu_k times the lagged
        normal force, fr_speed (n, d - 1) m/s the face's speed along its tangents.

    Returns:
        k, the number of friction rows written (the first k of the friction outputs).
    """
    obstacle, mode, normal_force, _, secondary, _ = state
    normal, tangents, _, props, origin_start, origin_end, velocity = faces
    n, d = x_n.shape
    for i in range(n):
        for a in range(d):
            start[i, a] = x_pred[i, a]
            for b in range(d):
                filters[i, a, b] = 1.0 if a == b else 0.0
    n_fr = 0
    for f in range(normal.shape[0]):
        for i in range(n):
            if obstacle[i] != f:
                continue
            penetration = max(0.0, -_gap(origin_start, normal, f, x_n, i))
            target = -max(0.0, penetration - v_corr * dt)
            correction = target - _gap(origin_end, normal, f, start, i)
            for c in range(d):
                start[i, c] += correction * normal[f, c]
            if mode[i] == STICK:
                for a in range(d - 1):  # the tangents are orthonormal: one at a time
                    along = (_along(x_n[i], tangents, f, a)
                             + dt * _along(velocity[f], tangents, f, a)
                             - _along(start[i], tangents, f, a))
                    for c in range(d):
                        start[i, c] += along * tangents[f, a, c]
                for a in range(d):
                    for b in range(d):
                        filters[i, a, b] = 0.0
                continue
            for a in range(d):
                for b in range(d):
                    filters[i, a, b] = (1.0 if a == b else 0.0) - normal[f, a] * normal[f, b]
            if mode[i] == SLIP and props[f, KINETIC_FRICTION] > 0:
                fr_nodes[n_fr] = i
                for a in range(d - 1):
                    for c in range(d):
                        fr_t[n_fr, a, c] = tangents[f, a, c]
                    fr_speed[n_fr, a] = _along(velocity[f], tangents, f, a)
                fr_bound[n_fr] = props[f, KINETIC_FRICTION] * max(normal_force[i], 0.0)
                n_fr += 1
    for i in range(n):
        f = secondary[i]
        if f < 0:
            continue
        u = np.empty(d)  # S n, the move that keeps the first face's gap
        uu = 0.0
        for a in range(d):
            u[a] = 0.0
            for b in range(d):
                u[a] += filters[i, a, b] * normal[f, b]
            uu += u[a] * u[a]
        if uu < _NO_FREE_DIRECTION:
            continue
        step = (0.0 - _gap(origin_end, normal, f, start, i)) / uu
        for a in range(d):
            start[i, a] += step * u[a]
        for a in range(d):
            for b in range(d):
                filters[i, a, b] -= u[a] * u[b] / uu
    return n_fr


@njit(cache=True, error_model='numpy', inline='always')
def _rebound_speed(faces, f, x_n, v_n, x, i, dt, v_min):
    """Outgoing normal speed (m/s) relative to face f of node i found inside it (0: no
    rebound): the node rebounds if it met the face faster than ``v_min`` and the face has
    restitution e; it leaves with e times its speed at the moment it met the face (linear
    in time between the start, x_n and v_n (n, d), and the solve's end x (n, d))."""
    normal, _, _, props, origin_start, origin_end, velocity = faces
    e = props[f, RESTITUTION]
    if e <= 0:
        return 0.0
    gap_start = _gap(origin_start, normal, f, x_n, i)
    gap_end = _gap(origin_end, normal, f, x, i)
    tau = min(max(gap_start / (gap_start - gap_end), 0.0), 1.0) if gap_start > 0 else 0.0
    v_start = 0.0
    v_end = 0.0
    for c in range(x.shape[1]):
        v_start += (v_n[i, c] - velocity[f, c]) * normal[f, c]
        v_end += ((x[i, c] - x_n[i, c]) / dt - velocity[f, c]) * normal[f, c]
    approach = -(v_start + tau * (v_end - v_start))
    return e * approach if approach > v_min else 0.0


#: m, how deep inside a face a node released earlier in the step (or in this same
#: ``update``, where it still lies on the face that held it) must be to be held again:
#: at the face it lies within round-off of it, on either side, and the routes of a step
#: (the compiled whole step, the generic one) must not tell those apart
RELEASED_DEPTH = 1e-9


@njit(cache=True, error_model='numpy', inline='always')
def update(state, faces, x, x_n, v_n, reaction, surface, dt, threshold, v_min,
           deepest_first, released, slipped):
    """Correct the contact set after a solve: pulling nodes are released (not IMPACT
    ones, and once per step: a node released in an earlier pass and found inside a face
    again is held again and stays held to the step's end, its pull read as no normal
    force, so that the passes cannot cycle and none ends with it inside), stuck nodes
    whose tangential reaction leaves the Coulomb cone slip, slipping
    nodes that stopped stick (unless they slipped in this step), pulling corner holds
    end, held nodes pushed into a second face get it as a frictionless corner hold, free
    surface nodes inside a face are held by the deepest one (IMPACT if they arrive fast
    at a face with restitution).

    Args:
        state, faces: see the module doc.
        x: (n, d) m, the solve's end.  x_n, v_n: (n, d) m and m/s, the step's start.
        reaction: (n, d) N, the forces the faces exert on the held nodes.
        surface: (m,) int64, the nodes that can touch a face.  dt: s.
        threshold: N, a held node is released when its normal reaction pulls by more.
        v_min: m/s, the slowest approach that rebounds.
        deepest_first: of the free nodes inside a face, add only those at least this
            fraction of the deepest one's depth (0: all of them).
        released, slipped: (n,) bool, the nodes released / set slipping in earlier
            passes of the step (updated).

    Returns:
        True if the set changed (solve again): also when a sliding node's normal force
        moved by more than 2 % from the lagged value its friction used.
    """
    obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce = state
    normal, tangents, _, props, origin_start, origin_end, velocity = faces
    n, d = x.shape
    n_faces = normal.shape[0]
    changed = False
    for f in range(n_faces):
        mu_s, mu_k = props[f, STATIC_FRICTION], props[f, KINETIC_FRICTION]
        for i in range(n):
            if obstacle[i] != f:
                continue
            r_n = 0.0
            for c in range(d):
                r_n += reaction[i, c] * normal[f, c]
            md = mode[i]
            if r_n < -threshold and md != IMPACT:
                if not released[i]:
                    release(state, i)
                    released[i] = True
                    changed = True
                    continue
                r_n = 0.0   # held again after its release: held to the step's end, no friction
            if md == STICK:
                r_t = 0.0
                for a in range(d - 1):
                    r_t += _along(reaction[i], tangents, f, a) ** 2
                if math.sqrt(r_t) > mu_s * r_n:
                    mode[i] = SLIP
                    slipped[i] = True
                    changed = True
            elif md == SLIP:
                rel = 0.0
                for a in range(d - 1):
                    s = 0.0
                    for c in range(d):
                        s += ((x[i, c] - x_n[i, c]) / dt - velocity[f, c]) * tangents[f, a, c]
                    rel += s * s
                to_stick = (math.sqrt(rel) < 2 * FRICTION_SMOOTHING and not slipped[i]
                            and mu_s > 0)
                if to_stick:
                    mode[i] = STICK
                    changed = True
                lag = normal_force[i]
                if not to_stick and abs(r_n - lag) > 0.02 * abs(lag) + 1e-9 and mu_k > 0:
                    changed = True
            normal_force[i] = r_n
    for i in range(n):
        f = secondary[i]
        if f < 0 or secondary_bounce[i] > 0:
            continue
        r_n = 0.0
        for c in range(d):
            r_n += reaction[i, c] * normal[f, c]
        if r_n < -threshold:
            secondary[i] = -1
            secondary_bounce[i] = 0.0
            changed = True
    # corners: held nodes pushed into a second face (one at most: a node given one here
    # is not looked at again)
    for f in range(n_faces):
        for i in range(n):
            if obstacle[i] < 0 or secondary[i] >= 0 or obstacle[i] == f:
                continue
            if _gap(origin_end, normal, f, x, i) < 0 and _covers(faces, f, x, i):
                secondary[i] = f
                if mode[i] == STICK:
                    mode[i] = SLIP
                secondary_bounce[i] = _rebound_speed(faces, f, x_n, v_n, x, i, dt, v_min)
                changed = True
    # free surface nodes inside a face, each to its deepest face; with deepest_first a
    # first sweep finds each face's deepest node, the second catches
    deepest = np.zeros(n_faces)  # m
    sweeps = 2 if deepest_first > 0 else 1
    for sweep in range(sweeps):
        for s in range(surface.shape[0]):
            i = surface[s]
            if obstacle[i] >= 0:
                continue
            chosen = np.int64(-1)
            depth = RELEASED_DEPTH if released[i] else 0.0
            for f in range(n_faces):
                gap = _gap(origin_end, normal, f, x, i)
                if gap < 0 and -gap > depth and _covers(faces, f, x, i):
                    depth = -gap
                    chosen = f
            if chosen < 0:
                continue
            if sweep < sweeps - 1:
                deepest[chosen] = max(deepest[chosen], depth)
                continue
            if depth < deepest_first * deepest[chosen]:
                continue  # shallower nodes often come free once the deepest hold
            obstacle[i] = chosen
            mode[i] = STICK if props[chosen, STATIC_FRICTION] > 0 else SLIP
            normal_force[i] = 0.0
            bounce_speed[i] = _rebound_speed(faces, chosen, x_n, v_n, x, i, dt, v_min)
            if bounce_speed[i] > 0:
                mode[i] = IMPACT
            changed = True
    return changed


#: a sliding node's normal force is extrapolated (``extrapolate_lag``) only where the
#: plain update converges or diverges no worse than this: |dR/dL| < 1 converges, and
#: 1 - dR/dL >= 0.1 keeps the secant's fixed point within ten times the last change
LAG_SLOPE_RANGE = (-10.0, 0.9)


@njit(cache=True, error_model='numpy', inline='always')
def extrapolate_lag(state, before, history):
    """After ``update`` asked for another pass: set each sliding node's lagged normal
    force to the secant estimate of its fixed point instead of the last reaction.

    A pass that slides node i with the friction bound mu_k L (L = its lagged normal
    force) ends with the normal reaction R(L); the next pass uses L' = R, so a gap
    |R - L| shrinks by the factor |dR/dL| per pass (about 1/2 for a node on a lifted
    jaw: many passes before the 2 % rule of ``update`` holds). With the pairs (L, R)
    of two passes of the same contact set, the slope s = dR/dL is known and the fixed
    point L = R(L) is (R - s L) / (1 - s) (the secant method on R(L) - L). The test
    that ends the passes is unchanged: the friction bound used within 2 % of the
    reaction it produced.

    Args:
        state: the contact state (see the module doc) after ``update``; its
            normal_force is changed at the extrapolated nodes.
        before: a copy of the state during the solve (before ``update``): its
            normal_force the lagged normal forces the friction bounds used.
        history: (previous lag (n,) N, previous reaction (n,) N, known (n,) bool), each
            sliding node's pair from the previous pass of the step (updated; a change
            of the contact set forgets every pair, since the reactions then move for
            another reason).
    """
    obstacle, mode, normal_force, _, secondary, _ = state
    obstacle_before, mode_before, lag_used, _, secondary_before, _ = before
    previous_lag, previous_reaction, known = history
    n = obstacle.shape[0]
    same_set = True
    for i in range(n):
        if (obstacle[i] != obstacle_before[i] or mode[i] != mode_before[i]
                or secondary[i] != secondary_before[i]):
            same_set = False
    for i in range(n):
        sliding = obstacle[i] >= 0 and mode[i] == SLIP and mode_before[i] == SLIP
        if not (same_set and sliding):
            known[i] = False
            continue
        lag = lag_used[i]
        reaction = normal_force[i]
        if known[i] and abs(lag - previous_lag[i]) > 1e-9:
            slope = (reaction - previous_reaction[i]) / (lag - previous_lag[i])
            if LAG_SLOPE_RANGE[0] <= slope <= LAG_SLOPE_RANGE[1]:
                estimate = (reaction - slope * lag) / (1.0 - slope)
                if estimate > 0.0:
                    normal_force[i] = estimate
        previous_lag[i] = lag
        previous_reaction[i] = reaction
        known[i] = True


@njit(cache=True, error_model='numpy', inline='always')
def capped_rebound_scale(v, rebound, v_start, dx, reaction, mass, dt):
    """The factor s in [0, 1] by which one node's rebound (d,) m/s is scaled so that it
    adds no energy: |v - (1 - s) rebound|^2 <= |v_start|^2 + 2 F . dx / m, with F =
    m (dx / dt - v_start) / dt - reaction the other forces on the node (N) and dx (d,) m
    its displacement; v (d,) m/s its end velocity with the full rebound (see
    ``contact_passes`` for why this bounds the step's energy)."""
    d = v.shape[0]
    work = 0.0
    budget = 0.0
    bb = 0.0
    br = 0.0
    rr = 0.0
    for c in range(d):
        work += (mass * (dx[c] / dt - v_start[c]) / dt - reaction[c]) * dx[c]
        budget += v_start[c] * v_start[c]
        base = v[c] - rebound[c]
        bb += base * base
        br += base * rebound[c]
        rr += rebound[c] * rebound[c]
    budget += 2.0 * work / mass
    # |base + s rebound|^2 = bb + 2 s br + s^2 rr <= budget: the largest s in [0, 1]
    if rr == 0.0 or bb + 2.0 * br + rr <= budget:
        return 1.0
    discriminant = br * br - rr * (bb - budget)
    if discriminant < 0.0:
        return 0.0  # no scale fits
    root = math.sqrt(discriminant)
    if (-br - root) / rr > 1.0:
        return 0.0  # only scales beyond the full rebound would fit
    return min(max((-br + root) / rr, 0.0), 1.0)


@njit(cache=True, error_model='numpy', inline='always')
def finish(state, faces, x, x_n, v_n, reaction, masses, dt, v_out, forces_out):
    """The end of a step after its last pass: velocities and contact forces, then the
    one-step holds let go (IMPACT nodes, rebounding corner holds).

    A held node moves with its face along the normal (plus its rebound), a stuck one
    along the tangents too; a corner node along the second face's normal (plus its
    rebound from it); a rebound is capped so that it adds no energy
    (``capped_rebound_scale``).

    Args:
        state, faces: see the module doc.
        x: (n, d) m, the last solve's end.  x_n, v_n: (n, d), the step's start.
        reaction: (n, d) N, the faces' forces on the held nodes.
        masses: (n,) kg.  dt: s.
        Outputs: v_out (n, d) m/s, forces_out (n, d) N (zero at free nodes).
    """
    obstacle, mode, _, bounce_speed, secondary, secondary_bounce = state
    normal, _, _, _, _, _, velocity = faces
    n, d = x.shape
    for i in range(n):
        for c in range(d):
            v_out[i, c] = (x[i, c] - x_n[i, c]) / dt
            forces_out[i, c] = 0.0
    for i in range(n):
        f = obstacle[i]
        if f < 0:
            continue
        v_along = 0.0  # the node's normal speed
        face_along = 0.0  # the face's
        for c in range(d):
            v_along += v_out[i, c] * normal[f, c]
            face_along += velocity[f, c] * normal[f, c]
        stuck = mode[i] == STICK
        for c in range(d):
            tangential = (velocity[f, c] - face_along * normal[f, c] if stuck
                          else v_out[i, c] - v_along * normal[f, c])
            v_out[i, c] = tangential + (face_along + bounce_speed[i]) * normal[f, c]
            forces_out[i, c] = reaction[i, c]
    for i in range(n):
        f = secondary[i]
        if f < 0:
            continue
        face_along = 0.0
        v_along = 0.0
        for c in range(d):
            face_along += velocity[f, c] * normal[f, c]
            v_along += v_out[i, c] * normal[f, c]
        change = face_along + secondary_bounce[i] - v_along
        for c in range(d):
            v_out[i, c] += change * normal[f, c]
    rebound = np.empty(d)
    dx = np.empty(d)
    for i in range(n):
        f = obstacle[i]
        if f < 0:
            continue
        moving = False
        for c in range(d):
            rebound[c] = bounce_speed[i] * normal[f, c]
            if secondary[i] >= 0:
                rebound[c] += secondary_bounce[i] * normal[secondary[i], c]
            moving = moving or rebound[c] != 0.0
            dx[c] = x[i, c] - x_n[i, c]
        if not moving:
            continue
        scale = capped_rebound_scale(v_out[i], rebound, v_n[i], dx, reaction[i], masses[i],
                                     dt)
        for c in range(d):
            v_out[i, c] -= (1.0 - scale) * rebound[c]
    for i in range(n):
        if mode[i] == IMPACT:
            release(state, i)
        elif secondary_bounce[i] > 0:
            secondary[i] = -1
            secondary_bounce[i] = 0.0
