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
in 2D). The per-node logic of a pass is compiled (``core.contact_kernels``, which the 2D
whole-step kernel calls too); this module drives it around the solver.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core import contact as cm
from gripper_sim.core import contact_kernels as ck
from gripper_sim.core.stepper import StepConstraints, StepSolution


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


def contact_step(solver, surface: np.ndarray, contacts: cm.ContactState, x_n: np.ndarray,
                 v_n: np.ndarray, old_faces: list, new_faces: list, dt: float,
                 settings: ContactSettings) -> StepOutcome:
    """One implicit step of ``dt`` from (x_n, v_n) (n, d) with the faces translating from
    ``old_faces`` to ``new_faces``; ``contacts`` is not modified. ``surface``: (m,) the
    nodes that can touch a face; ``solver``: ``solve(q_n, v_n, dt, q_start, constraints)``
    (``core.stepper``) with the per-dof masses ``m``.

    Raises:
        NewtonFailure: from the solver (the caller halves the step).
    """
    n, d = x_n.shape
    x_n = np.ascontiguousarray(x_n, dtype=float)
    v_n = np.ascontiguousarray(v_n, dtype=float)
    q_n = x_n.ravel()
    x_pred = x_n + dt * v_n
    contacts = contacts.copy()
    state = contacts.arrays()
    faces = ck.face_arrays(old_faces, new_faces, d)
    surface = np.ascontiguousarray(surface, dtype=np.int64)
    released = np.zeros(n, bool)
    slipped = np.zeros(n, bool)
    v_min = max(5.0 * settings.gravity * dt, 1e-3)  # m/s, the slowest approach that bounces
    iterations = 0
    lag_history = (np.zeros(n), np.zeros(n), np.zeros(n, bool))
    for pass_ in range(settings.max_passes):
        start, filters = np.empty((n, d)), np.empty((n, d, d))
        fr_nodes, fr_bound = np.empty(n, np.int64), np.empty(n)
        fr_tangents, fr_speed = np.empty((n, d - 1, d)), np.empty((n, d - 1))
        k = ck.constraints(state, faces, x_n, x_pred, dt, settings.max_correction_speed,
                           start, filters, fr_nodes, fr_tangents, fr_bound, fr_speed)
        constraints = StepConstraints(filters, fr_nodes[:k], fr_tangents[:k], fr_bound[:k],
                                      fr_speed[:k])
        solution = solver.solve(q_n, v_n.ravel(), dt, start.ravel(), constraints)
        iterations += solution.iterations
        x = np.ascontiguousarray(solution.q.reshape(-1, d))
        reaction = np.ascontiguousarray(solution.reaction.reshape(-1, d))
        before = tuple(field.copy() for field in state) if settings.extrapolate_lag else None
        if not ck.update(state, faces, x, x_n, v_n, reaction, surface, dt,
                         settings.release_threshold, v_min, settings.deepest_first, released,
                         slipped):
            break
        if settings.extrapolate_lag and pass_ < settings.max_passes - 1:
            ck.extrapolate_lag(state, before, lag_history)
    v, forces = np.empty((n, d)), np.empty((n, d))
    masses = np.ascontiguousarray(solver.m[::d], dtype=float)
    ck.finish(state, faces, x, x_n, v_n, reaction, masses, dt, v, forces)
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
