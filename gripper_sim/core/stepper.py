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

This module holds what every route of the step shares: the step's constraints and
solution, the failure, and ``StepProblem``, the interpreted Newton problems' common part.
The potential's terms besides the energies are ``core.potential_terms`` (compiled once
for both assemblies). The Newton iteration itself is ``core.newton.newton_iteration``
(the one for every set-up); the solver is ``core.fast_solver.PatternCachingSolver`` (the
2D whole-step kernel, ``core.kernels``, runs the same potential in band storage). The
triplet/SuperLU reference they are both checked against is ``test/reference_solver.py``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gripper_sim.core import newton

#: regularisation speed (m/s) of the kinetic friction law |s| ~ sqrt(s^2 + eps^2)
FRICTION_SMOOTHING = 1e-4


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


#: NewtonFailure's message for each failure status of ``newton.newton_iteration``
NEWTON_FAILURES = {newton.INFEASIBLE_START: 'start of step is infeasible (inverted element)',
                   newton.NO_DESCENT: 'no descent direction found',
                   newton.LINE_SEARCH_FAILED: 'line search failed',
                   newton.NO_CONVERGENCE: 'no convergence in {} iterations',
                   newton.CONTACTS_UNSETTLED: 'the contact set still changed after the last '
                   'predictor-corrector pass (sim.max_contact_passes)'}


class StepProblem:
    """What the interpreted problems of ``newton.newton_iteration`` share: the step's
    data, the loop's work vectors, and the ``evaluate`` hook on the solver's potential
    (``potential``: ``PatternCachingSolver.evaluate_fast``, or the test reference's
    ``incremental_potential``, both (Phi J, gradient (n_dof,) N, friction gradient, Hessian
    parts or None)).

    Args:
        solver: the solver whose step this is.
        q_n, v_n: (n_dof,) m, m/s at the start of the step.  dt: s.
        con: the step's constraints.
        potential: the solver's potential, called (q, q_n, v_n, dt, con, hessian).
    """

    def __init__(self, solver, q_n: np.ndarray, v_n: np.ndarray, dt: float,
                 con: StepConstraints, potential):
        self.solver, self.q_n, self.v_n, self.dt, self.con = solver, q_n, v_n, dt, con
        self.potential = potential
        self._vectors = tuple(np.empty(solver.n) for _ in range(5))
        self.parts = None  # the Hessian parts of the last evaluation with the Hessian
        self.fric_grad = None
        self.reaction = None

    def vectors(self):
        return self._vectors

    def evaluate(self, x, hessian, grad) -> float:
        phi, g, fric_grad, parts = self.potential(x, self.q_n, self.v_n, self.dt, self.con,
                                                  bool(hessian))
        if not math.isfinite(phi):
            return np.inf
        grad[:] = g
        self.fric_grad = fric_grad
        if hessian:
            self.parts = parts
        return phi


def stack_low_rank(low_rank, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The rank-one terms sum_j c_j u_j u_j^T as u (n, k) and c (k,); k may be 0."""
    if not low_rank:
        return np.zeros((n, 0)), np.zeros(0)
    return (np.stack([vec for _, vec in low_rank], axis=1),
            np.array([coef for coef, _ in low_rank]))

