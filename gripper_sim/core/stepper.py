"""Implicit (backward) Euler time stepping solved with Newton-Raphson.

One step from (q_n, v_n) over dt minimises the incremental potential
    Phi(q) = |q - q_n - dt v_n|^2_M / (2 dt^2) + sum E(q) + D_friction(q) + D_damping(q)
whose stationarity is backward Euler, M (v_{n+1} - v_n) / dt = F(q_{n+1}). Constrained
degrees of freedom follow the modified mass method (Baraff & Witkin 1998): a per-node
filter S_i (identity for free nodes, I - n n^T for a node held along its contact
normal n, zero for a stuck node) removes them from the Newton system
    (S K S + I - S) dq = -S g,
and the iterate starts with them at their prescribed values (the z vector). The
reaction an obstacle exerts on a constrained node is the residual g there.

The stepper is dimension-generic (``dim`` = 2: q = [x0, z0, ...]; 3: q = [x0, y0, z0, ...]).
Kinetic friction of a sliding node is the dissipation potential mu_k R_n dt |s_t|_eps,
|s|_eps = sqrt(|s|^2 + eps^2), with s_t its slip velocity relative to the obstacle along
one tangent (2D) or in the tangent plane (3D: a Coulomb cone, the smoothed norm).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gripper_sim.core.energies.base import Energy

#: regularisation speed (m/s) of the kinetic friction law |s| ~ sqrt(s^2 + eps^2)
FRICTION_SMOOTHING = 1e-4

#: a Newton step with a kept factorisation must cut the filtered residual max |S g| below
#: this fraction of the last one, else the matrix is assembled and factorised afresh
CONTRACTION = 0.25

#: Newton solves a kept factorisation serves at most before it is made afresh
MAX_FACTOR_AGE = 20


class NewtonFailure(Exception):
    """Newton did not converge on this step (the caller halves the step)."""

    def __init__(self, message: str, history: list[float]):
        super().__init__(message)
        self.history = history


@dataclass
class StepConstraints:
    """Per-node filters and kinetic friction of one step.

    Attributes:
        filters: (n_nodes, dim, dim) the S_i blocks.
        friction_nodes: (k,) nodes sliding on an obstacle.
        friction_tangents: (k, 2) unit tangents of their obstacles (2D), or (k, 2, 3)
            two orthonormal tangents spanning each obstacle's plane (3D).
        friction_bounds: (k,) N, mu_k times the (lagged) normal reaction.
        friction_obstacle_speed: (k,) m/s, obstacle speed along the tangent (2D), or
            (k, 2) its components along the two tangents (3D).
    """

    filters: np.ndarray
    friction_nodes: np.ndarray
    friction_tangents: np.ndarray
    friction_bounds: np.ndarray
    friction_obstacle_speed: np.ndarray

    @classmethod
    def free(cls, n_nodes: int, dim: int = 2) -> 'StepConstraints':
        if dim == 2:
            return cls(np.tile(np.eye(2), (n_nodes, 1, 1)), np.zeros(0, np.int64),
                       np.zeros((0, 2)), np.zeros(0), np.zeros(0))
        return cls(np.tile(np.eye(dim), (n_nodes, 1, 1)), np.zeros(0, np.int64),
                   np.zeros((0, dim - 1, dim)), np.zeros(0), np.zeros((0, dim - 1)))


@dataclass
class KeptFactor:
    """A Newton matrix's factorisation kept across iterations and solves.

    Attributes:
        key: what it was made for: (filters (n_nodes, dim, dim), kinetic friction nodes
            (count, frozenset), the energies' ``factor_key``s (tuple), dt s).
        lu: the factorisation of S H S + (I - S) + shift S M / dt^2.
        low: its rank-one terms [(c, S u)].
        age: Newton solves it has served since it was made.
    """

    key: tuple
    lu: object
    low: list
    age: int = 0

    def fits(self, key: tuple) -> bool:
        """Made for these constraints and dt, and younger than MAX_FACTOR_AGE solves."""
        filters, friction, energies, dt = key
        return (self.age < MAX_FACTOR_AGE and self.key[3] == dt and self.key[1] == friction
                and self.key[2] == energies and np.array_equal(self.key[0], filters))


@dataclass
class StepSolution:
    """Attributes:
        q: (n_dof,) m, positions at the end of the step.
        reaction: (n_dof,) N, the residual without friction: the force obstacles must
            exert on each node (only meaningful at constrained nodes).
        iterations: Newton iterations.
        history: infinity norms of dq / dt per iteration (m/s).
    """

    q: np.ndarray
    reaction: np.ndarray
    iterations: int
    history: list


class ImplicitEulerSolver:
    """Args:
        masses: (n_nodes,) kg.
        energies: internal and external potential energies.
        damping_mass: Rayleigh alpha (1/s).  damping_stiffness: Rayleigh beta (s),
            applied to the Hessian of the elastic energies.
        tolerance: m/s, stop when max |dq| / dt falls below it.
        max_iterations: Newton iterations before NewtonFailure.
        dim: 2 (planar) or 3, the coordinates per node.
        lu_options: keyword arguments for ``scipy.sparse.linalg.splu`` (None: its
            defaults), e.g. a symmetric ordering for the larger 3D systems.
    """

    #: keep the Newton matrix's factorisation from iteration to iteration and from solve
    #: to solve (a chord method, see ``solve``); the 2D simulation with the default
    #: contact model sets it, as its whole-step kernel (``kernels._newton_solve``) does
    keep_factor = False

    def __init__(self, masses: np.ndarray, energies: list[Energy], damping_mass: float = 0.0,
                 damping_stiffness: float = 0.0, tolerance: float = 1e-6,
                 max_iterations: int = 25, dim: int = 2, lu_options: dict | None = None):
        self.dim = int(dim)
        self.lu_options = lu_options
        self.m = np.repeat(np.asarray(masses, dtype=float), self.dim)
        self.energies = list(energies)
        self.alpha = damping_mass
        self.beta = damping_stiffness
        self.tolerance = tolerance
        self.max_iterations = max_iterations
        self.n = self.m.size
        self._kept: KeptFactor | None = None

    def forget_factor(self) -> None:
        """Drop the kept factorisation (a restarted simulation repeats its results)."""
        self._kept = None

    def _evaluate(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool):
        """Phi, its gradient, the gradient of the friction part, and the Hessian parts."""
        inertia = q - q_n - dt * v_n
        phi = 0.5 * float(np.sum(self.m * inertia ** 2)) / dt ** 2
        grad = self.m * inertia / dt ** 2
        rows, cols, vals, low_rank = [], [], [], []
        elastic_rows, elastic_cols, elastic_vals = [], [], []
        for energy in self.energies:
            ev = energy.evaluate(q, hessian=hessian or self.beta > 0)
            if not np.isfinite(ev.value):
                return np.inf, None, None, None
            phi += ev.value
            grad += ev.gradient
            if hessian or self.beta > 0:
                rows.append(ev.rows)
                cols.append(ev.cols)
                vals.append(ev.vals)
                low_rank.extend(ev.low_rank)
                if energy.elastic:
                    elastic_rows.append(ev.rows)
                    elastic_cols.append(ev.cols)
                    elastic_vals.append(ev.vals)
        dq = q - q_n
        if self.alpha > 0:
            phi += 0.5 * self.alpha * float(np.sum(self.m * dq ** 2)) / dt
            grad += self.alpha * self.m * dq / dt
        if self.beta > 0 and elastic_rows:
            c = sp.coo_matrix((np.concatenate(elastic_vals),
                               (np.concatenate(elastic_rows), np.concatenate(elastic_cols))),
                              shape=(self.n, self.n)).tocsr()
            cdq = c @ dq
            phi += 0.5 * self.beta * float(dq @ cdq) / dt
            grad += self.beta * cdq / dt
        fric_grad = np.zeros(self.n)
        fric_diag = None
        k = con.friction_nodes
        if k.size and con.friction_tangents.ndim == 3:
            phi_f, fric_diag = self._cone_friction(q, q_n, dt, con, fric_grad)
            phi += phi_f
            grad += fric_grad
        elif k.size:
            x = q.reshape(-1, 2)[k]
            x_n = q_n.reshape(-1, 2)[k]
            s = np.sum((x - x_n) * con.friction_tangents, axis=1) / dt - \
                con.friction_obstacle_speed
            root = np.sqrt(s ** 2 + FRICTION_SMOOTHING ** 2)
            phi += float(np.sum(con.friction_bounds * dt * root))
            local = (con.friction_bounds * s / root)[:, None] * con.friction_tangents
            np.add.at(fric_grad, 2 * k, local[:, 0])
            np.add.at(fric_grad, 2 * k + 1, local[:, 1])
            grad += fric_grad
            fric_diag = (con.friction_bounds * FRICTION_SMOOTHING ** 2 / root ** 3 / dt)
        if not hessian:
            return phi, grad, fric_grad, None
        diag = self.m / dt ** 2 + (self.alpha * self.m / dt if self.alpha > 0 else 0.0)
        all_rows = np.concatenate(rows + [np.arange(self.n)])
        all_cols = np.concatenate(cols + [np.arange(self.n)])
        all_vals = np.concatenate(vals + [np.broadcast_to(diag, (self.n,))])
        if self.beta > 0 and elastic_rows:
            all_rows = np.concatenate([all_rows] + elastic_rows)
            all_cols = np.concatenate([all_cols] + elastic_cols)
            all_vals = np.concatenate([all_vals] + [self.beta / dt * v for v in elastic_vals])
        if k.size and con.friction_tangents.ndim == 3:
            d = self.dim
            dofs = d * k[:, None] + np.arange(d)[None, :]
            all_rows = np.concatenate([all_rows, np.repeat(dofs, d, axis=1).ravel()])
            all_cols = np.concatenate([all_cols, np.tile(dofs, (1, d)).ravel()])
            all_vals = np.concatenate([all_vals, fric_diag.ravel()])
        elif k.size:
            t = con.friction_tangents
            blocks = fric_diag[:, None, None] * t[:, :, None] * t[:, None, :]
            dofs = np.stack([2 * k, 2 * k + 1], axis=1)
            all_rows = np.concatenate([all_rows, np.repeat(dofs, 2, axis=1).ravel()])
            all_cols = np.concatenate([all_cols, np.tile(dofs, (1, 2)).ravel()])
            all_vals = np.concatenate([all_vals, blocks.ravel()])
        hess = sp.csc_matrix((all_vals, (all_rows, all_cols)), shape=(self.n, self.n))
        return phi, grad, fric_grad, (hess, low_rank)

    def _cone_friction(self, q, q_n, dt, con: StepConstraints, fric_grad):
        """Friction in a tangent plane (3D): adds its gradient into ``fric_grad``.

        With T (2, 3) the tangents and s = T (x - x_n) / dt - v_obstacle (m/s), the
        potential b dt sqrt(|s|^2 + eps^2) has the gradient b T^T s / root and the
        Hessian (b / dt) T^T (I / root - s s^T / root^3) T, positive semi-definite.

        Returns:
            (potential in J, (k, 3, 3) Hessian blocks in N/m).
        """
        d = self.dim
        k = con.friction_nodes
        t = con.friction_tangents
        dx = q.reshape(-1, d)[k] - q_n.reshape(-1, d)[k]
        s = np.einsum('kad,kd->ka', t, dx) / dt - con.friction_obstacle_speed
        root = np.sqrt(np.sum(s * s, axis=1) + FRICTION_SMOOTHING ** 2)
        b = con.friction_bounds
        local = np.einsum('ka,kad->kd', (b / root)[:, None] * s, t)
        for c in range(d):
            np.add.at(fric_grad, d * k + c, local[:, c])
        inner = (np.eye(s.shape[1])[None] / root[:, None, None]
                 - s[:, :, None] * s[:, None, :] / root[:, None, None] ** 3)
        blocks = (b / dt)[:, None, None] * np.einsum('kad,kab,kbe->kde', t, inner, t)
        return float(np.sum(b * dt * root)), blocks

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The line search's first step: 1, or less where an energy bounds it (a contact
        barrier: the continuous-collision step, ``Energy.max_step``)."""
        return min([1.0] + [energy.max_step(q, dq) for energy in self.energies])

    def _filter_matrix(self, filters: np.ndarray) -> sp.csc_matrix:
        n_nodes = filters.shape[0]
        if self.dim != 2:
            d = self.dim
            base = d * np.arange(n_nodes)
            rows = (base[:, None] + np.repeat(np.arange(d), d)[None, :]).ravel()
            cols = (base[:, None] + np.tile(np.arange(d), d)[None, :]).ravel()
            return sp.csc_matrix((filters.reshape(-1), (rows, cols)), shape=(self.n, self.n))
        base = 2 * np.arange(n_nodes)
        rows = np.stack([base, base, base + 1, base + 1], axis=1).ravel()
        cols = np.stack([base, base + 1, base, base + 1], axis=1).ravel()
        return sp.csc_matrix((filters.reshape(-1), (rows, cols)), shape=(self.n, self.n))

    def solve(self, q_n: np.ndarray, v_n: np.ndarray, dt: float, q_start: np.ndarray,
              con: StepConstraints) -> StepSolution:
        """Newton iterations from ``q_start`` (constrained dofs already at their targets).

        With ``keep_factor`` the Newton matrix (S H S + (I - S), its rank-one terms
        filtered) is kept, factorised, from iteration to iteration and from solve to
        solve - a chord (modified Newton) method - while it fits (``KeptFactor.fits``:
        the same filters, kinetic friction nodes, energies' keys and dt, at most
        MAX_FACTOR_AGE solves old) and each whole step with it cuts the filtered
        residual max |S g| below CONTRACTION of the last. It is made afresh from the
        Hessian at the iterate when it does not fit, when a step with it fails (no
        descent, or no decrease at the whole step: that iteration is done again) or
        contracts too slowly. The stopping test is the same: max |dq| / dt < tolerance.

        Raises:
            NewtonFailure: no convergence within ``max_iterations``, or no descent.
        """
        s = self._filter_matrix(con.filters)
        eye = sp.identity(self.n, format='csc')
        complement = eye - s
        q = q_start.copy()
        history: list[float] = []
        key = self._factor_key(con, dt) if self.keep_factor else None
        kept = self._kept if key is not None and self._kept is not None else None
        fresh = kept is None or not kept.fits(key)  # the next step needs a new factor
        if not fresh:
            kept.age += 1
        phi, grad, _, parts = self._evaluate(q, q_n, v_n, dt, con, hessian=fresh)
        if not np.isfinite(phi):
            raise NewtonFailure('start of step is infeasible (inverted element)', history)
        iteration = 0
        while iteration < self.max_iterations:
            iteration += 1
            g_f = s @ grad
            if fresh:
                self._kept = None
                kept = self._factorised(parts, s, complement, dt, key)
                dq, slope = descent_direction(
                    lambda shift: kept.solve(shift, -g_f), g_f, history)
                found = True
                if key is not None:
                    self._kept = kept
            else:
                dq = _solve_low_rank(kept.lu, -g_f, kept.low)
                slope = float(g_f @ dq)
                found = bool(np.all(np.isfinite(dq))) and slope <= 0
            residual = float(np.max(np.abs(g_f)))
            if found and float(np.max(np.abs(dq))) / dt < self.tolerance:
                q = q + dq
                _, grad, fric_grad, _ = self._evaluate(q, q_n, v_n, dt, con, hessian=False)
                history.append(float(np.max(np.abs(dq))) / dt)
                return StepSolution(q, grad - fric_grad, iteration, history)
            try:
                if not found:
                    raise NewtonFailure('no descent with the kept factor', history)
                q, phi, grad, step = line_search(
                    lambda x: self._evaluate(x, q_n, v_n, dt, con, hessian=False)[:2],
                    q, dq, phi, slope, residual, lambda g: s @ g, history,
                    first_step=self.max_step(q, dq), halvings=30 if fresh else 1)
            except NewtonFailure:
                if fresh:
                    raise
                iteration -= 1  # this iteration again, with the Hessian at q
            else:
                norm = float(np.max(np.abs(step * dq))) / dt
                history.append(norm)
                if norm < self.tolerance:
                    _, grad, fric_grad, _ = self._evaluate(q, q_n, v_n, dt, con,
                                                           hessian=False)
                    return StepSolution(q, grad - fric_grad, iteration, history)
                if key is not None and (fresh or float(np.max(np.abs(s @ grad)))
                                        < CONTRACTION * residual):
                    fresh = False
                    continue
            fresh = True
            phi, grad, _, parts = self._evaluate(q, q_n, v_n, dt, con, hessian=True)
        raise NewtonFailure(f'no convergence in {self.max_iterations} iterations', history)

    def _factor_key(self, con: StepConstraints, dt: float) -> tuple:
        """What a kept factorisation must have been made for (``KeptFactor.key``)."""
        friction = con.friction_nodes.tolist()
        return (con.filters.copy(), (len(friction), frozenset(friction)),
                tuple(energy.factor_key() for energy in self.energies), dt)

    def _factorised(self, parts, s, complement, dt: float, key) -> '_ShiftedFactor':
        """The Newton matrix of the Hessian ``parts`` (hess, low_rank), to be factorised
        with a shift (``_ShiftedFactor.solve``)."""
        hess, low_rank = parts
        return _ShiftedFactor(key, s @ hess @ s + complement,
                              sp.diags(s.diagonal() * self.m / dt ** 2),
                              [(c, s @ u) for c, u in low_rank], self.lu_options)


class _ShiftedFactor(KeptFactor):
    """A ``KeptFactor`` made by its first successful ``solve``: the matrix plus ``shift``
    times the filtered inertia, factorised."""

    def __init__(self, key, matrix, inertia, low, lu_options):
        super().__init__(key, None, low)
        self.matrix, self.inertia, self.lu_options = matrix, inertia, lu_options

    def solve(self, shift: float, rhs: np.ndarray) -> np.ndarray:
        """(A + shift M_S + sum c u u^T)^-1 rhs; the factorisation is kept. RuntimeError
        if singular."""
        a = (self.matrix + shift * self.inertia).tocsc()
        self.lu = spla.splu(a) if self.lu_options is None else spla.splu(a, **self.lu_options)
        return _solve_low_rank(self.lu, rhs, self.low)


#: relative rise of the incremental potential that the line search's gradient test lets
#: pass (above its rounding noise, ~1e-11 at the end of a step's Newton iterations): a
#: step that lowers the projected gradient but raises the potential by more is no progress
#: (a Newton step across the kink of the smoothed friction law, back and forth: 7e-8)
PHI_ROUNDOFF = 1e-9

#: multiples of the (filtered) inertia M / dt^2 added to an indefinite Newton matrix
DESCENT_SHIFTS = (0.0, 1.0, 10.0, 100.0, 1000.0)


def descent_direction(solve_shifted, gradient: np.ndarray, history: list[float]):
    """The Newton step of the first shift in ``DESCENT_SHIFTS`` that descends.

    An indefinite Hessian (buckling skin, compressed flesh) may give an ascent direction:
    inertia-like diagonal terms are added until the step descends.

    Args:
        solve_shifted: shift -> the step dq (n,) of the matrix with ``shift`` times the
            inertia added; may raise RuntimeError (a singular factor).
        gradient: (n,) the filtered gradient.

    Returns:
        (dq, slope gradient . dq).

    Raises:
        NewtonFailure: no shift gave a finite descent direction.
    """
    for shift in DESCENT_SHIFTS:
        try:
            dq = solve_shifted(shift)
        except RuntimeError:  # singular factor
            continue
        slope = float(gradient @ dq)
        if np.all(np.isfinite(dq)) and slope <= 0:
            return dq, slope
    raise NewtonFailure('no descent direction found', history)


def line_search(evaluate, q: np.ndarray, dq: np.ndarray, phi: float, slope: float,
                residual: float, project, history: list[float], first_step: float = 1.0,
                halvings: int = 30):
    """Backtracking from the Newton step ``dq``: the first of the steps s, s/2, s/4, ...
    (``halvings`` trials; s = ``first_step``, 1 unless a barrier's collision-free bound is
    smaller) with sufficient decrease (Armijo, 1e-4 of ``slope``) or, with the potential
    risen by at most ``PHI_ROUNDOFF`` of itself, a projected gradient below half of
    ``residual``.

    Args:
        evaluate: x -> (phi, gradient) of the incremental potential (inf if infeasible).
        project: gradient -> its free (filtered) part.

    Returns:
        (q + step dq, its phi, its gradient, step).

    Raises:
        NewtonFailure: no acceptable step.
    """
    step = first_step
    for _ in range(halvings):
        trial = q + step * dq
        phi_trial, grad_trial = evaluate(trial)
        if np.isfinite(phi_trial) and (
                phi_trial <= phi + 1e-4 * step * slope
                or (phi_trial <= phi + PHI_ROUNDOFF * abs(phi)
                    and float(np.max(np.abs(project(grad_trial)))) < 0.5 * residual)):
            return trial, phi_trial, grad_trial, step
        step *= 0.5
    raise NewtonFailure('line search failed', history)


def stack_low_rank(low_rank, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The rank-one terms sum_j c_j u_j u_j^T as u (n, k) and c (k,); k may be 0."""
    if not low_rank:
        return np.zeros((n, 0)), np.zeros(0)
    return (np.stack([vec for _, vec in low_rank], axis=1),
            np.array([coef for coef, _ in low_rank]))


def woodbury_terms(solve, u: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A^-1 u (n, k) and the capacitance matrix diag(1/c) + u^T A^-1 u (k, k) of the
    Woodbury identity (A + u diag(c) u^T)^-1 = A^-1 - A^-1 u cap^-1 u^T A^-1, with
    ``solve`` applying A^-1 to a vector."""
    a_inv_u = solve(u) if u.shape[1] > 1 else solve(u[:, 0])[:, None]
    return a_inv_u, np.diag(1.0 / c) + u.T @ a_inv_u


def _solve_low_rank(lu, rhs: np.ndarray, low_rank) -> np.ndarray:
    """Solve (A + sum c u u^T) x = rhs with A's sparse LU ``lu`` and the Woodbury
    identity."""
    x = lu.solve(rhs)
    if not low_rank:
        return x
    u, c = stack_low_rank(low_rank, rhs.shape[0])
    a_inv_u, capacitance = woodbury_terms(lu.solve, u, c)
    return x - a_inv_u @ np.linalg.solve(capacitance, u.T @ x)
