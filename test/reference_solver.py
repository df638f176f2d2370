"""The reference implicit Euler solver, for the tests only: the incremental potential
assembled from the energies' IJV triplets (``Energy.evaluate``) into a scipy sparse
matrix at every evaluation, and SuperLU, on the one Newton iteration
(``core.newton.newton_iteration_interpreted``). Production has one solver,
``core.fast_solver.PatternCachingSolver``; the whole-step 2D kernel (``core.kernels``)
and it are checked against this one (test_fast_path, test_fast_solver, test_integrator,
test_3d_*).

``reference_route(sim)`` puts this solver into a simulation built with ``fast=False``
(the generic contact passes), so that whole trajectories compare against it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from gripper_sim.core import newton
from gripper_sim.core.energies.base import Energy
from gripper_sim.core.stepper import (FRICTION_SMOOTHING, NEWTON_FAILURES, NewtonFailure,
                                      StepConstraints, StepProblem, StepSolution,
                                      stack_low_rank)

#: SuperLU settings for the reference's Newton systems (symmetric pattern: minimum
#: degree on A^T + A and diagonal pivots, about twice as fast as the defaults for the
#: 3D fruit)
SYMMETRIC_LU_OPTIONS = dict(permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                            options=dict(SymmetricMode=True))


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
        """Made for these constraints and dt, and younger than ``newton.MAX_FACTOR_AGE``
        solves."""
        filters, friction, energies, dt = key
        return (self.age < newton.MAX_FACTOR_AGE and self.key[3] == dt and self.key[1] == friction
                and self.key[2] == energies and np.array_equal(self.key[0], filters))


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
        self.kept_factor: KeptFactor | None = None

    def reset(self) -> None:
        """Drop the kept factorisation (a restarted simulation repeats its results)."""
        self.kept_factor = None

    def incremental_potential(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool):
        """Phi, its gradient, the gradient of the friction part, and the Hessian parts
        (sparse matrix, rank-one terms). Stiffness damping: beta dq^T K_n dq / (2 dt), K_n
        the elastic energies' Hessian (triplets) at q_n."""
        inertia = q - q_n - dt * v_n
        phi = 0.5 * float(np.sum(self.m * inertia ** 2)) / dt ** 2
        grad = self.m * inertia / dt ** 2
        rows, cols, vals, low_rank = [], [], [], []
        for energy in self.energies:
            ev = energy.evaluate(q, hessian=hessian)
            if not np.isfinite(ev.value):
                return np.inf, None, None, None
            phi += ev.value
            grad += ev.gradient
            if hessian:
                rows.append(ev.rows)
                cols.append(ev.cols)
                vals.append(ev.vals)
                low_rank.extend(ev.low_rank)
        # stiffness damping's K_n: the elastic energies' Hessian triplets at q_n
        elastic_rows, elastic_cols, elastic_vals = [], [], []
        if self.beta > 0:
            for energy in self.energies:
                if energy.elastic:
                    ev = energy.evaluate(q_n, hessian=True)
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

    def filter_matrix(self, filters: np.ndarray) -> sp.csc_matrix:
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
        """Newton iterations from ``q_start`` (constrained dofs already at their targets):
        ``newton.newton_iteration`` (interpreted) on the triplet-assembled Newton matrix
        and its sparse LU (``_SparseProblem``).

        With ``keep_factor`` the factorised Newton matrix (S H S + (I - S), its rank-one
        terms filtered) is kept from iteration to iteration and from solve to solve by the
        iteration's chord rule, while it fits (``KeptFactor.fits``: the same filters,
        kinetic friction nodes, energies' keys and dt, at most ``newton.MAX_FACTOR_AGE``
        solves old); without it every iteration is a full Newton step.

        Raises:
            NewtonFailure: no convergence within ``max_iterations``, or no descent.
        """
        problem = _SparseProblem(self, q_n, v_n, dt, con)
        q = q_start.copy()
        history = np.zeros(self.max_iterations)
        status, iterations, n_hist = newton.newton_iteration_interpreted(
            problem, q, dt, self.tolerance, self.max_iterations, history,
            np.zeros(newton.C_SIZE, np.int64))
        done = history[:n_hist].tolist()
        if status != newton.OK:
            raise NewtonFailure(NEWTON_FAILURES[status].format(self.max_iterations), done)
        return StepSolution(q, problem.reaction, iterations, done)

    def factor_key(self, con: StepConstraints, dt: float) -> tuple:
        """What a kept factorisation must have been made for (``KeptFactor.key``)."""
        friction = con.friction_nodes.tolist()
        return (con.filters.copy(), (len(friction), frozenset(friction)),
                tuple(energy.factor_key() for energy in self.energies), dt)



