"""The compiled 2D barrier (``core.barrier_kernels``) equals ipctk's, term by term.

Random outlines pressed within dhat of each other (point-line and point-point pairs,
several candidates sharing an end point), each evaluated by ipctk (its candidates,
collision set, ``BarrierPotential`` with the physical barrier, the Hessian projected by
clamping) and by the kernel on the same candidates: value, gradient and Hessian agree
to 1e-10 relative. A self-contact's quiet test measures each vertex's move against its
body's mean move: a body carried along rigidly has not moved. The faces holding the
loaded nodes and the sticking marks equal their numpy references, as do the held nodes'
normal forces, the mean gap of a face's nodes and the start pushed ahead of a moving face.
"""
import ipctk
import numpy as np
import pytest

from gripper_sim.core.barrier_kernels import (add_local_hessian, edge_vertex_barrier,
                                              kept_step_bound, largest_relative_move,
                                              mark_sticking, mean_gap, nearest_faces,
                                              normal_components, push_ahead,
                                              relative_moves_within, same_values)
from gripper_sim.core.barrier_search import collision_free_step

DHAT = 1e-3
KAPPA = 0.1


def _mesh(seed: int):
    """A zig-zag outline below a flat one, within dhat of each other in places: (the
    vertices (n, 2) m, the edges (e, 2))."""
    rng = np.random.default_rng(seed)
    n = 8
    x = np.linspace(0.0, 0.01, n)
    lower = np.stack([x, -rng.uniform(0.1, 1.2, n) * DHAT], axis=1)
    upper = np.stack([x + rng.uniform(-4e-4, 4e-4, n), np.zeros(n)], axis=1)
    vertices = np.vstack([lower, upper])
    edges = np.array([(i, i + 1) for i in range(n - 1)]
                     + [(n + i, n + i + 1) for i in range(n - 1)])
    return vertices, edges


