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

from gripper_sim.core.energies.base import Energy, Evaluation
from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.membrane import Membrane


class WrinklingMembrane(Energy):
    """Relaxed (tension-field) St. Venant-Kirchhoff skin; same arguments as ``Membrane``.

    Args:
        triangles: (n_tri, 3) node indices.
        rest_positions: (n_nodes, 3) m, the stress-free shape.
        youngs_modulus: E_s, Pa.  poisson_ratio: nu (-).  thickness: t, m.

    ``evaluate`` is the numpy reference; ``evaluate_into`` the numba kernel of the 3D
    solver's fast path (``kernels.wrinkling_membrane``).
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
        cmat = None
        if hessian:
            cmat = (np.einsum('ab,eij->eaibj', np.eye(3), s)
                    + np.einsum('eak,ekilj,ebl->eaibj', f, c, f, optimize=True))
        return self._geometry.assemble(q.size, f, psi, s, cmat)

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The numba kernel ``kernels.wrinkling_membrane`` of ``evaluate`` (see
        ``Membrane.evaluate_into``)."""
        return kernels.wrinkling_membrane(q.reshape(-1, 3), self.tri, self.grad_n,
                                          self.weight, float(self.mu), float(self.lam),
                                          self.youngs_modulus, self.nu, grad, data, scatter,
                                          hessian), []
