"""Membrane stretching of a skin that wrinkles instead of carrying compression.

Tension field theory: a thin skin buckles into fine wrinkles under in-plane compression
at (almost) no cost, so its energy is the relaxed energy of the membrane (Pipkin 1986,
"The relaxed energy density for isotropic elastic membranes", IMA J. Appl. Math. 36,
85-99; Steigmann 1990, "Tension-field theory", Proc. R. Soc. Lond. A 429, 141-173).
Per constant-strain triangle (F = D_s D_m^-1, Green strain E = (F^T F - I) / 2 with
principal values E_1 >= E_2 along the unit vectors n_1, n_2 of the rest plane) and the
plane-stress St. Venant-Kirchhoff energy psi(E) of ``membrane.Membrane``:

- taut, E_2 >= -nu E_1 (both principal stresses S_i = lambda* tr E + 2 mu E_i >= 0):
  psi = lambda*/2 tr(E)^2 + mu tr(E^2), the ordinary energy;
- wrinkled, E_1 > 0 > E_2 + nu E_1 (the smaller principal stress would be compressive):
  psi = E_s / 2 E_1^2, the energy of uniaxial tension along n_1 (the minimum of psi
  over E_2 is at E_2 = -nu E_1), stress S = E_s E_1 n_1 n_1^T;
- slack, E_1 <= 0: psi = 0, S = 0.

psi is C1 (energy and stress agree on the region boundaries). The wrinkled tangent is
    dS/dE = E_s N (x) N + E_s E_1 / (2 (E_1 - E_2)) M (x) M,
N = n_1 n_1^T, M = n_1 n_2^T + n_2 n_1^T (the second term from the rotation of n_1;
E_1 - E_2 > (1 + nu) E_1 > 0 there), positive semi-definite like the geometric term
with the tensile S, so the Hessian of a wrinkled or slack triangle is positive
semi-definite without clamping. With the tangent C_kilj = d S_ki / d E_lj,
    dP_ai / dF_bj = d_ab S_ij + F_ak C_kilj F_bl      (P = F S).
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import (Energy, Evaluation, hessian_triplets,
                                            scatter_gradient)
from gripper_sim.core3d.energies.common import KernelValue, empty_triplets
from gripper_sim.core3d.energies.membrane import Membrane


class WrinklingMembrane(KernelValue, Energy):
    """Relaxed (tension-field) St. Venant-Kirchhoff skin; same arguments as ``Membrane``.

    Args:
        triangles: (n_tri, 3) node indices.
        rest_positions: (n_nodes, 3) m, the stress-free shape.
        youngs_modulus: E_s, Pa.  poisson_ratio: nu (-).  thickness: t, m.

    ``evaluate`` is the numpy reference; ``evaluate_into`` the numba kernel of the 3D
    solver's fast path (``_kernel`` below, compiled on first use and cached).
    """

    def __init__(self, triangles, rest_positions, youngs_modulus: float,
                 poisson_ratio: float, thickness: float):
        geometry = Membrane(triangles, rest_positions, youngs_modulus, poisson_ratio,
                            thickness)
        self._geometry = geometry
        self.tri, self.dofs = geometry.tri, geometry.dofs
        self.grad_n, self.weight, self.area = geometry.grad_n, geometry.weight, geometry.area
        self.mu, self.lam = geometry.mu, geometry.lam
        self.youngs_modulus = float(youngs_modulus)
        self.nu = float(poisson_ratio)

    def deformation_gradients(self, q: np.ndarray) -> np.ndarray:
        """(n_tri, 3, 2)."""
        return self._geometry.deformation_gradients(q)

    def strains(self, q: np.ndarray) -> np.ndarray:
        """(n_tri,) largest principal engineering strain of each triangle (-)."""
        return self._geometry.strains(q)

    def states(self, q: np.ndarray) -> np.ndarray:
        """(n_tri,) 0 taut, 1 wrinkled, 2 slack."""
        e1, e2, _, _ = self._principal(self._green(self.deformation_gradients(q)))
        return np.where(e2 >= -self.nu * e1, 0, np.where(e1 > 0, 1, 2))

    @staticmethod
    def _green(f: np.ndarray) -> np.ndarray:
        return 0.5 * (np.einsum('eai,eaj->eij', f, f) - np.eye(2))

    @staticmethod
    def _principal(e: np.ndarray):
        """Principal strains E_1 >= E_2 (n,) and unit vectors n_1, n_2 (n, 2)."""
        a, b, d = e[:, 0, 0], e[:, 0, 1], e[:, 1, 1]
        mean = 0.5 * (a + d)
        radius = np.hypot(0.5 * (a - d), b)
        phi = 0.5 * np.arctan2(2 * b, a - d)
        n1 = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        n2 = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
        return mean + radius, mean - radius, n1, n2

    def _stress(self, f: np.ndarray, hessian: bool):
        """Energy density psi (n,) Pa, PK2 stress S (n, 2, 2) Pa and, with ``hessian``,
        the tangent C (n, 2, 2, 2, 2) Pa."""
        e = self._green(f)
        e1, e2, n1, n2 = self._principal(e)
        taut = e2 >= -self.nu * e1
        wrinkled = ~taut & (e1 > 0)
        mu, lam, young = self.mu, self.lam, self.youngs_modulus
        tr = e[:, 0, 0] + e[:, 1, 1]
        eye = np.eye(2)
        psi = np.where(taut, 0.5 * lam * tr ** 2 + mu * np.einsum('eij,eij->e', e, e),
                       np.where(wrinkled, 0.5 * young * e1 ** 2, 0.0))
        big_n = np.einsum('ei,ej->eij', n1, n1)
        s_taut = 2 * mu * e + (lam * tr)[:, None, None] * eye
        s_wrinkled = (young * e1)[:, None, None] * big_n
        s = np.where(taut[:, None, None], s_taut,
                     np.where(wrinkled[:, None, None], s_wrinkled, 0.0))
        if not hessian:
            return psi, s, None
        c_taut = (lam * np.einsum('ki,lj->kilj', eye, eye)
                  + mu * (np.einsum('kl,ij->kilj', eye, eye)
                          + np.einsum('kj,il->kilj', eye, eye)))
        big_m = np.einsum('ei,ej->eij', n1, n2) + np.einsum('ei,ej->eij', n2, n1)
        gap = np.where(wrinkled, e1 - e2, 1.0)
        rotation = np.where(wrinkled, young * e1 / (2 * gap), 0.0)
        c_wrinkled = (young * np.einsum('eki,elj->ekilj', big_n, big_n)
                      + rotation[:, None, None, None, None]
                      * np.einsum('eki,elj->ekilj', big_m, big_m))
        state = taut[:, None, None, None, None]
        c = np.where(state, c_taut[None], np.where(wrinkled[:, None, None, None, None],
                                                   c_wrinkled, 0.0))
        return psi, s, c

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        f = self.deformation_gradients(q)
        psi, s, c = self._stress(f, hessian)
        value = float(np.sum(self.weight * psi))
        p = np.einsum('eai,eij->eaj', f, s)
        local = self.weight[:, None, None] * np.einsum('eaj,ekj->eka', p, self.grad_n)
        grad = scatter_gradient(q.size, self.dofs, local.reshape(len(self.tri), 9))
        if not hessian:
            return Evaluation(value, grad, *empty_triplets())
        cmat = (np.einsum('ab,eij->eaibj', np.eye(3), s)
                + np.einsum('eak,ekilj,ebl->eaibj', f, c, f, optimize=True))
        h = np.einsum('e,eki,eaibj,elj->ekalb', self.weight, self.grad_n, cmat, self.grad_n,
                      optimize=True)
        return Evaluation(value, grad, *hessian_triplets(self.dofs,
                                                         h.reshape(len(self.tri), 9, 9)))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel of ``evaluate``: adds the gradient (N) into ``grad`` and the
        Hessian (N/m) into the CSC values ``data`` at ``scatter`` (n_tri, 81); returns
        (value in J, low-rank terms)."""
        return _kernel()(q.reshape(-1, 3), self.tri, self.grad_n, self.weight,
                         float(self.mu), float(self.lam), self.youngs_modulus, self.nu,
                         grad, data, scatter, hessian), []


