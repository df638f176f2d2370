"""Axial stretching of skin segments (discrete elastic rod, stretching part).

Per edge of rest length L and axial stiffness EA (N): E = EA (l - L)^2 / (2 L).
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import kernels
from gripper_sim.core.energies.base import KernelEnergy, element_dofs


class Stretching(KernelEnergy):
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

    def kernel_data(self):
        """('stretching', (edges, rest lengths m, EA / L N/m)) (``core.energy_table``)."""
        return 'stretching', (self.edges, self.rest, self.k)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel: adds the gradient (N) into ``grad`` (2 n,) and the
        Hessian (N/m) into the CSC values ``data`` at ``scatter`` (n_edge, 16); returns
        (value in J, no rank-one terms)."""
        return kernels.stretching(q.reshape(-1, 2), self.edges, self.rest, self.k, grad, data,
                                  scatter, hessian), []