class _SparseProblem(StepProblem):
    """One ``ImplicitEulerSolver.solve``'s problem for ``newton.newton_iteration``: its
    hooks as methods (see ``core.newton``), on the energies' IJV triplets summed into a
    sparse matrix at each evaluation and SuperLU. The kept factor lives in the solver
    (``_kept``) with ``keep_factor``; without it nothing is kept (``keep_limit`` 0).

    Args:
        solver: the ``ImplicitEulerSolver``.
        q_n, v_n: (n_dof,) m, m/s at the start of the step.  dt: s.
        con: the step's constraints.
    """

    def __init__(self, solver: ImplicitEulerSolver, q_n: np.ndarray, v_n: np.ndarray,
                 dt: float, con: StepConstraints):
        super().__init__(solver, q_n, v_n, dt, con, solver.incremental_potential)
        self.s = solver.filter_matrix(con.filters)
        self.complement = sp.identity(solver.n, format='csc') - self.s
        self.key = solver.factor_key(con, dt) if solver.keep_factor else None
        self.factor = None  # the KeptFactor just made

    def kept_fits(self) -> bool:
        kept = self.solver.kept_factor
        if self.key is None or kept is None or not kept.fits(self.key):
            return False
        kept.age += 1
        return True

    def project(self, grad, g_f) -> None:
        g_f[:] = self.s @ grad

    def forget(self) -> None:
        self.solver.kept_factor = None

    def keep(self) -> None:
        if self.key is not None:
            self.solver.kept_factor = self.factor

    def factorise(self, x, shift) -> bool:
        solver, s = self.solver, self.s
        hess, low_rank = self.parts
        matrix = (s @ hess @ s + self.complement
                  + sp.diags(shift * s.diagonal() * solver.m / self.dt ** 2)).tocsc()
        try:
            lu = (spla.splu(matrix) if solver.lu_options is None
                  else spla.splu(matrix, **solver.lu_options))
        except RuntimeError:  # singular
            return False
        self.factor = KeptFactor(self.key, lu, [(c, s @ u) for c, u in low_rank])
        self.matrix = matrix
        return True

    def definite(self) -> bool:
        """Whether the matrix just factorised with its rank-one terms is positive
        definite (dense eigenvalues: the reference's problems are small)."""
        dense = self.matrix.toarray()
        for c, u in self.factor.low:
            dense += c * np.outer(u, u)
        return bool(np.linalg.eigvalsh(0.5 * (dense + dense.T))[0] > 0.0)

    def direction(self, g_f, dq, fresh) -> tuple[bool, float]:
        factor = self.factor if fresh else self.solver.kept_factor
        dq[:] = _solve_low_rank(factor.lu, -g_f, factor.low)
        return bool(np.all(np.isfinite(dq))), float(g_f @ dq)

    def step_bound(self, x, dq) -> float:
        return self.solver.max_step(x, dq)

    def keep_limit(self) -> float:
        return np.inf if self.key is not None else 0.0

    def filtered_max(self, g) -> float:
        return float(np.max(np.abs(self.s @ g), initial=0.0))

    def finish(self, x, grad) -> None:
        self.reaction = grad - self.fric_grad


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


def reference_route(sim, keep_factor: bool | None = None):
    """``sim`` (a Simulation or Simulation3D built with ``fast=False`` or in 3D) stepping on
    the reference solver instead of its own: the same energies, damping and tolerances.
    ``keep_factor`` None: the 2D whole-step kernel's chord rule in 2D with the default
    contact model (what its Newton iteration counts are compared with), else as given."""
    own = sim.solver
    solver = ImplicitEulerSolver(own.m[::own.dim], own.energies, damping_mass=own.alpha,
                                 damping_stiffness=own.beta, tolerance=own.tolerance,
                                 max_iterations=own.max_iterations, dim=own.dim,
                                 lu_options=SYMMETRIC_LU_OPTIONS)
    if keep_factor is None:
        keep_factor = own.dim == 2 and getattr(sim, '_barrier', None) is None
    solver.keep_factor = keep_factor
    sim.solver = solver
    return sim
