"""Numpy references of the 3D energies, for the tests only.

The simulation computes every 3D energy with one numba kernel (the energies'
``evaluate_into``, ``gripper_sim.core3d.kernels``). These are the same formulas written
again, vectorised in numpy from the class docstrings in ``gripper_sim.core3d.energies``,
so that the tests can check the kernels against an independent derivation (values,
gradients and Hessians equal to round-off) besides central differences.

Each function takes the energy (its rest data: element nodes, dofs, rest frames,
moduli) and the flat positions q (n_dof,) m, and returns an ``Evaluation``: value J,
gradient (n_dof,) N, Hessian triplets N/m, rank-one terms.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import Evaluation
from gripper_sim.core3d.energies.hinge import HingeBending
from gripper_sim.core3d.energies.membrane import Membrane
from gripper_sim.core3d.energies.neohookean import NeoHookeanTets
from gripper_sim.core3d.energies.pressure import EnclosedVolumePressure
from gripper_sim.core3d.energies.quadratic_tets import QuadraticNeoHookeanTets
from gripper_sim.core3d.energies.wrinkling_membrane import WrinklingMembrane

from reference_energies2d import hessian_triplets, scatter_gradient


def _no_triplets():
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)


def cross_matrices(v: np.ndarray) -> np.ndarray:
    """(n, 3, 3) matrices [v]x with [v]x w = v x w."""
    m = np.zeros(v.shape[:-1] + (3, 3))
    m[..., 0, 1], m[..., 0, 2] = -v[..., 2], v[..., 1]
    m[..., 1, 0], m[..., 1, 2] = v[..., 2], -v[..., 0]
    m[..., 2, 0], m[..., 2, 1] = -v[..., 1], v[..., 0]
    return m


# ---------------------------------------------------------------- membranes
def _assemble_membrane(energy, n_dof: int, f, psi, s, cmat) -> Evaluation:
    """Energy, gradient and Hessian of the skin triangles from their material response:
    f (n_tri, 3, 2) deformation gradients, psi (n_tri,) Pa, PK2 stresses s (n_tri, 2, 2)
    Pa, tangents cmat (n_tri, 3, 2, 3, 2) Pa of P = F S (None: no Hessian)."""
    value = float(np.sum(energy.weight * psi))
    p = np.einsum('eai,eij->eaj', f, s)
    # dW/dx_(k, a) = w P_aj dN_k/dX_j
    local = energy.weight[:, None, None] * np.einsum('eaj,ekj->eka', p, energy.grad_n)
    grad = scatter_gradient(n_dof, energy.dofs, local.reshape(len(energy.tri), 9))
    if cmat is None:
        return Evaluation(value, grad, *_no_triplets())
    # H_(k a)(l b) = w sum_ij dN_k/dX_i C_(a i)(b j) dN_l/dX_j
    h = np.einsum('e,eki,eaibj,elj->ekalb', energy.weight, energy.grad_n, cmat,
                  energy.grad_n, optimize=True)
    return Evaluation(value, grad, *hessian_triplets(energy.dofs,
                                                     h.reshape(len(energy.tri), 9, 9)))


def membrane(energy: Membrane, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """St. Venant-Kirchhoff constant-strain triangles (``membrane`` module docstring)."""
    f = energy.deformation_gradients(q)
    e = 0.5 * (np.einsum('eai,eaj->eij', f, f) - np.eye(2))
    tr = e[:, 0, 0] + e[:, 1, 1]
    mu, lam = energy.mu, energy.lam
    psi = 0.5 * lam * tr ** 2 + mu * np.einsum('eij,eij->e', e, e)
    s = 2 * mu * e + (lam * tr)[:, None, None] * np.eye(2)
    if not hessian:
        return _assemble_membrane(energy, q.size, f, psi, s, None)
    ffT = np.einsum('eaj,ebj->eab', f, f)
    cmat = (np.einsum('ab,eij->eaibj', np.eye(3), s)
            + lam * np.einsum('eai,ebj->eaibj', f, f)
            + mu * np.einsum('ij,eab->eaibj', np.eye(2), ffT)
            + mu * np.einsum('eaj,ebi->eaibj', f, f))
    return _assemble_membrane(energy, q.size, f, psi, s, cmat)


def green_strains(f: np.ndarray) -> np.ndarray:
    """(n, 2, 2) Green strains of membrane deformation gradients f (n, 3, 2)."""
    return 0.5 * (np.einsum('eai,eaj->eij', f, f) - np.eye(2))


def principal_strains(e: np.ndarray):
    """Principal strains E_1 >= E_2 (n,) and unit vectors n_1, n_2 (n, 2) of e (n, 2, 2)."""
    a, b, d = e[:, 0, 0], e[:, 0, 1], e[:, 1, 1]
    mean = 0.5 * (a + d)
    radius = np.hypot(0.5 * (a - d), b)
    phi = 0.5 * np.arctan2(2 * b, a - d)
    n1 = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    n2 = np.stack([-np.sin(phi), np.cos(phi)], axis=1)
    return mean + radius, mean - radius, n1, n2


def wrinkling_states(energy: WrinklingMembrane, q: np.ndarray) -> np.ndarray:
    """(n_tri,) 0 taut, 1 wrinkled, 2 slack."""
    e1, e2, _, _ = principal_strains(green_strains(energy.deformation_gradients(q)))
    return np.where(e2 >= -energy.nu * e1, 0, np.where(e1 > 0, 1, 2))


def _wrinkling_stress(energy: WrinklingMembrane, f: np.ndarray, hessian: bool):
    """psi (n,) Pa, PK2 stress S (n, 2, 2) Pa and, with ``hessian``, the tangent
    C (n, 2, 2, 2, 2) Pa of the relaxed (tension-field) energy."""
    e = green_strains(f)
    e1, e2, n1, n2 = principal_strains(e)
    taut = e2 >= -energy.nu * e1
    wrinkled = ~taut & (e1 > 0)
    mu, lam, young = energy.mu, energy.lam, energy.youngs_modulus
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
              + mu * (np.einsum('kl,ij->kilj', eye, eye) + np.einsum('kj,il->kilj', eye, eye)))
    big_m = np.einsum('ei,ej->eij', n1, n2) + np.einsum('ei,ej->eij', n2, n1)
    gap = np.where(wrinkled, e1 - e2, 1.0)
    rotation = np.where(wrinkled, young * e1 / (2 * gap), 0.0)
    c_wrinkled = (young * np.einsum('eki,elj->ekilj', big_n, big_n)
                  + rotation[:, None, None, None, None]
                  * np.einsum('eki,elj->ekilj', big_m, big_m))
    c = np.where(taut[:, None, None, None, None], c_taut[None],
                 np.where(wrinkled[:, None, None, None, None], c_wrinkled, 0.0))
    return psi, s, c


def wrinkling_membrane(energy: WrinklingMembrane, q: np.ndarray,
                       hessian: bool = True) -> Evaluation:
    """The relaxed skin (``wrinkling_membrane`` module docstring)."""
    f = energy.deformation_gradients(q)
    psi, s, c = _wrinkling_stress(energy, f, hessian)
    cmat = None
    if hessian:
        cmat = (np.einsum('ab,eij->eaibj', np.eye(3), s)
                + np.einsum('eak,ekilj,ebl->eaibj', f, c, f, optimize=True))
    return _assemble_membrane(energy, q.size, f, psi, s, cmat)


# ---------------------------------------------------------------- hinges
def _angle_derivatives(energy: HingeBending, x: np.ndarray, hessian: bool):
    """theta (n,), dtheta/dx (n, 12) and, if asked, d2theta/dx2 (n, 12, 12)."""
    h = energy.hinges
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


def hinge_bending(energy: HingeBending, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """Discrete-shell hinges (``hinge`` module docstring)."""
    theta, dtheta, d2theta = _angle_derivatives(energy, q.reshape(-1, 3), hessian)
    dev = (theta - energy.theta0 + np.pi) % (2 * np.pi) - np.pi
    value = float(np.sum(energy.k * dev ** 2))
    grad = scatter_gradient(q.size, energy.dofs, (2 * energy.k * dev)[:, None] * dtheta)
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    local = (2 * energy.k)[:, None, None] * (dtheta[:, :, None] * dtheta[:, None, :]
                                             + dev[:, None, None] * d2theta)
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, local))


# ---------------------------------------------------------------- pressure
def enclosed_volume_pressure(energy: EnclosedVolumePressure, q: np.ndarray,
                             hessian: bool = True) -> Evaluation:
    """Enclosed-volume pressure (``pressure`` module docstring), with its rank-one term."""
    p = q.reshape(-1, 3)[energy.tri]
    dv = energy.volume(q) - energy.v0
    value = -energy.p0 * dv + 0.5 * energy.k * dv ** 2 / energy.v0
    de_dv = -energy.p0 + energy.k * dv / energy.v0
    local = np.stack([np.cross(p[:, 1], p[:, 2]), np.cross(p[:, 2], p[:, 0]),
                      np.cross(p[:, 0], p[:, 1])], axis=1) / 6.0
    gv = scatter_gradient(q.size, energy.dofs, local.reshape(len(energy.tri), 9))
    if not hessian:
        return Evaluation(value, de_dv * gv, *_no_triplets())
    n = len(energy.tri)
    h = np.zeros((n, 3, 3, 3, 3))
    for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        block = cross_matrices(p[:, c]) * (-de_dv / 6.0)  # d2V/dx_a dx_b = -[x_c]x / 6
        h[:, a, :, b, :] = block
        h[:, b, :, a, :] = np.swapaxes(block, 1, 2)
    low_rank = [(energy.k / energy.v0, gv)] if energy.k > 0 else []
    return Evaluation(value, de_dv * gv, *hessian_triplets(energy.dofs, h.reshape(n, 9, 9)),
                      low_rank)


# ---------------------------------------------------------------- neo-Hookean flesh
def neohookean_response(f: np.ndarray, mu: float, lam: float):
    """(psi (...) J/m^3, ln J (...), F^-1 (..., 3, 3), P (..., 3, 3) Pa) at deformation
    gradients f (..., 3, 3), or None if J <= 0 anywhere (``neohookean`` docstring)."""
    j = np.linalg.det(f)
    if np.any(j <= 0):
        return None
    lnj = np.log(j)
    psi = 0.5 * mu * (np.einsum('...ij,...ij->...', f, f) - 3) - mu * lnj \
        + 0.5 * lam * lnj ** 2
    finv = np.linalg.inv(f)
    finv_t = np.swapaxes(finv, -1, -2)
    piola = mu * (f - finv_t) + (lam * lnj)[..., None, None] * finv_t
    return psi, lnj, finv, piola


def _inverted(q: np.ndarray) -> Evaluation:
    return Evaluation(np.inf, np.full(q.size, np.nan), *_no_triplets())


def neohookean_tets(energy: NeoHookeanTets, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """Linear tetrahedra (``neohookean`` module docstring)."""
    x = q.reshape(-1, 3)
    f = np.einsum('eki,ekj->eij', x[energy.tet], energy.grad_n)
    response = neohookean_response(f, energy.mu, energy.lam)
    if response is None:
        return _inverted(q)
    psi, lnj, finv, piola = response
    mu, lam = energy.mu, energy.lam
    value = float(np.sum(psi * energy.volume))
    local = energy.volume[:, None, None] * np.einsum('eij,ekj->eki', piola, energy.grad_n)
    n = len(energy.tet)
    grad = scatter_gradient(q.size, energy.dofs, local.reshape(n, 12))
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    eye = np.eye(3)
    c = (mu * np.einsum('im,jn->ijmn', eye, eye)[None]
         + (mu - lam * lnj)[:, None, None, None, None] * np.einsum('eni,ejm->eijmn', finv, finv)
         + lam * np.einsum('eji,enm->eijmn', finv, finv))
    # H_(k i)(l m) = V sum_jn dN_k/dX_j C_(ij)(mn) dN_l/dX_n
    h = np.einsum('e,ekj,eijmn,eln->ekilm', energy.volume, energy.grad_n, c, energy.grad_n,
                  optimize=True)
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, h.reshape(n, 12, 12)))


def neohookean_von_mises(energy: NeoHookeanTets, q: np.ndarray) -> np.ndarray:
    """(n_tet,) Pa, von Mises stress of the Cauchy stress of linear tetrahedra."""
    x = q.reshape(-1, 3)
    f = np.einsum('eki,ekj->eij', x[energy.tet], energy.grad_n)
    j = np.linalg.det(f)
    b = f @ np.swapaxes(f, 1, 2)
    lnj = np.log(np.maximum(j, 1e-12))
    sigma = (energy.mu * (b - np.eye(3)) + (energy.lam * lnj)[:, None, None] * np.eye(3)) \
        / j[:, None, None]
    dev = sigma - np.trace(sigma, axis1=1, axis2=2)[:, None, None] / 3 * np.eye(3)
    return np.sqrt(1.5 * np.einsum('eij,eij->e', dev, dev))


def quadratic_tets(energy: QuadraticNeoHookeanTets, q: np.ndarray,
                   hessian: bool = True) -> Evaluation:
    """Quadratic tetrahedra, 4-point rule (``quadratic_tets`` module docstring)."""
    response = neohookean_response(energy.deformation_gradients(q), energy.mu, energy.lam)
    if response is None:
        return _inverted(q)
    psi, lnj, finv, piola = response
    mu, lam, w = energy.mu, energy.lam, energy.weight
    value = float(np.sum(psi * w))
    local = np.einsum('eg,egij,egaj->eai', w, piola, energy.grad_n)
    n = len(energy.tet)
    grad = scatter_gradient(q.size, energy.dofs, local.reshape(n, 30))
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    # with G = B F^-1 (B_aj = dN_a/dX_j):
    #   H_(a i)(b m) = sum_g w [mu (B B^T)_ab d_im + (mu - lam ln J) G_am G_bi
    #                           + lam G_ai G_bm]
    b = energy.grad_n
    g = np.einsum('egaj,egji->egai', b, finv)
    bb = np.einsum('eg,egaj,egbj->eab', mu * w, b, b)
    h = np.einsum('eg,egam,egbi->eaibm', (mu - lam * lnj) * w, g, g, optimize=True)
    h += np.einsum('eg,egai,egbm->eaibm', lam * w, g, g, optimize=True)
    h += bb[:, :, None, :, None] * np.eye(3)[None, None, :, None, :]
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, h.reshape(n, 30, 30)))


#: the reference of each energy class (``WrinklingMembrane`` before ``Membrane``: it is
#: not a subclass, but keep the most specific first)
REFERENCES = (
    (WrinklingMembrane, wrinkling_membrane),
    (Membrane, membrane),
    (HingeBending, hinge_bending),
    (EnclosedVolumePressure, enclosed_volume_pressure),
    (QuadraticNeoHookeanTets, quadratic_tets),
    (NeoHookeanTets, neohookean_tets),
)


def reference_evaluation(energy, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """The numpy reference of ``energy`` at q; energies with one implementation only
    (e.g. gravity, which has no kernel of its own) evaluate themselves."""
    for cls, reference in REFERENCES:
        if isinstance(energy, cls):
            return reference(energy, q, hessian)
    return energy.evaluate(q, hessian)
