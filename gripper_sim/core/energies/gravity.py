"""Constant external forces: E = -sum_i f_i . x_i; gravity along -z (the last
coordinate), E = g sum_i m_i z_i, is one."""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import Energy, Evaluation


class ConstantForce(Energy):
    """Args:
        forces: (n_dof,) N, the force on each coordinate of q (a point load, a
            distributed load lumped on nodes), the same in every configuration.
    """

    elastic = False
    #: no Hessian: nothing to scatter
    dofs = None

    def __init__(self, forces: np.ndarray):
        self.grad = -np.asarray(forces, dtype=float).copy()

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        empty = np.zeros(0, np.int64)
        return Evaluation(float(self.grad @ q), self.grad.copy(), empty, empty, np.zeros(0))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter, hessian: bool = True):
        """``evaluate`` for the fast solver: adds the gradient into ``grad``."""
        grad += self.grad
        return float(self.grad @ q), []

    def value(self, q: np.ndarray) -> float:
        return float(self.grad @ q)


class Gravity(ConstantForce):
    """Args:
        masses: (n_nodes,) kg.
        g: m/s^2, magnitude of gravity (acting along -z).
        dim: 2 (q = [x0, z0, ...]) or 3 (q = [x0, y0, z0, ...]).
    """

    def __init__(self, masses: np.ndarray, g: float, dim: int = 2):
        self.g = float(g)
        weight = np.zeros(dim * len(masses))
        weight[dim - 1::dim] = -self.g * np.asarray(masses, dtype=float)
        super().__init__(weight)
