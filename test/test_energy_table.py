"""The 2D energies' table (``core.energy_table``): the one compiled call sums the leading
rod energies, pressure, neo-Hookean flesh and gravity to the same bits as their own
kernels called one by one after the inertia, and stops at the first energy without
``kernel_data``."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core import solver_kernels
from gripper_sim.core.energies.base import Energy
from gripper_sim.core.energy_table import EnergyTable
from gripper_sim.core.simulation import Simulation


#: each grasp's overrides and its solver's tabled energies (the next one: the barrier)
GRASPS = {
    'fin_ray': (['gripper.finger.type=fin_ray'],
                ['Stretching', 'RingBending', 'EnclosedAreaPressure', 'Gravity', 'Stretching',
                 'RodBending']),
    'solid_ipc': (['fruit.model=solid', 'contact.model=ipc'],
                  ['Stretching', 'RingBending', 'NeoHookeanTriangles', 'Gravity']),
    'solid_pad': (['gripper.finger.type=solid_pad', 'fruit.model=solid'],
                  ['Stretching', 'RingBending', 'NeoHookeanTriangles', 'Gravity',
                   'NeoHookeanTriangles']),
}


def _solver(grasp='fin_ray'):
    """A grasp's Newton solver (``GRASPS``) and a perturbed state of it."""
    sim = Simulation(load_config(overrides=GRASPS[grasp][0]))
    solver = sim.solver
    rng = np.random.default_rng(3)
    finger = getattr(sim, '_finger', None)
    q_n = (sim.q if solver.n == sim.q.size
           else np.vstack([sim.q, finger.positions])).ravel()
    assert q_n.size == solver.n
    q = q_n + 1e-5 * rng.normal(size=q_n.size)
    return solver, q, q_n, 1e-3 * rng.normal(size=q_n.size)


def _one_by_one(solver, energies, q, q_n, v_n, dt, hessian):
    """The inertia and ``energies`` evaluated one call each, as before the table."""
    n = q.size
    grad, dq = np.empty(n), np.empty(n)
    phi = solver_kernels.inertia_and_mass_damping(q, q_n, v_n, dt, solver.m, solver.alpha,
                                                  dq, grad)
    data = np.zeros(solver._nnz if hessian else 1)
    low_rank = []
    for energy, scatter in zip(energies, solver._scatter):
        value, terms = energy.evaluate_into(q, grad, data, scatter, hessian)
        phi += value
        low_rank.extend(terms)
    return phi, grad, dq, data, low_rank


@pytest.mark.parametrize('grasp', sorted(GRASPS))
@pytest.mark.parametrize('hessian', [False, True])
def test_the_table_sums_the_energies_as_their_own_calls_to_the_bit(grasp, hessian):
    solver, q, q_n, v_n = _solver(grasp)
    table = solver._table
    kinds = [type(e).__name__ for e in solver.energies[:table.count]]
    assert kinds == GRASPS[grasp][1]
    assert type(solver.energies[table.count]).__name__ == 'BarrierContact'
    dt = 1e-3
    grad = np.full(q.size, np.nan)  # written whole
    data = np.full(solver._nnz if hessian else 1, np.nan)  # zeroed with the Hessian
    phi, dq, low_rank = table.potential(q, q_n, v_n, dt, solver.m, solver.alpha, hessian,
                                        grad, data)
    if not hessian:
        data = np.zeros(1)
    expected = _one_by_one(solver, solver.energies[:table.count], q, q_n, v_n, dt, hessian)
    assert phi == expected[0]
    for got, want in zip((grad, dq, data), expected[1:4]):
        assert np.array_equal(got, want)
    pressures = kinds.count('EnclosedAreaPressure')
    assert len(low_rank) == len(expected[4]) == (pressures if hessian else 0)
    for (c, u), (c_ref, u_ref) in zip(low_rank, expected[4]):
        assert c == c_ref and np.array_equal(u, u_ref)
    if hessian:
        assert np.count_nonzero(data) > 0


def test_the_table_stops_at_an_energy_without_kernel_data():
    solver, q, q_n, v_n = _solver()
    energies = solver.energies[:2] + [Energy()] + solver.energies[2:4]
    table = EnergyTable(energies, solver._scatter[:len(energies)], 2, solver.n)
    assert table.count == 2
    assert EnergyTable(solver.energies, solver._scatter, 3, solver.n).count == 0


def test_an_infeasible_energy_makes_the_potential_infinite():
    solver, q, q_n, v_n = _solver()
    q = q.copy()
    q[0] = np.nan
    phi = solver._table.potential(q, q_n, v_n, 1e-3, solver.m, solver.alpha, False,
                                  np.empty(q.size), np.zeros(1))[0]
    assert not np.isfinite(phi)


def test_an_inverted_flesh_triangle_makes_the_potential_infinite_as_its_own_call():
    solver, q, q_n, v_n = _solver('solid_ipc')
    flesh = solver.energies[2]
    q = q.copy()
    a, b, c = flesh.tri[0]
    q[2 * a:2 * a + 2] = q[2 * b:2 * b + 2] + q[2 * c:2 * c + 2] - q[2 * a:2 * a + 2]
    grad = np.zeros(q.size)
    assert flesh.evaluate_into(q, grad, np.zeros(1), solver._scatter[2], False)[0] == np.inf
    assert not grad.any()  # nothing added
    for hessian in (False, True):
        data = np.zeros(solver._nnz if hessian else 1)
        phi = solver._table.potential(q, q_n, v_n, 1e-3, solver.m, solver.alpha, hessian,
                                      np.empty(q.size), data)[0]
        assert phi == np.inf
