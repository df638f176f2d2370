"""Enclosed-volume pressure of the flesh/turgor in the 3D shell model.

With V the volume the outward skin encloses, V = sum_t x0 . (x1 x x2) / 6, its rest
value V0, turgor p0 (Pa) and bulk modulus K (Pa):
    p(V) = p0 - K (V - V0) / V0        (gauge pressure, Pa)
    E(V) = -p0 (V - V0) + K (V - V0)^2 / (2 V0)     so that dE/dV = -p(V).
dV/dx0 = (x1 x x2) / 6 (cyclically), d2V/dx0 dx1 = -[x2]x / 6, d2V/dx0 dx2 = [x1]x / 6
(cyclically); the Hessian is dE/dV d2V/dx2 (sparse) plus the rank-one term
(K / V0) dV dV^T, which the stepper handles by the Woodbury identity.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import (Energy, Evaluation, hessian_triplets,
                                            scatter_gradient)
from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import cross_matrices, element_dofs3, empty_triplets


class EnclosedVolumePressure(Energy):
    """Args:
        triangles: (n_tri, 3) the closed outward skin.
        rest_volume: V0, m^3.  turgor: p0, Pa.  bulk_modulus: K, Pa.
    """

    def __init__(self, triangles, rest_volume: float, turgor: float, bulk_modulus: float):
        self.tri = np.asarray(triangles, dtype=np.int64)
        self.v0 = float(rest_volume)
        self.p0 = float(turgor)
        self.k = float(bulk_modulus)
        self.dofs = element_dofs3(self.tri)

    def volume(self, q: np.ndarray) -> float:
        p = q.reshape(-1, 3)[self.tri]
        return float(np.einsum('ij,ij->', p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0)

    def pressure(self, q: np.ndarray) -> float:
        """Internal gauge pressure (Pa) at configuration q."""
        return self.p0 - self.k * (self.volume(q) - self.v0) / self.v0

    def volume_gradient(self, q: np.ndarray) -> np.ndarray:
        p = q.reshape(-1, 3)[self.tri]
        local = np.stack([np.cross(p[:, 1], p[:, 2]), np.cross(p[:, 2], p[:, 0]),
                          np.cross(p[:, 0], p[:, 1])], axis=1) / 6.0
        return scatter_gradient(q.size, self.dofs, local.reshape(len(self.tri), 9))

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        dv = self.volume(q) - self.v0
        value = -self.p0 * dv + 0.5 * self.k * dv ** 2 / self.v0
        de_dv = -self.p0 + self.k * dv / self.v0
        gv = self.volume_gradient(q)
        grad = de_dv * gv
        if not hessian:
            return Evaluation(value, grad, *empty_triplets())
        p = q.reshape(-1, 3)[self.tri]
        n = len(self.tri)
        h = np.zeros((n, 3, 3, 3, 3))
        for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            block = cross_matrices(p[:, c]) * (-de_dv / 6.0)  # d2V/dx_a dx_b = -[x_c]x / 6
            h[:, a, :, b, :] = block
            h[:, b, :, a, :] = np.swapaxes(block, 1, 2)
        low_rank = [(self.k / self.v0, gv)] if self.k > 0 else []
        return Evaluation(value, grad, *hessian_triplets(self.dofs, h.reshape(n, 9, 9)),
                          low_rank)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate`` (see ``Membrane.evaluate_into``; scatter
        (n_tri, 81)); the rank-one term is returned as in ``evaluate``."""
        x = q.reshape(-1, 3)
        gv = np.empty(q.size)
        dv = kernels.volume_and_gradient(x, self.tri, gv) - self.v0
        value = -self.p0 * dv + 0.5 * self.k * dv ** 2 / self.v0
        de_dv = -self.p0 + self.k * dv / self.v0
        grad += de_dv * gv
        if not hessian:
            return value, []
        kernels.volume_pressure_hessian(x, self.tri, de_dv, data, scatter)
        return value, ([(self.k / self.v0, gv)] if self.k > 0 else [])
