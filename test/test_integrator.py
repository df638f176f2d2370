"""Integrator checks: backward Euler never gains energy without damping and contact."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.stepper import StepConstraints

from reference_solver import ImplicitEulerSolver


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_free_elastic_oscillation_never_gains_energy(model):
    turgor = ['fruit.pressure.turgor=2e4'] if model == 'shell' else []  # shell only
    config = load_config(overrides=[f'fruit.model={model}', *turgor])
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


@pytest.mark.parametrize('model', ['shell', 'solid'])
def test_a_kept_factorisation_serves_many_steps_to_the_same_tolerance(model, monkeypatch):
    """The chord rule (``keep_factor``): far fewer factorisations than Newton iterations,
    each step within a few tolerances (dq / dt, m/s) of full Newton's, and the factor made
    afresh when the filters change."""
    import scipy.sparse.linalg as spla

    import reference_solver
    config = load_config(overrides=[f'fruit.model={model}'])
    fruit = build_fruit(config)
    tol = 1e-6
    full = ImplicitEulerSolver(fruit.masses, fruit.energies, tolerance=tol)
    chord = ImplicitEulerSolver(fruit.masses, fruit.energies, tolerance=tol)
    chord.keep_factor = True
    factorisations = []
    splu = spla.splu
    monkeypatch.setattr(reference_solver.spla, 'splu', lambda *a, **k: factorisations.append(1)
                        or splu(*a, **k))
    rng = np.random.default_rng(1)
    q = (fruit.rest_positions + rng.normal(scale=3e-4, size=fruit.rest_positions.shape)).ravel()
    v = np.zeros_like(q)
    dt = 1e-3
    free = StepConstraints.free(fruit.n_nodes)
    held = StepConstraints.free(fruit.n_nodes)
    held.filters[0] = 0.0  # node 0 stuck
    iterations = chord_factorisations = 0
    for step in range(60):
        con = free if step < 30 else held
        start = q + dt * v
        if step >= 30:
            start[:2] = q[:2]
        expected = full.solve(q, v, dt, start, con).q
        before = len(factorisations)
        solution = chord.solve(q, v, dt, start, con)
        if step in (0, 30):  # a new constraint set: a new factor
            assert len(factorisations) > before
        chord_factorisations += len(factorisations) - before
        iterations += solution.iterations
        assert np.max(np.abs(solution.q - expected)) / dt < 5 * tol
        v, q = (solution.q - q) / dt, solution.q
    assert chord_factorisations <= iterations / 3
