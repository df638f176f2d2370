"""Numpy references of the 2D energies, for the tests only.

The simulation computes every 2D energy with one numba kernel (the energies'
``evaluate_into``, ``gripper_sim.core.energies.kernels``). These are the same formulas
written again, vectorised in numpy from the class docstrings in
``gripper_sim.core.energies``, so that the tests can check the kernels against an
independent derivation (values, gradients and Hessians equal to round-off) besides
central differences.

Each energy function takes the energy (its rest data: element nodes, dofs, rest
angles, moduli) and the flat positions q (n_dof,) m, and returns an ``Evaluation``:
value J, gradient (n_dof,) N, Hessian triplets N/m, rank-one terms.
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies import (ConstantForce, EnclosedAreaPressure,
                                       NeoHookeanTriangles, RodBending, Stretching)
from gripper_sim.core.energies.base import Evaluation


def scatter_gradient(n_dof: int, dofs: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Sum element gradients (n_elem, m) into a (n_dof,) vector."""
    return np.bincount(dofs.ravel(), weights=local.ravel(), minlength=n_dof)


def hessian_triplets(dofs: np.ndarray, local: np.ndarray):
    """Element Hessians (n_elem, m, m) to IJV triplets."""
    m = dofs.shape[1]
    rows = np.repeat(dofs, m, axis=1).ravel()
    cols = np.tile(dofs, (1, m)).ravel()
    return rows, cols, local.ravel()


def _no_triplets():
    return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)


# ---------------------------------------------------------------- stretching
def stretching(energy: Stretching, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """E = EA (l - L)^2 / (2 L) per edge."""
    x = q.reshape(-1, 2)
    e = x[energy.edges[:, 1]] - x[energy.edges[:, 0]]
    length = np.hypot(e[:, 0], e[:, 1])
    stretch = length - energy.rest
    k = energy.ea / energy.rest
    value = float(0.5 * np.sum(k * stretch ** 2))
    u = e / length[:, None]
    f = (k * stretch)[:, None] * u
    grad = scatter_gradient(q.size, energy.dofs, np.hstack([-f, f]))
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    uu = u[:, :, None] * u[:, None, :]
    ratio = (stretch / length)[:, None, None]
    block = k[:, None, None] * (uu + ratio * (np.eye(2) - uu))
    local = np.block([[block, -block], [-block, block]])
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, local))


# ---------------------------------------------------------------- bending
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


def bending(energy: RodBending, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """E = k (phi - phi0)^2 / 2 per triple, phi the turning angle at its middle node."""
    x = q.reshape(-1, 2)
    t = energy.triples
    a = x[t[:, 1]] - x[t[:, 0]]
    b = x[t[:, 2]] - x[t[:, 1]]
    dphi = turning_angles(x, t) - energy.phi0
    dphi = (dphi + np.pi) % (2 * np.pi) - np.pi
    value = float(0.5 * np.sum(energy.k * dphi ** 2))
    ga = -_angle_gradient(a)
    gb = _angle_gradient(b)
    jac = np.hstack([-ga, ga - gb, gb])  # d phi / d (x_{i-1}, x_i, x_{i+1})
    grad = scatter_gradient(q.size, energy.dofs, (energy.k * dphi)[:, None] * jac)
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    ha = -_angle_hessian(a)
    hb = _angle_hessian(b)
    hphi = np.zeros((len(energy.k), 6, 6))
    # a = x_i - x_{i-1}: selector [-I, I, 0]; b = x_{i+1} - x_i: [0, -I, I]
    for (si, ci), (sj, cj) in (((0, -1), (0, -1)), ((0, -1), (2, 1)),
                               ((2, 1), (0, -1)), ((2, 1), (2, 1))):
        hphi[:, si:si + 2, sj:sj + 2] += ci * cj * ha
    for (si, ci), (sj, cj) in (((2, -1), (2, -1)), ((2, -1), (4, 1)),
                               ((4, 1), (2, -1)), ((4, 1), (4, 1))):
        hphi[:, si:si + 2, sj:sj + 2] += ci * cj * hb
    local = energy.k[:, None, None] * (jac[:, :, None] * jac[:, None, :]
                                       + dphi[:, None, None] * hphi)
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, local))


