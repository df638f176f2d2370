"""Bending of open and branched rods (``RodBending``): finite-difference gradient and
Hessian, the compiled kernel against the numpy reference, rest-shape equilibrium, the
closed ring as its special case, and a cantilever against Euler-Bernoulli."""
import numpy as np
import pytest

from gripper_sim.core.energies import ConstantForce, RingBending, RodBending, Stretching
from gripper_sim.core.stepper import StepConstraints

from reference_solver import ImplicitEulerSolver

from helpers import kernel_evaluation
from reference_energies2d import dense_hessian, reference, turning_angles

RNG = np.random.default_rng(7)


def _branched_frame():
    """A bent open chain 0-1-2-3-4 and a branch 5-6 joined rigidly at node 2, with a
    per-triple EI: rest angles of all signs, up to 150 degrees at the joint."""
    x0 = np.array([[0.0, 0.0], [0.01, 0.002], [0.02, 0.0], [0.028, -0.006], [0.035, -0.015],
                   [0.012, 0.012], [0.006, 0.02]])
    triples = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4],     # the chain
                        [2, 5, 6],                           # the branch
                        [5, 2, 1], [5, 2, 3]])               # the joint, both sides
    stiffness = np.array([0.02, 0.02, 0.03, 0.01, 0.005, 0.005])
    return x0, triples, stiffness


def _perturbed(x0, scale):
    return (x0 + RNG.normal(scale=scale, size=x0.shape)).ravel()


def test_rest_angles_are_kept_and_vary():
    x0, triples, stiffness = _branched_frame()
    rod = RodBending(triples, x0, stiffness)
    assert np.ptp(rod.phi0) > 1.0, 'the frame must have varied rest angles'
    assert np.max(np.abs(rod.phi0)) > np.radians(100)
    assert rod.value(x0.ravel()) == pytest.approx(0.0, abs=1e-15)
    assert np.max(np.abs(rod.gradient(x0.ravel()))) < 1e-10


def test_gradient_and_hessian_match_central_differences():
    x0, triples, stiffness = _branched_frame()
    rod = RodBending(triples, x0, stiffness)
    q = _perturbed(x0, 1e-3)
    h = 1e-7
    grad = rod.gradient(q)
    fd = np.array([(rod.value(q + h * e) - rod.value(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(grad)) > 1e-3, 'gradient is trivially zero'
    assert np.max(np.abs(grad - fd)) <= 1e-6 * np.max(np.abs(grad))
    hess = rod.hessian(q)
    fd = np.array([(rod.gradient(q + h * e) - rod.gradient(q - h * e)) / (2 * h)
                   for e in np.eye(q.size)])
    assert np.max(np.abs(hess)) > 1.0, 'Hessian is trivially zero'
    assert np.max(np.abs(hess - fd)) <= 1e-6 * np.max(np.abs(hess))
    assert np.allclose(hess, hess.T, atol=1e-9 * np.max(np.abs(hess)))


def test_compiled_kernel_matches_the_numpy_reference():
    x0, triples, stiffness = _branched_frame()
    rod = RodBending(triples, x0, stiffness)
    q = _perturbed(x0, 1e-3)
    value, grad, hess = kernel_evaluation(rod, q)
    ref = reference(rod, q)
    assert value == pytest.approx(ref.value, rel=1e-12)
    assert np.max(np.abs(grad - ref.gradient)) <= 1e-12 * np.max(np.abs(grad))
    assert np.max(np.abs(hess - dense_hessian(ref, q.size))) <= 1e-11 * np.max(np.abs(hess))
    np.testing.assert_allclose(rod.phi0, turning_angles(x0, rod.triples), rtol=1e-13,
                               atol=1e-15)


def test_the_ring_is_the_closed_case_of_the_rod():
    n = 10
    angle = 2 * np.pi * np.arange(n) / n
    x0 = 0.03 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    ring = RingBending(np.arange(n), x0, 0.02)
    ring_nodes = np.arange(n)
    rod = RodBending(np.stack([np.roll(ring_nodes, 1), ring_nodes, np.roll(ring_nodes, -1)],
                              axis=1), x0, 0.02)
    q = _perturbed(x0, 2e-3)
    assert ring.value(q) > 0
    assert ring.value(q) == pytest.approx(rod.value(q), rel=1e-14)


@pytest.mark.parametrize('n_elem', [10, 20, 40])
def test_cantilever_tip_deflection_matches_euler_bernoulli(n_elem):
    """A straight rod clamped at one end (a fixed edge before it, whose triple stands for
    half the first free edge), a small transverse tip load P: tip deflection P L^3 / (3 EI)
    (within the O(1 / n^2) of the discretisation), solved quasi-statically by the project's
    Newton."""
    length, ei, ea, load = 0.05, 1e-4, 1e3, 0.002
    h = length / n_elem
    x0 = np.stack([np.linspace(-h, length, n_elem + 2), np.zeros(n_elem + 2)], axis=1)
    nodes = np.arange(n_elem + 2)
    edges = np.stack([nodes[:-1], nodes[1:]], axis=1)
    rest = np.linalg.norm(x0[1:] - x0[:-1], axis=1)
    triples = np.stack([nodes[:-2], nodes[1:-1], nodes[2:]], axis=1)
    lengths = np.full(len(triples), h)
    lengths[0] = 0.5 * h
    tip_force = np.zeros(x0.size)
    tip_force[-1] = load
    solver = ImplicitEulerSolver(np.full(len(x0), 1e-6),
                                 [Stretching(edges, rest, ea),
                                  RodBending(triples, x0, ei, lengths),
                                  ConstantForce(tip_force)], tolerance=1e-12, max_iterations=50)
    con = StepConstraints.free(len(x0))
    con.filters[:2] = 0.0    # the clamp: nodes -h and 0
    q0 = x0.ravel()
    solution = solver.solve(q0, np.zeros_like(q0), 1e3, q0.copy(), con)
    deflection = solution.q.reshape(-1, 2)[-1, 1]
    assert deflection == pytest.approx(load * length ** 3 / (3 * ei), rel=0.01)
