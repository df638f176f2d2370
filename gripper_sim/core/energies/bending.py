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
from gripper_sim.core.energies.base import KernelEnergy, element_dofs


def turning_angles(x: np.ndarray, triples: np.ndarray) -> np.ndarray:
    """Signed turning angles (n_triple,) rad at the middle node of each triple of
    ``triples`` (n_triple, 3) (previous, middle, next) of positions x (n_nodes, 2) m."""
    out = np.empty(len(triples))
    kernels.turning_angles(np.ascontiguousarray(x, dtype=float),
                           np.ascontiguousarray(triples, dtype=np.int64), out)
    return out


class RodBending(KernelEnergy):
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

    def kernel_data(self):
        """('bending', (triples, phi0 rad, EI / l N m)) (``core.energy_table``)."""
        return 'bending', (self.triples, self.phi0, self.k)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Stretching.evaluate_into``; scatter (n_triple, 36))."""
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
