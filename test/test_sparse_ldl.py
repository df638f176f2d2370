"""The sparse block LDL^T (core/sparse_ldl.py) against dense numpy solves."""
import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee
from scipy.spatial import Delaunay

from gripper_sim.configuration import load_config
from gripper_sim.core import sparse_ldl
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.pattern_keys import sorted_unique


def _mesh(n_points: int, seed: int):
    """A Delaunay triangle mesh of random points: (triangles (n_tri, 3), edges (m, 2))."""
    points = np.random.default_rng(seed).random((n_points, 2))
    tri = Delaunay(points).simplices
    return tri, np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]])


def _assemble(pattern, tri, block, rng, shift=0.1, definite=True):
    """Random symmetric element matrices on the triangles, assembled through the
    pattern's scatter map and densely: (values, dense A)."""
    n = pattern.n_nodes
    m = 3 * block
    values = pattern.new_values()
    dense = np.zeros((n * block, n * block))
    dofs = (block * tri[:, :, None] + np.arange(block)).reshape(len(tri), m)
    scatter = pattern.scatter(tri)
    for e in range(len(tri)):
        g = rng.standard_normal((m, m))
        local = g @ g.T if definite else g + g.T
        np.add.at(values.reshape(-1), scatter[e], local.ravel())
        dense[np.ix_(dofs[e], dofs[e])] += local
    diagonal = shift + rng.random(n * block)
    dense += np.diag(diagonal)
    for i in range(n):
        values[pattern.position[i]] += np.diag(diagonal[block * i:block * (i + 1)])
    return values, dense


@pytest.mark.parametrize('block', [1, 2, 3])
@pytest.mark.parametrize('seed', [0, 1])
def test_solves_random_spd_mesh_matrices_as_numpy(block, seed):
    tri, pairs = _mesh(150, seed)
    pattern = sparse_ldl.analyse(150, pairs, block)
    rng = np.random.default_rng(seed)
    values, dense = _assemble(pattern, tri, block, rng)
    ldl = sparse_ldl.SparseLDL(pattern)
    assert ldl.factorise(values) == 0  # positive definite: no indefinite pivot
    rhs = rng.standard_normal((150 * block, 3))
    x = ldl.solve(rhs)
    expected = np.linalg.solve(dense, rhs)
    assert np.abs(expected).max() > 1e-3
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-10 * np.abs(expected).max())
    product = np.empty(150 * block)
    sparse_ldl.multiply(pattern.arrays, values, rhs[:, 0].copy(), product)
    np.testing.assert_allclose(product, dense @ rhs[:, 0], rtol=1e-12, atol=1e-12)


def test_scatter_sends_the_upper_side_to_the_sink():
    tri, pairs = _mesh(40, 3)
    pattern = sparse_ldl.analyse(40, pairs, 2)
    scatter = pattern.scatter(tri)
    sink = pattern.sink * 4
    # of a triangle's 36 entries, 3 diagonal blocks and 3 lower blocks are stored
    assert np.all(np.sum(scatter >= sink, axis=1) == 12)
    assert scatter.max() < sink + 4
    stored = scatter[scatter < sink]
    assert stored.min() >= 0 and len(np.unique(stored)) > 0.5 * len(stored) / 6


def test_an_indefinite_matrix_is_reported_and_still_solved():
    tri, pairs = _mesh(80, 4)
    pattern = sparse_ldl.analyse(80, pairs, 2)
    rng = np.random.default_rng(4)
    values, dense = _assemble(pattern, tri, 2, rng, shift=-3.0, definite=False)
    ldl = sparse_ldl.SparseLDL(pattern)
    status = ldl.factorise(values)
    assert np.min(np.linalg.eigvalsh(dense)) < 0
    assert status > 0  # pivots that are not positive definite, counted
    rhs = rng.standard_normal(160)
    np.testing.assert_allclose(dense @ ldl.solve(rhs), rhs, atol=1e-8)


def test_a_singular_pivot_is_reported_with_its_position():
    tri, pairs = _mesh(30, 5)
    pattern = sparse_ldl.analyse(30, pairs, 2)
    values, _ = _assemble(pattern, tri, 2, np.random.default_rng(5))
    # the node at position 3 decoupled with a zero block: the pivot there is singular
    k = 3
    rows = np.repeat(np.arange(30), np.diff(pattern.a_ptr))
    values[k] = 0.0
    values[30:pattern.n_blocks][(rows == k) | (pattern.a_col == k)] = 0.0
    assert sparse_ldl.SparseLDL(pattern).factorise(values) == -1 - k


