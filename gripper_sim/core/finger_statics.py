"""A deformable finger on its own: its base held, loads on its nodes, the static
equilibrium solved by the project's Newton (the implicit Euler step with a long step and
the load applied in increments, so that the inertia term is a vanishing regulariser).
For structural checks and figures, without fruit or jaws.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.energies import ConstantForce, Energy
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.fast_solver import PatternCachingSolver
from gripper_sim.core.stepper import StepConstraints

#: s, the step of the quasi-static solve: m / dt^2 (a few 1e-4 N/m for a finger's grams)
#: is far below the stiffness of any finger (> 1 N/m)
STATIC_STEP = 1.0


@dataclass(frozen=True)
class StaticState:
    """Attributes:
        positions: (n_nodes, d) m, the deformed finger.
        base_reaction: (d,) N, the force the base exerts on the finger (x, z; 3D x, y, z).
    """

    positions: np.ndarray
    base_reaction: np.ndarray


def static_equilibrium(body: FingerBody, forces: np.ndarray, increments: int = 8,
                       tolerance: float = 1e-10, self_contact: BarrierSettings | None = None,
                       on_increment=None, step: float = STATIC_STEP,
                       hold: int = 1, elastic: list[Energy] | None = None,
                       before_increment=None) -> StaticState:
    """The finger under ``forces`` with its base nodes fixed at rest.

    Args:
        body: the finger (a 2D ``FingerBody``, or a 3D body with ``elastic`` given: any
            body with rest_positions (n_nodes, d), masses and base_nodes).
        forces: (n_nodes, d) N, constant loads on the nodes (x, z; 3D x, y, z).
        increments: load steps from 0 to the full load (each a Newton solve).
        tolerance: m, Newton stops when the largest update is below it.
        self_contact: the barrier of the finger's self-contact
            (``FingerBody.self_contact``); None: its members pass through each other.
        on_increment: called with the positions (n_nodes, d) m after each increment.
        step: s, the implicit Euler step of each increment (each starts at rest): a short
            one makes the increments an overdamped motion that follows a snap-through,
            where the long default jumps to the loaded equilibrium if one is near.
        hold: further increments at the full load.
        elastic: the body's elastic energies on its own q; None: its rods'. Other
            potentials may join them (an obstacle's contact barrier).
        before_increment: called before each increment's solve with its load fraction
            (0..1] and the positions it starts from (n_nodes, d) m; it may change
            something of the energies (move an obstacle) and returns the positions to
            start from (feasible for them).

    Raises:
        NewtonFailure: no equilibrium found.
    """
    dim = body.rest_positions.shape[1]
    constraints = StepConstraints.free(body.n_nodes, dim)
    constraints.filters[body.base_nodes] = 0.0
    elastic = body.rod_energies() if elastic is None else list(elastic)
    barrier = body.self_contact(self_contact) if self_contact is not None else None
    if barrier is not None:
        elastic.append(barrier)
    q = body.rest_positions.ravel().copy()
    still = np.zeros_like(q)
    solution = None
    full_load = np.asarray(forces, dtype=float).ravel()
    load = ConstantForce(np.zeros_like(full_load))
    solver = PatternCachingSolver(body.masses, elastic + [load], dim=dim,
                                  tolerance=tolerance / step, max_iterations=100)
    for fraction in list(np.linspace(1.0 / increments, 1.0, increments)) + [1.0] * hold:
        load.grad[:] = -fraction * full_load  # the potential -f . q of the increment's load
        if before_increment is not None:
            q = np.asarray(before_increment(fraction, q.reshape(-1, dim)),
                           dtype=float).ravel().copy()
        if barrier is not None:
            barrier.begin_step(q.reshape(-1, dim), [], [], step)
        solution = solver.solve(q, still, step, q.copy(), constraints)
        q = solution.q
        if on_increment is not None:
            on_increment(q.reshape(-1, dim))
    reaction = solution.reaction.reshape(-1, dim)[body.base_nodes]
    return StaticState(q.reshape(-1, dim), reaction.sum(axis=0))
