"""Numba kernels of the 2D energies (the ``evaluate_into`` of each energy class).

Free functions ``@njit(cache=True)`` on arrays: the one implementation of each energy
(the value, gradient and Hessian of its class in ``gripper_sim.core.energies``, which
the tests compare with the numpy references of ``test/reference_energies2d.py`` and
with central differences), adding the gradient into a preallocated (n_dof,)
vector and each element Hessian entry straight into the ``data`` array of a fixed CSC
matrix: ``scatter[e, r * m + c]`` is the position in ``data`` of the entry (row
``dofs[e, r]``, column ``dofs[e, c]``) of element e with m dofs (``base.element_dofs``
order: [x, z] of each element node), read as unsigned (no negative-index wraparound in
the adds). With ``hessian`` False only the value and the gradient are computed (line
searches).

Positions x are (n_nodes, 2) (m). Import this module only where numba is installed.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64


@njit(cache=True, inline='always')
def edge_spring(ex, ez, rest, k):
    """One edge's axial spring E = k (l - L)^2 / 2 (``Stretching``), the edge vector
    (ex, ez) = x_j - x_i m, rest length L m, stiffness k = EA / L N/m.

    Returns:
        (energy J, dE/dx_j (fx, fz) N (dE/dx_i = -that), the Hessian's (j, j) block
        (b00, b01 = b10, b11) N/m ((i, i) the same, (i, j) and (j, i) minus it)).
    """
    length = math.sqrt(ex * ex + ez * ez)
    inverse = 1.0 / length
    stretch = length - rest
    ux, uz = ex * inverse, ez * inverse
    ks = k * stretch
    ratio = stretch * inverse
    return (0.5 * ks * stretch, ks * ux, ks * uz, k * (ux * ux + ratio * (1.0 - ux * ux)),
            k * (ux * uz - ratio * ux * uz), k * (uz * uz + ratio * (1.0 - uz * uz)))


@njit(cache=True)
def stretching(x, edges, rest, k, grad, data, scatter, hessian):
    """Axial springs E = k (l - L)^2 / 2 per edge (``Stretching``, ``edge_spring``).

    Args:
        x: (n, 2) m.  edges: (n_edge, 2).  rest: (n_edge,) L (m).  k: (n_edge,) EA / L
        (N/m).  grad: (2 n,) N, added to.  data: CSC values (N/m), added to.
        scatter: (n_edge, 16) positions in data.

    Returns:
        Energy (J).
    """
    value = 0.0
    for e in range(edges.shape[0]):
        i, j = edges[e, 0], edges[e, 1]
        v, fx, fz, b00, b01, b11 = edge_spring(x[j, 0] - x[i, 0], x[j, 1] - x[i, 1], rest[e],
                                               k[e])
        value += v
        grad[2 * i] -= fx
        grad[2 * i + 1] -= fz
        grad[2 * j] += fx
        grad[2 * j + 1] += fz
        if not hessian:
            continue
        sc = scatter[e]
        for r in range(4):
            for c in range(4):
                a, b = r % 2, c % 2
                h = b00 if a + b == 0 else (b11 if a + b == 2 else b01)
                if (r < 2) != (c < 2):
                    h = -h
                data[uint64(sc[4 * r + c])] += h
    return value


@njit(cache=True, inline='always')
def _turning_angle(ax, az, bx, bz):
    """Signed angle (rad) from edge a to edge b."""
    return math.atan2(ax * bz - az * bx, ax * bx + az * bz)


@njit(cache=True)
def turning_angles(x, triples, out):
    """Signed turning angles (n_t,) rad at the middle node of each triple (previous,
    middle, next), between the edges x_i - x_p and x_n - x_i, written into out."""
    for t in range(triples.shape[0]):
        p, i, n = triples[t, 0], triples[t, 1], triples[t, 2]
        out[t] = _turning_angle(x[i, 0] - x[p, 0], x[i, 1] - x[p, 1],
                                x[n, 0] - x[i, 0], x[n, 1] - x[i, 1])


@njit(cache=True, inline='always')
def hinge(ax, az, bx, bz, phi0, k):
    """One bending triple (p, i, n) (``RodBending``): E = k (phi - phi0)^2 / 2, phi the
    turning angle from edge a = x_i - x_p to edge b = x_n - x_i (m), phi0 rad, k N m.

    Returns:
        (energy J, k dphi N m, dphi / dx (j0 .. j5) 1/m over [x_p, z_p, x_i, z_i, x_n,
        z_n], and (ha00, ha01), (hb00, hb01) 1/m^2: d^2 phi / da^2 and d^2 phi / db^2,
        each symmetric with h11 = -h00). The Hessian is k J J^T + k dphi d^2 phi / dx^2;
        its 2x2 node blocks are ``hinge_block``.
    """
    ia = 1.0 / (ax * ax + az * az)  # 1 / |a|^2 (one division per edge: a step does many)
    ib = 1.0 / (bx * bx + bz * bz)
    gax, gaz = az * ia, -ax * ia  # d phi / da = -d atan2(a) / da
    gbx, gbz = -bz * ib, bx * ib  # d phi / db
    dphi = math.atan2(ax * bz - az * bx, ax * bx + az * bz) - phi0
    y = dphi + math.pi  # dphi into [-pi, pi)
    if 0.0 <= y < 2 * math.pi:
        dphi = y - math.pi
    else:
        dphi = y % (2 * math.pi) - math.pi
    ia2 = ia * ia
    ib2 = ib * ib
    return (0.5 * k * dphi * dphi, k * dphi, -gax, -gaz, gax - gbx, gaz - gbz, gbx, gbz,
            -2.0 * ax * az * ia2, (ax * ax - az * az) * ia2,
            2.0 * bx * bz * ib2, (bz * bz - bx * bx) * ib2)


@njit(cache=True, inline='always')
def hinge_block(k, kd, jr0, jr1, jc0, jc1, h00, h01):
    """A 2x2 node block (b00, b01, b10, b11) N/m of a hinge's Hessian (``hinge``): rows of
    a node with Jacobian (jr0, jr1), columns of a node with (jc0, jc1), and that block of
    d^2 phi / dx^2 (h00, h01; h11 = -h00): with nodes p, i, n it is ha at (p, p), -ha at
    (p, i), ha + hb at (i, i), -hb at (i, n), hb at (n, n) and 0 at (p, n)."""
    return (k * (jr0 * jc0) + kd * h00, k * (jr0 * jc1) + kd * h01,
            k * (jr1 * jc0) + kd * h01, k * (jr1 * jc1) - kd * h00)


@njit(cache=True, inline='always')
def _add_block(data, sc, m, r, c, b00, b01, b10, b11):
    """Adds the node block (r, c) (b00, b01, b10, b11) of an element matrix with m dofs at
    its scatter positions sc (m^2,), and for r != c its transpose at (c, r)."""
    data[uint64(sc[m * (2 * r) + 2 * c])] += b00
    data[uint64(sc[m * (2 * r) + 2 * c + 1])] += b01
    data[uint64(sc[m * (2 * r + 1) + 2 * c])] += b10
    data[uint64(sc[m * (2 * r + 1) + 2 * c + 1])] += b11
    if r != c:
        data[uint64(sc[m * (2 * c) + 2 * r])] += b00
        data[uint64(sc[m * (2 * c) + 2 * r + 1])] += b10
        data[uint64(sc[m * (2 * c + 1) + 2 * r])] += b01
        data[uint64(sc[m * (2 * c + 1) + 2 * r + 1])] += b11


@njit(cache=True)
def bending(x, triples, phi0, k, grad, data, scatter, hessian):
    """Turning-angle bending E = k (phi - phi0)^2 / 2 per triple (``RodBending``,
    ``hinge``).

    Args:
        x: (n, 2) m.  triples: (n_t, 3) previous, middle, next node.  phi0: (n_t,) rad.
        k: (n_t,) EI / l (N m).  grad, data: added to.  scatter: (n_t, 36).

    Returns:
        Energy (J).
    """
    value = 0.0
    for t in range(triples.shape[0]):
        p, i, n = triples[t, 0], triples[t, 1], triples[t, 2]
        kt = k[t]
        v, kd, j0, j1, j2, j3, j4, j5, ha00, ha01, hb00, hb01 = hinge(
            x[i, 0] - x[p, 0], x[i, 1] - x[p, 1], x[n, 0] - x[i, 0], x[n, 1] - x[i, 1],
            phi0[t], kt)
        value += v
        grad[2 * p] += kd * j0
        grad[2 * p + 1] += kd * j1
        grad[2 * i] += kd * j2
        grad[2 * i + 1] += kd * j3
        grad[2 * n] += kd * j4
        grad[2 * n + 1] += kd * j5
        if not hessian:
            continue
        sc = scatter[t]
        # the pairs' blocks of d^2 phi / dx^2 (see hinge_block): ha at (p, p), ha + hb
        # at (i, i), hb at (n, n), -ha at (i, p), -hb at (n, i), 0 at (n, p)
        b00, b01, b10, b11 = hinge_block(kt, kd, j0, j1, j0, j1, ha00, ha01)
        _add_block(data, sc, 6, 0, 0, b00, b01, b10, b11)
        b00, b01, b10, b11 = hinge_block(kt, kd, j2, j3, j2, j3, ha00 + hb00, ha01 + hb01)
        _add_block(data, sc, 6, 1, 1, b00, b01, b10, b11)
        b00, b01, b10, b11 = hinge_block(kt, kd, j4, j5, j4, j5, 0.0 + hb00, 0.0 + hb01)
        _add_block(data, sc, 6, 2, 2, b00, b01, b10, b11)
        b00, b01, b10, b11 = hinge_block(kt, kd, j2, j3, j0, j1, -ha00, -ha01)
        _add_block(data, sc, 6, 1, 0, b00, b01, b10, b11)
        b00, b01, b10, b11 = hinge_block(kt, kd, j4, j5, j2, j3, -hb00, -hb01)
        _add_block(data, sc, 6, 2, 1, b00, b01, b10, b11)
        b00, b01, b10, b11 = hinge_block(kt, kd, j4, j5, j0, j1, 0.0, 0.0)
        _add_block(data, sc, 6, 2, 0, b00, b01, b10, b11)
    return value


@njit(cache=True)
def area_and_gradient(x, ring, ga):
    """Signed area (m^2) of the polygon x[ring]; dA/dx (m) written into ga (2 n,)."""
    ga[:] = 0.0
    area = 0.0
    m = ring.shape[0]
    for r in range(m):
        i = ring[r]
        nxt = ring[(r + 1) % m]
        prv = ring[(r - 1) % m]
        area += x[i, 0] * x[nxt, 1] - x[nxt, 0] * x[i, 1]
        ga[2 * i] += 0.5 * (x[nxt, 1] - x[prv, 1])
        ga[2 * i + 1] += 0.5 * (x[prv, 0] - x[nxt, 0])
    return 0.5 * area


@njit(cache=True, inline='always')
def area_pressure(area, a0, b, p0, kb):
    """The enclosed-area pressure law (``EnclosedAreaPressure``) at area A (m^2), rest
    area A0, depth b m, turgor p0 Pa, bulk modulus K Pa: (energy J, dE/dA N/m, the
    rank-one coefficient c = b K / A0 N/m^3 (0 without K))."""
    da = area - a0
    value = b * (-p0 * da + 0.5 * kb * da ** 2 / a0)
    de_da = b * (-p0 + kb * da / a0)
    return value, de_da, (b * kb / a0 if kb > 0 else 0.0)


@njit(cache=True)
def area_pressure_hessian(de_da, data, scatter):
    """The sparse part dE/dA d2A/dx2 of the pressure Hessian, added into data; each ring
    edge (i, next) an element with dofs [x_i, z_i, x_next, z_next] and scatter (n, 16):
    d2A/(dx_i dz_next) = 1/2, d2A/(dz_i dx_next) = -1/2, and their transposes."""
    h = 0.5 * de_da
    for e in range(scatter.shape[0]):
        sc = scatter[e]
        data[uint64(sc[0 * 4 + 3])] += h
        data[uint64(sc[3 * 4 + 0])] += h
        data[uint64(sc[1 * 4 + 2])] -= h
        data[uint64(sc[2 * 4 + 1])] -= h


@njit(cache=True)
def enclosed_area_pressure(x, ring, a0, b, p0, kb, grad, ga, data, scatter, hessian):
    """The enclosed-area pressure (``EnclosedAreaPressure``) in one call:
    ``area_and_gradient`` into ``ga`` (2 n,) m, ``area_pressure``, the gradient
    dE/dA ga (N) added into ``grad`` and, with ``hessian``, ``area_pressure_hessian``
    into ``data``. Returns (energy J, the rank-one coefficient c N/m^3)."""
    area = area_and_gradient(x, ring, ga)
    value, de_da, c = area_pressure(area, a0, b, p0, kb)
    for m in range(grad.shape[0]):
        grad[m] += de_da * ga[m]
    if hessian:
        area_pressure_hessian(de_da, data, scatter)
    return value, c


@njit(cache=True)
def _deformation_gradient(x, tri, dm_inv, t):
    """F (f00, f01, f10, f11) of triangle t: its edge matrix times dm_inv[t]."""
    i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
    a = dm_inv[t]
    d00 = x[i1, 0] - x[i0, 0]
    d01 = x[i2, 0] - x[i0, 0]
    d10 = x[i1, 1] - x[i0, 1]
    d11 = x[i2, 1] - x[i0, 1]
    return (d00 * a[0, 0] + d01 * a[1, 0], d00 * a[0, 1] + d01 * a[1, 1],
            d10 * a[0, 0] + d11 * a[1, 0], d10 * a[0, 1] + d11 * a[1, 1])


@njit(cache=True, inline='always')
def _neohookean_block(data, sc, k, m, cg, c2, c3, gkx, gkz, hkx, hkz, glx, glz, hlx, hlz):
    """Adds the node block (k, m) of a triangle's Hessian (``neohookean_triangles``) at
    its scatter positions sc (36,), and for m != k its transpose at (m, k): with
    dP_ij/dF_mn = mu d_im d_jn + (mu - lam lnJ) Finv_ni Finv_jm + lam Finv_ji Finv_nm
    the block (k, i), (l, n) is V (mu d_in g_k.g_l + (mu - lam lnJ) h_k[n] h_l[i]
    + lam h_k[i] h_l[n]); cg = V mu, c2 = V (mu - lam lnJ), c3 = V lam."""
    gg = cg * (gkx * glx + gkz * glz)
    kxx = gg + c2 * hkx * hlx + c3 * hkx * hlx
    kxz = c2 * hkz * hlx + c3 * hkx * hlz
    kzx = c2 * hkx * hlz + c3 * hkz * hlx
    kzz = gg + c2 * hkz * hlz + c3 * hkz * hlz
    _add_block(data, sc, 6, k, m, kxx, kxz, kzx, kzz)


@njit(cache=True)
def neohookean_triangles(x, tri, dm_inv, volume, mu, lam, grad, data, scatter, hessian):
    """Plane-strain neo-Hookean linear triangles (``NeoHookeanTriangles``).

    Args:
        x: (n, 2) m.  tri: (n_tri, 3).  dm_inv: (n_tri, 2, 2) 1/m, inverse rest edge
        matrices.  volume: (n_tri,) m^3.  mu, lam: Lame parameters (Pa).
        grad, data: added to.  scatter: (n_tri, 36).

    Returns:
        Energy (J); inf, nothing added, if an element is inverted (J <= 0).
    """
    n_tri = tri.shape[0]
    for t in range(n_tri):
        f00, f01, f10, f11 = _deformation_gradient(x, tri, dm_inv, t)
        if f00 * f11 - f01 * f10 <= 0.0:
            return np.inf
    value = 0.0
    for t in range(n_tri):
        i0, i1, i2 = tri[t, 0], tri[t, 1], tri[t, 2]
        a = dm_inv[t]
        # shape-function gradients g_k (1/m): dF_ij / dx_(k, i) = g_k[j]
        g1x, g1z = a[0, 0], a[0, 1]
        g2x, g2z = a[1, 0], a[1, 1]
        g0x, g0z = -(g1x + g2x), -(g1z + g2z)
        f00, f01, f10, f11 = _deformation_gradient(x, tri, dm_inv, t)
        jdet = f00 * f11 - f01 * f10
        lnj = math.log(jdet)
        vol = volume[t]
        value += vol * (0.5 * mu * (f00 * f00 + f01 * f01 + f10 * f10 + f11 * f11 - 2.0)
                        - mu * lnj + 0.5 * lam * lnj * lnj)
        v00, v01 = f11 / jdet, -f01 / jdet  # F^-1
        v10, v11 = -f10 / jdet, f00 / jdet
        # h_k = F^-T g_k: h_k[i] = sum_j g_k[j] F^-1[j, i]
        h0x, h0z = g0x * v00 + g0z * v10, g0x * v01 + g0z * v11
        h1x, h1z = g1x * v00 + g1z * v10, g1x * v01 + g1z * v11
        h2x, h2z = g2x * v00 + g2z * v10, g2x * v01 + g2z * v11
        # dE/dx_(k, i) = V (mu F g_k + (lam lnJ - mu) h_k)[i]  (P = mu (F - F^-T)
        # + lam lnJ F^-T, Bonet & Wood eq. 6.28)
        cg = vol * mu
        ch = vol * (lam * lnj - mu)
        grad[2 * i0] += cg * (f00 * g0x + f01 * g0z) + ch * h0x
        grad[2 * i0 + 1] += cg * (f10 * g0x + f11 * g0z) + ch * h0z
        grad[2 * i1] += cg * (f00 * g1x + f01 * g1z) + ch * h1x
        grad[2 * i1 + 1] += cg * (f10 * g1x + f11 * g1z) + ch * h1z
        grad[2 * i2] += cg * (f00 * g2x + f01 * g2z) + ch * h2x
        grad[2 * i2 + 1] += cg * (f10 * g2x + f11 * g2z) + ch * h2z
        if not hessian:
            continue
        # the element Hessian's six node blocks (k <= l), written out
        c2 = vol * (mu - lam * lnj)
        c3 = vol * lam
        sc = scatter[t]
        _neohookean_block(data, sc, 0, 0, cg, c2, c3, g0x, g0z, h0x, h0z, g0x, g0z, h0x, h0z)
        _neohookean_block(data, sc, 1, 1, cg, c2, c3, g1x, g1z, h1x, h1z, g1x, g1z, h1x, h1z)
        _neohookean_block(data, sc, 2, 2, cg, c2, c3, g2x, g2z, h2x, h2z, g2x, g2z, h2x, h2z)
        _neohookean_block(data, sc, 0, 1, cg, c2, c3, g0x, g0z, h0x, h0z, g1x, g1z, h1x, h1z)
        _neohookean_block(data, sc, 0, 2, cg, c2, c3, g0x, g0z, h0x, h0z, g2x, g2z, h2x, h2z)
        _neohookean_block(data, sc, 1, 2, cg, c2, c3, g1x, g1z, h1x, h1z, g2x, g2z, h2x, h2z)
    return value


@njit(cache=True)
def neohookean_von_mises(x, tri, dm_inv, mu, lam, out):
    """(n_tri,) Pa written into out: ``NeoHookeanTriangles.von_mises``."""
    for t in range(tri.shape[0]):
        f00, f01, f10, f11 = _deformation_gradient(x, tri, dm_inv, t)
        j = f00 * f11 - f01 * f10
        lnj = math.log(max(j, 1e-12))
        bxx = f00 * f00 + f01 * f01
        bzz = f10 * f10 + f11 * f11
        bxz = f00 * f10 + f01 * f11
        sxx = (mu * (bxx - 1.0) + lam * lnj) / j
        szz = (mu * (bzz - 1.0) + lam * lnj) / j
        sxz = mu * bxz / j
        s33 = lam * lnj / j
        out[t] = math.sqrt(0.5 * ((sxx - szz) ** 2 + (szz - s33) ** 2 + (s33 - sxx) ** 2)
                           + 3.0 * sxz * sxz)