def test_a_non_finite_value_is_a_failed_factorisation():
    tri, pairs = _mesh(30, 6)
    pattern = sparse_ldl.analyse(30, pairs, 3)
    values, _ = _assemble(pattern, tri, 3, np.random.default_rng(6))
    values[pattern.n_nodes - 1, 1, 1] = np.nan
    assert sparse_ldl.SparseLDL(pattern).factorise(values) == -pattern.n_nodes


def test_minimum_degree_fills_less_than_the_solid_fruits_band():
    config = load_config(overrides=['fruit.model=solid'])
    fruit = build_fruit(config)
    tri = fruit.flesh.tri
    n = fruit.n_nodes
    pairs = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]],
                            fruit.skin_edges])
    graph = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    rcm = reverse_cuthill_mckee((graph + graph.T).tocsr(), symmetric_mode=True)
    position = np.empty(n, np.int64)
    position[rcm] = np.arange(n)
    half_bandwidth = int(np.max(np.abs(position[pairs[:, 0]] - position[pairs[:, 1]])))
    minimum = sparse_ldl.analyse(n, pairs, 2)
    envelope = sparse_ldl.analyse(n, pairs, 2, order=rcm)  # RCM's own fill (its envelope)
    assert minimum.n_factor < 0.7 * envelope.n_factor
    assert envelope.n_factor < n * half_bandwidth  # the band holds more than the envelope


def test_minimum_degree_of_a_path_makes_no_fill():
    n = 12
    pairs = np.stack([np.arange(n - 1), np.arange(1, n)], axis=1)
    order = sparse_ldl.minimum_degree(n, pairs)
    assert sorted(order.tolist()) == list(range(n))
    assert sparse_ldl.analyse(n, pairs, 1, order=order).n_factor == n - 1


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_the_symbolic_factorisation_is_the_fill_of_dense_elimination(seed):
    """L's pattern, by columns and by rows, and the elimination tree equal those of an
    elimination on a dense boolean matrix (each eliminated node's later neighbours made
    a clique), on a random graph in a random order."""
    rng = np.random.default_rng(seed)
    n = 60
    pairs = rng.integers(0, n, size=(90, 2))
    order = rng.permutation(n)
    pattern = sparse_ldl.analyse(n, pairs, 2, order=order)
    position = pattern.position
    filled = np.zeros((n, n), bool)
    filled[position[pairs[:, 0]], position[pairs[:, 1]]] = True
    filled |= filled.T
    for k in range(n):
        later = np.flatnonzero(filled[k + 1:, k]) + k + 1
        filled[np.ix_(later, later)] = True
    lower = np.tril(filled, -1)
    for column in range(n):
        rows = pattern.l_row[pattern.l_ptr[column]:pattern.l_ptr[column + 1]]
        assert rows.tolist() == np.flatnonzero(lower[:, column]).tolist()
        below = np.flatnonzero(lower[:, column])
        assert pattern.parent[column] == (below[0] if below.size else -1)
    for row in range(n):
        columns = pattern.r_col[pattern.r_ptr[row]:pattern.r_ptr[row + 1]]
        assert columns.tolist() == np.flatnonzero(lower[row]).tolist()
        at = pattern.r_index[pattern.r_ptr[row]:pattern.r_ptr[row + 1]]
        assert pattern.l_row[at].tolist() == [row] * len(columns)


@pytest.mark.parametrize('keys', [np.zeros(0, np.int64), np.array([7]), np.array([[3, 1], [3, 2]]),
                                  np.random.default_rng(0).integers(0, 40, (50, 6)),
                                  np.random.default_rng(1).integers(0, 10**12, 10**5)])
def test_sorted_unique_is_numpys_unique(keys):
    got, expected = sorted_unique(keys), np.unique(keys)
    assert got.dtype == expected.dtype and np.array_equal(got, expected)


def test_bad_patterns_are_refused():
    with pytest.raises(ValueError, match='pairs'):
        sparse_ldl.analyse(3, [[0, 3]], 2)
    with pytest.raises(ValueError, match='permutation'):
        sparse_ldl.analyse(3, [[0, 1]], 2, order=[0, 0, 1])
    pattern = sparse_ldl.analyse(3, [[0, 1]], 2)
    with pytest.raises(ValueError, match='outside the pattern'):
        pattern.block_index(np.array([0]), np.array([2]))
