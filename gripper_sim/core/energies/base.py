"""The energy protocol, the triplet form of a compiled energy, and assembly helpers.

Every energy of the fruit and of the fingers, 2D and 3D, is computed by one numba kernel
(its ``evaluate_into``: the gradient added into a vector, each element Hessian entry
added into the values of a sparse matrix at a scatter index). ``KernelEnergy`` gives that
kernel the ``Energy.evaluate`` protocol (IJV triplets) for the callers that assemble
their own matrix (the generic stepper, the shell's relaxation at build, the tests). The
numpy references the kernels are tested against live in ``test/reference_energies2d.py``
and ``test/reference_energies3d.py``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class Evaluation:
    """Value, gradient and Hessian of an energy at one configuration.

    Attributes:
        value: J.
        gradient: (n_dof,) N.
        rows, cols, vals: Hessian triplets, N/m.
        low_rank: list of (c, u), each adding ``c * outer(u, u)`` to the Hessian.
    """

    value: float
    gradient: np.ndarray
    rows: np.ndarray
    cols: np.ndarray
    vals: np.ndarray
    low_rank: list = field(default_factory=list)


class Energy:
    """Base energy: zero everywhere (the do-nothing extension point)."""

    #: whether the energy is elastic (counted in the elastic energy output)
    elastic = True

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        empty = np.zeros(0, dtype=np.int64)
        return Evaluation(0.0, np.zeros_like(q), empty, empty, np.zeros(0))

    def factor_key(self):
        """What of this energy's Hessian changes with the step's set-up (a soft pad's
        rows): a Newton matrix factorised under another key is not kept
        (the test reference solver's ``keep_factor``). None: nothing."""
        return None

    def kernel_data(self):
        """(kind, arrays) of an energy the solver's compiled potential sums itself
        (``core.energy_table``: 'stretching', 'bending', 'pressure', 'neohookean',
        'constant'), or None: the energy is evaluated by its own call."""
        return None

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The largest fraction of the step ``dq`` from ``q`` (both (n_dof,) m) this energy
        allows (a contact barrier: no crossing along it); 1 = no bound."""
        return 1.0

    def value(self, q: np.ndarray) -> float:
        """J, through the energy's compiled ``evaluate_into`` when it has one."""
        evaluate_into = getattr(self, 'evaluate_into', None)
        if evaluate_into is None:
            return self.evaluate(q, hessian=False).value
        value, _ = evaluate_into(q, np.zeros(q.size), np.zeros(1), np.zeros((0, 0), np.int64),
                                 False)
        return float(value)

    def gradient(self, q: np.ndarray) -> np.ndarray:
        return self.evaluate(q, hessian=False).gradient

    def hessian(self, q: np.ndarray) -> np.ndarray:
        """Dense Hessian (n_dof, n_dof), for tests and small problems."""
        ev = self.evaluate(q)
        dense = np.zeros((q.size, q.size))
        np.add.at(dense, (ev.rows, ev.cols), ev.vals)
        for c, u in ev.low_rank:
            dense += c * np.outer(u, u)
        return dense


_NO_VALUES = np.zeros(1)
_NO_SCATTER = np.zeros((0, 0), np.int64)


class KernelEnergy(Energy):
    """An energy whose one implementation is its kernel ``evaluate_into(q, grad, data,
    scatter, hessian) -> (value J, rank-one terms)``; subclasses set ``dofs`` (n_elem,
    m), the dofs of each element, or None for an energy without a Hessian."""

    dofs: np.ndarray | None
    _triplets: tuple | None = None

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        raise NotImplementedError

    def _triplet_pattern(self):
        """(rows, cols) (n_elem m^2,) of the element Hessians and the scatter (n_elem,
        m^2) that writes each entry to its own triplet."""
        if self._triplets is None:
            if self.dofs is None:
                empty = np.zeros(0, np.int64)
                self._triplets = (empty, empty, _NO_SCATTER)
            else:
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


def element_dofs(nodes: np.ndarray, dim: int = 2) -> np.ndarray:
    """(n_elem, k) node indices to (n_elem, dim k) dof indices, [x, z] (dim 2) or
    [x, y, z] (dim 3) per node."""
    nodes = np.asarray(nodes, dtype=np.int64)
    return (dim * nodes[:, :, None] + np.arange(dim)).reshape(nodes.shape[0], -1)
