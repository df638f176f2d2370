"""Gravity along -z: E = g sum_i m_i z_i."""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import Energy, Evaluation
from gripper_sim.core3d.energies.common import empty_triplets


class Gravity3D(Energy):
    """Args:
        masses: (n_nodes,) kg.
        g: m/s^2, magnitude of gravity (acting along -z).
    """

    elastic = False
    #: no Hessian: nothing to scatter
    dofs = None

    def __init__(self, masses: np.ndarray, g: float):
        self.g = float(g)
        self.grad = np.zeros(3 * len(masses))
        self.grad[2::3] = self.g * np.asarray(masses, dtype=float)

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        return Evaluation(float(self.grad @ q), self.grad.copy(), *empty_triplets())

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter, hessian: bool = True):
        """``evaluate`` for the fast solver: adds the gradient into ``grad``."""
        grad += self.grad
        return float(self.grad @ q), []
