"""What the 3D energies share: dof indices, and the triplet form of their kernels.

Every 3D energy is computed by one numba kernel (``gripper_sim.core3d.kernels``), which
its ``evaluate_into`` runs: the gradient added into a vector, each element Hessian
entry added into the values of a sparse matrix at a scatter index. ``KernelEnergy``
gives the same kernel the ``Energy.evaluate`` protocol (IJV triplets) for the callers
that assemble their own matrix (the generic stepper, the shell's relaxation at build,
the tests). The numpy references the kernels are tested against live in
``test/reference_energies3d.py``.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import Energy, Evaluation, element_dofs

_NO_VALUES = np.zeros(1)
_NO_SCATTER = np.zeros((0, 0), np.int64)


def element_dofs3(nodes: np.ndarray) -> np.ndarray:
    """(n_elem, k) node indices to (n_elem, 3k) dof indices [x, y, z] per node."""
    return element_dofs(nodes, 3)


class KernelEnergy(Energy):
    """A 3D energy whose one implementation is its kernel ``evaluate_into(q, grad, data,
    scatter, hessian) -> (value J, rank-one terms)``; subclasses set ``dofs``
    (n_elem, m), the dofs of each element."""

    dofs: np.ndarray
    _triplets: tuple | None = None

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        raise NotImplementedError

    def _triplet_pattern(self):
        """(rows, cols) (n_elem m^2,) of the element Hessians and the scatter (n_elem,
        m^2) that writes each entry to its own triplet."""
        if self._triplets is None:
            n_elem, m = self.dofs.shape
            rows = np.repeat(self.dofs, m, axis=1).ravel()
            cols = np.tile(self.dofs, (1, m)).ravel()
            scatter = np.arange(n_elem * m * m, dtype=np.int64).reshape(n_elem, m * m)
            self._triplets = (rows, cols, scatter)
        return self._triplets

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        """The kernel's value (J), gradient (n_dof,) N and Hessian as IJV triplets (N/m)
        plus rank-one terms; an inverted element gives value inf."""
        grad = np.zeros(q.size)
        if not hessian:
            value, low_rank = self.evaluate_into(q, grad, _NO_VALUES, _NO_SCATTER, False)
            empty = np.zeros(0, np.int64)
            return Evaluation(float(value), grad, empty, empty, np.zeros(0), low_rank)
        rows, cols, scatter = self._triplet_pattern()
        vals = np.zeros(rows.size)
        value, low_rank = self.evaluate_into(q, grad, vals, scatter, True)
        return Evaluation(float(value), grad, rows, cols, vals, low_rank)
