"""The energy protocol and the triplet assembly helper."""
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


def element_dofs(nodes: np.ndarray, dim: int = 2) -> np.ndarray:
    """(n_elem, k) node indices to (n_elem, dim k) dof indices, [x, z] (dim 2) or
    [x, y, z] (dim 3) per node."""
    nodes = np.asarray(nodes, dtype=np.int64)
    return (dim * nodes[:, :, None] + np.arange(dim)).reshape(nodes.shape[0], -1)


def scatter_gradient(n_dof: int, dofs: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Sum element gradients (n_elem, m) into a (n_dof,) vector."""
    return np.bincount(dofs.ravel(), weights=local.ravel(), minlength=n_dof)


def hessian_triplets(dofs: np.ndarray, local: np.ndarray):
    """Element Hessians (n_elem, m, m) to IJV triplets."""
    m = dofs.shape[1]
    rows = np.repeat(dofs, m, axis=1).ravel()
    cols = np.tile(dofs, (1, m)).ravel()
    return rows, cols, local.ravel()
