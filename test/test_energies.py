"""Every 2D energy's one implementation (its numba kernel): gradient and Hessian against
central differences, and value, gradient and Hessian against the numpy references of
``reference_energies2d.py``."""
import numpy as np
import pytest

from gripper_sim.core.energies import (EnclosedAreaPressure, Gravity, NeoHookeanTriangles,
                                       RingBending, Stretching)
from gripper_sim.core.energies.bending import turning_angles as ring_turning_angles
from gripper_sim.core.mesh import mesh_outline
from gripper_sim.core.obstacles import FlatFace
from gripper_sim.core.pad import PadLayer
from gripper_sim.geometry.shapes import circle

from helpers import kernel_evaluation
from reference_pad2d import PadStep
from reference_energies2d import dense_hessian, enclosed_area, reference, turning_angles, von_mises

RNG = np.random.default_rng(42)


def _ring(n=12, radius=0.03):
    x0 = circle(2 * radius, n)
    ring = np.arange(n)
    edges = np.stack([ring, np.roll(ring, -1)], axis=1)
    rest = np.linalg.norm(x0[edges[:, 1]] - x0[edges[:, 0]], axis=1)
    return x0, ring, edges, rest


def _perturbed(x0, scale):
    return (x0 + RNG.normal(scale=scale, size=x0.shape)).ravel()


def _energies():
    x0, ring, edges, rest = _ring()
    nodes, tri = mesh_outline(circle(0.06, 16), 1.3)
    return [
        ('stretching', Stretching(edges, rest, 1500.0), _perturbed(x0, 2e-3)),
        ('bending', RingBending(ring, x0, 0.02), _perturbed(x0, 2e-3)),
        ('pressure', EnclosedAreaPressure(ring, np.pi * 0.03 ** 2, 0.04, 2e4, 3e6),
         _perturbed(x0, 2e-3)),
        ('neo-hookean', NeoHookeanTriangles(tri, nodes, 2e6, 0.38, 0.04),
         _perturbed(nodes, 5e-4)),
        ('gravity', Gravity(np.full(len(x0), 0.01), 9.81), _perturbed(x0, 2e-3)),
    ]


