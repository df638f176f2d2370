"""Bending of the skin: discrete-shell hinges (Grinspun, Hirani, Desbrun & Schroeder 2003,
"Discrete shells", SCA).

Each interior edge e = (p0, p1) shared by triangles A = (p0, p1, p2) and
B = (p1, p0, p3) carries the energy
    E_e = k_e (theta_e - theta0_e)^2,   k_e = (D / 2) |e0|^2 / A0_e,
with theta_e the signed angle between the outward normals of A and B about e, the
rest values theta0, |e0| and A0_e (the two rest triangle areas summed) from the
stress-free shape, and D = E_s t^3 / (12 (1 - nu^2)) the plate bending stiffness.
(Grinspun et al. write k_B 3 |e0|^2 / A0_e; k_B = D / 6 here.) The factor makes a
regular mesh rolled into a cylinder of curvature kappa store D kappa^2 / 2 per unit
area, as a plate does (test_3d_energies checks it in two directions).

Gradient (Bridson, Marino & Fedkiw 2003): with N_A = e x (p2 - p0), N_B = (p3 - p0) x e,
g_W = N_W / |N_W|^2 and e_hat = e / |e|,
    dtheta/dp0 = -[(p2 - p1).e_hat g_A + (p3 - p1).e_hat g_B]
    dtheta/dp1 = +[(p2 - p0).e_hat g_A + (p3 - p0).e_hat g_B]
    dtheta/dp2 = -|e| g_A,   dtheta/dp3 = -|e| g_B.
The Hessian differentiates these products: d g_W = (I - 2 n_W n_W^T) / |N_W|^2 dN_W,
with dN_A = [p2 - p1]x dp0 - [p2 - p0]x dp1 + [e]x dp2 and
dN_B = [p1 - p3]x dp0 + [p3 - p0]x dp1 - [e]x dp3.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy, element_dofs3


def dihedral_angles(x: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """(n_hinge,) rad, signed angle from n_A to n_B about e (0 when flat, > 0 convex)."""
    p0, p1, p2, p3 = (x[hinges[:, i]] for i in range(4))
    e = p1 - p0
    na = np.cross(e, p2 - p0)
    nb = np.cross(p3 - p0, e)
    sin = np.einsum('ij,ij->i', np.cross(na, nb), e) / np.linalg.norm(e, axis=1)
    cos = np.einsum('ij,ij->i', na, nb)
    return np.arctan2(sin, cos)


class HingeBending(KernelEnergy):
    """Args:
        hinges: (n_hinge, 4) nodes (p0, p1, p2, p3), see ``meshes.hinges``.
        rest_positions: (n_nodes, 3) m, the stress-free shape (theta0, |e0|, A0).
        bending_stiffness: D, N m: one for all hinges, or (n_hinge,) one per hinge.
    """

    def __init__(self, hinges: np.ndarray, rest_positions: np.ndarray, bending_stiffness):
        self.hinges = np.asarray(hinges, dtype=np.int64)
        x0 = np.asarray(rest_positions, dtype=float)
        self.theta0 = dihedral_angles(x0, self.hinges)
        p0, p1, p2, p3 = (x0[self.hinges[:, i]] for i in range(4))
        e = p1 - p0
        area = 0.5 * (np.linalg.norm(np.cross(e, p2 - p0), axis=1)
                      + np.linalg.norm(np.cross(p3 - p0, e), axis=1))
        self.k = 0.5 * bending_stiffness * np.einsum('ij,ij->i', e, e) / area
        self.dofs = element_dofs3(self.hinges)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel (see ``Membrane.evaluate_into``; scatter (n_hinge, 144))."""
        return kernels.hinge_bending(q.reshape(-1, 3), self.hinges, self.theta0, self.k,
                                     grad, data, scatter, hessian), []
