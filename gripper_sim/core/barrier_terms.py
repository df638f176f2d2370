"""The 2D barrier contact's evaluation (``core.barrier``) in one kernel call: the collision
mesh's vertices gathered from the state, the barrier of the candidate pairs
(``barrier_kernels.edge_vertex_barrier``) and the lagged friction
(``friction_kernels.friction_terms``), each gradient gathered onto the deformable
vertices' dofs. The same kernels in the same order as one call each: the same values to
the last bit, without the Python between them (a Newton evaluation of the Fin Ray grasp
has only tens of pairs, and the calls' overhead was most of its time).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from gripper_sim.core.barrier_kernels import edge_vertex_barrier
from gripper_sim.core.friction_kernels import friction_terms


@njit(cache=True)
def _gather(full, vertex_dofs, out):
    """out (n_d,) = full[vertex_dofs]."""
    for i in range(vertex_dofs.shape[0]):
        out[i] = full[vertex_dofs[i]]


@njit(cache=True)
def _add_at(full, vertex_dofs, part):
    """full[vertex_dofs] += part (the dofs distinct)."""
    for i in range(vertex_dofs.shape[0]):
        full[vertex_dofs[i]] += part[i]


@njit(cache=True)
def barrier_terms(q, dof_pairs, corners, edges, candidates, dhat, stiffness, mesh_dofs,
                  want_hessian, project, pattern_keys, slots, values, start, dt, eps_v,
                  friction_pairs, with_friction, friction_hessian, barrier_gradient,
                  friction_gradient, gradient, friction_into_gradient):
    """The barrier and lagged friction at positions ``q`` (2 n,) m, their gradients
    added into the state's.

    Args:
        q: (2 n,) m, the state's positions.
        dof_pairs: (n_v, 2) the dofs of each deformable vertex of the collision mesh.
        corners: (c k, 2) m, the faces' corners (the mesh's other vertices).
        edges, candidates, dhat, stiffness, mesh_dofs, project, pattern_keys: as
            ``edge_vertex_barrier``'s (mesh_dofs its ``vertex_dofs``).
        want_hessian: whether the barrier's Hessian entries are added into ``values`` at
            ``slots`` (the pattern's keys' places).
        start: (n_m, 2) m, the mesh's vertices at the step's start.  dt: s.
        eps_v: m/s, the friction's smoothing speed.
        friction_pairs: the lagged friction's (vertex ids, weights, tangents, forces,
            coefficients) (``friction_kernels.lagged_friction``).
        with_friction: whether there is friction (else ``friction_pairs`` is ignored).
        friction_hessian: whether the friction's Hessian entries are added too.
        barrier_gradient, friction_gradient: (n_d,) N over the deformable vertices' dofs
            (``dof_pairs`` raveled), written.
        gradient: (2 n,) N, the barrier's gradient added into it, and the friction's
            with ``friction_into_gradient`` (nothing added where a pair touches).

    Returns:
        (barrier value J (inf: a pair touches), friction value J, Hessian entries outside
        the pattern of the barrier, of the friction).
    """
    n_v = dof_pairs.shape[0]
    v = np.empty((n_v + corners.shape[0], 2))
    for i in range(n_v):
        v[i, 0] = q[dof_pairs[i, 0]]
        v[i, 1] = q[dof_pairs[i, 1]]
    v[n_v:] = corners
    flat_dofs = dof_pairs.reshape(2 * n_v)
    full = np.zeros(q.shape[0])
    barrier_value, barrier_outside = edge_vertex_barrier(
        v, edges, candidates, dhat, stiffness, mesh_dofs, full, want_hessian, project,
        pattern_keys, q.shape[0], slots, values)
    if not np.isfinite(barrier_value):
        return np.inf, 0.0, 0, 0
    _gather(full, flat_dofs, barrier_gradient)
    _add_at(gradient, flat_dofs, barrier_gradient)
    friction_value = 0.0
    friction_outside = 0
    if with_friction:
        ids, weights, tangents, forces, coefficients = friction_pairs
        full[:] = 0.0
        friction_value, friction_outside = friction_terms(
            v, start, dt, eps_v, ids, weights, tangents, forces, coefficients, mesh_dofs,
            full, friction_hessian, pattern_keys, q.shape[0], slots, values)
        _gather(full, flat_dofs, friction_gradient)
        if friction_into_gradient:
            _add_at(gradient, flat_dofs, friction_gradient)
    return barrier_value, friction_value, barrier_outside, friction_outside
