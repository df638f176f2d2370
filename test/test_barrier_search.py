"""The compiled 2D collision search (``core.barrier_search``) against ipctk's.

Candidates: on random outlines moving along random straight paths, every pair ipctk's
broad phase finds (same inflation, same patches filter) is among the compiled search's,
once each. Step bound: never past the first crossing ipctk's exact CCD finds (the
motion scaled by the bound crosses nothing), and a point falling head-on on a segment
stops at 0.8 of its time of impact. Clear paths: only motions ipctk's exact CCD finds
free of crossings, and a point pushed from far to a small gap (which the step bound
stops).
"""
import ipctk
import numpy as np
import pytest
from numba import njit

from gripper_sim.core.barrier_search import (_may_collide, collision_free_step,
                                             edge_vertex_candidates, paths_clear)

DHAT = 1e-3
EXACT = ipctk.TightInclusionCCD(1e-9, 10 ** 7, 1.0)


def _outlines(seed: int):
    """Two zig-zag outlines 0-1.2 dhat apart and their moves (up to 3 dhat): (start
    (n, 2) m, end (n, 2) m, edges (e, 2), the outline of each vertex (n,))."""
    rng = np.random.default_rng(seed)
    n = 10
    x = np.linspace(0.0, 0.01, n)
    lower = np.stack([x, -rng.uniform(0.1, 1.2, n) * DHAT], axis=1)
    upper = np.stack([x + rng.uniform(-4e-4, 4e-4, n), np.zeros(n)], axis=1)
    start = np.vstack([lower, upper])
    end = start + rng.uniform(-3 * DHAT, 3 * DHAT, start.shape)
    edges = np.array([(i, i + 1) for i in range(n - 1)]
                     + [(n + i, n + i + 1) for i in range(n - 1)])
    return start, end, edges, (np.arange(2 * n) >= n).astype(np.int64)


def _mesh(start, edges, groups):
    mesh = ipctk.CollisionMesh(np.asfortranarray(start),
                               np.asfortranarray(edges.astype(np.int32)))
    mesh.can_collide = ipctk.make_vertex_patches_filter(groups.astype(np.int32))
    return mesh


@pytest.mark.parametrize('seed', range(8))
def test_the_candidates_hold_ipctks(seed):
    start, end, edges, groups = _outlines(seed)
    mesh = _mesh(start, edges, groups)
    reference = ipctk.Candidates()
    reference.build(mesh, np.asfortranarray(start), np.asfortranarray(end), 0.5 * DHAT)
    theirs = {(c.edge_id, c.vertex_id) for c in reference.ev_candidates}
    mine = edge_vertex_candidates(start, end, edges, groups, False, 0.5 * DHAT)
    pairs = [tuple(p) for p in mine]
    assert len(pairs) == len(set(pairs))
    assert theirs and theirs <= set(pairs)
    assert all(groups[v] != groups[edges[e, 0]] for e, v in pairs)


@njit(cache=True)
def _one_sweep(v0, v1, edges, groups, same_group, radius):
    """The candidates by one sweep over all vertices in the order of their boxes' low x
    (``np.argsort``'s), each edge scanning every vertex whose low x lies in its x range
    widened by the widest box: the plain search, the reference of the order."""
    low = np.minimum(v0, v1) - radius
    high = np.maximum(v0, v1) + radius
    widest = np.max(high[:, 0] - low[:, 0])
    order = np.argsort(low[:, 0])
    sorted_low = low[order, 0]
    pairs = []
    for e in range(edges.shape[0]):
        a, b = edges[e, 0], edges[e, 1]
        e_low, e_high = np.minimum(low[a], low[b]), np.maximum(high[a], high[b])
        for k in range(np.searchsorted(sorted_low, e_low[0] - widest),
                       np.searchsorted(sorted_low, e_high[0], side='right')):
            i = order[k]
            if (high[i, 0] >= e_low[0] and low[i, 0] <= e_high[0] and high[i, 1] >= e_low[1]
                    and low[i, 1] <= e_high[1] and _may_collide(i, a, b, groups, same_group)):
                pairs.append((e, i))
    return pairs


