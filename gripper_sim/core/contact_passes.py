"""One implicit step with contact: the predictor-corrector passes, for 2D and 3D.

The modified mass method (Baraff & Witkin 1998) around the Newton solve of the implicit
Euler step (``core.stepper``): each pass prescribes the held nodes (z targets: a stuck
node moves with its obstacle, a sliding one and an IMPACT node keep their normal gap;
the S filter frees the rest), solves, and corrects the contact set
(``core.contact``): pulling nodes are released, stuck nodes whose tangential reaction
leaves the Coulomb cone |R_t| <= mu_s R_n slip, slipping nodes that stopped stick, a
held node pushed into a second face gets it as a frictionless secondary hold (a
corner), free surface nodes found inside a face are added (with restitution if they
arrive fast, at the first face and at the second of a corner alike: a node that hits a
floor and a wall in one step rebounds from both). The passes end when the set no longer
changes.

Restitution never adds energy: the outgoing velocity of a node that rebounds is capped so
that its kinetic energy after the step is at most its kinetic energy before plus the work
the fruit's forces (elastic, gravity, damping) did on it during the step. Backward Euler
with the obstacles' reactions R gives E_end - E_start <= sum R . dx (convex energies);
replacing a node's velocity dx / dt by v_out changes that node's part to
m |v_out|^2 / 2 - m |v_start|^2 / 2 - F . dx with F = m (dx / dt - v_start) / dt - R
the other forces on it, so with the cap no rebound raises the total energy.

Dimension is a parameter, not a copy: positions are (n, d), faces (``FlatFace`` in 2D,
``Plate`` in 3D) have a unit ``normal`` (d,) and ``tangents`` (d - 1, d), and kinetic
friction is the smoothed Coulomb cone of the stepper in the tangent space (one tangent
in 2D). The per-node logic of a pass is compiled (``core.contact_kernels``); the loop
over the passes is one function, ``contact_passes``, written as ``newton.newton_iteration``
is: over hooks (``pass_arrays``, ``solve``, ``solution``) on a *problem*. ``contact_step``
runs it by Python on ``_SolverPasses`` (every set-up, around a solver object); the 2D
whole-step kernel (``core.kernels.substep``) compiles it with the hooks overloaded for
its tuple (the solve its compiled Newton solve).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from gripper_sim.core import contact as cm
from gripper_sim.core import contact_kernels as ck
from gripper_sim.core.newton import CONTACTS_UNSETTLED, OK
from gripper_sim.core.stepper import (NEWTON_FAILURES, NewtonFailure, StepConstraints,
                                      StepSolution)


@dataclass(frozen=True)
class ContactSettings:
    """Attributes:
        max_passes: predictor-corrector passes per step.
        max_correction_speed: m/s, fastest rate at which a penetration is undone.
        release_threshold: N, a held node is released when its normal reaction pulls
            by more than this.
        gravity: m/s^2, sets the slowest approach that bounces (5 g dt, at least 1 mm/s).
        deepest_first: a pass adds, of the free nodes inside a face, those at least this
            fraction of the deepest one's depth (0: all of them).
        extrapolate_lag: a sliding node's lagged normal force goes to the secant
            estimate of its fixed point (``contact_kernels.extrapolate_lag``) between
            passes. On in 3D; off in 2D, whose whole-step kernel (``core.kernels``) has
            not got it yet and whose reference path must match it.
    """

    max_passes: int
    max_correction_speed: float
    release_threshold: float
    gravity: float
    deepest_first: float = 0.0
    extrapolate_lag: bool = False

    @classmethod
    def from_config(cls, config, deepest_first: float = 0.0) -> 'ContactSettings':
        return cls(int(config['sim.max_contact_passes']),
                   float(config['contact.max_correction_speed']),
                   float(config['contact.release_threshold']), float(config['world.gravity']),
                   deepest_first, int(config.get('dimension', 2)) == 3)


@dataclass
class StepOutcome:
    """Attributes:
        x: (n, d) m, end positions.  v: (n, d) m/s, end velocities (held nodes with their
        obstacle's normal speed, stuck ones with its tangential speed too).
        forces: (n, d) N, the obstacles' reactions on the held nodes.
        contacts: the contact set at the end of the step.  iterations: Newton iterations.
        reaction: (n, d) N, the forces holding prescribed nodes (a soft finger's base,
        ``barrier.soft_body_step``), None where no node is prescribed.
    """

    x: np.ndarray
    v: np.ndarray
    forces: np.ndarray
    contacts: cm.ContactState
    iterations: int
    reaction: np.ndarray | None = None


# ---------------------------------------------------------------------- hooks
# What the pass driver asks of its problem. The interpreted versions: methods of the
# problem object (``_SolverPasses``, around a solver object). The compiled ones are
# overloads registered for the 2D whole-step kernel's tuple (``core.kernels``).
def pass_arrays(problem):
    """-> (start (n, d), filters (n, d, d), fr_nodes (n,) int64, fr_tangents
    (n, d - 1, d), fr_bound (n,), fr_speed (n, d - 1)): the outputs of a pass's
    ``contact_kernels.constraints``."""
    return problem.pass_arrays()


def solve(problem, start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed, k):
    """The Newton solve of a pass from ``start`` under the filters and the first ``k``
    friction rows -> (status, Newton iterations); its end is then ``solution``."""
    return problem.solve(start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed, k)


def solution(problem):
    """-> (x (n, d) m, reaction (n, d) N): the last solve's end and the faces' forces."""
    return problem.solution()


# ---------------------------------------------------------------------- the passes
@njit(cache=True, error_model='numpy', inline='always')
def _copy_state(state):
    obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce = state
    return (obstacle.copy(), mode.copy(), normal_force.copy(), bounce_speed.copy(),
            secondary.copy(), secondary_bounce.copy())


@njit(cache=True, error_model='numpy', inline='always')
def contact_passes(problem, state, faces, x_n, v_n, x_pred, surface, masses, dt, rules,
                   released, slipped, v_out, forces_out):
    """The predictor-corrector passes of one step (see the module's docstring): per pass
    the constraints (``contact_kernels.constraints``), the solve (hook ``solve``), the
    contact set's correction (``contact_kernels.update``) and, with ``extrapolate``, the
    sliding nodes' lag extrapolation, until the set stops changing; then the end
    velocities and contact forces (``contact_kernels.finish``). A set still changing
    after ``max_passes`` fails the step (``CONTACTS_UNSETTLED``; the caller halves it):
    the last solve's reactions belong to a set the step would not keep (a large step
    onto the table flattens the fruit, and the passes then release one pulling node a
    side at a time).

    Args:
        problem: what is solved (a tuple for the compiled hooks, an object for the
            interpreted ones: see the hooks above).
        state, faces: the contact state (updated in place) and the faces (see
            ``contact_kernels``).
        x_n, v_n: (n, d) m and m/s, the step's start.  x_pred: (n, d) m, x_n + dt v_n.
        surface: (m,) int64, the nodes that can touch a face.
        masses: (n,) kg.  dt: s.
        rules: (max_passes, v_corr m/s, release threshold N, v_min m/s, deepest_first,
            extrapolate) (see ``ContactSettings``; v_min the slowest approach that
            rebounds).
        released, slipped: (n,) bool scratch.
        Outputs: v_out (n, d) m/s, forces_out (n, d) N.

    Returns:
        (status, Newton iterations); a failed solve's status, or ``CONTACTS_UNSETTLED``,
        ends the step (no outputs).
    """
    max_passes, v_corr, threshold, v_min, deepest_first, extrapolate = rules
    n = x_n.shape[0]
    released[:] = False
    slipped[:] = False
    lagged = n if extrapolate else 0
    lag_history = (np.zeros(lagged), np.zeros(lagged), np.zeros(lagged, np.bool_))
    iterations = 0
    settled = False
    for pass_ in range(max_passes):
        start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed = pass_arrays(problem)
        k = ck.constraints(state, faces, x_n, x_pred, dt, v_corr, start, filters, fr_nodes,
                           fr_tangents, fr_bound, fr_speed)
        status, its = solve(problem, start, filters, fr_nodes, fr_tangents, fr_bound,
                            fr_speed, k)
        if status != OK:
            return status, iterations
        iterations += its
        x, reaction = solution(problem)
        # the state during the solve: a copy only where extrapolate_lag needs it
        before = _copy_state(state) if extrapolate else state
        if not ck.update(state, faces, x, x_n, v_n, reaction, surface, dt, threshold, v_min,
                         deepest_first, released, slipped):
            settled = True
            break
        if extrapolate and pass_ < max_passes - 1:
            ck.extrapolate_lag(state, before, lag_history)
    if not settled:
        return CONTACTS_UNSETTLED, iterations
    x, reaction = solution(problem)
    ck.finish(state, faces, x, x_n, v_n, reaction, masses, dt, v_out, forces_out)
    return OK, iterations


class _SolverPasses:
    """The pass hooks around a solver object (``solve(q_n, v_n, dt, q_start,
    constraints)``, ``core.stepper``): fresh arrays each pass (the solver may keep the
    constraints it was given), failures raised as ``NewtonFailure``."""

    def __init__(self, solver, q_n: np.ndarray, v_n: np.ndarray, dt: float):
        self.solver = solver
        self.q_n = q_n
        self.v_n = v_n
        self.dt = dt
        self.n, self.d = v_n.shape
        self.x = np.empty((self.n, self.d))
        self.reaction = np.empty((self.n, self.d))

    def pass_arrays(self):
        n, d = self.n, self.d
        return (np.empty((n, d)), np.empty((n, d, d)), np.empty(n, np.int64),
                np.empty((n, d - 1, d)), np.empty(n), np.empty((n, d - 1)))

    def solve(self, start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed, k):
        constraints = StepConstraints(filters, fr_nodes[:k], fr_tangents[:k], fr_bound[:k],
                                      fr_speed[:k])
        result = self.solver.solve(self.q_n, self.v_n.ravel(), self.dt, start.ravel(),
                                   constraints)
        self.x = np.ascontiguousarray(result.q.reshape(-1, self.d))
        self.reaction = np.ascontiguousarray(result.reaction.reshape(-1, self.d))
        return OK, result.iterations

    def solution(self):
        return self.x, self.reaction


def contact_step(solver, surface: np.ndarray, contacts: cm.ContactState, x_n: np.ndarray,
                 v_n: np.ndarray, old_faces: list, new_faces: list, dt: float,
                 settings: ContactSettings) -> StepOutcome:
    """One implicit step of ``dt`` from (x_n, v_n) (n, d) with the faces translating from
    ``old_faces`` to ``new_faces``; ``contacts`` is not modified. ``surface``: (m,) the
    nodes that can touch a face; ``solver``: ``solve(q_n, v_n, dt, q_start, constraints)``
    (``core.stepper``) with the per-dof masses ``m``. The passes are ``contact_passes``
    run by Python.

    Raises:
        NewtonFailure: from the solver, or the contact set not settled in
            ``settings.max_passes`` passes (the caller halves the step).
    """
    n, d = x_n.shape
    x_n = np.ascontiguousarray(x_n, dtype=float)
    v_n = np.ascontiguousarray(v_n, dtype=float)
    x_pred = x_n + dt * v_n
    contacts = contacts.copy()
    faces = ck.face_arrays(old_faces, new_faces, d)
    surface = np.ascontiguousarray(surface, dtype=np.int64)
    masses = np.ascontiguousarray(solver.m[::d], dtype=float)
    v_min = max(5.0 * settings.gravity * dt, 1e-3)  # m/s, the slowest approach that bounces
    rules = (settings.max_passes, settings.max_correction_speed, settings.release_threshold,
             v_min, settings.deepest_first, settings.extrapolate_lag)
    problem = _SolverPasses(solver, x_n.ravel(), v_n, dt)
    v, forces = np.empty((n, d)), np.empty((n, d))
    status, iterations = contact_passes.py_func(problem, contacts.arrays(), faces, x_n, v_n,
                                                x_pred, surface, masses, dt, rules,
                                                np.zeros(n, bool), np.zeros(n, bool), v,
                                                forces)
    if status != OK:
        raise NewtonFailure(NEWTON_FAILURES[status], [])
    x, _ = problem.solution()
    return StepOutcome(x, v, forces, contacts, iterations)


def load_kernels(masses: np.ndarray, surface: np.ndarray, x: np.ndarray, faces: list,
                 dt: float, settings: ContactSettings) -> None:
    """Run each compiled function of a contact pass once, on a throwaway step from
    positions ``x`` (n, d) m at rest with the faces ``faces`` standing still and a solve
    that returns its start: numba loads a kernel's compiled code from its cache on first
    use (10-20 ms each), which then happens here, when a simulation is built, and not in
    its first steps. ``masses``: (d n,) kg per dof; ``surface``: (m,) node indices."""
    n, d = x.shape

    class _Start:
        m = masses

        @staticmethod
        def solve(q_n, v_n, dt_, q_start, constraints):
            return StepSolution(q_start, np.zeros_like(q_start), 0, [])

    outcome = contact_step(_Start, surface, cm.ContactState.empty(n), x, np.zeros((n, d)),
                           faces, faces, dt, settings)
    state = outcome.contacts.arrays()
    ck.extrapolate_lag(state, tuple(field.copy() for field in state),
                       (np.zeros(n), np.zeros(n), np.zeros(n, bool)))
