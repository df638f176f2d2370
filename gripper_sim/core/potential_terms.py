"""The incremental potential's terms besides the energies, compiled once for every
storage of the Newton matrix.

One implicit Euler step minimises (``core.stepper``)
    Phi(q) = |q - q_n - dt v_n|^2_M / (2 dt^2)        inertia
           + alpha |q - q_n|^2_M / (2 dt)              Rayleigh mass damping
           + beta dq^T K_n dq / (2 dt)                 Rayleigh stiffness damping
           + sum_k b_k dt sqrt(|s_k|^2 + eps^2)        kinetic friction of sliding nodes
           + the energies,
with dq = q - q_n, K_n the elastic energies' Hessian at q_n (fixed for the step, so the
damping is a quadratic with exact gradient and Hessian), b_k the kinetic friction bound
(N) of sliding node k and s_k = T_k (x_k - x_n,k) / dt - v_k its slip velocity (m/s)
along its m tangents T_k (m, d) (2D: one tangent; 3D: the tangent plane, a Coulomb
cone). These functions give each term's value, gradient and Hessian entries; the two
assemblies call them: the 2D whole-step kernel (``core.kernels``: a node-block band or
the solid's sparse blocks) and the solver of every other set-up
(``core.fast_solver.PatternCachingSolver``: CSC values on a fixed pattern).

Flat vectors are q = [x0, z0, ...] (d = 2) or [x0, y0, z0, ...] (d = 3), m; masses are
per dof (kg).
"""
from __future__ import annotations

import math

from numba import njit


@njit(cache=True, error_model='numpy', inline='always')
def inertia(q, q_n, v_n, dt, masses, grad):
    """Inertia: its gradient M (q - q_n - dt v_n) / dt^2 written into ``grad`` (n_dof,)
    N. Returns its value (J)."""
    acc = 0.0
    for m in range(q.shape[0]):
        inert = q[m] - q_n[m] - dt * v_n[m]
        acc += masses[m] * inert ** 2
        grad[m] = masses[m] * inert / dt ** 2
    return 0.5 * acc / dt ** 2


@njit(cache=True, error_model='numpy', inline='always')
def mass_damping(dq, masses, alpha, dt, grad):
    """Mass damping of the step dq = q - q_n (n_dof,) m: its gradient alpha M dq / dt
    added into ``grad``. Returns its value (J); 0 for alpha = 0."""
    if alpha <= 0:
        return 0.0
    acc = 0.0
    for m in range(dq.shape[0]):
        acc += masses[m] * dq[m] ** 2
    for m in range(dq.shape[0]):
        grad[m] += alpha * masses[m] * dq[m] / dt
    return 0.5 * alpha * acc / dt


@njit(cache=True, error_model='numpy', inline='always')
def inertia_diagonal(masses, dt, alpha, m):
    """The Hessian of inertia and mass damping at dof m (N/m; a diagonal matrix)."""
    return masses[m] / dt ** 2 + (alpha * masses[m] / dt if alpha > 0 else 0.0)


@njit(cache=True, error_model='numpy', inline='always')
def stiffness_damping(dq, k_dq, beta, dt, grad):
    """Stiffness damping from dq (n_dof,) m and K_n dq (n_dof,) N (the caller's storage
    multiplies): its gradient beta K_n dq / dt added into ``grad``. Returns its value
    (J). Its Hessian is beta K_n / dt."""
    acc = 0.0
    for m in range(dq.shape[0]):
        acc += dq[m] * k_dq[m]
    for m in range(dq.shape[0]):
        grad[m] += beta * k_dq[m] / dt
    return 0.5 * beta * acc / dt


@njit(cache=True, error_model='numpy', inline='always')
def slip(q, q_n, i, tangents, speed, dt):
    """Node i's slip velocity (s0, s1) m/s along its tangents (m, d), m = 1 or 2 (s1 = 0
    for one tangent), relative to the obstacle's speed (m,) m/s along them."""
    d = tangents.shape[1]
    s0 = 0.0
    for c in range(d):
        s0 += (q[d * i + c] - q_n[d * i + c]) * tangents[0, c]
    s0 = s0 / dt - speed[0]
    s1 = 0.0
    if tangents.shape[0] > 1:
        for c in range(d):
            s1 += (q[d * i + c] - q_n[d * i + c]) * tangents[1, c]
        s1 = s1 / dt - speed[1]
    return s0, s1


@njit(cache=True, error_model='numpy', inline='always')
def friction(q, q_n, i, tangents, speed, bound, dt, eps, fric_grad):
    """Kinetic friction of sliding node i: the potential b dt sqrt(|s|^2 + eps^2), its
    gradient b T^T s / root added into ``fric_grad`` (n_dof,) N. Returns (value J, s0,
    s1, root) for ``friction_block``.

    Args:
        tangents: (m, d) unit tangents T.  speed: (m,) m/s, the obstacle's along them.
        bound: N, mu_k times the normal reaction.  eps: m/s, the smoothing speed.
    """
    d = tangents.shape[1]
    s0, s1 = slip(q, q_n, i, tangents, speed, dt)
    root = math.sqrt(s0 ** 2 + s1 ** 2 + eps ** 2)
    if tangents.shape[0] == 1:
        w = bound * s0 / root
        for c in range(d):
            fric_grad[d * i + c] += w * tangents[0, c]
    else:
        for c in range(d):
            fric_grad[d * i + c] += bound / root * (s0 * tangents[0, c] + s1 * tangents[1, c])
    return bound * dt * root, s0, s1, root


@njit(cache=True, error_model='numpy', inline='always')
def friction_block(tangents, s0, s1, root, bound, dt, eps, c, e):
    """Entry (c, e) of a sliding node's friction Hessian block (N/m),
    (b / dt) T^T (I / root - s s^T / root^3) T; for one tangent t, in the form
    b eps^2 / (root^3 dt) t t^T (no cancellation where |s| >> eps)."""
    if tangents.shape[0] == 1:
        return one_tangent_curvature(root, bound, dt, eps) * tangents[0, c] * tangents[0, e]
    along = tangents[0, c] * tangents[0, e] + tangents[1, c] * tangents[1, e]
    proj_c = s0 * tangents[0, c] + s1 * tangents[1, c]
    proj_e = s0 * tangents[0, e] + s1 * tangents[1, e]
    return bound / dt * (along / root - proj_c * proj_e / root ** 3)


@njit(cache=True, error_model='numpy', inline='always')
def one_tangent_curvature(root, bound, dt, eps):
    """g (N/m) of a node sliding along one tangent t, whose friction Hessian block is
    g t t^T: b eps^2 / (root^3 dt)."""
    return bound * eps ** 2 / root ** 3 / dt
