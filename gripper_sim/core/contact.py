"""Contact bookkeeping of the modified mass method with Coulomb friction.

Each node is free or held by one obstacle in one of three modes:
- STICK: both directions prescribed, the node moves with the obstacle;
- SLIP: the normal direction prescribed, kinetic friction mu_k |R_n| opposing the
  relative tangential velocity (R_n lagged from the previous pass or step);
- IMPACT: a one-step normal constraint that sends the node back out with
  restitution e (its velocity is set to -e times its approach speed).
The contact set changes between Newton solves of a step (predictor-corrector), never
inside one: nodes found inside an obstacle are added, a held node whose reaction turns
attractive (beyond a small hysteresis threshold) is released, a stuck node whose
tangential reaction exceeds mu_s R_n starts slipping, a slipping node whose relative
speed vanishes sticks again.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FREE, STICK, SLIP, IMPACT = 0, 1, 2, 3


@dataclass
class ContactState:
    """Per-node contact state carried from step to step.

    Attributes:
        obstacle: (n_nodes,) int, index of the holding obstacle, -1 if free.
        mode: (n_nodes,) int, FREE, STICK, SLIP or IMPACT.
        normal_force: (n_nodes,) N, last normal reaction (friction bound lag).
        bounce_speed: (n_nodes,) m/s, outgoing normal speed of an IMPACT node.
        impact_gap: (n_nodes,) m, gap an IMPACT node ends its step at.
        secondary: (n_nodes,) int, a second obstacle whose face also holds the node
            (a corner, e.g. wall and table), frictionless, -1 if none.
    """

    obstacle: np.ndarray
    mode: np.ndarray
    normal_force: np.ndarray
    bounce_speed: np.ndarray
    impact_gap: np.ndarray
    secondary: np.ndarray

    @classmethod
    def empty(cls, n_nodes: int) -> 'ContactState':
        return cls(-np.ones(n_nodes, np.int64), np.zeros(n_nodes, np.int64),
                   np.zeros(n_nodes), np.zeros(n_nodes), np.zeros(n_nodes),
                   -np.ones(n_nodes, np.int64))

    def copy(self) -> 'ContactState':
        return ContactState(self.obstacle.copy(), self.mode.copy(), self.normal_force.copy(),
                            self.bounce_speed.copy(), self.impact_gap.copy(),
                            self.secondary.copy())

    def release(self, nodes) -> None:
        self.obstacle[nodes] = -1
        self.mode[nodes] = FREE
        self.normal_force[nodes] = 0.0
        self.bounce_speed[nodes] = 0.0
        self.impact_gap[nodes] = 0.0
        self.secondary[nodes] = -1

    @property
    def held(self) -> np.ndarray:
        return np.flatnonzero(self.obstacle >= 0)
