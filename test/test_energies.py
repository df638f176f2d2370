"""Finite-difference checks of every energy's gradient and Hessian."""
import numpy as np
import pytest

from gripper_sim.core.energies import (EnclosedAreaPressure, Gravity, NeoHookeanTriangles,
                                       RingBending, Stretching)
from gripper_sim.core.mesh import mesh_outline
from gripper_sim.core.shapes import circle

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
