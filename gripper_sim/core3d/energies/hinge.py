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

from gripper_sim.core.energies.base import (Energy, Evaluation, hessian_triplets,
                                            scatter_gradient)
from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import cross_matrices, element_dofs3, empty_triplets


def dihedral_angles(x: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """(n_hinge,) rad, signed angle from n_A to n_B about e (0 when flat, > 0 convex)."""
    p0, p1, p2, p3 = (x[hinges[:, i]] for i in range(4))
    e = p1 - p0
    na = np.cross(e, p2 - p0)
    nb = np.cross(p3 - p0, e)
    sin = np.einsum('ij,ij->i', np.cross(na, nb), e) / np.linalg.norm(e, axis=1)
    cos = np.einsum('ij,ij->i', na, nb)
    return np.arctan2(sin, cos)


class HingeBending(Energy):
    """Args:
        hinges: (n_hinge, 4) nodes (p0, p1, p2, p3), see ``meshes.hinges``.
        rest_positions: (n_nodes, 3) m, the stress-free shape (theta0, |e0|, A0).
        bending_stiffness: D, N m.
    """

    def __init__(self, hinges: np.ndarray, rest_positions: np.ndarray, bending_stiffness: float):
        self.hinges = np.asarray(hinges, dtype=np.int64)
        x0 = np.asarray(rest_positions, dtype=float)
        self.theta0 = dihedral_angles(x0, self.hinges)
        p0, p1, p2, p3 = (x0[self.hinges[:, i]] for i in range(4))
        e = p1 - p0
        area = 0.5 * (np.linalg.norm(np.cross(e, p2 - p0), axis=1)
                      + np.linalg.norm(np.cross(p3 - p0, e), axis=1))
        self.k = 0.5 * bending_stiffness * np.einsum('ij,ij->i', e, e) / area
        self.dofs = element_dofs3(self.hinges)

    def angle_derivatives(self, x: np.ndarray, hessian: bool):
        """theta (n,), dtheta/dx (n, 12) and, if asked, d2theta/dx2 (n, 12, 12)."""
        h = self.hinges
        p0, p1, p2, p3 = (x[h[:, i]] for i in range(4))
        e = p1 - p0
        length = np.linalg.norm(e, axis=1)
        eh = e / length[:, None]
        na = np.cross(e, p2 - p0)
        nb = np.cross(p3 - p0, e)
        sin = np.einsum('ij,ij->i', np.cross(na, nb), eh)
        theta = np.arctan2(sin, np.einsum('ij,ij->i', na, nb))
        na2 = np.einsum('ij,ij->i', na, na)
        nb2 = np.einsum('ij,ij->i', nb, nb)
        ga, gb = na / na2[:, None], nb / nb2[:, None]
        d21 = np.einsum('ij,ij->i', p2 - p1, eh)
        d20 = np.einsum('ij,ij->i', p2 - p0, eh)
        d31 = np.einsum('ij,ij->i', p3 - p1, eh)
        d30 = np.einsum('ij,ij->i', p3 - p0, eh)
        n = len(h)
        zero = np.zeros(n)
        # dtheta/dp_i = sum_W c_(W,i) g_W
        ca = np.stack([-d21, d20, -length, zero], axis=1)
        cb = np.stack([-d31, d30, zero, -length], axis=1)
        grad = (ca[:, :, None] * ga[:, None, :] + cb[:, :, None] * gb[:, None, :]).reshape(n, 12)
        if not hessian:
            return theta, grad, None
        proj = (np.eye(3)[None] - eh[:, :, None] * eh[:, None, :]) / length[:, None, None]

        def coeff_grad(tip, other, sign):
            """d/dx of sign * (tip - other).e_hat, other in {p0, p1}: (n, 4, 3)."""
            g = np.zeros((n, 4, 3))
            w = np.einsum('nij,nj->ni', proj, tip - other)  # d/de of (tip - other).e_hat
            g[:, 1] += w
            g[:, 0] -= w
            return sign * g

        dca = np.zeros((n, 4, 4, 3))  # d c_(A,i) / d p_j
        dcb = np.zeros((n, 4, 4, 3))
        dca[:, 0] = coeff_grad(p2, p1, -1.0)
        dca[:, 0, 2] -= eh
        dca[:, 0, 1] += eh
        dca[:, 1] = coeff_grad(p2, p0, 1.0)
        dca[:, 1, 2] += eh
        dca[:, 1, 0] -= eh
        dca[:, 2, 1] -= eh
        dca[:, 2, 0] += eh
        dcb[:, 0] = coeff_grad(p3, p1, -1.0)
        dcb[:, 0, 3] -= eh
        dcb[:, 0, 1] += eh
        dcb[:, 1] = coeff_grad(p3, p0, 1.0)
        dcb[:, 1, 3] += eh
        dcb[:, 1, 0] -= eh
        dcb[:, 3, 1] -= eh
        dcb[:, 3, 0] += eh
        # d g_W / d p_j = M_W dN_W/dp_j, M_W = (I - 2 n n^T) / |N|^2
        ma = (np.eye(3)[None] - 2 * ga[:, :, None] * na[:, None, :]) / na2[:, None, None]
        mb = (np.eye(3)[None] - 2 * gb[:, :, None] * nb[:, None, :]) / nb2[:, None, None]
        dna = np.zeros((n, 4, 3, 3))
        dna[:, 0] = cross_matrices(p2 - p1)
        dna[:, 1] = -cross_matrices(p2 - p0)
        dna[:, 2] = cross_matrices(e)
        dnb = np.zeros((n, 4, 3, 3))
        dnb[:, 0] = cross_matrices(p1 - p3)
        dnb[:, 1] = cross_matrices(p3 - p0)
        dnb[:, 3] = -cross_matrices(e)
        dga = np.einsum('nab,njbc->najc', ma, dna)  # (n, 3, 4, 3)
        dgb = np.einsum('nab,njbc->najc', mb, dnb)
        hess = (np.einsum('na,nijc->niajc', ga, dca) + np.einsum('na,nijc->niajc', gb, dcb)
                + np.einsum('ni,najc->niajc', ca, dga) + np.einsum('ni,najc->niajc', cb, dgb))
        return theta, grad, hess.reshape(n, 12, 12)

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        x = q.reshape(-1, 3)
        theta, dtheta, d2theta = self.angle_derivatives(x, hessian)
        dev = theta - self.theta0
        dev = (dev + np.pi) % (2 * np.pi) - np.pi
        value = float(np.sum(self.k * dev ** 2))
        grad = scatter_gradient(q.size, self.dofs, (2 * self.k * dev)[:, None] * dtheta)
        if not hessian:
            return Evaluation(value, grad, *empty_triplets())
        local = (2 * self.k)[:, None, None] * (dtheta[:, :, None] * dtheta[:, None, :]
                                               + dev[:, None, None] * d2theta)
        return Evaluation(value, grad, *hessian_triplets(self.dofs, local))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate`` (see ``Membrane.evaluate_into``; scatter
        (n_hinge, 144))."""
        return kernels.hinge_bending(q.reshape(-1, 3), self.hinges, self.theta0, self.k,
                                     grad, data, scatter, hessian), []
