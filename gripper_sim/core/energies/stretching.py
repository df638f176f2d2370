"""Axial stretching of skin segments (discrete elastic rod, stretching part).

Per edge of rest length L and axial stiffness EA (N): E = EA (l - L)^2 / (2 L).
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import kernels
from gripper_sim.core.energies.base import (Energy, Evaluation, element_dofs,
                                            hessian_triplets, scatter_gradient)


class Stretching(Energy):
    """Args:
        edges: (n_edge, 2) node indices.
        rest_lengths: (n_edge,) m.
        axial_stiffness: EA in N (scalar or (n_edge,)).
    """

    def __init__(self, edges: np.ndarray, rest_lengths: np.ndarray, axial_stiffness):
        self.edges = np.asarray(edges, dtype=np.int64)
        self.rest = np.asarray(rest_lengths, dtype=float)
        self.ea = np.broadcast_to(np.asarray(axial_stiffness, dtype=float), self.rest.shape)
        self.k = np.ascontiguousarray(self.ea / self.rest)
        self.dofs = element_dofs(self.edges)

    def strains(self, q: np.ndarray) -> np.ndarray:
        """(n_edge,) engineering strain l / L - 1."""
        x = q.reshape(-1, 2)
        e = x[self.edges[:, 1]] - x[self.edges[:, 0]]
        return np.hypot(e[:, 0], e[:, 1]) / self.rest - 1.0

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        x = q.reshape(-1, 2)
        e = x[self.edges[:, 1]] - x[self.edges[:, 0]]
        length = np.hypot(e[:, 0], e[:, 1])
        stretch = length - self.rest
        k = self.ea / self.rest
        value = float(0.5 * np.sum(k * stretch ** 2))
        u = e / length[:, None]
        f = (k * stretch)[:, None] * u
        grad = scatter_gradient(q.size, self.dofs, np.hstack([-f, f]))
        if not hessian:
            return Evaluation(value, grad, *_empty())
        uu = u[:, :, None] * u[:, None, :]
        ratio = (stretch / length)[:, None, None]
        block = k[:, None, None] * (uu + ratio * (np.eye(2) - uu))
        local = np.block([[block, -block], [-block, block]])
        return Evaluation(value, grad, *hessian_triplets(self.dofs, local))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate``: adds the gradient (N) into ``grad`` and the
        Hessian (N/m) into the CSC values ``data`` at ``scatter`` (n_edge, 16); returns
        (value in J, low-rank terms)."""
        return kernels.stretching(q.reshape(-1, 2), self.edges, self.rest, self.k, grad, data,
                                  scatter, hessian), []


def _empty():
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