_COMPILED = []


def _kernel():
    """The compiled ``_wrinkling_kernel`` (numba imported only here)."""
    if not _COMPILED:
        from numba import njit
        _COMPILED.append(njit(cache=True)(_wrinkling_kernel))
    return _COMPILED[0]


def _wrinkling_kernel(x, tri, grad_n, weight, mu, lam, young, nu, grad, data, scatter,
                      hessian):
    """Loop form of ``WrinklingMembrane.evaluate`` for numba, in the conventions of
    ``gripper_sim.core3d.kernels`` (x (n, 3) m, scatter (n_tri, 81) positions in the CSC
    ``data``, gradient and Hessian added to). Returns the energy (J)."""
    value = 0.0
    f = np.empty((3, 2))
    s = np.empty((2, 2))
    p = np.empty((3, 2))
    tan = np.zeros((2, 2, 2, 2))
    big_n = np.empty((2, 2))
    big_m = np.empty((2, 2))
    cm = np.empty((3, 2, 3, 2))
    for t in range(tri.shape[0]):
        gn = grad_n[t]
        for a in range(3):
            for j in range(2):
                acc = 0.0
                for k in range(3):
                    acc += x[tri[t, k], a] * gn[k, j]
                f[a, j] = acc
        c00 = f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0]
        c01 = f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1]
        c11 = f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1]
        e00, e01, e11 = 0.5 * (c00 - 1.0), 0.5 * c01, 0.5 * (c11 - 1.0)
        mean = 0.5 * (e00 + e11)
        radius = np.hypot(0.5 * (e00 - e11), e01)
        e1, e2 = mean + radius, mean - radius
        taut = e2 >= -nu * e1
        if not taut and e1 <= 0.0:
            continue  # slack
        w = weight[t]
        if taut:
            tr = e00 + e11
            value += w * (0.5 * lam * tr * tr + mu * (e00 * e00 + 2.0 * e01 * e01
                                                      + e11 * e11))
            s[0, 0] = 2.0 * mu * e00 + lam * tr
            s[0, 1] = 2.0 * mu * e01
            s[1, 0] = s[0, 1]
            s[1, 1] = 2.0 * mu * e11 + lam * tr
        else:
            phi = 0.5 * np.arctan2(2.0 * e01, e00 - e11)
            n1x, n1y = np.cos(phi), np.sin(phi)
            n2x, n2y = -n1y, n1x
            big_n[0, 0], big_n[0, 1], big_n[1, 1] = n1x * n1x, n1x * n1y, n1y * n1y
            big_n[1, 0] = big_n[0, 1]
            big_m[0, 0], big_m[1, 1] = 2.0 * n1x * n2x, 2.0 * n1y * n2y
            big_m[0, 1] = n1x * n2y + n2x * n1y
            big_m[1, 0] = big_m[0, 1]
            value += w * 0.5 * young * e1 * e1
            for i in range(2):
                for j in range(2):
                    s[i, j] = young * e1 * big_n[i, j]
        for a in range(3):
            for j in range(2):
                p[a, j] = f[a, 0] * s[0, j] + f[a, 1] * s[1, j]
        for k in range(3):
            dof = 3 * tri[t, k]
            for a in range(3):
                grad[dof + a] += w * (p[a, 0] * gn[k, 0] + p[a, 1] * gn[k, 1])
        if not hessian:
            continue
        # tangent C_kilj = dS_ki / dE_lj of the element's state
        rotation = 0.0 if taut else young * e1 / (2.0 * (e1 - e2))
        for k in range(2):
            for i in range(2):
                for ll in range(2):
                    for j in range(2):
                        if taut:
                            v = 0.0
                            if k == i and ll == j:
                                v += lam
                            if k == ll and i == j:
                                v += mu
                            if k == j and i == ll:
                                v += mu
                        else:
                            v = (young * big_n[k, i] * big_n[ll, j]
                                 + rotation * big_m[k, i] * big_m[ll, j])
                        tan[k, i, ll, j] = v
        # dP_ai / dF_bj = d_ab S_ij + F_ak C_kilj F_bl
        for a in range(3):
            for i in range(2):
                for b in range(3):
                    for j in range(2):
                        v = s[i, j] if a == b else 0.0
                        for k in range(2):
                            for ll in range(2):
                                v += f[a, k] * tan[k, i, ll, j] * f[b, ll]
                        cm[a, i, b, j] = v
        sc = scatter[t]
        for k in range(3):
            for a in range(3):
                row = (3 * k + a) * 9
                for ll in range(3):
                    for b in range(3):
                        acc = 0.0
                        for i in range(2):
                            for j in range(2):
                                acc += gn[k, i] * cm[a, i, b, j] * gn[ll, j]
                        data[sc[row + 3 * ll + b]] += w * acc
    return value
