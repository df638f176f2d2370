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
from gripper_sim.core.energies.base import Energy, Evaluation, element_dofs


def enclosed_area(x: np.ndarray, ring: np.ndarray) -> float:
    """Signed area (m^2) of the polygon ``x[ring]`` (shoelace formula)."""
    p = x[ring]
    nxt = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * nxt[:, 1] - nxt[:, 0] * p[:, 1]))


class EnclosedAreaPressure(Energy):
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
        nxt = np.roll(self.ring, -1)
        #: each ring edge (node, next node) an element of the Hessian's pattern
        self.dofs = element_dofs(np.stack([self.ring, nxt], axis=1))
        # d2A/(dx_i dz_j) = +1/2 for j = next(i), -1/2 for i = next(j); symmetric
        self.h_rows = np.concatenate([2 * self.ring, 2 * nxt + 1, 2 * nxt, 2 * self.ring + 1])
        self.h_cols = np.concatenate([2 * nxt + 1, 2 * self.ring, 2 * self.ring + 1, 2 * nxt])
        self.h_vals = np.concatenate([np.full(2 * len(self.ring), 0.5),
                                      np.full(2 * len(self.ring), -0.5)])

    elastic = True

    def pressure(self, q: np.ndarray) -> float:
        """Internal gauge pressure (Pa) at configuration q."""
        area = enclosed_area(q.reshape(-1, 2), self.ring)
        return self.p0 - self.k * (area - self.a0) / self.a0

    def area_gradient(self, q: np.ndarray) -> np.ndarray:
        x = q.reshape(-1, 2)
        p = x[self.ring]
        prv, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
        g = np.zeros(q.size)
        g[2 * self.ring] = 0.5 * (nxt[:, 1] - prv[:, 1])
        g[2 * self.ring + 1] = 0.5 * (prv[:, 0] - nxt[:, 0])
        return g

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        da = enclosed_area(q.reshape(-1, 2), self.ring) - self.a0
        value = self.b * (-self.p0 * da + 0.5 * self.k * da ** 2 / self.a0)
        de_da = self.b * (-self.p0 + self.k * da / self.a0)
        ga = self.area_gradient(q)
        grad = de_da * ga
        if not hessian:
            empty = np.zeros(0, np.int64)
            return Evaluation(value, grad, empty, empty, np.zeros(0))
        low_rank = [(self.b * self.k / self.a0, ga)] if self.k > 0 else []
        return Evaluation(value, grad, self.h_rows, self.h_cols, de_da * self.h_vals, low_rank)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate`` (see ``Stretching.evaluate_into``; scatter
        (n_ring, 16)); the rank-one term is returned as in ``evaluate``."""
        ga = np.empty(q.size)
        da = kernels.area_and_gradient(q.reshape(-1, 2), self.ring, ga) - self.a0
        value = self.b * (-self.p0 * da + 0.5 * self.k * da ** 2 / self.a0)
        de_da = self.b * (-self.p0 + self.k * da / self.a0)
        grad += de_da * ga
        if not hessian:
            return value, []
        kernels.area_pressure_hessian(de_da, data, scatter)
        return value, ([(self.b * self.k / self.a0, ga)] if self.k > 0 else [])
