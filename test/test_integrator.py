"""Integrator checks: backward Euler never gains energy without damping and contact."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.stepper import ImplicitEulerSolver, StepConstraints


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_free_elastic_oscillation_never_gains_energy(model):
    config = load_config(overrides=[f'fruit.model={model}', 'fruit.pressure.turgor=2e4'])
    fruit = build_fruit(config)
    solver = ImplicitEulerSolver(fruit.masses, fruit.energies, tolerance=1e-9)
    rng = np.random.default_rng(1)
    q = (fruit.rest_positions + rng.normal(scale=3e-4, size=fruit.rest_positions.shape)).ravel()
    v = np.zeros_like(q)
    masses = np.repeat(fruit.masses, 2)

    def energy(q, v):
        return 0.5 * np.sum(masses * v * v) + sum(e.value(q) for e in fruit.energies)

    free = StepConstraints.free(fruit.n_nodes)
    dt = 1e-3
    start = previous = energy(q, v)
    assert start > 0
    for _ in range(200):
        q_new = solver.solve(q, v, dt, q + dt * v, free).q
        v, q = (q_new - q) / dt, q_new
        current = energy(q, v)
        # never grows beyond the Newton tolerance's round-off, measured on the start energy
        assert current <= previous + 1e-7 * start
        previous = current
    assert previous < start
