"""Compressible neo-Hookean flesh on linear tetrahedra.

With F = D_s D_m^-1 (3x3; D columns x_k - x_0, k = 1..3), J = det F and the Lame
parameters mu, lambda of the flesh (E, nu), the energy density (J/m^3) is
    psi = mu/2 (tr(F^T F) - 3) - mu ln J + lambda/2 (ln J)^2
(Bonet & Wood, Nonlinear Continuum Mechanics, eq. 6.28), the first Piola-Kirchhoff
stress P = mu (F - F^-T) + lambda ln J F^-T, and
    dP_ij / dF_mn = mu d_im d_jn + (mu - lambda ln J) Finv_ni Finv_jm
                    + lambda Finv_ji Finv_nm.
An inverted element (J <= 0) has infinite energy, which the line search backs away from.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.neohookean import lame_parameters
from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy, element_dofs3


def rest_tetrahedra(tetrahedra, rest_positions):
    """Rest frames of tetrahedra whose first four nodes are the corners.

    Args:
        tetrahedra: (n_tet, k) node indices, corners positively oriented at rest.
        rest_positions: (n_nodes, 3) m.

    Returns:
        (tet (n_tet, k) int64, D_m (n_tet, 3, 3) m with columns X_k - X_0 (k = 1..3),
        rest volumes (n_tet,) m^3). Raises ValueError for an inverted or flat one.
    """
    tet = np.asarray(tetrahedra, dtype=np.int64)
    x0 = np.asarray(rest_positions, dtype=float)
    dm = np.stack([x0[tet[:, k]] - x0[tet[:, 0]] for k in (1, 2, 3)], axis=2)
    det = np.linalg.det(dm)
    if np.any(det <= 0):
        raise ValueError('tetrahedra must be positively oriented with positive volume')
    return tet, dm, det / 6.0


class NeoHookeanTets(KernelEnergy):
    """Args:
        tetrahedra: (n_tet, 4) node indices, positively oriented at rest.
        rest_positions: (n_nodes, 3) m.
        youngs_modulus: Pa.  poisson_ratio: -.
    """

    def __init__(self, tetrahedra, rest_positions, youngs_modulus: float,
                 poisson_ratio: float):
        self.tet, dm, self.volume = rest_tetrahedra(tetrahedra, rest_positions)
        self.dm_inv = np.linalg.inv(dm)
        self.mu, self.lam = lame_parameters(youngs_modulus, poisson_ratio)
        self.dofs = element_dofs3(self.tet)
        # dF_ij / dx_(k, i) = dN_k/dX_j, dN/dX = [-1 -1 -1; I] D_m^-1   (n, 4, 3)
        shape = np.vstack([-np.ones((1, 3)), np.eye(3)])
        self.grad_n = np.ascontiguousarray(np.einsum('kc,ecj->ekj', shape, self.dm_inv))

    def von_mises(self, q: np.ndarray) -> np.ndarray:
        """(n_tet,) Pa, von Mises stress of the Cauchy stress (damage measure)."""
        out = np.empty(len(self.tet))
        kernels.neohookean_von_mises(q.reshape(-1, 3), self.tet, self.grad_n, float(self.mu),
                                     float(self.lam), out)
        return out

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Membrane.evaluate_into``; scatter (n_tet, 144));
        value inf, nothing added, if an element is inverted."""
        return kernels.neohookean_tets(q.reshape(-1, 3), self.tet, self.grad_n, self.volume,
                                       float(self.mu), float(self.lam), grad, data, scatter,
                                       hessian), []
