"""Compressible neo-Hookean flesh on linear triangles, plane strain.

With the deformation gradient F (2x2, out-of-plane stretch 1), J = det F and Lame
parameters mu, lambda (from E, nu), the energy density (J/m^3) is
    psi = mu/2 (tr(F^T F) - 2) - mu ln J + lambda/2 (ln J)^2
(Bonet & Wood, Nonlinear Continuum Mechanics, eq. 6.28, with F33 = 1), and the
element energy is psi * A_rest * depth. An inverted element (J <= 0) has infinite
energy, which the line search of the stepper backs away from.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import kernels
from gripper_sim.core.energies.base import KernelEnergy, element_dofs


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(mu, lambda) in Pa."""
    mu = youngs_modulus / (2 * (1 + poisson_ratio))
    lam = youngs_modulus * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio))
    return mu, lam


class NeoHookeanTriangles(KernelEnergy):
    """Args:
        triangles: (n_tri, 3) node indices, counter-clockwise in the rest shape.
        rest_positions: (n_nodes, 2) m.
        youngs_modulus: Pa. poisson_ratio: -. depth: m.
    """

    def __init__(self, triangles, rest_positions, youngs_modulus: float,
                 poisson_ratio: float, depth: float):
        self.tri = np.asarray(triangles, dtype=np.int64)
        x0 = np.asarray(rest_positions, dtype=float)
        dm = np.stack([x0[self.tri[:, 1]] - x0[self.tri[:, 0]],
                       x0[self.tri[:, 2]] - x0[self.tri[:, 0]]], axis=2)  # columns
        det = dm[:, 0, 0] * dm[:, 1, 1] - dm[:, 0, 1] * dm[:, 1, 0]
        if np.any(det <= 0):
            raise ValueError('triangles must be counter-clockwise with positive area')
        self.dm_inv = np.ascontiguousarray(np.linalg.inv(dm))
        self.volume = 0.5 * det * depth  # m^3 per element
        self.mu, self.lam = lame_parameters(youngs_modulus, poisson_ratio)
        self.dofs = element_dofs(self.tri)

    def von_mises(self, q: np.ndarray) -> np.ndarray:
        """(n_tri,) Pa, plane-strain von Mises of the Cauchy stress (damage measure)."""
        out = np.empty(len(self.tri))
        kernels.neohookean_von_mises(q.reshape(-1, 2), self.tri, self.dm_inv, float(self.mu),
                                     float(self.lam), out)
        return out

    def kernel_data(self):
        """('neohookean', (triangles, [mu, lambda] Pa, the rest volumes (n_tri,) m^3 then
        dm^-1 (n_tri, 2, 2) 1/m flattened)) (``core.energy_table``)."""
        return 'neohookean', (self.tri, np.array([self.mu, self.lam], dtype=float),
                              np.concatenate([self.volume, self.dm_inv.ravel()]))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Stretching.evaluate_into``; scatter (n_tri, 36));
        value inf, nothing added, if an element is inverted."""
        return kernels.neohookean_triangles(q.reshape(-1, 2), self.tri, self.dm_inv,
                                            self.volume, float(self.mu), float(self.lam), grad,
                                            data, scatter, hessian), []
