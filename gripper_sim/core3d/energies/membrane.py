"""Membrane stretching of the skin: constant-strain triangles, St. Venant-Kirchhoff.

Each triangle maps its rest shape (in its own plane, 2D coordinates with the
2x2 matrix D_m of rest edge vectors) to the current one with the 3x2 deformation
gradient F = D_s D_m^-1, D_s = [x1 - x0, x2 - x0]. With the Green strain
E = (F^T F - I) / 2 and the plane-stress Lame constants of the skin
    mu = E_s / (2 (1 + nu)),  lambda* = E_s nu / (1 - nu^2),
the energy is W = t A_0 [lambda*/2 tr(E)^2 + mu tr(E^2)], the second Piola-Kirchhoff
stress S = lambda* tr(E) I + 2 mu E, the first P = F S (Bonet & Wood, Nonlinear
Continuum Mechanics, ch. 6, Saint Venant-Kirchhoff; membrane = plane stress), and
    dP_ai / dF_bj = d_ab S_ij + lambda* F_ai F_bj + mu d_ij (F F^T)_ab + mu F_aj F_bi.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy, element_dofs3


class Membrane(KernelEnergy):
    """Args:
        triangles: (n_tri, 3) node indices.
        rest_positions: (n_nodes, 3) m, the stress-free shape.
        youngs_modulus: E_s, Pa.  poisson_ratio: nu (-).
        thickness: t, m: one for all triangles, or (n_tri,) one per triangle (a Fin Ray
            finger's members of different thickness).
    """

    def __init__(self, triangles, rest_positions, youngs_modulus: float,
                 poisson_ratio: float, thickness):
        self.tri = np.asarray(triangles, dtype=np.int64)
        x0 = np.asarray(rest_positions, dtype=float)
        e1 = x0[self.tri[:, 1]] - x0[self.tri[:, 0]]
        e2 = x0[self.tri[:, 2]] - x0[self.tri[:, 0]]
        normal = np.cross(e1, e2)
        area2 = np.linalg.norm(normal, axis=1)
        if np.any(area2 <= 0):
            raise ValueError('degenerate skin triangle')
        t1 = e1 / np.linalg.norm(e1, axis=1)[:, None]
        t2 = np.cross(normal / area2[:, None], t1)
        dm = np.empty((len(self.tri), 2, 2))
        dm[:, 0, 0] = np.einsum('ij,ij->i', e1, t1)
        dm[:, 1, 0] = 0.0
        dm[:, 0, 1] = np.einsum('ij,ij->i', e2, t1)
        dm[:, 1, 1] = np.einsum('ij,ij->i', e2, t2)
        self.dm_inv = np.linalg.inv(dm)
        self.area = 0.5 * area2
        self.weight = thickness * self.area  # m^3
        self.mu = youngs_modulus / (2 * (1 + poisson_ratio))
        self.lam = youngs_modulus * poisson_ratio / (1 - poisson_ratio ** 2)
        self.dofs = element_dofs3(self.tri)
        # dF_(a,i) / dx_(node k, comp b) = d_ab dN_k/dX_i with dN/dX = [-1 -1; 1 0; 0 1] D_m^-1
        grad_n = np.einsum('kc,ecj->ekj', np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]]),
                           self.dm_inv)  # (n, 3 nodes, 2)
        self.grad_n = np.ascontiguousarray(grad_n)

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """(n_tri, 3, 2)."""
        x = q.reshape(-1, 3)
        g = self.grad_n
        return (x[self.tri[:, 0], :, None] * g[:, 0, None, :]
                + x[self.tri[:, 1], :, None] * g[:, 1, None, :]
                + x[self.tri[:, 2], :, None] * g[:, 2, None, :])

    def strains(self, q: np.ndarray) -> np.ndarray:
        """(n_tri,) largest principal engineering strain of each triangle (-)."""
        f = self.deformation_gradients(q)
        c00 = np.sum(f[:, :, 0] ** 2, axis=1)
        c11 = np.sum(f[:, :, 1] ** 2, axis=1)
        c01 = np.sum(f[:, :, 0] * f[:, :, 1], axis=1)
        tr, det = c00 + c11, c00 * c11 - c01 ** 2
        disc = np.sqrt(np.maximum(0.25 * tr ** 2 - det, 0.0))
        lam_max = 0.5 * tr + disc
        lam_min = np.maximum(0.5 * tr - disc, 0.0)
        big = np.sqrt(lam_max) - 1.0
        small = np.sqrt(lam_min) - 1.0
        return np.where(np.abs(big) >= np.abs(small), big, small)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel: adds the gradient (N) into ``grad`` and the Hessian (N/m)
        into the sparse values ``data`` at ``scatter`` (n_tri, 81); returns (value in J,
        low-rank terms)."""
        return kernels.membrane(q.reshape(-1, 3), self.tri, self.grad_n, self.weight,
                                float(self.mu), float(self.lam), grad, data, scatter,
                                hessian), []
