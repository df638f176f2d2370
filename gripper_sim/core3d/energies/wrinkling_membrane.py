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

from gripper_sim.core3d import kernels
from gripper_sim.core3d.energies.common import KernelEnergy
from gripper_sim.core3d.energies.membrane import Membrane


class WrinklingMembrane(KernelEnergy):
    """Relaxed (tension-field) St. Venant-Kirchhoff skin; same arguments as ``Membrane``.

    Args:
        triangles: (n_tri, 3) node indices.
        rest_positions: (n_nodes, 3) m, the stress-free shape.
        youngs_modulus: E_s, Pa.  poisson_ratio: nu (-).  thickness: t, m.
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

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """The energy's kernel ``kernels.wrinkling_membrane`` (see
        ``Membrane.evaluate_into``)."""
        return kernels.wrinkling_membrane(q.reshape(-1, 3), self.tri, self.grad_n,
                                          self.weight, float(self.mu), float(self.lam),
                                          self.youngs_modulus, self.nu, grad, data, scatter,
                                          hessian), []