# ---------------------------------------------------------------- pressure
def enclosed_area(x: np.ndarray, ring: np.ndarray) -> float:
    """Signed area (m^2) of the polygon ``x[ring]`` (shoelace formula)."""
    p = x[ring]
    nxt = np.roll(p, -1, axis=0)
    return float(0.5 * np.sum(p[:, 0] * nxt[:, 1] - nxt[:, 0] * p[:, 1]))


def area_gradient(energy: EnclosedAreaPressure, q: np.ndarray) -> np.ndarray:
    """dA/dq (n_dof,) m."""
    p = q.reshape(-1, 2)[energy.ring]
    prv, nxt = np.roll(p, 1, axis=0), np.roll(p, -1, axis=0)
    g = np.zeros(q.size)
    g[2 * energy.ring] = 0.5 * (nxt[:, 1] - prv[:, 1])
    g[2 * energy.ring + 1] = 0.5 * (prv[:, 0] - nxt[:, 0])
    return g


def pressure(energy: EnclosedAreaPressure, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """E = b [-p0 (A - A0) + K (A - A0)^2 / (2 A0)]; Hessian dE/dA d2A/dq2 plus the
    rank-one term b K / A0 gA gA^T."""
    da = enclosed_area(q.reshape(-1, 2), energy.ring) - energy.a0
    value = energy.b * (-energy.p0 * da + 0.5 * energy.k * da ** 2 / energy.a0)
    de_da = energy.b * (-energy.p0 + energy.k * da / energy.a0)
    ga = area_gradient(energy, q)
    grad = de_da * ga
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    ring, nxt = energy.ring, np.roll(energy.ring, -1)
    # d2A/(dx_i dz_j) = +1/2 for j = next(i), -1/2 for i = next(j); symmetric
    rows = np.concatenate([2 * ring, 2 * nxt + 1, 2 * nxt, 2 * ring + 1])
    cols = np.concatenate([2 * nxt + 1, 2 * ring, 2 * ring + 1, 2 * nxt])
    vals = np.concatenate([np.full(2 * len(ring), 0.5), np.full(2 * len(ring), -0.5)])
    low_rank = [(energy.b * energy.k / energy.a0, ga)] if energy.k > 0 else []
    return Evaluation(value, grad, rows, cols, de_da * vals, low_rank)


# ---------------------------------------------------------------- neo-Hookean
def _b_matrices(energy: NeoHookeanTriangles) -> np.ndarray:
    """(n_tri, 4, 6) dF_flat / dx_local: F_ij = sum_k Ds_ik Dminv_kj, Ds_:k = x_{k+1} - x_0."""
    b = np.zeros((len(energy.tri), 4, 6))
    for i in range(2):
        for j in range(2):
            for k in range(2):
                b[:, 2 * i + j, 2 * (k + 1) + i] += energy.dm_inv[:, k, j]
                b[:, 2 * i + j, i] -= energy.dm_inv[:, k, j]
    return b


def deformation_gradients(energy: NeoHookeanTriangles, q: np.ndarray) -> np.ndarray:
    """(n_tri, 2, 2) deformation gradients."""
    x = q.reshape(-1, 2)
    t = energy.tri
    ds = np.stack([x[t[:, 1]] - x[t[:, 0]], x[t[:, 2]] - x[t[:, 0]]], axis=2)
    return ds @ energy.dm_inv


def neohookean(energy: NeoHookeanTriangles, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """psi = mu/2 (tr(F^T F) - 2) - mu ln J + lambda/2 (ln J)^2 per unit volume."""
    f = deformation_gradients(energy, q)
    j = f[:, 0, 0] * f[:, 1, 1] - f[:, 0, 1] * f[:, 1, 0]
    if np.any(j <= 0):
        return Evaluation(np.inf, np.full(q.size, np.nan), *_no_triplets())
    lnj = np.log(j)
    mu, lam = energy.mu, energy.lam
    psi = 0.5 * mu * (np.sum(f * f, axis=(1, 2)) - 2) - mu * lnj + 0.5 * lam * lnj ** 2
    value = float(np.sum(psi * energy.volume))
    finv = np.empty_like(f)
    finv[:, 0, 0], finv[:, 1, 1] = f[:, 1, 1] / j, f[:, 0, 0] / j
    finv[:, 0, 1], finv[:, 1, 0] = -f[:, 0, 1] / j, -f[:, 1, 0] / j
    finv_t = np.swapaxes(finv, 1, 2)
    piola = mu * (f - finv_t) + lam * lnj[:, None, None] * finv_t
    b = _b_matrices(energy)
    local_grad = np.einsum('e,ea,eak->ek', energy.volume, piola.reshape(-1, 4), b)
    grad = scatter_gradient(q.size, energy.dofs, local_grad)
    if not hessian:
        return Evaluation(value, grad, *_no_triplets())
    # dP_ij/dF_mn = mu d_im d_jn + (mu - lam lnJ) Finv_ni Finv_jm + lam Finv_ji Finv_nm
    c = (mu * np.eye(4)[None]
         + ((mu - lam * lnj)[:, None, None, None, None]
            * np.einsum('eni,ejm->eijmn', finv, finv)).reshape(-1, 4, 4)
         + lam * np.einsum('eji,enm->eijmn', finv, finv).reshape(-1, 4, 4))
    local = np.einsum('e,eak,eab,ebl->ekl', energy.volume, b, c, b)
    return Evaluation(value, grad, *hessian_triplets(energy.dofs, local))


def von_mises(energy: NeoHookeanTriangles, q: np.ndarray) -> np.ndarray:
    """(n_tri,) Pa, plane-strain von Mises stress of the Cauchy stress."""
    f = deformation_gradients(energy, q)
    j = np.linalg.det(f)
    b = f @ np.swapaxes(f, 1, 2)
    lnj = np.log(np.maximum(j, 1e-12))
    eye = np.eye(2)
    sigma = (energy.mu * (b - eye) + energy.lam * lnj[:, None, None] * eye) / j[:, None, None]
    s33 = (energy.lam * lnj) / j  # out-of-plane (F33 = 1: b33 - 1 = 0)
    sxx, szz, sxz = sigma[:, 0, 0], sigma[:, 1, 1], sigma[:, 0, 1]
    return np.sqrt(0.5 * ((sxx - szz) ** 2 + (szz - s33) ** 2 + (s33 - sxx) ** 2)
                   + 3 * sxz ** 2)


# ---------------------------------------------------------------- constant forces
def constant_force(energy: ConstantForce, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """E = -f . q."""
    return Evaluation(float(energy.grad @ q), energy.grad.copy(), *_no_triplets())


#: the reference of each energy class (subclasses find their base's)
REFERENCES = {Stretching: stretching, RodBending: bending, EnclosedAreaPressure: pressure,
              NeoHookeanTriangles: neohookean, ConstantForce: constant_force}


def reference(energy, q: np.ndarray, hessian: bool = True) -> Evaluation:
    """The numpy reference evaluation of a 2D energy."""
    for cls in type(energy).__mro__:
        if cls in REFERENCES:
            return REFERENCES[cls](energy, q, hessian)
    raise TypeError(f'no numpy reference for {type(energy).__name__}')


def dense_hessian(ev: Evaluation, n_dof: int) -> np.ndarray:
    """(n_dof, n_dof) N/m from an evaluation's triplets and rank-one terms."""
    dense = np.zeros((n_dof, n_dof))
    np.add.at(dense, (ev.rows, ev.cols), ev.vals)
    for c, u in ev.low_rank:
        dense += c * np.outer(u, u)
    return dense
