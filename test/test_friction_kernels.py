"""The compiled 2D lagged friction (``core.friction_kernels``) equals ipctk's.

Random outlines within dhat of each other (point-line and point-point pairs), moved by a
random displacement: ipctk's ``TangentialCollisions`` (per-vertex static and kinetic
coefficients blended by ``max``) and ``FrictionPotential`` on velocities (x - x_start)
/ dt against the kernel's pairs from the same candidates: value, gradient and Hessian
(clamped) to 1e-10 relative, slow (below eps_v) and sliding speeds.
"""
import ipctk
import numpy as np
import pytest

from gripper_sim.core.friction_kernels import friction_terms, lagged_friction

DHAT = 1e-3
KAPPA = 0.1
EPS_V = 1e-3
DT = 1e-3


def _mesh(seed: int):
    """A zig-zag outline below a flat one, within dhat of each other in places."""
    rng = np.random.default_rng(seed)
    n = 8
    x = np.linspace(0.0, 0.01, n)
    lower = np.stack([x, -rng.uniform(0.1, 1.2, n) * DHAT], axis=1)
    upper = np.stack([x + rng.uniform(-4e-4, 4e-4, n), np.zeros(n)], axis=1)
    edges = np.array([(i, i + 1) for i in range(n - 1)]
                     + [(n + i, n + i + 1) for i in range(n - 1)])
    return np.vstack([lower, upper]), edges


def _friction(seed: int, speed: float, mu_s, mu_k):
    start, edges = _mesh(seed)
    n = len(start)
    rng = np.random.default_rng(100 + seed)
    now = start + speed * DT * rng.uniform(-1.0, 1.0, start.shape)
    v0 = np.asfortranarray(start)
    mesh = ipctk.CollisionMesh(v0, np.asfortranarray(edges.astype(np.int32)))
    mesh.can_collide = ipctk.make_vertex_patches_filter((np.arange(n) >= n // 2).astype(np.int32))
    candidates = ipctk.Candidates()
    candidates.build(mesh, v0, 0.5 * DHAT)
    collisions = ipctk.NormalCollisions()
    collisions.build(candidates, mesh, v0, DHAT)
    barrier = ipctk.BarrierPotential(DHAT, KAPPA, True)
    tangential = ipctk.TangentialCollisions()
    tangential.build(mesh, v0, collisions, barrier, mu_s, mu_k, max)
    assert len(tangential.ev_collisions) and len(tangential.vv_collisions)
    friction = ipctk.FrictionPotential(EPS_V)
    velocity = np.asfortranarray((now - start) / DT)
    value = DT * friction(tangential, mesh, velocity)
    gradient = friction.gradient(tangential, mesh, velocity)
    hessian = friction.hessian(tangential, mesh, velocity,
                               ipctk.PSDProjectionMethod.CLAMP).toarray() / DT

    pairs = np.array([(c.edge_id, c.vertex_id) for c in candidates.ev_candidates], np.int64)
    k = len(pairs)
    ids, weights = np.empty((k, 3), np.int64), np.empty((k, 3))
    tangents, forces, mus = np.empty((k, 2)), np.empty(k), np.empty((k, 2))
    count = lagged_friction(start, edges.astype(np.int64), pairs, DHAT, KAPPA, mu_s, mu_k,
                            ids, weights, tangents, forces, mus)
    n_dof = 2 * n
    mine = np.zeros(n_dof)
    keys = np.arange(n_dof ** 2, dtype=np.int64)      # a full pattern
    matrix = np.zeros(n_dof ** 2)
    total, outside = friction_terms(now, start, DT, EPS_V, ids[:count], weights[:count],
                                    tangents[:count], forces[:count], mus[:count],
                                    np.arange(n_dof).reshape(n, 2), mine, True, keys, n_dof,
                                    keys, matrix)
    assert outside == 0
    matrix = matrix.reshape(n_dof, n_dof).T           # keys are col n_dof + row
    return (value, gradient, hessian), (total, mine, matrix)


@pytest.mark.parametrize('seed', range(4))
@pytest.mark.parametrize('speed', [0.2 * EPS_V, 0.7 * EPS_V, 5 * EPS_V])
@pytest.mark.parametrize('blend', [False, True])
def test_the_compiled_friction_equals_ipctks(seed, speed, blend):
    n = 16
    rng = np.random.default_rng(seed)
    mu_k = rng.uniform(0.2, 0.6, n)
    mu_s = mu_k + (rng.uniform(0.0, 0.3, n) if blend else 0.0)
    (value, gradient, hessian), (total, mine, matrix) = _friction(seed, speed, mu_s, mu_k)
    assert total == pytest.approx(value, rel=1e-10)
    assert np.max(np.abs(mine - gradient)) <= 1e-10 * np.max(np.abs(gradient))
    assert np.max(np.abs(matrix - hessian)) <= 1e-10 * max(np.max(np.abs(hessian)), 1e-300)
