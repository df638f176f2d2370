"""The 2D core's implicit Euler Newton stepper with a faster Hessian assembly for 3D.

``ImplicitEulerSolver`` turns the energies' IJV triplets into a sparse matrix on every
evaluation (a sort of ~10^5-10^6 triplets). The meshes of the 3D fruit do not change,
so neither do the triplets' positions: this subclass finds the CSC pattern once and then
sums each evaluation's values into it with one ``np.bincount``. Same incremental
potential, gradient and Hessian as the base class (up to round-off in the summation
order); the friction cone and everything else are inherited.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from gripper_sim.core.stepper import ImplicitEulerSolver, StepConstraints


class PatternCachingSolver(ImplicitEulerSolver):
    """``ImplicitEulerSolver`` whose energy Hessians keep one sparsity pattern."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._pattern = None  # (signature, inverse, indices, indptr, nnz)

    def _assemble(self, rows: list, cols: list, vals: list) -> sp.csc_matrix:
        signature = tuple(r.size for r in rows)
        if self._pattern is None or self._pattern[0] != signature:
            r = np.concatenate(rows)
            c = np.concatenate(cols)
            keys = c.astype(np.int64) * self.n + r
            unique, inverse = np.unique(keys, return_inverse=True)
            indices = (unique % self.n).astype(np.int32)
            indptr = np.searchsorted(unique // self.n, np.arange(self.n + 1)).astype(np.int32)
            self._pattern = (signature, inverse.ravel(), indices, indptr, unique.size)
        _, inverse, indices, indptr, nnz = self._pattern
        data = np.bincount(inverse, weights=np.concatenate(vals), minlength=nnz)
        return sp.csc_matrix((data, indices, indptr), shape=(self.n, self.n))

    def _evaluate(self, q, q_n, v_n, dt, con: StepConstraints, hessian: bool):
        inertia = q - q_n - dt * v_n
        phi = 0.5 * float(np.sum(self.m * inertia ** 2)) / dt ** 2
        grad = self.m * inertia / dt ** 2
        need = hessian or self.beta > 0
        rows, cols, vals, low_rank = [], [], [], []
        elastic_rows, elastic_cols, elastic_vals = [], [], []
        for energy in self.energies:
            ev = energy.evaluate(q, hessian=need)
            if not np.isfinite(ev.value):
                return np.inf, None, None, None
            phi += ev.value
            grad += ev.gradient
            if need and ev.rows.size:
                rows.append(ev.rows)
                cols.append(ev.cols)
                vals.append(ev.vals)
                if energy.elastic:
                    elastic_rows.append(ev.rows)
                    elastic_cols.append(ev.cols)
                    elastic_vals.append(ev.vals)
            if need:
                low_rank.extend(ev.low_rank)
        dq = q - q_n
        if self.alpha > 0:
            phi += 0.5 * self.alpha * float(np.sum(self.m * dq ** 2)) / dt
            grad += self.alpha * self.m * dq / dt
        stiffness = self._assemble(rows, cols, vals) if need and rows else None
        if self.beta > 0 and elastic_rows:
            damping = (stiffness if len(elastic_rows) == len(rows) else
                       sp.coo_matrix((np.concatenate(elastic_vals),
                                      (np.concatenate(elastic_rows),
                                       np.concatenate(elastic_cols))),
                                     shape=(self.n, self.n)).tocsc())
            cdq = damping @ dq
            phi += 0.5 * self.beta * float(dq @ cdq) / dt
            grad += self.beta * cdq / dt
        fric_grad = np.zeros(self.n)
        blocks = None
        k = con.friction_nodes
        if k.size:
            phi_f, blocks = self._cone_friction(q, q_n, dt, con, fric_grad)
            phi += phi_f
            grad += fric_grad
        if not hessian:
            return phi, grad, fric_grad, None
        diag = self.m / dt ** 2 + (self.alpha * self.m / dt if self.alpha > 0 else 0.0)
        hess = sp.diags(np.broadcast_to(diag, (self.n,)).astype(float), format='csc')
        if stiffness is not None:
            hess = hess + stiffness
            if self.beta > 0 and elastic_rows:
                hess = hess + (self.beta / dt) * damping
        if k.size:
            d = self.dim
            dofs = d * k[:, None] + np.arange(d)[None, :]
            hess = hess + sp.csc_matrix(
                (blocks.ravel(), (np.repeat(dofs, d, axis=1).ravel(),
                                  np.tile(dofs, (1, d)).ravel())), shape=(self.n, self.n))
        return phi, grad, fric_grad, (hess.tocsc(), low_rank)
