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

from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy, element_dofs3


class EnclosedVolumePressure(KernelEnergy):
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

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Membrane.evaluate_into``; scatter (n_tri, 81)); the
        rank-one term (K / V0) dV dV^T is returned, not added."""
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
