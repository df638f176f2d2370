"""Enclosed-area pressure of the flesh/turgor in the shell model.

With A the area enclosed by the skin ring (m^2, positive counter-clockwise in x-z),
A0 its rest value, depth b (m), turgor p0 (Pa) and area bulk modulus K (Pa):
    p(A) = p0 - K (A - A0) / A0        (gauge pressure, Pa)
    E(A) = b [ -p0 (A - A0) + K (A - A0)^2 / (2 A0) ]   so that  dE/dA = -b p(A).
The Hessian is dE/dA * d2A/dq2 (sparse) plus the rank-one term b K / A0 * gA gA^T.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import kernels
from gripper_sim.core.energies.base import KernelEnergy, element_dofs


class EnclosedAreaPressure(KernelEnergy):
    """Args:
        ring: (n,) node indices in counter-clockwise outline order.
        rest_area: A0, m^2.
        depth: b, m.
        turgor: p0, Pa.
        bulk_modulus: K, Pa.
    """

    def __init__(self, ring, rest_area: float, depth: float, turgor: float,
                 bulk_modulus: float):
        self.ring = np.asarray(ring, dtype=np.int64)
        self.a0 = float(rest_area)
        self.b = float(depth)
        self.p0 = float(turgor)
        self.k = float(bulk_modulus)
        #: each ring edge (node, next node) an element of the Hessian's pattern
        self.dofs = element_dofs(np.stack([self.ring, np.roll(self.ring, -1)], axis=1))

    elastic = True

    def pressure(self, q: np.ndarray) -> float:
        """Internal gauge pressure (Pa) at configuration q."""
        area = kernels.area_and_gradient(q.reshape(-1, 2), self.ring, np.empty(q.size))
        return self.p0 - self.k * (area - self.a0) / self.a0

    def kernel_data(self):
        """('pressure', (ring, [A0 m^2, b m, p0 Pa, K Pa])) (``core.energy_table``)."""
        return 'pressure', (self.ring, np.array([self.a0, self.b, self.p0, self.k]))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Stretching.evaluate_into``; scatter (n_ring, 16));
        returns (value J, the rank-one term b K / A0 dA/dq dA/dq^T if K > 0)."""
        ga = np.empty(q.size)
        value, c = kernels.enclosed_area_pressure(q.reshape(-1, 2), self.ring, self.a0,
                                                  self.b, self.p0, self.k, grad, ga, data,
                                                  scatter, hessian)
        return value, ([(c, ga)] if hessian and self.k > 0 else [])
