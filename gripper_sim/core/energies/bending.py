"""Bending of planar rods (discrete elastic rods in the plane): open chains, branched
frames with rigid joints, and the closed skin ring.

A bending triple (p, i, n) is bent at its middle node i: the turning angle phi between
the edges a = x_i - x_p and b = x_n - x_i is a discrete curvature times the Voronoi
length l = (|a_0| + |b_0|) / 2. The energy is E = EI (phi - phi0)^2 / (2 l), phi0 the
rest shape's angle (natural curvature, or a joint's angle kept rigid), EI in N m^2
(Bergou et al. 2008, "Discrete elastic rods", planar case). A chain gives the triples of
its interior nodes; a rigid joint of two members gives a triple across the joint.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import kernels
from gripper_sim.core.energies.base import (Energy, Evaluation, element_dofs,
                                            hessian_triplets, scatter_gradient)


def turning_angles(x: np.ndarray, triples: np.ndarray) -> np.ndarray:
    """Signed turning angles (n_triple,) rad at the middle node of each triple."""
    a = x[triples[:, 1]] - x[triples[:, 0]]
    b = x[triples[:, 2]] - x[triples[:, 1]]
    cross = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    dot = a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]
    return np.arctan2(cross, dot)


def _angle_gradient(v: np.ndarray) -> np.ndarray:
    """d atan2(v_z, v_x) / dv, (n, 2)."""
    r2 = v[:, 0] ** 2 + v[:, 1] ** 2
    return np.stack([-v[:, 1], v[:, 0]], axis=1) / r2[:, None]


def _angle_hessian(v: np.ndarray) -> np.ndarray:
    """d^2 atan2(v_z, v_x) / dv^2, (n, 2, 2)."""
    vx, vz = v[:, 0], v[:, 1]
    r4 = (vx ** 2 + vz ** 2) ** 2
    h = np.empty((v.shape[0], 2, 2))
    h[:, 0, 0] = 2 * vx * vz / r4
    h[:, 1, 1] = -h[:, 0, 0]
    h[:, 0, 1] = h[:, 1, 0] = (vz ** 2 - vx ** 2) / r4
    return h


class RodBending(Energy):
    """Args:
        triples: (n_t, 3) node indices (previous, middle, next), bent at the middle one.
        rest_positions: (n_nodes, 2) m, the rest shape giving phi0 and lengths.
        bending_stiffness: EI in N m^2, scalar or (n_t,) (one per triple).
        voronoi_lengths: (n_t,) m, the rod length each triple's curvature stands for;
            None = the mean rest length of its two edges. At a clamp (an edge that does
            not bend, e.g. a rigid base) only half the free edge: l = |b_0| / 2.
    """

    def __init__(self, triples: np.ndarray, rest_positions: np.ndarray, bending_stiffness,
                 voronoi_lengths: np.ndarray | None = None):
        self.triples = np.ascontiguousarray(np.asarray(triples, dtype=np.int64).reshape(-1, 3))
        x0 = np.asarray(rest_positions, dtype=float)
        self.phi0 = turning_angles(x0, self.triples)
        if voronoi_lengths is None:
            la = np.linalg.norm(x0[self.triples[:, 1]] - x0[self.triples[:, 0]], axis=1)
            lb = np.linalg.norm(x0[self.triples[:, 2]] - x0[self.triples[:, 1]], axis=1)
            voronoi_lengths = 0.5 * (la + lb)
        lengths = np.asarray(voronoi_lengths, dtype=float)
        ei = np.broadcast_to(np.asarray(bending_stiffness, dtype=float), lengths.shape)
        self.k = np.ascontiguousarray(ei / lengths)
        self.dofs = element_dofs(self.triples)

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        x = q.reshape(-1, 2)
        a = x[self.triples[:, 1]] - x[self.triples[:, 0]]
        b = x[self.triples[:, 2]] - x[self.triples[:, 1]]
        dphi = turning_angles(x, self.triples) - self.phi0
        dphi = (dphi + np.pi) % (2 * np.pi) - np.pi
        value = float(0.5 * np.sum(self.k * dphi ** 2))
        ga = -_angle_gradient(a)
        gb = _angle_gradient(b)
        jac = np.hstack([-ga, ga - gb, gb])  # d phi / d (x_{i-1}, x_i, x_{i+1})
        grad = scatter_gradient(q.size, self.dofs, (self.k * dphi)[:, None] * jac)
        if not hessian:
            return Evaluation(value, grad, np.zeros(0, np.int64), np.zeros(0, np.int64),
                              np.zeros(0))
        ha = -_angle_hessian(a)
        hb = _angle_hessian(b)
        hphi = np.zeros((len(self.k), 6, 6))
        # a = x_i - x_{i-1}: selector [-I, I, 0]; b = x_{i+1} - x_i: [0, -I, I]
        for (si, ci), (sj, cj) in (((0, -1), (0, -1)), ((0, -1), (2, 1)),
                                   ((2, 1), (0, -1)), ((2, 1), (2, 1))):
            hphi[:, si:si + 2, sj:sj + 2] += ci * cj * ha
        for (si, ci), (sj, cj) in (((2, -1), (2, -1)), ((2, -1), (4, 1)),
                                   ((4, 1), (2, -1)), ((4, 1), (4, 1))):
            hphi[:, si:si + 2, sj:sj + 2] += ci * cj * hb
        local = self.k[:, None, None] * (jac[:, :, None] * jac[:, None, :]
                                         + dphi[:, None, None] * hphi)
        return Evaluation(value, grad, *hessian_triplets(self.dofs, local))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate`` (see ``Stretching.evaluate_into``; scatter
        (n_triple, 36))."""
        return kernels.bending(q.reshape(-1, 2), self.triples, self.phi0, self.k, grad, data,
                               scatter, hessian), []


class RingBending(RodBending):
    """The closed skin ring: one triple per node, its two outline neighbours around it.

    Args:
        ring: (n,) node indices in outline order (closed: last joins first).
        rest_positions: (n_nodes, 2) m, the rest shape giving phi0 and lengths.
        bending_stiffness: EI in N m^2.
    """

    def __init__(self, ring: np.ndarray, rest_positions: np.ndarray, bending_stiffness: float):
        ring = np.asarray(ring, dtype=np.int64)
        super().__init__(np.stack([np.roll(ring, 1), ring, np.roll(ring, -1)], axis=1),
                         rest_positions, bending_stiffness)
