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
from gripper_sim.core.energies.base import (Energy, Evaluation, element_dofs,
                                            hessian_triplets, scatter_gradient)


def lame_parameters(youngs_modulus: float, poisson_ratio: float) -> tuple[float, float]:
    """(mu, lambda) in Pa."""
    mu = youngs_modulus / (2 * (1 + poisson_ratio))
    lam = youngs_modulus * poisson_ratio / ((1 + poisson_ratio) * (1 - 2 * poisson_ratio))
    return mu, lam


class NeoHookeanTriangles(Energy):
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
        # dF_flat / dx_local: F_ij = sum_k Ds_ik Dminv_kj, Ds_:k = x_{k+1} - x_0
        n = len(self.tri)
        self.b = np.zeros((n, 4, 6))
        for i in range(2):
            for j in range(2):
                for k in range(2):
                    self.b[:, 2 * i + j, 2 * (k + 1) + i] += self.dm_inv[:, k, j]
                    self.b[:, 2 * i + j, i] -= self.dm_inv[:, k, j]

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """(n_tri, 2, 2) deformation gradients."""
        x = q.reshape(-1, 2)
        ds = np.stack([x[self.tri[:, 1]] - x[self.tri[:, 0]],
                       x[self.tri[:, 2]] - x[self.tri[:, 0]]], axis=2)
        return ds @ self.dm_inv

    def von_mises(self, q: np.ndarray) -> np.ndarray:
        """(n_tri,) Pa, plane-strain von Mises of the Cauchy stress (damage measure)."""
        out = np.empty(len(self.tri))
        kernels.neohookean_von_mises(q.reshape(-1, 2), self.tri, self.dm_inv, float(self.mu),
                                     float(self.lam), out)
        return out

    def von_mises_reference(self, q: np.ndarray) -> np.ndarray:
        """``von_mises`` in numpy (the reference of the numba kernel)."""
        f = self.deformation_gradients(q)
        j = np.linalg.det(f)
        b = f @ np.swapaxes(f, 1, 2)
        lnj = np.log(np.maximum(j, 1e-12))
        eye = np.eye(2)
        sigma = (self.mu * (b - eye) + self.lam * lnj[:, None, None] * eye) / j[:, None, None]
        s33 = (self.lam * lnj) / j  # out-of-plane (F33 = 1: b33 - 1 = 0)
        sxx, szz, sxz = sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 0, 1]
        return np.sqrt(0.5 * ((sxx - szz) ** 2 + (szz - s33) ** 2 + (s33 - sxx) ** 2)
                       + 3 * sxz ** 2)

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        f = self.deformation_gradients(q)
        j = f[:, 0, 0] * f[:, 1, 1] - f[:, 0, 1] * f[:, 1, 0]
        if np.any(j <= 0):
            empty = np.zeros(0, np.int64)
            return Evaluation(np.inf, np.full(q.size, np.nan), empty, empty, np.zeros(0))
        lnj = np.log(j)
        mu, lam = self.mu, self.lam
        psi = 0.5 * mu * (np.sum(f * f, axis=(1, 2)) - 2) - mu * lnj + 0.5 * lam * lnj ** 2
        value = float(np.sum(psi * self.volume))
        finv = np.empty_like(f)
        finv[:, 0, 0], finv[:, 1, 1] = f[:, 1, 1] / j, f[:, 0, 0] / j
        finv[:, 0, 1], finv[:, 1, 0] = -f[:, 0, 1] / j, -f[:, 1, 0] / j
        finv_t = np.swapaxes(finv, 1, 2)
        piola = mu * (f - finv_t) + lam * lnj[:, None, None] * finv_t
        local_grad = np.einsum('e,ea,eak->ek', self.volume, piola.reshape(-1, 4), self.b)
        grad = scatter_gradient(q.size, self.dofs, local_grad)
        if not hessian:
            empty = np.zeros(0, np.int64)
            return Evaluation(value, grad, empty, empty, np.zeros(0))
        # dP_ij/dF_mn = mu d_im d_jn + (mu - lam lnJ) Finv_ni Finv_jm + lam Finv_ji Finv_nm
        c = (mu * np.eye(4)[None]
             + ((mu - lam * lnj)[:, None, None, None, None]
                * np.einsum('eni,ejm->eijmn', finv, finv)).reshape(-1, 4, 4)
             + lam * np.einsum('eji,enm->eijmn', finv, finv).reshape(-1, 4, 4))
        local = np.einsum('e,eak,eab,ebl->ekl', self.volume, self.b, c, self.b)
        return Evaluation(value, grad, *hessian_triplets(self.dofs, local))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate`` (see ``Stretching.evaluate_into``; scatter
        (n_tri, 36)); value inf, nothing added, if an element is inverted."""
        return kernels.neohookean_triangles(q.reshape(-1, 2), self.tri, self.dm_inv,
                                            self.volume, float(self.mu), float(self.lam), grad,
                                            data, scatter, hessian), []
