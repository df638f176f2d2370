"""The 2D outline measures are compiled functions (``core.measures``) that the generic
route and the compiled step both call; they equal the numpy reference
(``reference_measures2d``) to round-off."""
import numpy as np
import pytest

import reference_measures2d as reference
from gripper_sim.configuration import load_config
from gripper_sim.core import kernels
from gripper_sim.core.fast import ring_model
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.measures import (deformation, face_contact_length, held_length,
                                       jaw_normal_forces, numpy_sum, tributary_lengths)
from gripper_sim.core.obstacles import FlatFace

MODELS = (['fruit.nodes=40'], ['fruit.model=solid', 'fruit.nodes=48'])


def _pressed(fruit, seed):
    """An outline pressed flat against a face at x = 0.9 of its right extent, perturbed;
    (positions (n, 2) m, the face, the nodes it holds (n,) bool, normal forces (n,) N)."""
    rng = np.random.default_rng(seed)
    x = fruit.rest_positions + rng.normal(scale=1e-4, size=(fruit.n_nodes, 2))
    wall = 0.9 * x[fruit.surface, 0].max()
    held = np.zeros(fruit.n_nodes, bool)
    held[fruit.surface] = x[fruit.surface, 0] >= wall
    x[held, 0] = wall
    face = FlatFace('right_jaw', np.array([wall, 0.0]), np.array([-1.0, 0.0]))
    normal = np.where(held, rng.uniform(0.1, 1.0, fruit.n_nodes), 0.0)
    return x, face, held, normal


@pytest.mark.parametrize('model', MODELS, ids=['shell', 'solid'])
@pytest.mark.parametrize('seed', [0, 1])
def test_the_measures_equal_the_numpy_reference(model, seed):
    fruit = build_fruit(load_config(overrides=model))
    x, face, held, normal = _pressed(fruit, seed)
    assert held.sum() >= 3
    length = face_contact_length(fruit, x, face, np.where(held, 0, -1), 0)
    assert length > 0
    assert length == pytest.approx(reference.face_contact_length(fruit, x, face, held),
                                   rel=1e-12)
    np.testing.assert_allclose(tributary_lengths(fruit, x),
                               reference.tributary_lengths(fruit, x), rtol=1e-14)
    shape = deformation(fruit, x, normal, held)
    width, strain, peak, pressure = reference.outline(fruit, x, normal)
    assert shape.compression == pytest.approx(fruit.rest_width - width, rel=1e-12)
    assert shape.max_skin_strain == pytest.approx(strain, rel=1e-12)
    assert shape.peak_contact_pressure == pytest.approx(peak, rel=1e-12) and peak > 0
    np.testing.assert_allclose(shape.node_pressure, pressure, rtol=1e-12)
    assert shape.contact_length == pytest.approx(
        float(np.sum(reference.tributary_lengths(fruit, x)[held[fruit.surface]])), rel=1e-12)


def test_the_compiled_step_measures_with_the_same_functions():
    """``kernels.step_measures`` (the compiled step's measures) gives the outline measures
    of ``measures.deformation`` and ``face_contact_length`` bit for bit."""
    fruit = build_fruit(load_config(overrides=['fruit.nodes=40']))
    x, face, held, normal = _pressed(fruit, 3)
    n = fruit.n_nodes
    obstacle = np.where(held, 1, -1).astype(np.int64)  # face 1: the right jaw
    forces = np.zeros((n, 2))
    forces[:, 0] = -normal  # along the face normal (-1, 0)
    face_par = np.zeros((2, kernels.FP_SIZE))
    face_par[0, :2], face_par[1, :2] = (1.0, 0.0), (-1.0, 0.0)
    face_par[:, kernels.FP_JAW] = (0, 1)
    jaw_origins = np.array([[-1.0, 0.0], [face.origin[0], 0.0]])
    skin = np.ascontiguousarray(fruit.skin_edges, np.int64)
    rest = fruit.rest_positions
    rest_segments = np.hypot(*(rest[skin[:, 1]] - rest[skin[:, 0]]).T)
    normal_out, pressure, out = np.empty(n), np.empty(len(fruit.surface)), np.empty(
        kernels.M_SIZE)
    model = ring_model(fruit, fruit.energies)
    kernels.step_measures(
        x, np.zeros((n, 2)), forces, obstacle, fruit.masses, np.asarray(fruit.surface, np.int64),
        skin, rest_segments, face_par, jaw_origins, fruit.depth, *(model[key] for key in (
            'edges', 'spar', 'triples', 'bpar', 'ring', 'press', 'flesh')), np.zeros(2 * n),
        True, np.zeros(4), normal_out, pressure, out)
    shape = deformation(fruit, x, normal, held)
    assert np.array_equal(normal_out, normal)
    assert out[kernels.M_WIDTH] == fruit.rest_width - shape.compression
    assert out[kernels.M_MAX_STRAIN] == shape.max_skin_strain
    assert out[kernels.M_PEAK_PRESSURE] == shape.peak_contact_pressure
    assert np.array_equal(pressure, shape.node_pressure)
    assert out[kernels.M_CONTACT_LENGTH] == face_contact_length(fruit, x, face, obstacle, 1) > 0