@pytest.mark.parametrize('seed', range(6))
def test_the_compiled_barrier_equals_ipctks(seed):
    vertices, edges = _mesh(seed)
    n = len(vertices)
    v = np.asfortranarray(vertices)
    mesh = ipctk.CollisionMesh(v, np.asfortranarray(edges.astype(np.int32)))
    patches = (np.arange(n) >= n // 2).astype(np.int32)
    mesh.can_collide = ipctk.make_vertex_patches_filter(patches)
    candidates = ipctk.Candidates()
    candidates.build(mesh, v, 0.5 * DHAT)
    collisions = ipctk.NormalCollisions()
    collisions.build(candidates, mesh, v, DHAT)
    assert len(collisions.ev_collisions) and len(collisions.vv_collisions)
    potential = ipctk.BarrierPotential(DHAT, KAPPA, True)
    value = potential(collisions, mesh, v)
    gradient = potential.gradient(collisions, mesh, v)
    hessian = potential.hessian(collisions, mesh, v, ipctk.PSDProjectionMethod.CLAMP).toarray()

    pairs = np.array([(c.edge_id, c.vertex_id) for c in candidates.ev_candidates], np.int64)
    n_dof = 2 * n
    dofs = np.arange(n_dof).reshape(n, 2)
    keys = np.arange(n_dof ** 2, dtype=np.int64)          # a full pattern
    mine = np.zeros(n_dof)
    matrix = np.zeros(n_dof ** 2)
    total, outside = edge_vertex_barrier(vertices, edges.astype(np.int64), pairs, DHAT, KAPPA,
                                         dofs, mine, True, True, keys, n_dof, keys, matrix)
    assert outside == 0
    matrix = matrix.reshape(n_dof, n_dof).T           # keys are col n_dof + row

    assert total == pytest.approx(value, rel=1e-10)
    scale = np.max(np.abs(gradient))
    assert np.max(np.abs(mine - gradient)) <= 1e-10 * scale
    assert np.max(np.abs(matrix - hessian)) <= 1e-10 * np.max(np.abs(hessian))


def test_a_touching_pair_is_infinite():
    vertices = np.array([[0.0, 0.0], [1e-3, 0.0], [5e-4, 0.0]])
    edges = np.array([[0, 1]])
    total, _ = edge_vertex_barrier(vertices, edges, np.array([[0, 2]]), DHAT, KAPPA,
                                   np.arange(6).reshape(3, 2), np.zeros(6), False, True,
                                   np.zeros(0, np.int64), 6, np.zeros(0, np.int64),
                                   np.zeros(0))
    assert total == np.inf


def test_a_bodys_move_is_measured_against_its_mean_move():
    start = np.arange(16, dtype=float).reshape(8, 2) * 1e-3
    body = np.repeat([0, 1], 4)
    dofs = np.arange(16).reshape(8, 2)
    q = start.copy()
    q[body == 1] += [1.0, 2.0]                       # the second body carried along
    assert largest_relative_move(q.ravel(), dofs, start, body, 2) == pytest.approx(0.0,
                                                                                    abs=1e-12)
    q[0, 0] += 4e-3                                  # one vertex of the first body moves
    assert largest_relative_move(q.ravel(), dofs, start, body, 2) == pytest.approx(3e-3)


@pytest.mark.parametrize('adjacent', [True, False])
def test_a_local_hessian_adds_where_the_pattern_has_its_keys(adjacent):
    """Each entry of a pair's local Hessian adds at its key's slot, fixed coordinates (-1)
    are skipped and keys missing from the pattern are counted (a vertex's y dof next to
    its x dof, one search for both, or not)."""
    n_dof = 12
    dofs = (np.array([[0, 1], [4, 5], [8, 9]]) if adjacent
            else np.array([[0, 7], [4, 2], [8, 11]]))
    dofs[1, 1] = -1                                  # a fixed coordinate
    rng = np.random.default_rng(4)
    local = rng.normal(size=(6, 6))
    dense = np.zeros((n_dof, n_dof))                 # [row, col]
    for a in range(6):
        for b in range(6):
            row, col = dofs[a // 2, a % 2], dofs[b // 2, b % 2]
            if row >= 0 and col >= 0:
                dense[row, col] += local[a, b]
    keys = np.flatnonzero(dense.T.ravel() != 0.0)   # col n_dof + row, sorted
    missing = keys[[3, 10, 11]]
    kept = np.setdiff1d(keys, missing)
    slots = rng.permutation(kept.size)
    values = np.zeros(kept.size)
    outside = add_local_hessian(local, np.array([0, 1, 2]), 3, dofs, n_dof, kept, slots,
                                values)
    assert outside == missing.size
    expected = dense.T.ravel()[kept]
    assert np.array_equal(values[slots], expected)


def test_the_kept_step_bound_is_the_ccd_over_the_kept_pairs_or_none():
    """Within the margin of where the pairs were sought the bound is
    ``collision_free_step``'s over them, vertices gathered from the state and the faces'
    corners after them; a vertex beyond the margin at either end gives -1."""
    vertices, edges = _mesh(2)
    n = len(vertices)
    dofs = np.arange(2 * n).reshape(n, 2)[:n - 2]  # the last two vertices: a face's corners
    corners = vertices[n - 2:].copy()
    q = vertices[:n - 2].ravel().copy()
    pairs = np.array([(e, i) for e in range(len(edges)) for i in range(n)
                      if i not in edges[e]], np.int64)
    dq = np.zeros_like(q)
    dq[1::2] = 2e-3                                  # the lower outline up through the upper
    margin = 1.0
    bound = kept_step_bound(q, dq, dofs, corners, edges, vertices[:n - 2], pairs, margin)
    end = vertices.copy()
    end[:n - 2] += dq.reshape(-1, 2)
    assert 0.0 < bound < 1.0
    assert bound == collision_free_step(vertices, end, edges, pairs)
    assert kept_step_bound(q, dq, dofs, corners, edges, vertices[:n - 2], pairs,
                           1e-3) == -1.0


def test_quiet_along_a_step_and_equal_values():
    start = np.zeros((4, 2))
    dofs = np.arange(8).reshape(4, 2)
    body = np.zeros(4, np.int64)
    q = np.zeros(8)
    step = np.zeros(8)
    step[0] = 2e-3                                   # vertex 0 moves 2 mm, the mean 0.5 mm
    assert relative_moves_within(q, np.zeros(0), dofs, start, body, 1, 1e-3)
    assert not relative_moves_within(q, step, dofs, start, body, 1, 1e-3)
    assert relative_moves_within(q, step, dofs, start, body, 1, 2e-3)
    assert same_values(q, np.zeros(8)) and not same_values(q, step)
    assert not same_values(np.full(2, np.nan), np.full(2, np.nan))


def _nearest_faces_reference(x, forces, origins, normals, tangents, half, dhat):
    """numpy: each loaded node's nearest face within dhat (the distance to its segment or
    rectangle), -1 else."""
    holder = -np.ones(len(x), np.int64)
    best = np.full(len(x), np.inf)
    loaded = np.flatnonzero(np.any(forces != 0.0, axis=1))
    for k in range(len(origins)):
        rel = x[loaded] - origins[k]
        along = rel @ tangents[k].T
        outside = along - np.clip(along, -half[k], half[k])
        dist = np.sqrt((rel @ normals[k]) ** 2 + np.sum(outside ** 2, axis=1))
        closer = (dist < dhat) & (dist < best[loaded])
        holder[loaded[closer]] = k
        best[loaded[closer]] = dist[closer]
    return holder


@pytest.mark.parametrize('d', [2, 3])
def test_the_nearest_faces_are_the_references(d):
    rng = np.random.default_rng(d)
    n, k = 400, 5
    x = rng.uniform(-2e-3, 2e-3, (n, d))
    forces = np.where(rng.random((n, 1)) < 0.7, rng.normal(size=(n, d)), 0.0)
    normals = rng.normal(size=(k, d))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    tangents = np.empty((k, d - 1, d))
    for f in range(k):  # an orthonormal basis of the face's plane
        basis = np.linalg.svd(normals[f][None])[2][1:]
        tangents[f] = basis
    origins = rng.uniform(-1e-3, 1e-3, (k, d))
    half = rng.uniform(2e-4, 2e-3, (k, d - 1))
    holder = np.empty(n, np.int64)
    nearest_faces(x, forces, origins, normals, tangents, half, DHAT, holder)
    expected = _nearest_faces_reference(x, forces, origins, normals, tangents, half, DHAT)
    assert np.count_nonzero(expected >= 0) > n // 4
    np.testing.assert_array_equal(holder, expected)


def test_the_sticking_marks_are_the_references():
    rng = np.random.default_rng(3)
    n, k, eps = 300, 4, 1e-3
    v = rng.normal(scale=2e-3, size=(n, 2))
    obstacle = rng.integers(-1, k, n)
    normals = rng.normal(size=(k, 2))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    velocities = rng.normal(scale=1e-3, size=(k, 2))
    mode = np.zeros(n, np.int64)
    mark_sticking(v, obstacle, normals, velocities, eps, 1, 2, mode)
    held = np.flatnonzero(obstacle >= 0)
    relative = v[held] - velocities[obstacle[held]]
    along = relative - np.sum(relative * normals[obstacle[held]], axis=1)[:, None] * normals[
        obstacle[held]]
    expected = np.zeros(n, np.int64)
    expected[held] = np.where(np.linalg.norm(along, axis=1) < eps, 1, 2)
    assert 0 < np.count_nonzero(expected == 1) < held.size
    np.testing.assert_array_equal(mode, expected)


def _random_face(rng, d):
    """A face's origin, unit normal (d,), orthonormal tangents (d - 1, d) and half
    extents (d - 1,) m, near the origin."""
    normal = rng.normal(size=d)
    normal /= np.linalg.norm(normal)
    tangents = np.linalg.svd(normal[None])[2][1:]
    return rng.uniform(-1e-3, 1e-3, d), normal, tangents, rng.uniform(5e-4, 2e-3, d - 1)


def test_the_held_normal_forces_and_mean_gaps_are_the_references():
    rng = np.random.default_rng(5)
    n, k = 200, 3
    x = rng.uniform(-2e-3, 2e-3, (n, 2))
    forces = rng.normal(size=(n, 2))
    holder = rng.integers(-1, k, n)
    faces = [_random_face(rng, 2) for _ in range(k)]
    normals = np.array([face[1] for face in faces])
    normal_force = np.full(n, 7.0)
    normal_components(holder, forces, normals, normal_force)
    held = holder >= 0
    np.testing.assert_allclose(normal_force[held],
                               np.sum(forces[held] * normals[holder[held]], axis=1),
                               rtol=1e-12, atol=1e-15)
    assert np.all(normal_force[~held] == 7.0)  # the others left as they were
    for face, (origin, normal, _, _) in enumerate(faces):
        mine = holder == face
        assert np.count_nonzero(mine) > 0
        assert mean_gap(x, holder, face, origin, normal) == pytest.approx(
            np.mean((x[mine] - origin) @ normal), rel=1e-12)
    assert mean_gap(x, holder, k, faces[0][0], faces[0][1]) == 0.0  # a face holding none


def _pushed_reference(x_n, surface, origin, normal, tangents, half, thickness, shift, dhat,
                      fraction, predicted=None):
    """The start pushed ahead of a face moving by ``shift`` in numpy (as
    ``BarrierContact.pushed_start`` computed it before the kernel), from ``predicted``
    (none: x_n, the touching nodes moved with the face, their gap kept, where it recedes
    too)."""
    start = (x_n if predicted is None else predicted).copy()
    rel = x_n[surface] - origin
    covered = (np.all(np.abs(rel @ tangents.T) <= half, axis=1) & (rel @ normal > -thickness))
    nodes = surface[covered]
    gap = (x_n[nodes] - origin) @ normal
    move = (start[nodes] - x_n[nodes]) @ normal
    advance = float(shift @ normal)
    target = np.where(gap < dhat, gap, fraction * dhat)
    push = np.maximum(advance - gap - move + target, 0.0)
    front = gap >= 0
    touching = front & (gap < dhat)
    pushed = front if predicted is not None else front & ~touching
    start[nodes[pushed]] += push[pushed, None] * normal
    if predicted is None:
        start[nodes[touching]] += shift
    return start


def _random_start(rng, d):
    """A face, nodes in front of it, behind it and beside it (some within dhat of it), the
    outline's nodes among them and the face's shift."""
    n = 300
    origin, normal, tangents, half = _random_face(rng, d)
    x_n = origin + rng.uniform(-3e-3, 3e-3, (n, d))
    near = rng.random(n) < 0.3
    x_n[near] += (rng.uniform(0.0, DHAT, near.sum())
                  - (x_n[near] - origin) @ normal)[:, None] * normal
    surface = np.sort(rng.choice(n, 250, replace=False)).astype(np.int64)
    shift = 4e-4 * normal + rng.normal(scale=2e-4, size=d)
    return x_n, surface, origin, normal, tangents, half, shift


def _pushed(x_n, surface, origin, normal, tangents, half, shift, predicted=None):
    """``push_ahead`` for one face of thickness 1 mm and a face beside it standing still:
    (the start from x_n, the one from ``predicted`` or None)."""
    d = x_n.shape[1]
    faces = (np.stack([origin, origin + 1e-3]), np.stack([normal, normal]),
             np.stack([tangents, tangents]), np.stack([half, half]), np.full(2, 1e-3),
             np.stack([shift, np.zeros(d)]))
    plain = x_n.copy()
    ahead = np.zeros((0, 0)) if predicted is None else predicted.copy()
    push_ahead(x_n, surface, *faces, DHAT, 0.5, plain, ahead)
    return plain, (None if predicted is None else ahead)


@pytest.mark.parametrize('d', [2, 3])
def test_the_start_pushed_ahead_of_a_moving_face_is_the_reference(d):
    rng = np.random.default_rng(10 + d)
    x_n, surface, origin, normal, tangents, half, shift = _random_start(rng, d)
    start, _ = _pushed(x_n, surface, origin, normal, tangents, half, shift)
    expected = _pushed_reference(x_n, surface, origin, normal, tangents, half, 1e-3, shift,
                                 DHAT, 0.5)
    moved = np.any(expected != x_n, axis=1)
    assert 10 < np.count_nonzero(moved) < len(surface)
    np.testing.assert_allclose(start, expected, rtol=0, atol=1e-15)


@pytest.mark.parametrize('d', [2, 3])
def test_the_nodes_touching_a_receding_face_start_where_it_takes_them(d):
    """A face moving away (a jaw opening on a fruit squeezed past its command) takes the
    nodes within dhat of it along, their gap kept: left behind, they started beyond the
    barrier's reach and Newton's first step, with no barrier in its model, went through
    the face (the 3D solid apple at 120 N: no convergence). Nodes further off, behind
    the face or beside it stay at x_n."""
    rng = np.random.default_rng(30 + d)
    x_n, surface, origin, normal, tangents, half, shift = _random_start(rng, d)
    shift = shift - 8e-4 * normal   # receding
    assert shift @ normal < 0
    start, _ = _pushed(x_n, surface, origin, normal, tangents, half, shift)
    rel = x_n[surface] - origin
    gap = rel @ normal
    covered = np.all(np.abs(rel @ tangents.T) <= half, axis=1)
    touching = surface[covered & (gap >= 0) & (gap < DHAT)]
    assert len(touching) > 10
    np.testing.assert_allclose(start[touching], x_n[touching] + shift, rtol=0, atol=1e-15)
    np.testing.assert_allclose((start[touching] - origin - shift) @ normal,
                               (x_n[touching] - origin) @ normal, rtol=0, atol=1e-15)
    others = np.setdiff1d(np.arange(len(x_n)), touching)
    np.testing.assert_array_equal(start[others], x_n[others])
    np.testing.assert_allclose(start, _pushed_reference(
        x_n, surface, origin, normal, tangents, half, 1e-3, shift, DHAT, 0.5),
        rtol=0, atol=1e-15)


@pytest.mark.parametrize('d', [2, 3])
def test_a_predicted_start_is_pushed_only_as_far_as_the_face_needs(d):
    """From the predictor (each node's own move besides the face's), a covered node in
    front of the face ends at least its gap (below dhat) or dhat / 2 ahead of the face
    where it ends; the others keep their predicted places (a face standing still pushes
    none), and the start from x_n is the one without a prediction."""
    rng = np.random.default_rng(20 + d)
    x_n, surface, origin, normal, tangents, half, shift = _random_start(rng, d)
    predicted = x_n + rng.normal(scale=4e-4, size=x_n.shape)
    plain, start = _pushed(x_n, surface, origin, normal, tangents, half, shift, predicted)
    expected = _pushed_reference(x_n, surface, origin, normal, tangents, half, 1e-3, shift,
                                 DHAT, 0.5, predicted)
    np.testing.assert_allclose(start, expected, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(plain, _pushed(x_n, surface, origin, normal, tangents,
                                                 half, shift)[0])
    rel = x_n[surface] - origin
    gap = rel @ normal
    front = surface[(gap >= 0) & np.all(np.abs(rel @ tangents.T) <= half, axis=1)]
    moved = np.any(start != predicted, axis=1)
    assert np.count_nonzero(moved) >= 3 and not np.any(moved[np.setdiff1d(
        np.arange(len(x_n)), front)])
    gap_n = (x_n[front] - origin) @ normal
    ends = (start[front] - origin - shift) @ normal
    assert np.all(ends >= np.minimum(gap_n, 0.5 * DHAT) - 1e-15)