@pytest.mark.parametrize('name,energy,q', _energies(), ids=[e[0] for e in _energies()])
def test_gradient_matches_central_differences(name, energy, q):
    h = 1e-7
    grad = energy.gradient(q)
    fd = np.array([(energy.value(q + h * e) - energy.value(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(grad)) > 1e-6, 'gradient is trivially zero'
    assert np.max(np.abs(grad - fd)) <= 1e-6 * np.max(np.abs(grad))


@pytest.mark.parametrize('name,energy,q', _energies()[:4], ids=[e[0] for e in _energies()[:4]])
def test_hessian_matches_central_differences(name, energy, q):
    h = 1e-7
    hess = energy.hessian(q)
    fd = np.array([(energy.gradient(q + h * e) - energy.gradient(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(hess)) > 1e-3, 'Hessian is trivially zero'
    assert np.max(np.abs(hess - fd)) <= 1e-6 * np.max(np.abs(hess))
    assert np.allclose(hess, hess.T, atol=1e-9 * np.max(np.abs(hess)))


def test_energies_vanish_at_rest_shape():
    x0, ring, edges, rest = _ring()
    for energy in (Stretching(edges, rest, 1500.0), RingBending(ring, x0, 0.02)):
        assert energy.value(x0.ravel()) == pytest.approx(0.0, abs=1e-15)
        assert np.max(np.abs(energy.gradient(x0.ravel()))) < 1e-10


def test_inverted_triangle_has_infinite_energy():
    nodes, tri = mesh_outline(circle(0.06, 16), 1.3)
    flesh = NeoHookeanTriangles(tri, nodes, 2e6, 0.38, 0.04)
    flipped = nodes.copy()
    flipped[:, 0] *= -1  # mirror: every triangle turns clockwise
    assert flesh.value(flipped.ravel()) == np.inf


def _pad_in_contact():
    """A pad layer on a face of normal +x that the perturbed ring presses into and slides
    along: every term of the pad energy (penalty, static and kinetic friction) active."""
    x0, ring, _, _ = _ring()
    pad = PadLayer(ring, np.full(len(ring), 0.015), 0.04, 2e-3, 2e5, 0.45, 0.8, len(x0))
    face = FlatFace('left_jaw', np.array([x0[:, 0].min() - 1.5e-3, 0.0]),
                    np.array([1.0, 0.0]), half_length=0.05, thickness=0.01)
    moved = FlatFace('left_jaw', face.origin + np.array([1e-4, 2e-5]), face.normal,
                     half_length=0.05, thickness=0.01, velocity=np.array([0.1, 0.02]))
    pad.begin_step(x0, [(face, 0, 0)], [(moved, 0, 0)], 1e-3)
    q = (x0 + np.random.default_rng(7).normal(scale=1e-5, size=x0.shape)).ravel()
    return pad, q, PadStep(pad, x0, [(face, 0, 0)], [(moved, 0, 0)], 1e-3)


def _compiled_cases():
    return _energies() + [('pad', *_pad_in_contact()[:2])]


@pytest.mark.parametrize('name,energy,q', _compiled_cases(),
                         ids=[e[0] for e in _compiled_cases()])
def test_compiled_kernel_matches_the_numpy_reference(name, energy, q):
    """Each energy's ``evaluate_into`` (what the solvers run) gives the value, gradient
    and Hessian of its numpy reference, and so do
    ``evaluate``, ``value``, ``gradient`` and ``hessian`` (built on it)."""
    value, grad, hess = kernel_evaluation(energy, q)
    ref = _pad_in_contact()[2].evaluate(q) if name == 'pad' else reference(energy, q)
    ref_hess = dense_hessian(ref, q.size)
    assert value == pytest.approx(ref.value, rel=1e-12, abs=1e-18)
    assert energy.value(q) == pytest.approx(value, rel=1e-12, abs=1e-18)
    assert np.max(np.abs(grad)) > 0, 'gradient is trivially zero'
    assert np.max(np.abs(grad - ref.gradient)) <= 1e-12 * np.max(np.abs(grad))
    if energy.dofs is not None:
        assert np.max(np.abs(ref_hess)) > 0, 'Hessian is trivially zero'
    assert np.max(np.abs(hess - ref_hess)) <= 1e-11 * max(np.max(np.abs(ref_hess)), 1.0)
    triplets = energy.evaluate(q)
    assert triplets.value == value and np.array_equal(triplets.gradient, grad)
    assert np.max(np.abs(energy.hessian(q) - hess)) <= 1e-12 * max(np.max(np.abs(hess)), 1.0)
    assert np.array_equal(energy.gradient(q), grad)
    value_only, grad_only, untouched = kernel_evaluation(energy, q, hessian=False)
    assert value_only == value and np.array_equal(grad_only, grad)
    assert not np.any(untouched)


def test_compiled_von_mises_matches_the_numpy_reference():
    nodes, tri = mesh_outline(circle(0.06, 16), 1.3)
    flesh = NeoHookeanTriangles(tri, nodes, 2e6, 0.38, 0.04)
    q = _perturbed(nodes, 5e-4)
    stress = flesh.von_mises(q)
    assert np.max(stress) > 0
    np.testing.assert_allclose(stress, von_mises(flesh, q), rtol=1e-12)


def test_compiled_turning_angles_and_pressure_match_the_numpy_reference():
    x0, ring, _, _ = _ring()
    x = _perturbed(x0, 2e-3).reshape(-1, 2)
    triples = np.stack([np.roll(ring, 1), ring, np.roll(ring, -1)], axis=1)
    angles = ring_turning_angles(x, triples)
    assert np.all(angles > 0)  # a counter-clockwise ring turns left everywhere
    np.testing.assert_allclose(angles, turning_angles(x, triples), rtol=1e-13)
    pressure = EnclosedAreaPressure(ring, np.pi * 0.03 ** 2, 0.04, 2e4, 3e6)
    expected = 2e4 - 3e6 * (enclosed_area(x, ring) - pressure.a0) / pressure.a0
    assert pressure.pressure(x.ravel()) == pytest.approx(expected, rel=1e-12)
    assert abs(expected - 2e4) > 100  # the perturbation changes the area


def test_compiled_kernel_of_an_inverted_triangle_is_infinite_and_adds_nothing():
    nodes, tri = mesh_outline(circle(0.06, 16), 1.3)
    flesh = NeoHookeanTriangles(tri, nodes, 2e6, 0.38, 0.04)
    x = nodes.copy()
    x[tri[0, 0]], x[tri[0, 1]] = nodes[tri[0, 1]], nodes[tri[0, 0]]
    value, grad, hess = kernel_evaluation(flesh, x.ravel())
    assert value == np.inf and not np.any(grad) and not np.any(hess)
