"""Compiled 2D lagged friction: the IPC friction potential of edge-vertex pairs
(``core.barrier``).

The same potential as ipctk's ``FrictionPotential(eps_v)`` over the tangential collisions
it builds from the start of the step (``TangentialCollisions.build`` with per-vertex
static and kinetic coefficients blended by ``max``), following Li et al. 2020
("Incremental Potential Contact", ACM Trans. Graph. 39(4) 49, section 5):

- lagged at the start of the step, per candidate (edge a-b, vertex p) closer than dhat:
  the distance type as in ``barrier_kernels`` (t < 0 or t > 1 a point-point pair with
  the nearer end, else point-line), the normal force lambda = -dB/dd = -2 d B'(d^2) of
  the barrier B (N), the tangent (unit along the edge; for a point-point pair
  perpendicular to p - q), the relative velocity's weights (p minus the closest point:
  1, -(1 - t), -t; or 1, -1) and the pair's coefficients (the larger of each side's,
  an edge's interpolated at the closest point);
- per evaluation at velocities u = (x - x_start) / dt: y = |tangent . (weights u)|, the
  dissipative potential dt lambda mu f0(y), f0 the mollified speed and mu(y) the smooth
  static-to-kinetic blend below eps_v (ipctk's ``smooth_mu_f0``); its gradient
  lambda mu f1(y) / y (tangent . w u) G, G = weights (x) tangent (2 m,), and its Hessian
  lambda max(h, 0) / dt G G^T with h = d(mu f1)/dy, the clamped (CLAMP) projection of
  the rank-one term (for y >= eps_v h = 0: sliding adds no stiffness in 2D).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from gripper_sim.core.barrier_kernels import add_local_hessian


@njit(cache=True)
def _blend(mu_s, mu_k, y, eps_v):
    """(mu, dmu/dy) at speed y >= 0: mu_k at and beyond eps_v, from mu_s at 0 along two
    quadratic arcs meeting at eps_v / 2 (ipctk's ``smooth_mu``)."""
    if mu_s == mu_k or y >= eps_v:
        return mu_k, 0.0
    z = y / eps_v
    if y < 0.5 * eps_v:
        return 2.0 * (mu_k - mu_s) * z * z + mu_s, 4.0 * (mu_k - mu_s) * z / eps_v
    return (-2.0 * (mu_k - mu_s) * (z * (z - 2.0) + 1.0) + mu_k,
            -4.0 * (mu_k - mu_s) * (z - 1.0) / eps_v)


@njit(cache=True)
def _mu_f0(y, mu_s, mu_k, eps_v):
    """m/s, the integral of mu(y) f1(y) from 0 plus ipctk's constant (``smooth_mu_f0``):
    y mu_k beyond eps_v."""
    if mu_s == mu_k or y >= eps_v:
        if y >= eps_v:
            return mu_k * y
        return mu_k * (-y * y * y / (3.0 * eps_v * eps_v) + y * y / eps_v + eps_v / 3.0)
    delta = mu_k - mu_s
    z = y / eps_v
    if y < 0.5 * eps_v:
        return (y * z * (z * (z * (1.0 - 0.4 * z) * delta - mu_s / 3.0) + mu_s)
                + (9.0 / 16.0) * eps_v * mu_k - (11.0 / 48.0) * eps_v * mu_s)
    return (y * z * (z * (z * (0.4 * z - 2.0) * delta + (3.0 * mu_k - (10.0 / 3.0) * mu_s))
                     + (2.0 * mu_s - mu_k))
            + 0.6 * eps_v * mu_k - (4.0 / 15.0) * eps_v * mu_s)


@njit(cache=True)
def _mu_f1_terms(y, mu_s, mu_k, eps_v):
    """(mu f1 / y, d(mu f1)/dy) at speed y >= 0, f1(y) = 2 y / eps_v - y^2 / eps_v^2 below
    eps_v, 1 beyond (the first is its limit 2 mu_s / eps_v at y = 0)."""
    mu, dmu = _blend(mu_s, mu_k, y, eps_v)
    if y >= eps_v:
        return mu / y, 0.0
    f1_over_y = 2.0 / eps_v - y / (eps_v * eps_v)
    f1 = y * f1_over_y
    f2 = 2.0 / eps_v - 2.0 * y / (eps_v * eps_v)
    return mu * f1_over_y, dmu * f1 + mu * f2


@njit(cache=True)
def lagged_friction(v, edges, candidates, dhat, stiffness, mu_s, mu_k, vertex_ids, weights,
                    tangents, forces, coefficients):
    """The lagged friction pairs of the edge-vertex ``candidates`` at the start vertices.

    Args:
        v: (n_m, 2) m, the collision mesh's vertices at the start of the step.
        edges: (n_e, 2) its edges.  candidates: (k, 2) (edge, vertex) pairs.
        dhat: m.  stiffness: N, kappa (the physical barrier, ``barrier_kernels``).
        mu_s, mu_k: (n_m,) each vertex's static and kinetic coefficient.
        vertex_ids, weights: (>= k, 3) out: the pair's vertices (-1 unused) and their
            weights in its relative velocity.
        tangents: (>= k, 2) out: the unit tangent.  forces: (>= k,) out: lambda, N.
        coefficients: (>= k, 2) out: (static, kinetic) coefficient of the pair.

    Returns:
        The number of pairs written (those closer than dhat with a nonzero force).
    """
    s_hat = dhat * dhat
    scale = stiffness / dhat ** 3
    written = 0
    for k in range(candidates.shape[0]):
        edge, vertex = candidates[k, 0], candidates[k, 1]
        a_id, b_id = edges[edge, 0], edges[edge, 1]
        p, a, b = v[vertex], v[a_id], v[b_id]
        ex, ey = b[0] - a[0], b[1] - a[1]
        length2 = ex * ex + ey * ey
        t = (ex * (p[0] - a[0]) + ey * (p[1] - a[1])) / length2
        if t < 0.0 or t > 1.0:
            q_id = a_id if t < 0.0 else b_id
            dx, dy = p[0] - v[q_id, 0], p[1] - v[q_id, 1]
            s = dx * dx + dy * dy
            if s >= s_hat or s <= 0.0:
                continue
            norm = np.sqrt(s)
            tx, ty = -dy / norm, dx / norm
            vertex_ids[written, 0], vertex_ids[written, 1], vertex_ids[written, 2] = \
                vertex, q_id, -1
            weights[written, 0], weights[written, 1], weights[written, 2] = 1.0, -1.0, 0.0
            edge_mu_s, edge_mu_k = mu_s[q_id], mu_k[q_id]
        else:
            cross = (a[0] - p[0]) * (b[1] - p[1]) - (a[1] - p[1]) * (b[0] - p[0])
            s = cross * cross / length2
            if s >= s_hat or s <= 0.0:
                continue
            norm = np.sqrt(length2)
            tx, ty = ex / norm, ey / norm
            vertex_ids[written, 0], vertex_ids[written, 1], vertex_ids[written, 2] = \
                vertex, a_id, b_id
            weights[written, 0], weights[written, 1], weights[written, 2] = 1.0, t - 1.0, -t
            edge_mu_s = (1.0 - t) * mu_s[a_id] + t * mu_s[b_id]
            edge_mu_k = (1.0 - t) * mu_k[a_id] + t * mu_k[b_id]
        log = np.log(s / s_hat)
        first = (s_hat - s) * (2.0 * log - s_hat / s + 1.0) * scale
        tangents[written, 0], tangents[written, 1] = tx, ty
        forces[written] = -2.0 * np.sqrt(s) * first
        coefficients[written, 0] = max(mu_s[vertex], edge_mu_s)
        coefficients[written, 1] = max(mu_k[vertex], edge_mu_k)
        written += 1
    return written


@njit(cache=True)
def friction_terms(v, start, dt, eps_v, vertex_ids, weights, tangents, forces, coefficients,
                   vertex_dofs, gradient, want_hessian, pattern_keys, n_dof, slots,
                   hessian_values):
    """The lagged friction potential of the pairs of ``lagged_friction`` at vertices ``v``.

    Args:
        v, start: (n_m, 2) m, the collision mesh's vertices now and at the step's start.
        dt: s, the step.  eps_v: m/s, the slip speed below which friction is smoothed.
        vertex_ids, weights, tangents, forces, coefficients: the k pairs (``lagged_friction``).
        vertex_dofs: (n_m, 2) the state's dof of each vertex coordinate, -1 for none.
        gradient: (n_dof,) N, the potential's gradient in positions is added into it.
        want_hessian: whether to give the Hessian's entries.
        pattern_keys: (p,) sorted keys col n_dof + row of the Hessian's pattern.
        slots: (p,) where in ``hessian_values`` each key of the pattern adds.
        hessian_values: the Hessian's entries (N/m) are added into it.

    Returns:
        (value J, the Hessian's entries outside the pattern, left out).
    """
    total = 0.0
    outside = 0
    g = np.empty(6)
    local = np.zeros((6, 6))
    for k in range(forces.shape[0]):
        m = 3 if vertex_ids[k, 2] >= 0 else 2
        tx, ty = tangents[k, 0], tangents[k, 1]
        speed = 0.0
        for i in range(m):
            node = vertex_ids[k, i]
            w = weights[k, i] / dt
            g[2 * i] = weights[k, i] * tx
            g[2 * i + 1] = weights[k, i] * ty
            speed += w * ((v[node, 0] - start[node, 0]) * tx + (v[node, 1] - start[node, 1]) * ty)
        y = abs(speed)
        mu_s, mu_k = coefficients[k, 0], coefficients[k, 1]
        total += dt * forces[k] * _mu_f0(y, mu_s, mu_k, eps_v)
        f1_over_y, slope = _mu_f1_terms(y, mu_s, mu_k, eps_v)
        along = forces[k] * f1_over_y * speed
        for i in range(m):
            for c in range(2):
                dof = vertex_dofs[vertex_ids[k, i], c]
                if dof >= 0:
                    gradient[dof] += along * g[2 * i + c]
        if not want_hessian or slope <= 0.0:
            continue
        stiffness = forces[k] * slope / dt
        for i in range(2 * m):
            for j in range(2 * m):
                local[i, j] = stiffness * g[i] * g[j]
        outside += add_local_hessian(local, vertex_ids[k], m, vertex_dofs, n_dof, pattern_keys,
                                     slots, hessian_values)
    return total, outside


@njit(cache=True)
def point_friction(slips, forces, mu, eps, along, stiffness):
    """The lagged friction potential of points sliding on a rigid surface, in statics:
    each point's lambda mu f0(|s|) of its tangential slip s over a load increment (the
    dissipative potential above with the step's slip in place of dt times the speed).

    Args:
        slips: (k,) m, each point's slip along its lagged tangent since the increment's
            start (relative to the surface).
        forces: (k,) N, each point's lagged normal force lambda.
        mu: the friction coefficient (static and kinetic alike).
        eps: m, the slip below which friction is smoothed (sticking).
        along: (k,) out: N, d(potential)/d(slip) of each point.
        stiffness: (k,) out: N/m, its second derivative, clamped at 0 (0 once sliding).

    Returns:
        The potential, J.
    """
    total = 0.0
    for k in range(slips.shape[0]):
        y = abs(slips[k])
        total += forces[k] * _mu_f0(y, mu, mu, eps)
        f1_over_y, slope = _mu_f1_terms(y, mu, mu, eps)
        along[k] = forces[k] * f1_over_y * slips[k]
        stiffness[k] = forces[k] * max(slope, 0.0)
    return total
