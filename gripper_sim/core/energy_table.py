"""The 2D elastic energies of a Newton solver's potential summed in one compiled call.

``PatternCachingSolver.evaluate_fast`` (``core.fast_solver``) sums the inertia and the
energies in their list's order. The leading energies whose kernels take fixed arrays
(``Energy.kernel_data``: the rods' stretching and bending, the enclosed-area pressure,
the neo-Hookean triangles of a solid fruit or pad, the constant forces such as gravity)
are summed here in one call with the inertia, in the same order and by the same kernels
(``core.energies.kernels``), so the sums are the same to the last bit; the energies
after them (the contact barrier, the 3D energies) follow in Python, one call each. The
Fin Ray grasp has its first six energies here (the apple's four, the fingers' stretching
and bending), the solid apple all four of its own (skin stretching and bending, flesh,
gravity), leaving only the barrier, if any, to its own call.

The table is one numba typed list of equally typed items (a list is passed to a kernel
as one object, ~1 us, where a tuple of arrays costs each array's unboxing), each item
(index (k, m) int64, reals a (p,), reals b (r,), scatter (n_elem, m^2) int64):
- stretching: (edges, rest lengths L m, EA / L N/m, scatter);
- bending: (triples, phi0 rad, EI / l N m, scatter);
- pressure: (ring (n, 1), [A0 m^2, depth b m, p0 Pa, K Pa], -, scatter);
- neo-Hookean triangles: (triangles, [mu Pa, lambda Pa], the rest volumes (n_tri,) m^3
  then dm^-1 (n_tri, 2, 2) 1/m flattened, scatter);
- constant force: (-, the gradient -f (n_dof,) N (the energy's own array, so a load
  changed in place is seen), -, -).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit, typeof
from numba.typed import List

from gripper_sim.core.energies import kernels as energy_kernels
from gripper_sim.core.solver_kernels import inertia_and_mass_damping

#: the kinds of ``Energy.kernel_data`` and their codes in ``EnergyTable.order``
STRETCHING, BENDING, PRESSURE, CONSTANT, NEOHOOKEAN = range(5)
KINDS = {'stretching': STRETCHING, 'bending': BENDING, 'pressure': PRESSURE,
         'constant': CONSTANT, 'neohookean': NEOHOOKEAN}

_NO_INDEX, _NO_REALS = np.zeros((0, 0), np.int64), np.zeros(0)


class EnergyTable:
    """The leading energies of a solver's list that one kernel call sums (see the
    module): those with ``kernel_data``, in 2D; none in 3D.

    Args:
        energies: the solver's energies.  scatters: their scatter indices (n_elem, m^2)
            int64 into the solver's CSC values.  dim: 2 or 3.

    Attributes:
        count: how many of the list's first energies are tabled (0: none).
        order: (count,) int64, each tabled energy's kind.
        items: the typed list of their arrays.
        pressures: how many of them are pressures (each with a rank-one Hessian term,
            kept when its coefficient b K / A0 is not 0, i.e. K > 0).
    """

    def __init__(self, energies: list, scatters: list, dim: int, n_dof: int):
        self.items = List.empty_list(typeof((_NO_INDEX, _NO_REALS, _NO_REALS, _NO_INDEX)))
        order = []
        for energy, scatter in zip(energies, scatters):
            entry = energy.kernel_data() if dim == 2 else None
            if entry is None:
                break
            kind = KINDS[entry[0]]
            order.append(kind)
            self.items.append(_item(kind, entry[1], scatter))
        self.count = len(order)
        self.order = np.array(order, np.int64)
        self.pressures = order.count(PRESSURE)
        #: work arrays of ``potential``: dq (n_dof,) m, the pressures' coefficients and
        #: their dA/dq (n_pressure, n_dof) of the last evaluation with the Hessian (the
        #: rank-one terms it returns) and of one without
        self._dq = np.empty(n_dof)
        self._coefs = np.empty(self.pressures)
        self._vectors = np.empty((self.pressures, n_dof))
        self._scratch_vectors = np.empty((self.pressures, n_dof))

    def potential(self, q, q_n, v_n, dt, masses, alpha, hessian: bool, grad, data):
        """Inertia, mass damping and the tabled energies at ``q`` (n_dof,) m
        (``inertia_and_energies``), the gradient (n_dof,) N written into ``grad`` and,
        with ``hessian``, the Hessians into the CSC values ``data`` (N/m; zeroed first):
        (Phi so far J, inf if infeasible; dq = q - q_n (n_dof,) m; the pressures'
        rank-one terms [(c, dA/dq)] with ``hessian``, else []). dq and the rank-one
        vectors are this table's arrays, valid until its next call (the vectors: its
        next call with the Hessian)."""
        vectors = self._vectors if hessian else self._scratch_vectors
        phi = inertia_and_energies(q, q_n, v_n, dt, masses, alpha, self._dq, grad, hessian,
                                   data, self.order, self.items, self._coefs, vectors)
        if not (hessian and self.pressures):
            return phi, self._dq, []
        coefs = self._coefs
        return phi, self._dq, [(float(coefs[p]), vectors[p]) for p in range(self.pressures)
                               if coefs[p] != 0.0]


    def kernel_arrays(self) -> tuple:
        """The arrays ``inertia_and_energies`` takes from the table, for a compiled caller:
        (order, items, the pressures' coefficients (n_pressure,), their dA/dq of an
        evaluation with the Hessian and of one without (n_pressure, n_dof), dq (n_dof,))."""
        return (self.order, self.items, self._coefs, self._vectors, self._scratch_vectors,
                self._dq)


def _item(kind: int, arrays: tuple, scatter: np.ndarray) -> tuple:
    """The table's item of an energy's ``kernel_data`` arrays (see the module)."""
    scatter = np.ascontiguousarray(scatter, dtype=np.int64)
    if kind == CONSTANT:
        return _NO_INDEX, np.ascontiguousarray(arrays[0], dtype=float), _NO_REALS, _NO_INDEX
    if kind == PRESSURE:
        ring, params = arrays
        return (np.ascontiguousarray(ring, dtype=np.int64).reshape(-1, 1),
                np.ascontiguousarray(params, dtype=float), _NO_REALS, scatter)
    index, a, b = arrays
    return (np.ascontiguousarray(index, dtype=np.int64), np.ascontiguousarray(a, dtype=float),
            np.ascontiguousarray(b, dtype=float), scatter)


@njit(cache=True)
def inertia_and_energies(q, q_n, v_n, dt, masses, alpha, dq, grad, hessian, data, order,
                         items, rank_one_coefs, rank_one_vectors):
    """Inertia and mass damping (``solver_kernels.inertia_and_mass_damping``) and then
    the tabled energies (``EnergyTable``) in their order.

    Args:
        q, q_n, v_n: (2 n,) m, m, m/s.  dt: s.  masses: (2 n,) kg.  alpha: 1/s.
        dq: (2 n,) m, q - q_n written.  grad: (2 n,) N, written.
        hessian: whether the Hessians are added into the CSC values ``data`` (N/m),
            zeroed first.
        order: (count,) the energies' kinds.  items: their arrays (the typed list).
        rank_one_coefs: (n_pressure,) N/m^3, each pressure's rank-one coefficient c,
            written.  rank_one_vectors: (n_pressure, 2 n) m, its dA/dq, written.

    Returns:
        Phi so far (J), or inf as soon as an energy is not finite (the rest not summed).
    """
    if hessian:
        data[:] = 0.0
    phi = inertia_and_mass_damping(q, q_n, v_n, dt, masses, alpha, dq, grad)
    pressure = 0
    for slot in range(order.shape[0]):
        kind = order[slot]
        index, a, b, scatter = items[slot]
        x = q.reshape(-1, 2)  # here, not before the loop: a 3D solver has no tabled energies
        if kind == STRETCHING:
            value = energy_kernels.stretching(x, index, a, b, grad, data, scatter, hessian)
        elif kind == BENDING:
            value = energy_kernels.bending(x, index, a, b, grad, data, scatter, hessian)
        elif kind == NEOHOOKEAN:
            n_tri = index.shape[0]
            value = energy_kernels.neohookean_triangles(
                x, index, b[n_tri:].reshape(n_tri, 2, 2), b[:n_tri], a[0], a[1], grad, data,
                scatter, hessian)
        elif kind == PRESSURE:
            value, c = energy_kernels.enclosed_area_pressure(
                x, index[:, 0], a[0], a[1], a[2], a[3], grad, rank_one_vectors[pressure],
                data, scatter, hessian)
            rank_one_coefs[pressure] = c
            pressure += 1
        else:
            for m in range(grad.shape[0]):
                grad[m] += a[m]
            value = np.dot(a, q)
        if not math.isfinite(value):
            return np.inf
        phi += value
    return phi