@pytest.mark.parametrize('same_group', [False, True], ids=['across', 'within'])
@pytest.mark.parametrize('seed', range(6))
def test_the_candidates_are_the_plain_sweeps_in_its_order(seed, same_group):
    """Searching each group's vertices apart finds the pairs of one sweep over all of
    them, each edge's in the same order: four groups (one edge joining two), vertices on
    a coarse grid (many equal low x, ordered as ``np.argsort`` orders them)."""
    rng = np.random.default_rng(seed)
    n = 60
    start = rng.integers(0, 12, (n, 2)) * 1e-3
    end = start + rng.integers(-2, 3, (n, 2)) * 1e-3 * (seed % 2)
    groups = rng.integers(0, 4, n)
    other = int(np.flatnonzero(groups != groups[0])[0])  # an edge across two groups
    edges = np.array([(i, i + 1) for i in range(n - 1) if groups[i] == groups[i + 1]]
                     + [(0, other)])
    mine = [tuple(p) for p in edge_vertex_candidates(start, end, edges, groups, same_group,
                                                     1.5e-3)]
    plain = [tuple(p) for p in _one_sweep(start, end, edges, groups, same_group, 1.5e-3)]
    assert len(plain) > 50
    assert mine == plain


@pytest.mark.parametrize('seed', range(8))
def test_the_step_bound_stops_short_of_every_crossing(seed):
    start, end, edges, groups = _outlines(seed)
    mesh = _mesh(start, edges, groups)
    pairs = edge_vertex_candidates(start, end, edges, groups, False, 0.5 * DHAT)
    step = collision_free_step(start, end, edges, pairs)
    exact = ipctk.compute_collision_free_stepsize(mesh, np.asfortranarray(start),
                                                  np.asfortranarray(end),
                                                  narrow_phase_ccd=EXACT)
    assert 0.0 < step <= exact
    if exact < 1.0:
        assert step >= 0.5 * exact
    moved = np.asfortranarray(start + step * (end - start))
    assert ipctk.compute_collision_free_stepsize(
        mesh, np.asfortranarray(start), moved, narrow_phase_ccd=EXACT) == 1.0


def test_a_head_on_point_stops_at_four_fifths_of_its_impact():
    start = np.array([[0.0, 0.0], [1e-2, 0.0], [5e-3, 1e-3]])
    end = start.copy()
    end[2, 1] = -1e-3                        # through the segment at half the step
    pairs = np.array([[0, 2]])
    step = collision_free_step(start, end, np.array([[0, 1]]), pairs)
    assert step == pytest.approx(0.4, rel=1e-9)


@pytest.mark.parametrize('seed', range(8))
def test_paths_are_cleared_only_without_a_crossing(seed):
    start, end, edges, groups = _outlines(seed)
    mesh = _mesh(start, edges, groups)
    for scale in (0.05, 0.2, 1.0):
        moved = start + scale * (end - start)
        pairs = edge_vertex_candidates(start, moved, edges, groups, False, 0.5 * DHAT)
        if paths_clear(start, moved, edges, pairs):
            assert ipctk.compute_collision_free_stepsize(
                mesh, np.asfortranarray(start), np.asfortranarray(moved),
                narrow_phase_ccd=EXACT) == 1.0


def test_a_point_pushed_to_a_small_gap_is_cleared_and_one_through_is_not():
    start = np.array([[0.0, 0.0], [1e-2, 0.0], [5e-3, 50 * DHAT]])
    edges, pairs = np.array([[0, 1]]), np.array([[0, 2]])
    end = start.copy()
    end[2, 1] = 0.5 * DHAT                   # pushed ahead of the segment
    assert collision_free_step(start, end, edges, pairs) < 1.0
    assert paths_clear(start, end, edges, pairs)
    for stop in (0.0, -DHAT):                # onto the segment, through it
        end[2, 1] = stop
        assert not paths_clear(start, end, edges, pairs)