@pytest.mark.parametrize('size', [0, 1, 7, 8, 14, 127, 128, 129, 300, 1000])
def test_numpy_sum_adds_as_numpy_does_to_the_bit(size):
    """The compiled sum follows numpy's pairwise order: equal to ``np.sum`` bit for bit
    (a plain running sum differs in the last bits for most of these), zeros' sign too."""
    rng = np.random.default_rng(size)
    for _ in range(20):
        values = rng.standard_normal(size) * 10.0 ** rng.uniform(-6, 6, size)
        assert numpy_sum(values, size) == np.sum(values)
        assert numpy_sum(np.append(values, 5.0), size) == np.sum(values)  # only count
    minus_zeros = np.full(size, -0.0)
    assert np.signbit(numpy_sum(minus_zeros, size)) == np.signbit(np.sum(minus_zeros))


@pytest.mark.parametrize('model', MODELS, ids=['shell', 'solid'])
def test_held_length_is_the_sum_of_the_held_tributary_lengths(model):
    fruit = build_fruit(load_config(overrides=model))
    x, _, held, _ = _pressed(fruit, 0)
    expected = float(np.sum(tributary_lengths(fruit, x)[held[fruit.surface]]))
    assert expected > 0
    assert held_length(fruit, x, held) == expected
    assert held_length(fruit, x, np.zeros(fruit.n_nodes, bool)) == 0.0


@pytest.mark.parametrize('n, d', [(40, 2), (300, 2), (60, 3)])
def test_jaw_normal_forces_are_the_normal_components_and_their_numpy_sums(n, d):
    """Each node's force along its obstacle's normal (0 where free), the nodes each jaw
    holds and each jaw's sum as ``normal[held].sum()`` gives it, bit for bit: obstacles
    0 (left jaw), 1 (right jaw) and 2 (a table, no jaw) with tilted normals."""
    rng = np.random.default_rng(n + d)
    normals = rng.standard_normal((3, d))
    normals /= np.linalg.norm(normals, axis=1)[:, None]
    side_of_obstacle = np.array([0, 1, -1, -1])
    for _ in range(5):
        obstacle = rng.integers(-1, 3, n)
        forces = rng.standard_normal((n, d)) * 10.0 ** rng.uniform(-3, 3, (n, 1))
        left, right, normal = np.empty(n, bool), np.empty(n, bool), np.empty(n)
        any_left, any_right, left_n, right_n = jaw_normal_forces(
            obstacle, forces, normals, side_of_obstacle, left, right, normal, np.empty(n))
        expected = np.zeros(n)
        for i in np.flatnonzero(obstacle >= 0):
            for c in range(d):
                expected[i] += forces[i, c] * normals[obstacle[i], c]
        assert np.array_equal(normal, expected)
        assert np.array_equal(left, obstacle == 0) and np.array_equal(right, obstacle == 1)
        assert (any_left, any_right) == (left.any(), right.any()) == (True, True)
        assert left_n == np.sum(expected[left]) and right_n == np.sum(expected[right])
    free = np.full(n, -1)
    assert jaw_normal_forces(free, forces, normals, side_of_obstacle, left, right, normal,
                             np.empty(n)) == (False, False, 0.0, 0.0)
    assert not normal.any() and not left.any() and not right.any()
