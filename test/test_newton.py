"""The one Newton iteration (core/newton.py) on small problems of known minimum, run
interpreted as the shared and reference solvers run it, and its being the only one."""
from pathlib import Path

import numpy as np
import pytest

from gripper_sim.core import newton


class QuarticProblem:
    """Phi(q) = sum(q^4 / 4 + a q^2 / 2 - b q) with unit filters and dense linear
    algebra; ``keep`` keeps the factor (an inverse) within the solve."""

    def __init__(self, a: float, b: np.ndarray, keep: bool = False, wall: float = 1e3):
        self.a, self.b, self.keeps, self.wall = a, b, keep, wall
        n = b.size
        self._vectors = tuple(np.empty(n) for _ in range(5))
        self.hessian = None
        self.inverse = self.kept = None
        self.shifts = []
        self.reaction = None

    def vectors(self):
        return self._vectors

    def kept_fits(self):
        return False

    def evaluate(self, x, hessian, grad):
        if np.any(np.abs(x) > self.wall):  # infeasible (an inverted element)
            return np.inf
        grad[:] = x ** 3 + self.a * x - self.b
        if hessian:
            self.hessian = np.diag(3 * x ** 2 + self.a)
        return float(np.sum(x ** 4 / 4 + self.a * x ** 2 / 2 - self.b * x))

    def project(self, grad, g_f):
        g_f[:] = grad

    def forget(self):
        self.kept = None

    def keep(self):
        self.kept = self.inverse

    def factorise(self, x, shift):
        matrix = self.hessian + shift * np.eye(x.size)
        if abs(np.linalg.det(matrix)) < 1e-300:
            return False
        self.inverse = np.linalg.inv(matrix)
        self.matrix = matrix
        self.shifts.append(shift)
        return True

    def definite(self):
        return bool(np.linalg.eigvalsh(self.matrix)[0] > 0.0)

    def direction(self, g_f, dq, fresh):
        dq[:] = -(self.inverse if fresh else self.kept) @ g_f
        return bool(np.all(np.isfinite(dq))), float(g_f @ dq)

    def step_bound(self, x, dq):
        return 1.0

    def keep_limit(self):
        return np.inf if self.keeps else 0.0

    def filtered_max(self, g):
        return float(np.max(np.abs(g)))

    def finish(self, x, grad):
        self.reaction = grad.copy()


def _solve(problem, q0, tol=1e-10, max_it=50):
    q = np.array(q0, dtype=float)
    history = np.zeros(max_it)
    counts = np.zeros(newton.C_SIZE, np.int64)
    status, iterations, n_hist = newton.newton_iteration_interpreted(
        problem, q, 1.0, tol, max_it, history, counts)
    return status, q, iterations, history[:n_hist], counts


def test_converges_to_the_minimum_with_the_stopping_test_on_the_step():
    b = np.array([1.0, -2.0, 0.5])
    problem = QuarticProblem(1.0, b)
    status, q, iterations, history, counts = _solve(problem, np.zeros(3))
    assert status == newton.OK
    np.testing.assert_allclose(q ** 3 + q - b, 0.0, atol=1e-12)
    assert history[-1] < 1e-10 <= history[-2]
    assert counts[newton.C_FACTORS] == iterations  # full Newton: a factor an iteration


def test_an_indefinite_hessian_is_shifted_until_the_step_descends():
    # at q = 0.1 the Hessian 3 q^2 - 1 is negative: the plain Newton step climbs
    problem = QuarticProblem(-1.0, np.zeros(1))
    status, q, _, _, _ = _solve(problem, [0.1])
    assert status == newton.OK
    assert problem.shifts[:2] == [0.0, 1.0]
    assert abs(q[0]) == pytest.approx(1.0, abs=1e-12)


def test_a_shifted_matrix_must_be_positive_definite_not_only_descend():
    # at q = (0.1, 0) the Hessian diag(-4.97, -0.5): the plain Newton step climbs;
    # shifted by 1 it is still indefinite, yet its step descends (the second
    # component's gradient dominates); by 10 it is positive definite, and that is taken
    a, b, q0 = np.array([-5.0, -0.5]), np.array([0.0, 1.0]), np.array([0.1, 0.0])
    problem = QuarticProblem(a, b)
    grad = np.empty(2)
    problem.evaluate(q0, True, grad)
    problem.factorise(q0, 1.0)
    assert not problem.definite() and grad @ (-problem.inverse @ grad) < 0
    problem = QuarticProblem(a, b)
    status, q, _, _, _ = _solve(problem, q0)
    assert status == newton.OK
    assert problem.shifts[:3] == [0.0, 1.0, 10.0]
    np.testing.assert_allclose(q ** 3 + a * q - b, 0.0, atol=1e-12)
    assert np.all(3 * q ** 2 + a > 0)  # a minimum
    assert q[0] == pytest.approx(np.sqrt(5.0))


def test_the_kept_matrix_serves_iterations_while_it_contracts():
    b = np.array([1.0, -2.0, 0.5])
    full = _solve(QuarticProblem(1.0, b), np.zeros(3))
    chord = _solve(QuarticProblem(1.0, b, keep=True), np.zeros(3))
    assert chord[0] == newton.OK
    np.testing.assert_allclose(chord[1], full[1], atol=1e-9)
    assert chord[4][newton.C_FACTORS] < chord[2]  # fewer factors than iterations


def test_an_infeasible_start_and_a_failed_line_search_are_reported():
    assert _solve(QuarticProblem(1.0, np.ones(1)), [2e3])[0] == newton.INFEASIBLE_START
    # every trial point of the line search (down to 2^-29 of the step) infeasible
    problem = QuarticProblem(1.0, np.ones(1), wall=1e-12)
    assert _solve(problem, [0.0])[0] == newton.LINE_SEARCH_FAILED


def test_the_newton_iteration_exists_once():
    """Only core/newton.py runs a line search (its sufficient-decrease test)."""
    root = Path(newton.__file__).resolve().parents[1]
    holders = [path.relative_to(root).as_posix() for path in root.rglob('*.py')
               if 'ARMIJO' in path.read_text() or '1e-4 * step' in path.read_text()]
    assert holders == ['core/newton.py']
