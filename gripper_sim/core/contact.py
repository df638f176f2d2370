"""Contact bookkeeping of the modified mass method with Coulomb friction.

Each node is free or held by one obstacle in one of three modes:
- STICK: both directions prescribed, the node moves with the obstacle;
- SLIP: the normal direction prescribed, kinetic friction mu_k |R_n| opposing the
  relative tangential velocity (R_n lagged from the previous pass or step);
- IMPACT: a one-step normal hold at the face after which the node leaves with
  restitution e (its normal velocity is set to e times its approach speed, less if that
  would add energy: ``contact_passes`` caps the rebound).
A held node pushed into a second face (a corner) is held by it too, frictionless; if it
arrived fast at that face it rebounds from it as well (a secondary impact).
The contact set changes between Newton solves of a step (predictor-corrector), never
inside one: nodes found inside an obstacle are added, a held node whose reaction turns
attractive (beyond a small hysteresis threshold) is released, a stuck node whose
tangential reaction exceeds mu_s R_n starts slipping, a slipping node whose relative
speed vanishes sticks again.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

FREE, STICK, SLIP, IMPACT = 0, 1, 2, 3


@njit(cache=True)
def jaw_sides(obstacle, side_of_obstacle, left, right):
    """Set ``left`` and ``right`` (n,) bool to the nodes the left (side 0) and the right
    (side 1) jaw hold: the side of each node's obstacle (``obstacle`` (n,), -1 none;
    ``side_of_obstacle`` (k + 1,) each obstacle's side, -1 none, and last -1 for no
    obstacle); returns whether each jaw holds any node."""
    any_left = any_right = False
    for i in range(obstacle.shape[0]):
        side = side_of_obstacle[obstacle[i]]
        left[i] = side == 0
        right[i] = side == 1
        any_left = any_left or side == 0
        any_right = any_right or side == 1
    return any_left, any_right


@dataclass
class ContactState:
    """Per-node contact state carried from step to step.

    Attributes:
        obstacle: (n_nodes,) int, index of the holding obstacle, -1 if free.
        mode: (n_nodes,) int, FREE, STICK, SLIP or IMPACT.
        normal_force: (n_nodes,) N, last normal reaction (friction bound lag).
        bounce_speed: (n_nodes,) m/s, outgoing normal speed of an IMPACT node.
        secondary: (n_nodes,) int, a second obstacle whose face also holds the node
            (a corner, e.g. wall and table), frictionless, -1 if none.
        secondary_bounce: (n_nodes,) m/s, outgoing speed along the second face's normal
            of a node that hit it this step (0: held at the face).
    """

    obstacle: np.ndarray
    mode: np.ndarray
    normal_force: np.ndarray
    bounce_speed: np.ndarray
    secondary: np.ndarray
    secondary_bounce: np.ndarray

    @classmethod
    def empty(cls, n_nodes: int) -> 'ContactState':
        return cls.held_by(np.full(n_nodes, -1, np.int64))

    @classmethod
    def held_by(cls, obstacle: np.ndarray) -> 'ContactState':
        """The contact set whose nodes are held by ``obstacle`` (n,) (-1: free; taken, not
        copied), all FREE, no forces, no second obstacle."""
        n_nodes = obstacle.shape[0]
        return cls(obstacle, np.zeros(n_nodes, np.int64), np.zeros(n_nodes), np.zeros(n_nodes),
                   np.full(n_nodes, -1, np.int64), np.zeros(n_nodes))

    def copy(self) -> 'ContactState':
        return ContactState(self.obstacle.copy(), self.mode.copy(), self.normal_force.copy(),
                            self.bounce_speed.copy(), self.secondary.copy(),
                            self.secondary_bounce.copy())

    def arrays(self) -> tuple:
        """(obstacle, mode, normal_force, bounce_speed, secondary, secondary_bounce): the
        state as the compiled passes take it (``core.contact_kernels``), the same arrays."""
        return (self.obstacle, self.mode, self.normal_force, self.bounce_speed,
                self.secondary, self.secondary_bounce)

    def release(self, nodes) -> None:
        self.obstacle[nodes] = -1
        self.mode[nodes] = FREE
        self.normal_force[nodes] = 0.0
        self.bounce_speed[nodes] = 0.0
        self.release_secondary(nodes)

    def release_secondary(self, nodes) -> None:
        self.secondary[nodes] = -1
        self.secondary_bounce[nodes] = 0.0

    @property
    def held(self) -> np.ndarray:
        return np.flatnonzero(self.obstacle >= 0)
