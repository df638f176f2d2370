"""The fast Newton solver's own parts (``core.fast_solver``, ``core.solver_kernels``):
the compiled friction against the stepper's numpy version, the line search's first step
at the kink of the friction law, and the factor ordering chosen from the pattern."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla

from gripper_sim.configuration import load_config
from numba import njit

from gripper_sim.core import linear_solve, solver_kernels, sparse_ldl
from gripper_sim.core.fast_solver import KINK_FACTOR, PatternCachingSolver, as_cone
from gripper_sim.core.stepper import FRICTION_SMOOTHING, StepConstraints
from gripper_sim.workflows.factory import make_simulation

from reference_solver import ImplicitEulerSolver


def _sliding(dim: int, k: int, seed: int):
    """Positions q, q_n (n dim,) and the constraints of k sliding nodes of 2k nodes."""
    rng = np.random.default_rng(seed)
    n = 2 * k
    q_n = rng.normal(size=n * dim)
    q = q_n + 1e-3 * rng.normal(size=n * dim)
    nodes = rng.choice(n, size=k, replace=False).astype(np.int64)
    if dim == 2:
        t = rng.normal(size=(k, 2))
        tangents = t / np.linalg.norm(t, axis=1)[:, None]
        speed = 0.01 * rng.normal(size=k)
    else:
        tangents = np.stack([np.linalg.qr(rng.normal(size=(3, 3)))[0][:, :2].T
                             for _ in range(k)])
        speed = 0.01 * rng.normal(size=(k, 2))
    filters = np.tile(np.eye(dim), (n, 1, 1))
    con = StepConstraints(filters, nodes, tangents, rng.uniform(0.1, 2.0, size=k), speed)
    return q, q_n, con


@pytest.mark.parametrize('dim', [2, 3])
def test_compiled_friction_is_the_steppers_cone(dim):
    q, q_n, con = _sliding(dim, 7, seed=dim)
    con = as_cone(con)
    dt = 0.02
    solver = ImplicitEulerSolver(np.ones(q.size // dim), [], dim=dim)
    reference_grad = np.zeros(q.size)
    phi, blocks = solver._cone_friction(q, q_n, dt, con, reference_grad)
    grad = np.zeros(q.size)
    out = np.empty((con.friction_nodes.size, dim, dim))
    value = solver_kernels.cone_friction(
        q, q_n, con.friction_nodes,
        np.ascontiguousarray(con.friction_tangents), con.friction_bounds,
        np.ascontiguousarray(con.friction_obstacle_speed, dtype=float), dt,
        FRICTION_SMOOTHING, grad, out)
    assert phi > 0 and np.max(np.abs(reference_grad)) > 0 and np.max(np.abs(blocks)) > 0
    assert value == pytest.approx(phi, rel=1e-12)
    np.testing.assert_allclose(grad, reference_grad, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(out, blocks, rtol=1e-10, atol=1e-12 * np.max(np.abs(blocks)))


def _one_sliding_node(slip: np.ndarray, dt: float = 0.02):
    """A 3D solver with one node sliding on the plane z = 0 (tangents x and y) at the
    slip velocity ``slip`` (2,) m/s; (solver, q, q_n, constraints)."""
    solver = PatternCachingSolver(np.ones(1), [], dim=3)
    q_n = np.zeros(3)
    q = np.array([slip[0] * dt, slip[1] * dt, 0.0])
    con = StepConstraints(np.eye(3)[None], np.array([0]), np.eye(3)[None, :2],
                          np.array([1.0]), np.zeros((1, 2)))
    return solver, q, q_n, con


def test_first_step_stops_a_turning_slip_where_it_is_nearest_zero():
    dt = 0.02
    slip = np.array([0.3, 0.1])
    solver, q, q_n, con = _one_sliding_node(slip, dt)
    # a Newton step that turns the slip velocity round to -3 times itself: it passes
    # zero at a quarter of the step
    dq = np.append(-4.0 * slip * dt, 0.0)
    assert solver.kink_step(q, q_n, dq, dt, con) == pytest.approx(0.25)
    # a step that speeds the slip up, or one that stops short of zero, is taken whole
    assert solver.kink_step(q, q_n, -dq, dt, con) == 1.0
    assert solver.kink_step(q, q_n, 0.5 * dq / 4.0, dt, con) == 1.0
    # a node slipping within the smoothing speed is inside the kink already
    slow = 0.5 * KINK_FACTOR * FRICTION_SMOOTHING * slip / np.linalg.norm(slip)
    solver, q, q_n, con = _one_sliding_node(slow, dt)
    assert solver.kink_step(q, q_n, np.append(-4.0 * slow * dt, 0.0), dt, con) == 1.0


#: 3D fruits whose Newton matrix the solver's linear algebra is checked on
FRUITS_3D = [['fruit.model=shell', 'fruit.mesh.subdivisions=4'],
             ['fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.mesh.subdivisions=3']]


def _rest_newton_matrix(model: list[str]):
    """(solver, q (n d,), dt, CSC values of the fruit's Hessian at rest plus the inertia)
    of the 3D fruit ``model`` (configuration overrides)."""
    sim = make_simulation(load_config(overrides=['dimension=3'] + model))
    solver = sim.solver
    q = sim.q.ravel()
    data = np.zeros(solver._nnz)
    for energy, scatter in zip(solver.energies, solver._scatter):
        energy.evaluate_into(q, np.zeros(q.size), data, scatter, True)
    solver_kernels.add_inertia_diagonal(data, solver._diag_pos, solver.m, sim.dt, 0.0)
    return solver, q, sim.dt, data


@njit
def _kept_factor(state):
    return state.l_values.copy(), state.d_inv.copy()


@pytest.mark.parametrize('model', FRUITS_3D, ids=['shell', 'solid'])
def test_the_block_ldl_preconditioner_solves_a_newton_matrix(model):
    """The kept factorisation (block LDL^T, its 3 x 3 kernels; ``linear_solve``) of a
    real Newton matrix (the fruit's Hessian at rest plus the inertia) solves it to
    round-off, and its factors are those of the generic ``sparse_ldl.factor``."""
    solver, q, dt, data = _rest_newton_matrix(model)
    state = solver.linear
    before = solver.stats['factorisations']
    assert linear_solve.factorise(state, data) == 0  # positive definite
    assert solver.stats['factorisations'] == before + 1
    matrix = solver._csc(data).tocsc()
    rhs = np.linspace(-1.0, 1.0, q.size)
    exact = spla.spsolve(matrix, rhs)
    x = np.empty(q.size)
    linear_solve.ldl_solve(state, rhs, x)
    assert np.max(np.abs(x - exact)) < 1e-9 * np.max(np.abs(exact))
    kept_l, kept_d = _kept_factor(state)
    pattern = solver._ldl_pattern
    values = pattern.new_values()
    target, source = solver._ldl_gather
    values.reshape(-1)[target] = data[source]
    l_values = np.empty_like(kept_l)
    d_inv = np.empty_like(kept_d)
    assert sparse_ldl.factor(pattern.arrays, values, l_values, d_inv) == 0
    assert np.allclose(l_values, kept_l, rtol=1e-10, atol=1e-12 * np.abs(l_values).max())
    assert np.allclose(d_inv, kept_d, rtol=1e-10, atol=1e-12 * np.abs(d_inv).max())


@pytest.mark.parametrize('overrides', [['fruit.model=shell', 'fruit.mesh.subdivisions=3'],
                                       ['fruit.model=solid', 'fruit.skin.enabled=false',
                                        'fruit.mesh.subdivisions=3']], ids=['shell', 'solid'])
def test_stiffness_damping_matches_the_reference(overrides):
    """Rayleigh stiffness damping (fruit.damping.stiffness > 0) on the solver: its
    potential, gradient and Hessian equal the reference evaluation's (triplets,
    ``ImplicitEulerSolver.incremental_potential``) at a moved, squeezed configuration."""
    sim = make_simulation(load_config(overrides=['dimension=3', 'fruit.damping.stiffness=1e-4',
                                                 'fruit.damping.mass=3'] + overrides))
    solver = sim.solver
    assert solver.beta == pytest.approx(1e-4)
    reference = ImplicitEulerSolver(solver.m[::3], solver.energies, damping_mass=solver.alpha,
                                    damping_stiffness=solver.beta, dim=3,
                                    tolerance=solver.tolerance)
    rng = np.random.default_rng(5)
    q_n = sim.q.ravel().copy()
    q_n[2::3] *= 0.97  # squeezed a little along z
    v_n = 0.02 * rng.normal(size=q_n.size)
    dt = sim.dt
    q = q_n + dt * v_n + 1e-5 * rng.normal(size=q_n.size)
    con = StepConstraints.free(q_n.size // 3, dim=3)
    for hessian in (False, True):
        phi, grad, _, parts = solver.evaluate_fast(q, q_n, v_n, dt, con, hessian)
        phi_ref, grad_ref, _, parts_ref = reference.incremental_potential(q, q_n, v_n, dt,
                                                                          con, hessian)
        assert phi == pytest.approx(phi_ref, rel=1e-10)
        np.testing.assert_allclose(grad, grad_ref, rtol=0,
                                   atol=1e-9 * np.max(np.abs(grad_ref)))
    dense = solver._csc(parts[0]).toarray()
    np.testing.assert_allclose(dense, parts_ref[0].toarray(), rtol=0,
                               atol=1e-10 * np.max(np.abs(dense)))
    # the damping term is there at all
    undamped = make_simulation(load_config(overrides=['dimension=3', 'fruit.damping.mass=3']
                                           + overrides)).solver
    _, grad_plain, _, _ = undamped.evaluate_fast(q, q_n, v_n, dt, con, False)
    assert np.max(np.abs(grad - grad_plain)) > 1e-3 * np.max(np.abs(grad))


#: the stiffness damping of the checks below (s): 20 times the 3D grasp's 1e-4
BETA = 2e-3
DAMPED = {'2d-shell': ['dimension=2', 'fruit.nodes=24', 'fruit.pressure.turgor=3e4'],
          '2d-solid': ['dimension=2', 'fruit.model=solid'],
          '3d-shell': ['dimension=3', 'fruit.model=shell', 'fruit.mesh.subdivisions=3'],
          '3d-solid': ['dimension=3', 'fruit.model=solid', 'fruit.skin.enabled=false',
                       'fruit.mesh.subdivisions=3']}


def _damped_step(name: str, beta: float = BETA):
    """A simulation of the set-up ``name`` with stiffness damping ``beta`` and mass
    damping, and a step's data: (sim, q, q_n, v_n, dt), q_n the fruit at rest and q moved
    well away from it (0.3 % of the fruit's size per coordinate: K(q) differs from
    K(q_n)). (At rest K_n is positive semi-definite; at a squeezed q_n a neo-Hookean
    solid's may not be, and the damping term then has more than one stationary point.)"""
    sim = make_simulation(load_config(overrides=DAMPED[name] + [
        f'fruit.damping.stiffness={beta}', 'fruit.damping.mass=3']))
    rng = np.random.default_rng(11)
    q_n = sim.q.ravel().copy()
    size = float(np.ptp(q_n))
    v_n = 0.01 * rng.normal(size=q_n.size)
    q = q_n + 3e-3 * size * rng.normal(size=q_n.size)
    return sim, q, q_n, v_n, sim.dt


@pytest.mark.parametrize('name', list(DAMPED))
def test_stiffness_damping_gradient_and_hessian_are_those_of_its_potential(name):
    """beta dq^T K_n dq / (2 dt) with K_n the elastic Hessian at the step's start: the
    potential's gradient and Hessian agree with central differences of its value and
    gradient at a point far from q_n, where K(q) is not K(q_n) (with K at q, as before,
    the gradient beta K(q) dq / dt left out dK/dq)."""
    sim, q, q_n, v_n, dt = _damped_step(name)
    solver = sim.solver
    con = StepConstraints.free(q.size // solver.dim, solver.dim)
    phi, grad, _, (data, low_rank) = solver.evaluate_fast(q, q_n, v_n, dt, con, True)
    hess = solver._csc(data).toarray()
    for c, u in low_rank:
        hess += c * np.outer(u, u)
    rng = np.random.default_rng(2)
    h = 1e-7 * float(np.ptp(q_n))
    for _ in range(3):
        direction = rng.normal(size=q.size)
        plus = solver.evaluate_fast(q + h * direction, q_n, v_n, dt, con, False)
        minus = solver.evaluate_fast(q - h * direction, q_n, v_n, dt, con, False)
        slope = (plus[0] - minus[0]) / (2 * h)
        assert slope == pytest.approx(grad @ direction, rel=1e-6)
        curvature = (plus[1] - minus[1]) / (2 * h)
        np.testing.assert_allclose(curvature, hess @ direction, rtol=0,
                                   atol=1e-6 * np.max(np.abs(hess @ direction)))
    # the damping is a large part of the gradient: the checks above see it
    undamped = PatternCachingSolver(solver.m[::solver.dim], solver.energies,
                                    damping_mass=solver.alpha, dim=solver.dim)
    plain = undamped.evaluate_fast(q, q_n, v_n, dt, con, False)[1]
    assert np.max(np.abs(grad - plain)) > 1e-2 * np.max(np.abs(grad))


def _held_and_sliding(n_nodes: int, dim: int) -> StepConstraints:
    """Node 0 stuck, nodes 1 and 2 held along x with kinetic friction along the last
    axis (z)."""
    con = StepConstraints.free(n_nodes, dim)
    con.filters[0] = 0.0
    for node in (1, 2):
        con.filters[node] = np.eye(dim) - np.outer(np.eye(dim)[0], np.eye(dim)[0])
    tangents = np.eye(dim)[-1:][None].repeat(2, axis=0)  # (2, 1, dim)
    if dim == 2:
        return StepConstraints(con.filters, np.array([1, 2]), tangents[:, 0],
                               np.array([0.3, 0.5]), np.array([0.01, 0.01]))
    return StepConstraints(con.filters, np.array([1, 2]), tangents, np.array([0.3, 0.5]),
                           np.array([[0.01], [0.01]]))


@pytest.mark.parametrize('name', list(DAMPED))
def test_the_solver_and_the_reference_stop_at_one_point_with_stiffness_damping(name):
    """At beta = 2e-3 the solver (and in 2D the whole-step kernel's Newton, which the
    reference with its chord rule follows to round-off elsewhere) and the reference end
    a step with contact and friction at the same positions, to ~1e-9 of the fruit's
    size: the damping's gradient is that of the potential both minimise."""
    sim, q, q_n, v_n, dt = _damped_step(name)
    solver = sim.solver
    solver.tolerance = 1e-9
    start = q_n + dt * v_n
    con = _held_and_sliding(q_n.size // solver.dim, solver.dim)
    reference = ImplicitEulerSolver(solver.m[::solver.dim], solver.energies,
                                    damping_mass=solver.alpha, damping_stiffness=solver.beta,
                                    tolerance=1e-9, dim=solver.dim)
    expected = reference.solve(q_n, v_n, dt, start, con)
    size = float(np.ptp(q_n))
    got = solver.solve(q_n, v_n, dt, start.copy(), con)
    assert np.max(np.abs(got.q - expected.q)) < 1e-9 * size
    assert np.max(np.abs(got.q - q_n)) > 1e-6 * size  # the step moved the fruit


@pytest.mark.parametrize('model', FRUITS_3D, ids=['shell', 'solid'])
def test_the_compiled_cg_solves_a_filtered_newton_system_with_a_rank_one_term(model):
    """``linear_solve.solve`` (the solver's ``linear_solve``) on a real Newton matrix
    S A S + (I - S) plus a rank-one term, its factorisation and Woodbury terms made of the
    same matrix (an exact preconditioner): the dense solution within round-off, zero in
    the held directions, in one CG iteration."""
    solver, q, dt, data = _rest_newton_matrix(model)
    filters = np.tile(np.eye(3), (q.size // 3, 1, 1))
    filters[0] = 0.0  # a node held in every direction
    filters[1] = np.diag([1.0, 1.0, 0.0])  # one held along z
    values = solver.newton_matrix(data, filters, np.zeros(q.size))
    rng = np.random.default_rng(7)
    u = np.zeros((q.size, 1))
    solver_kernels.apply_filters(filters, rng.normal(size=q.size), u[:, 0])
    c = np.array([1e-2 * np.max(np.abs(values))])
    rhs = np.empty(q.size)
    solver_kernels.apply_filters(filters, np.linspace(-1.0, 1.0, q.size), rhs)
    before = solver.stats['cg_iterations']
    # a fresh factorisation of this matrix, its Woodbury terms, then CG on them
    x = solver.linear_solve(values, rhs, (u, c, np.ascontiguousarray(u.T)), True, dt,
                            filters)
    dense = solver._csc(values).toarray() + c[0] * u @ u.T
    exact = np.linalg.solve(dense, rhs)
    assert solver.stats['cg_iterations'] - before == 1
    assert np.max(np.abs(x - exact)) < 1e-9 * np.max(np.abs(exact))
    assert np.all(x[:3] == 0.0) and x[5] == 0.0


def test_a_fresh_factorisation_counts_the_newton_matrix_negative_eigenvalues():
    """``linear_solve.solve`` with a new factorisation counts the negative eigenvalues of
    A + u diag(c) u^T (``F_NEGATIVE``: D's blocks and the capacitance matrix), as the dense
    eigenvalues do: A a 3D shell's Newton matrix with the inertia taken away four times
    over (indefinite), with and without rank-one terms that make it less or more so."""
    solver, q, dt, data = _rest_newton_matrix(['fruit.model=shell',
                                               'fruit.mesh.subdivisions=2'])
    n = q.size
    filters = np.tile(np.eye(3), (n // 3, 1, 1))
    filters[0] = 0.0  # a node held in every direction
    values = solver.newton_matrix(data, filters, -4.0 * solver.m / dt ** 2)
    dense = solver._csc(values).toarray()
    eigenvalues, vectors = np.linalg.eigh(dense)
    negative = int(np.sum(eigenvalues < 0))
    assert 0 < negative < n
    lowest = vectors[:, 0]
    scale = np.abs(eigenvalues).max()
    flags = solver.linear.flags
    cases = [(np.zeros((n, 0)), np.zeros(0), negative),
             (lowest[:, None], np.array([10.0 * scale]), negative - 1),
             (vectors[:, -1:], np.array([-10.0 * scale]), negative + 1)]
    for u, c, expected in cases:
        u = np.ascontiguousarray(u)
        total = dense + (u * c) @ u.T
        assert int(np.sum(np.linalg.eigvalsh(total) < 0)) == expected
        solver.linear_solve(values, np.linspace(-1.0, 1.0, n), (u, c, np.ascontiguousarray(u.T)),
                            True, dt, filters)
        assert flags[linear_solve.F_NEGATIVE] == expected
    solver.linear_solve(solver.newton_matrix(data, filters, np.zeros(n)), np.ones(n),
                        cases[0][:2] + (np.zeros((0, n)),), True, dt, filters)
    assert flags[linear_solve.F_NEGATIVE] == 0  # the Newton matrix at rest: definite


@pytest.mark.parametrize('name', ['2d-shell', '3d-solid'])
def test_potential_with_sliding_nodes_and_damping_is_the_references(name):
    """The solver's potential with stiffness and mass damping and sliding nodes (the
    terms after the energies: one kernel, ``solver_kernels.add_step_terms``) equals the
    reference's triplet evaluation: value, gradient, friction gradient and Hessian."""
    sim, q, q_n, v_n, dt = _damped_step(name)
    solver = sim.solver
    d = solver.dim
    reference = ImplicitEulerSolver(solver.m[::d], solver.energies, damping_mass=solver.alpha,
                                    damping_stiffness=solver.beta, dim=d,
                                    tolerance=solver.tolerance)
    _, _, sliding = _sliding(d, 5, seed=d)
    n_nodes = q.size // d
    con = StepConstraints(np.tile(np.eye(d), (n_nodes, 1, 1)), sliding.friction_nodes,
                          sliding.friction_tangents, sliding.friction_bounds,
                          sliding.friction_obstacle_speed)
    for hessian in (False, True):
        phi, grad, fric_grad, parts = solver.evaluate_fast(q, q_n, v_n, dt, con, hessian)
        phi_ref, grad_ref, fric_ref, parts_ref = reference.incremental_potential(
            q, q_n, v_n, dt, as_cone(con), hessian)
        assert np.max(np.abs(fric_ref)) > 0
        assert phi == pytest.approx(phi_ref, rel=1e-10)
        np.testing.assert_allclose(grad, grad_ref, rtol=0,
                                   atol=1e-9 * np.max(np.abs(grad_ref)))
        np.testing.assert_allclose(fric_grad, fric_ref, rtol=0,
                                   atol=1e-12 * np.max(np.abs(fric_ref)))
    dense = solver._csc(parts[0]).toarray()
    np.testing.assert_allclose(dense, parts_ref[0].toarray(), rtol=0,
                               atol=1e-10 * np.max(np.abs(dense)))


def test_a_solve_still_converging_at_the_limit_goes_on_and_a_stalled_one_does_not():
    """``still_converging``: the last PROGRESS_SPAN steps shrank by PROGRESS_FACTOR."""
    from gripper_sim.core.fast_solver import PROGRESS_SPAN, still_converging
    linear = [1e-2 * 0.8 ** k for k in range(25)]  # 0.8^5 = 0.33 over the span
    assert still_converging(linear)
    stalled = linear[:20] + [linear[19] * f for f in (1.2, 0.9, 1.1, 0.8, 1.0)]
    assert not still_converging(stalled)
    assert not still_converging(linear[:PROGRESS_SPAN])
