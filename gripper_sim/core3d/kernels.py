"""Numba kernels of the 3D energies.

Free functions ``@njit(cache=True)`` on arrays, one kernel per energy of
``gripper_sim.core3d.energies`` (its only implementation; the tests compare each with
an independent numpy derivation in test/reference_energies3d.py). Each adds the
gradient into a preallocated (n_dof,) vector and each element Hessian entry straight
into the ``data`` array of a sparse matrix: ``scatter[e, r * m + c]`` is the position in
``data`` of the entry (row ``dofs[e, r]``, column ``dofs[e, c]``) of element e (m dofs
per element). With ``hessian`` False only the value and the gradient are computed (line
searches).

Positions x are (n_nodes, 3) (m); element dofs are [x, y, z] of each element node in
order, as ``energies.common.element_dofs3``.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _cross_matrix(v, out):
    """out (3, 3) = [v]x, with [v]x w = v x w."""
    out[0, 0] = 0.0
    out[0, 1] = -v[2]
    out[0, 2] = v[1]
    out[1, 0] = v[2]
    out[1, 1] = 0.0
    out[1, 2] = -v[0]
    out[2, 0] = -v[1]
    out[2, 1] = v[0]
    out[2, 2] = 0.0


@njit(cache=True, inline='always')
def _deformation_gradient(x, nodes, b, f, n_nodes, n_dims):
    """f (3, c) = sum_k x[nodes[k]] outer b[k]: F = dx/dX of an element at a point.

    Args:
        x: (n, 3) m.  nodes: (k,) the element's nodes.
        b: (k, c) dN_k/dX_j (1/m) at the point.  f: (3, c) written (-).
        n_nodes, n_dims: k and c (literal constants where known, so that the loops unroll).
    """
    for i in range(3):
        for j in range(n_dims):
            acc = 0.0
            for k in range(n_nodes):
                acc += x[nodes[k], i] * b[k, j]
            f[i, j] = acc


@njit(cache=True, inline='always')
def _membrane_green_strain(x, nodes, gn, f):
    """A constant-strain triangle's F (3, 2) written into f and its Green strain
    E = (F^T F - I) / 2 (-) returned as (E_00, E_01, E_11).

    Args: x (n, 3) m; nodes (3,); gn (3, 2) dN_k/dX_j (1/m).
    """
    _deformation_gradient(x, nodes, gn, f, 3, 2)
    c00 = f[0, 0] * f[0, 0] + f[1, 0] * f[1, 0] + f[2, 0] * f[2, 0]
    c01 = f[0, 0] * f[0, 1] + f[1, 0] * f[1, 1] + f[2, 0] * f[2, 1]
    c11 = f[0, 1] * f[0, 1] + f[1, 1] * f[1, 1] + f[2, 1] * f[2, 1]
    return 0.5 * (c00 - 1.0), 0.5 * c01, 0.5 * (c11 - 1.0)


@njit(cache=True, inline='always')
def _svk_density_and_stress(e00, e01, e11, mu, lam, s):
    """Plane-stress St. Venant-Kirchhoff: the energy density lam/2 tr(E)^2 + mu tr(E^2)
    (Pa) returned, the PK2 stress S = lam tr(E) I + 2 mu E (2, 2) (Pa) written into s."""
    tr = e00 + e11
    s[0, 0] = 2.0 * mu * e00 + lam * tr
    s[0, 1] = 2.0 * mu * e01
    s[1, 0] = s[0, 1]
    s[1, 1] = 2.0 * mu * e11 + lam * tr
    return 0.5 * lam * tr * tr + mu * (e00 * e00 + 2.0 * e01 * e01 + e11 * e11)


@njit(cache=True, inline='always')
def _add_membrane_gradient(nodes, gn, f, s, w, p, grad):
    """grad[3 nodes[k] + a] += w (P gn_k)_a with P = F S (3, 2) (Pa, written into p).

    Args: nodes (3,); gn (3, 2) 1/m; f (3, 2); s (2, 2) Pa; w t A0 (m^3); grad (3 n,) N.
    """
    for a in range(3):
        for j in range(2):
            p[a, j] = f[a, 0] * s[0, j] + f[a, 1] * s[1, j]
    for k in range(3):
        dof = 3 * nodes[k]
        for a in range(3):
            grad[dof + a] += w * (p[a, 0] * gn[k, 0] + p[a, 1] * gn[k, 1])


@njit(cache=True, inline='always')
def _add_membrane_hessian(gn, cm, w, sc, data):
    """H_(k a)(l b) = w sum_ij gn[k, i] C_(a i)(b j) gn[l, j] added into data at sc (81,).

    Args: gn (3, 2) 1/m; cm (3, 2, 3, 2) dP_ai/dF_bj (Pa); w m^3; data N/m.
    """
    for k in range(3):
        for a in range(3):
            row = (3 * k + a) * 9
            for l in range(3):
                for b in range(3):
                    acc = 0.0
                    for i in range(2):
                        for j in range(2):
                            acc += gn[k, i] * cm[a, i, b, j] * gn[l, j]
                    data[sc[row + 3 * l + b]] += w * acc


@njit(cache=True)
def membrane(x, tri, grad_n, weight, mu, lam, grad, data, scatter, hessian):
    """St. Venant-Kirchhoff constant-strain triangles (``energies.membrane.Membrane``).

    Args:
        x: (n, 3) m.  tri: (n_tri, 3).  grad_n: (n_tri, 3, 2) dN_k/dX_j (1/m).
        weight: (n_tri,) t A0 (m^3).  mu, lam: plane-stress Lame constants (Pa).
        grad: (3 n,) N, added to.  data: CSC values (N/m), added to.
        scatter: (n_tri, 81) positions in data.

    Returns:
        Energy (J).
    """
    value = 0.0
    f = np.empty((3, 2))
    s = np.empty((2, 2))
    p = np.empty((3, 2))
    ff = np.empty((3, 3))
    cm = np.empty((3, 2, 3, 2))
    for t in range(tri.shape[0]):
        gn = grad_n[t]
        e00, e01, e11 = _membrane_green_strain(x, tri[t], gn, f)
        w = weight[t]
        value += w * _svk_density_and_stress(e00, e01, e11, mu, lam, s)
        _add_membrane_gradient(tri[t], gn, f, s, w, p, grad)
        if not hessian:
            continue
        for a in range(3):
            for b in range(3):
                ff[a, b] = f[a, 0] * f[b, 0] + f[a, 1] * f[b, 1]
        # C_(a i)(b j) = d_ab S_ij + lam F_ai F_bj + mu d_ij (F F^T)_ab + mu F_aj F_bi
        for a in range(3):
            for i in range(2):
                for b in range(3):
                    for j in range(2):
                        v = lam * f[a, i] * f[b, j] + mu * f[a, j] * f[b, i]
                        if a == b:
                            v += s[i, j]
                        if i == j:
                            v += mu * ff[a, b]
                        cm[a, i, b, j] = v
        _add_membrane_hessian(gn, cm, w, scatter[t], data)
    return value


@njit(cache=True)
def wrinkling_membrane(x, tri, grad_n, weight, mu, lam, young, nu, grad, data, scatter,
                       hessian):
    """Relaxed (tension-field) St. Venant-Kirchhoff triangles
    (``energies.wrinkling_membrane.WrinklingMembrane``): taut, wrinkled or slack.

    Args:
        x, tri, grad_n, weight, mu, lam, grad, data, scatter: as ``membrane``.
        young: E_s (Pa).  nu: Poisson's ratio (-).

    Returns:
        Energy (J).
    """
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
        e00, e01, e11 = _membrane_green_strain(x, tri[t], gn, f)
        mean = 0.5 * (e00 + e11)
        radius = np.hypot(0.5 * (e00 - e11), e01)
        e1, e2 = mean + radius, mean - radius
        taut = e2 >= -nu * e1
        if not taut and e1 <= 0.0:
            continue  # slack
        w = weight[t]
        if taut:
            value += w * _svk_density_and_stress(e00, e01, e11, mu, lam, s)
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
        _add_membrane_gradient(tri[t], gn, f, s, w, p, grad)
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
        _add_membrane_hessian(gn, cm, w, scatter[t], data)
    return value


@njit(cache=True)
def hinge_bending(x, hinges, theta0, stiffness, grad, data, scatter, hessian):
    """Discrete-shell hinges (``energies.hinge.HingeBending``): sum k (theta - theta0)^2.

    Args:
        x: (n, 3) m.  hinges: (n_hinge, 4) nodes (p0, p1, p2, p3).
        theta0: (n_hinge,) rad.  stiffness: (n_hinge,) k (N m).
        grad, data, scatter: as ``membrane`` (scatter (n_hinge, 144)).

    Returns:
        Energy (J).
    """
    value = 0.0
    p = np.empty((4, 3))
    e = np.empty(3)
    eh = np.empty(3)
    na = np.empty(3)
    nb = np.empty(3)
    tmp = np.empty(3)
    tmp2 = np.empty(3)
    ga = np.empty(3)
    gb = np.empty(3)
    ca = np.empty(4)
    cb = np.empty(4)
    dth = np.empty(12)
    proj = np.empty((3, 3))
    dca = np.zeros((4, 4, 3))
    dcb = np.zeros((4, 4, 3))
    ma = np.empty((3, 3))
    mb = np.empty((3, 3))
    dna = np.zeros((4, 3, 3))
    dnb = np.zeros((4, 3, 3))
    dga = np.empty((3, 4, 3))
    dgb = np.empty((3, 4, 3))
    cross = np.empty((3, 3))
    w = np.empty((4, 3))
    for h in range(hinges.shape[0]):
        for i in range(4):
            for c in range(3):
                p[i, c] = x[hinges[h, i], c]
        for c in range(3):
            e[c] = p[1, c] - p[0, c]
        length = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        for c in range(3):
            eh[c] = e[c] / length
            tmp[c] = p[2, c] - p[0, c]
            tmp2[c] = p[3, c] - p[0, c]
        _cross(e, tmp, na)
        _cross(tmp2, e, nb)
        _cross(na, nb, tmp)
        sin = tmp[0] * eh[0] + tmp[1] * eh[1] + tmp[2] * eh[2]
        cos = na[0] * nb[0] + na[1] * nb[1] + na[2] * nb[2]
        theta = math.atan2(sin, cos)
        na2 = na[0] * na[0] + na[1] * na[1] + na[2] * na[2]
        nb2 = nb[0] * nb[0] + nb[1] * nb[1] + nb[2] * nb[2]
        d21 = d20 = d31 = d30 = 0.0
        for c in range(3):
            ga[c] = na[c] / na2
            gb[c] = nb[c] / nb2
            d21 += (p[2, c] - p[1, c]) * eh[c]
            d20 += (p[2, c] - p[0, c]) * eh[c]
            d31 += (p[3, c] - p[1, c]) * eh[c]
            d30 += (p[3, c] - p[0, c]) * eh[c]
        ca[0], ca[1], ca[2], ca[3] = -d21, d20, -length, 0.0
        cb[0], cb[1], cb[2], cb[3] = -d31, d30, 0.0, -length
        for i in range(4):
            for c in range(3):
                dth[3 * i + c] = ca[i] * ga[c] + cb[i] * gb[c]
        dev = theta - theta0[h]
        dev = (dev + math.pi) % (2.0 * math.pi) - math.pi
        k = stiffness[h]
        value += k * dev * dev
        for i in range(4):
            dof = 3 * hinges[h, i]
            for c in range(3):
                grad[dof + c] += 2.0 * k * dev * dth[3 * i + c]
        if not hessian:
            continue
        for a in range(3):
            for b in range(3):
                proj[a, b] = ((1.0 if a == b else 0.0) - eh[a] * eh[b]) / length
        # w[0..3] = proj (p2 - p1), proj (p2 - p0), proj (p3 - p1), proj (p3 - p0)
        for a in range(3):
            w[0, a] = w[1, a] = w[2, a] = w[3, a] = 0.0
            for b in range(3):
                w[0, a] += proj[a, b] * (p[2, b] - p[1, b])
                w[1, a] += proj[a, b] * (p[2, b] - p[0, b])
                w[2, a] += proj[a, b] * (p[3, b] - p[1, b])
                w[3, a] += proj[a, b] * (p[3, b] - p[0, b])
        dca[:] = 0.0
        dcb[:] = 0.0
        for c in range(3):
            # c_A0 = -(p2 - p1).eh, c_A1 = (p2 - p0).eh, c_A2 = -|e|
            dca[0, 1, c] = -w[0, c] + eh[c]
            dca[0, 0, c] = w[0, c]
            dca[0, 2, c] = -eh[c]
            dca[1, 1, c] = w[1, c]
            dca[1, 0, c] = -w[1, c] - eh[c]
            dca[1, 2, c] = eh[c]
            dca[2, 1, c] = -eh[c]
            dca[2, 0, c] = eh[c]
            # c_B0 = -(p3 - p1).eh, c_B1 = (p3 - p0).eh, c_B3 = -|e|
            dcb[0, 1, c] = -w[2, c] + eh[c]
            dcb[0, 0, c] = w[2, c]
            dcb[0, 3, c] = -eh[c]
            dcb[1, 1, c] = w[3, c]
            dcb[1, 0, c] = -w[3, c] - eh[c]
            dcb[1, 3, c] = eh[c]
            dcb[3, 1, c] = -eh[c]
            dcb[3, 0, c] = eh[c]
        for a in range(3):
            for b in range(3):
                delta = 1.0 if a == b else 0.0
                ma[a, b] = (delta - 2.0 * ga[a] * na[b]) / na2
                mb[a, b] = (delta - 2.0 * gb[a] * nb[b]) / nb2
        for c in range(3):
            tmp[c] = p[2, c] - p[1, c]
        _cross_matrix(tmp, cross)
        dna[0] = cross
        for c in range(3):
            tmp[c] = p[2, c] - p[0, c]
        _cross_matrix(tmp, cross)
        for a in range(3):
            for b in range(3):
                dna[1, a, b] = -cross[a, b]
        _cross_matrix(e, cross)
        for a in range(3):
            for b in range(3):
                dna[2, a, b] = cross[a, b]
                dnb[3, a, b] = -cross[a, b]
        for c in range(3):
            tmp[c] = p[1, c] - p[3, c]
        _cross_matrix(tmp, cross)
        dnb[0] = cross
        for c in range(3):
            tmp[c] = p[3, c] - p[0, c]
        _cross_matrix(tmp, cross)
        dnb[1] = cross
        for a in range(3):
            for j in range(4):
                for c in range(3):
                    acc_a = 0.0
                    acc_b = 0.0
                    for b in range(3):
                        acc_a += ma[a, b] * dna[j, b, c]
                        acc_b += mb[a, b] * dnb[j, b, c]
                    dga[a, j, c] = acc_a
                    dgb[a, j, c] = acc_b
        sc = scatter[h]
        # the Hessian is symmetric: the upper triangle, mirrored, by 3x3 node blocks
        twok = 2.0 * k
        for i in range(4):
            cai, cbi = ca[i], cb[i]
            for j in range(i, 4):
                for a in range(3):
                    r = 3 * i + a
                    gaa, gba, dr = ga[a], gb[a], dth[r]
                    for c in range(3):
                        if j == i and c < a:
                            continue
                        col = 3 * j + c
                        v = twok * (dr * dth[col] + dev * (
                            gaa * dca[i, j, c] + gba * dcb[i, j, c]
                            + cai * dga[a, j, c] + cbi * dgb[a, j, c]))
                        data[sc[r * 12 + col]] += v
                        if col != r:
                            data[sc[col * 12 + r]] += v
    return value


@njit(cache=True)
def volume_and_gradient(x, tri, gv):
    """Enclosed volume V (m^3) of the outward skin; dV/dx (m^2) written into gv (3 n,)."""
    gv[:] = 0.0
    volume = 0.0
    c = np.empty(3)
    for t in range(tri.shape[0]):
        i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
        _cross(x[i1], x[i2], c)
        volume += x[i0, 0] * c[0] + x[i0, 1] * c[1] + x[i0, 2] * c[2]
        for a in range(3):
            gv[3 * i0 + a] += c[a] / 6.0
        _cross(x[i2], x[i0], c)
        for a in range(3):
            gv[3 * i1 + a] += c[a] / 6.0
        _cross(x[i0], x[i1], c)
        for a in range(3):
            gv[3 * i2 + a] += c[a] / 6.0
    return volume / 6.0


@njit(cache=True)
def volume_pressure_hessian(x, tri, de_dv, data, scatter):
    """The sparse part dE/dV d2V/dx2 of the pressure Hessian, added into data.

    d2V/dx_a dx_b = -[x_c]x / 6 for (a, b, c) cyclic, its transpose for (b, a).
    """
    cross = np.empty((3, 3))
    for t in range(tri.shape[0]):
        sc = scatter[t]
        for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
            _cross_matrix(x[tri[t, c]], cross)
            for i in range(3):
                for j in range(3):
                    v = cross[i, j] * (-de_dv / 6.0)
                    data[sc[(3 * a + i) * 9 + 3 * b + j]] += v
                    data[sc[(3 * b + j) * 9 + 3 * a + i]] += v


@njit(cache=True, inline='always')
def _det3(f):
    """det F of a (3, 3) matrix, by cofactors of the first row."""
    return (f[0, 0] * (f[1, 1] * f[2, 2] - f[1, 2] * f[2, 1])
            - f[0, 1] * (f[1, 0] * f[2, 2] - f[1, 2] * f[2, 0])
            + f[0, 2] * (f[1, 0] * f[2, 1] - f[1, 1] * f[2, 0]))


@njit(cache=True, inline='always')
def _inverse_and_log_det(f, finv):
    """F^-1 (3, 3) by cofactors written into finv; ln J (J = det F > 0) returned."""
    c00 = f[1, 1] * f[2, 2] - f[1, 2] * f[2, 1]
    c01 = f[1, 2] * f[2, 0] - f[1, 0] * f[2, 2]
    c02 = f[1, 0] * f[2, 1] - f[1, 1] * f[2, 0]
    det = f[0, 0] * c00 + f[0, 1] * c01 + f[0, 2] * c02
    finv[0, 0] = c00 / det
    finv[1, 0] = c01 / det
    finv[2, 0] = c02 / det
    finv[0, 1] = (f[0, 2] * f[2, 1] - f[0, 1] * f[2, 2]) / det
    finv[1, 1] = (f[0, 0] * f[2, 2] - f[0, 2] * f[2, 0]) / det
    finv[2, 1] = (f[0, 1] * f[2, 0] - f[0, 0] * f[2, 1]) / det
    finv[0, 2] = (f[0, 1] * f[1, 2] - f[0, 2] * f[1, 1]) / det
    finv[1, 2] = (f[0, 2] * f[1, 0] - f[0, 0] * f[1, 2]) / det
    finv[2, 2] = (f[0, 0] * f[1, 1] - f[0, 1] * f[1, 0]) / det
    return math.log(det)


@njit(cache=True, inline='always')
def _neohookean_density_and_piola(f, finv, lnj, mu, lam, piola):
    """Neo-Hookean density psi = mu/2 (tr F^T F - 3) - mu ln J + lam/2 ln^2 J (J/m^3)
    returned; P = mu (F - F^-T) + lam ln J F^-T (3, 3) (Pa) written into piola."""
    ff = 0.0
    for i in range(3):
        for j in range(3):
            ff += f[i, j] * f[i, j]
    for i in range(3):
        for j in range(3):
            piola[i, j] = mu * (f[i, j] - finv[j, i]) + lam * lnj * finv[j, i]
    return 0.5 * mu * (ff - 3.0) - mu * lnj + 0.5 * lam * lnj * lnj


@njit(cache=True, inline='always')
def _add_piola_gradient(nodes, b, piola, w, grad, n_nodes):
    """grad[3 nodes[a] + i] += w (P b_a)_i: the point's share of dW/dx (N).

    Args: nodes (k,); b (k, 3) dN_a/dX_j (1/m); piola (3, 3) Pa; w m^3; grad (3 n,);
    n_nodes k (as in ``_deformation_gradient``).
    """
    for a in range(n_nodes):
        dof = 3 * nodes[a]
        for i in range(3):
            grad[dof + i] += w * (piola[i, 0] * b[a, 0] + piola[i, 1] * b[a, 1]
                                  + piola[i, 2] * b[a, 2])


@njit(cache=True, inline='always')
def _shape_times_inverse(b, finv, out, n_nodes):
    """out (k, 3) = B F^-1 (1/m): out[a, m] = sum_j b[a, j] finv[j, m]; n_nodes k."""
    for a in range(n_nodes):
        for m in range(3):
            out[a, m] = b[a, 0] * finv[0, m] + b[a, 1] * finv[1, m] + b[a, 2] * finv[2, m]


@njit(cache=True)
def neohookean_tets(x, tet, grad_n, volume, mu, lam, grad, data, scatter, hessian):
    """Compressible neo-Hookean tetrahedra (``energies.neohookean.NeoHookeanTets``).

    Args:
        x: (n, 3) m.  tet: (n_tet, 4).  grad_n: (n_tet, 4, 3) dN_k/dX_j (1/m).
        volume: (n_tet,) rest volumes (m^3).  mu, lam: Lame parameters (Pa).
        grad, data, scatter: as ``membrane`` (scatter (n_tet, 144)).

    Returns:
        Energy (J); inf (and nothing added) if an element is inverted (J <= 0).
    """
    # first pass: reject inverted elements before anything is added
    f = np.empty((3, 3))
    for t in range(tet.shape[0]):
        _deformation_gradient(x, tet[t], grad_n[t], f, 4, 3)
        if not _det3(f) > 0.0:
            return np.inf
    value = 0.0
    finv = np.empty((3, 3))
    piola = np.empty((3, 3))
    bk = np.empty((4, 3))
    for t in range(tet.shape[0]):
        gn = grad_n[t]
        _deformation_gradient(x, tet[t], gn, f, 4, 3)
        lnj = _inverse_and_log_det(f, finv)
        vol = volume[t]
        value += vol * _neohookean_density_and_piola(f, finv, lnj, mu, lam, piola)
        _add_piola_gradient(tet[t], gn, piola, vol, grad, 4)
        if not hessian:
            continue
        # H_(k i)(l m) = V [mu d_im (gn_k . gn_l) + (mu - lam ln J) B_l[i] B_k[m]
        #                   + lam B_k[i] B_l[m]],   B_k[m] = sum_j gn[k, j] Finv[j, m];
        # symmetric: the blocks l >= k are computed, the (l, k) ones are their transposes
        _shape_times_inverse(gn, finv, bk, 4)
        c2 = vol * (mu - lam * lnj)
        c3 = vol * lam
        sc = scatter[t]
        for k in range(4):
            for l in range(k, 4):
                dot = vol * mu * (gn[k, 0] * gn[l, 0] + gn[k, 1] * gn[l, 1]
                                  + gn[k, 2] * gn[l, 2])
                for i in range(3):
                    row = (3 * k + i) * 12 + 3 * l
                    for m in range(3):
                        v = c2 * bk[l, i] * bk[k, m] + c3 * bk[k, i] * bk[l, m]
                        if i == m:
                            v += dot
                        data[sc[row + m]] += v
                        if l != k:
                            data[sc[(3 * l + m) * 12 + 3 * k + i]] += v
    return value


@njit(cache=True)
def neohookean_quadrature(x, elem, grad_n, weight, mu, lam, grad, data, scatter, hessian):
    """Neo-Hookean elements integrated at quadrature points (the quadratic tetrahedra of
    ``energies.quadratic_tets``); the density and tangent are those of
    ``neohookean_tets``.

    Args:
        x: (n, 3) m.  elem: (n_elem, k) nodes.  grad_n: (n_elem, n_points, k, 3)
        dN_a/dX_j (1/m) at the points.  weight: (n_elem, n_points) m^3.
        mu, lam: Lame parameters (Pa).  grad, data: as ``membrane``;
        scatter: (n_elem, (3 k)^2).

    Returns:
        Energy (J); inf (and nothing added) if J <= 0 at a point.
    """
    n_elem, n_pts, n_k = grad_n.shape[0], grad_n.shape[1], grad_n.shape[2]
    f = np.empty((3, 3))
    for e in range(n_elem):
        for g in range(n_pts):
            _deformation_gradient(x, elem[e], grad_n[e, g], f, n_k, 3)
            if not _det3(f) > 0.0:
                return np.inf
    m = 3 * n_k
    value = 0.0
    finv = np.empty((3, 3))
    piola = np.empty((3, 3))
    gk = np.empty((n_k, 3))
    local = np.empty((m, m))
    for e in range(n_elem):
        if hessian:
            local[:] = 0.0
        for g in range(n_pts):
            b = grad_n[e, g]
            # F spelled out: through _deformation_gradient (n_k not a compile-time
            # constant) the gradient-only evaluation runs ~25 % slower
            for i in range(3):
                for j in range(3):
                    acc = 0.0
                    for a in range(n_k):
                        acc += x[elem[e, a], i] * b[a, j]
                    f[i, j] = acc
            lnj = _inverse_and_log_det(f, finv)
            w = weight[e, g]
            value += w * _neohookean_density_and_piola(f, finv, lnj, mu, lam, piola)
            _add_piola_gradient(elem[e], b, piola, w, grad, n_k)
            if not hessian:
                continue
            _shape_times_inverse(b, finv, gk, n_k)
            c2 = mu - lam * lnj
            for a in range(n_k):
                for bb in range(n_k):
                    dot = b[a, 0] * b[bb, 0] + b[a, 1] * b[bb, 1] + b[a, 2] * b[bb, 2]
                    for i in range(3):
                        for mm in range(3):
                            v = c2 * gk[bb, i] * gk[a, mm] + lam * gk[a, i] * gk[bb, mm]
                            if i == mm:
                                v += mu * dot
                            local[3 * a + i, 3 * bb + mm] += w * v
        if hessian:
            sc = scatter[e]
            for r in range(m):
                for c in range(m):
                    data[sc[r * m + c]] += local[r, c]
    return value


@njit(cache=True)
def neohookean_von_mises(x, tet, grad_n, mu, lam, out):
    """von Mises stress (Pa) of each tetrahedron's Cauchy stress into out (n_tet,), as
    ``NeoHookeanTets.von_mises``: sigma = (mu (F F^T - I) + lam ln J I) / J."""
    f = np.empty((3, 3))
    sig = np.empty((3, 3))
    for t in range(tet.shape[0]):
        _deformation_gradient(x, tet[t], grad_n[t], f, 4, 3)
        det = _det3(f)
        lnj = math.log(max(det, 1e-12))
        for i in range(3):
            for j in range(3):
                b = f[i, 0] * f[j, 0] + f[i, 1] * f[j, 1] + f[i, 2] * f[j, 2]
                if i == j:
                    sig[i, j] = (mu * (b - 1.0) + lam * lnj) / det
                else:
                    sig[i, j] = mu * b / det
        mean = (sig[0, 0] + sig[1, 1] + sig[2, 2]) / 3.0
        acc = 0.0
        for i in range(3):
            for j in range(3):
                d = sig[i, j] - (mean if i == j else 0.0)
                acc += d * d
        out[t] = math.sqrt(1.5 * acc)
