"""Compressible neo-Hookean flesh on quadratic (10-node) tetrahedra.

The energy density is that of ``NeoHookeanTets`` (Bonet & Wood eq. 6.28); the
displacement is quadratic in each element: with barycentric coordinates L_0..L_3, the
corner shape functions N_a = L_a (2 L_a - 1) and the edge-midpoint ones
N_ab = 4 L_a L_b (Zienkiewicz & Taylor, The Finite Element Method vol. 1, ch. 8), the
edges in the order of ``meshes.TET10_EDGES``. The edges are straight, so the L are
affine in X and dN/dX = sum_k dN/dL_k dL_k/dX. The energy is integrated with the
4-point degree-2 rule (barycentric (a, b, b, b) and permutations, a = 0.5854101966,
b = 0.1381966011, weights V/4). Linear tetrahedra are stiff in contact (the Hertz force
converges from above, slowly); quadratic ones converge much faster.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.neohookean import lame_parameters
from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy, element_dofs3
from gripper_sim.core3d.energies.neohookean import rest_tetrahedra

_EDGES = ((0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3))
_A, _B = 0.5854101966249685, 0.1381966011250105
#: (4, 4) barycentric coordinates of the quadrature points
QUADRATURE = np.full((4, 4), _B) + np.eye(4) * (_A - _B)


def shape_gradients_barycentric(bary: np.ndarray) -> np.ndarray:
    """(10, 4) dN_a / dL_k of the 10-node tetrahedron at barycentric point (4,)."""
    d = np.zeros((10, 4))
    for a in range(4):
        d[a, a] = 4 * bary[a] - 1
    for m, (i, j) in enumerate(_EDGES):
        d[4 + m, i] = 4 * bary[j]
        d[4 + m, j] = 4 * bary[i]
    return d


def lumped_masses(tetrahedra: np.ndarray, volumes: np.ndarray, density: float,
                  n_nodes: int) -> np.ndarray:
    """(n_nodes,) kg, HRZ-lumped masses (diagonal of the consistent mass matrix scaled
    to the element mass: 1/36 of it at each corner, 4/27 at each midpoint)."""
    share = np.array([1 / 36] * 4 + [4 / 27] * 6)
    weights = (density * volumes)[:, None] * share[None, :]
    return np.bincount(tetrahedra.ravel(), weights=weights.ravel(), minlength=n_nodes)


class QuadraticNeoHookeanTets(KernelEnergy):
    """Args:
        tetrahedra: (n_tet, 10) corners (positively oriented) then edge midpoints.
        rest_positions: (n_nodes, 3) m.
        youngs_modulus: Pa.  poisson_ratio: -.
    """

    def __init__(self, tetrahedra, rest_positions, youngs_modulus: float,
                 poisson_ratio: float):
        self.tet, dm, self.volume = rest_tetrahedra(tetrahedra, rest_positions)
        self.mu, self.lam = lame_parameters(youngs_modulus, poisson_ratio)
        self.dofs = element_dofs3(self.tet)
        # dL/dX (n, 4, 3): rows of [-1 -1 -1; I] D_m^-1
        grad_l = np.einsum('kc,ecj->ekj', np.vstack([-np.ones((1, 3)), np.eye(3)]),
                           np.linalg.inv(dm))
        dndl = np.stack([shape_gradients_barycentric(p) for p in QUADRATURE])  # (4,10,4)
        self.grad_n = np.ascontiguousarray(np.einsum('gak,ekj->egaj', dndl, grad_l))
        self.weight = np.repeat(self.volume[:, None] / 4.0, 4, axis=1)  # (n, 4)

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """(n_tet, 4, 3, 3) at the quadrature points."""
        x = q.reshape(-1, 3)
        return np.einsum('eai,egaj->egij', x[self.tet], self.grad_n)

    def von_mises(self, q: np.ndarray) -> np.ndarray:
        """(n_tet,) Pa, largest von Mises stress of the Cauchy stress at the element's
        quadrature points (damage measure)."""
        f = self.deformation_gradients(q).reshape(-1, 3, 3)
        j = np.linalg.det(f)
        b = f @ np.swapaxes(f, 1, 2)
        lnj = np.log(np.maximum(j, 1e-12))
        sigma = (self.mu * (b - np.eye(3)) + (self.lam * lnj)[:, None, None] * np.eye(3)) \
            / np.maximum(j, 1e-12)[:, None, None]
        dev = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
        return np.sqrt(1.5 * np.einsum('eij,eij->e', dev, dev)).reshape(-1, 4).max(axis=1)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Membrane.evaluate_into``; scatter (n_tet, 900));
        value inf, nothing added, if J <= 0 at a quadrature point."""
        return kernels.neohookean_quadrature(q.reshape(-1, 3), self.tet, self.grad_n,
                                             self.weight, float(self.mu), float(self.lam),
                                             grad, data, scatter, hessian), []
