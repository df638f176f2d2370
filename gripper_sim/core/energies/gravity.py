"""Constant external forces: E = -sum_i f_i . x_i; gravity along -z (the last
coordinate), E = g sum_i m_i z_i, is one."""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import KernelEnergy


class ConstantForce(KernelEnergy):
    """Args:
        forces: (n_dof,) N, the force on each coordinate of q (a point load, a
            distributed load lumped on nodes), the same in every configuration.
    """

    elastic = False
    #: no Hessian: nothing to scatter
    dofs = None

    def __init__(self, forces: np.ndarray):
        self.grad = -np.asarray(forces, dtype=float).copy()

    def kernel_data(self):
        """('constant', (the gradient -f N,)) (``core.energy_table``; the same array, so
        a load changed in place is seen)."""
        return 'constant', (self.grad,)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter, hessian: bool = True):
        """Adds the gradient -f (N) into ``grad``; returns (value J, no rank-one
        terms); no Hessian."""
        grad += self.grad
        return float(self.grad @ q), []


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
