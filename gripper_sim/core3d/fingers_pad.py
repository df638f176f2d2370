"""A soft pad on the 3D jaw faces: the 2D elastic-foundation layer per vertex area.

Same law as ``gripper_sim.core.pad`` (Winkler layer, Johnson 1985; friction as IPC's
lagged smoothed Coulomb potential, Li et al. 2020): a skin node i of rest vertex area
A_i (a third of each adjacent triangle) that indents the pad of thickness t by delta
feels the normal force k_i delta, k_i = K A_i / t, K the constrained modulus of the
pad. Its friction potential is mu lambda_i f0(|u_i|), u_i (2,) its tangential
displacement over the step relative to the pad (in the pad plane), lambda_i its normal
force at the start of the step, f0 as in 2D (isotropic in the tangent plane: a smoothed
Coulomb cone). The pad's free surface lies where the rigid face would be; the rigid
``Plate`` is t behind it and a node pushed through the whole pad meets it (hard contact).

The Hessian always has one 3x3 block per skin node (zero when the node touches no pad),
so its sparsity pattern does not change from step to step.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.energies.base import Evaluation
from gripper_sim.core.pad import PadState, _df1, _f0, _f1
from gripper_sim.core.stepper import FRICTION_SMOOTHING


@dataclass
class _PadFace:
    """One pad surface during a step: the rigid plate's geometry moved t forward."""

    origin: np.ndarray      # (3,) m
    normal: np.ndarray      # (3,)
    tangents: np.ndarray    # (2, 3)
    slide: np.ndarray       # (2,) m, the pad's tangential displacement over the step
    side: int
    index: int


class PadLayer3D(PadState):
    """The pads of both jaws as one energy of the fruit node positions (n_nodes * 3,).

    Args:
        surface: (n_s,) skin node indices.  areas: (n_s,) m^2, rest vertex areas.
        thickness: m.  youngs_modulus: Pa.  poisson_ratio: -, of the pad.
        friction: mu fruit-pad.  n_nodes: fruit nodes.
    """

    def __init__(self, surface, areas, thickness: float, youngs_modulus: float,
                 poisson_ratio: float, friction: float, n_nodes: int):
        super().__init__(surface, areas, thickness, youngs_modulus, poisson_ratio, friction,
                         n_nodes, dim=3)
        #: each surface node one element of the Hessian's pattern (its 3x3 node block)
        self.dofs = 3 * self.surface[:, None] + np.arange(3)[None, :]
        self._rows = np.repeat(self.dofs, 3, axis=1).ravel()
        self._cols = np.tile(self.dofs, (1, 3)).ravel()

    def begin_step(self, x_n: np.ndarray, old_faces, new_faces, dt: float) -> None:
        """Set the pad surfaces for a step from ``x_n`` (n_nodes, 3) over ``dt`` (s).

        Args:
            old_faces, new_faces: lists of (Plate of the rigid jaw face behind the pad,
                jaw side, obstacle index) at the start and the end of the step.
        """
        self.x_start = np.array(x_n, dtype=float)
        self.dt = float(dt)
        self.faces, self.active, self.lagged = [], [], []
        xs = self.x_start[self.surface]
        for (old, side, index), (new, _, _) in zip(old_faces, new_faces):
            slide = dt * (new.tangents @ new.velocity)
            self.faces.append(_PadFace(new.origin + self.thickness * new.normal, new.normal,
                                       new.tangents, slide, side, index))
            old_origin = old.origin + self.thickness * old.normal
            rel = xs - old_origin
            gap = rel @ old.normal
            along = np.abs(rel @ old.tangents.T)
            near = (np.all(along <= old.half_extents, axis=1) & (gap < self.thickness)
                    & (gap > -self.thickness - 1e-3))
            self.active.append(np.flatnonzero(near))
            self.lagged.append(self.k[near] * np.maximum(0.0, -gap[near]))

    def _terms(self, x, face, active, lagged):
        """Per active node: indentation delta, tangential slip u (k, 2), friction bound."""
        nodes = self.surface[active]
        delta = np.maximum(0.0, -(x[nodes] - face.origin) @ face.normal)
        u = (x[nodes] - self.x_start[nodes]) @ face.tangents.T - face.slide
        return nodes, delta, u, self.mu * lagged

    def finish_step(self, q: np.ndarray) -> None:
        """Record the pad forces on the fruit at the step's end positions ``q``."""
        x = q.reshape(-1, 3)
        self._clear_forces()
        eps = FRICTION_SMOOTHING * self.dt
        for face, active, lagged in zip(self.faces, self.active, self.lagged):
            if not active.size:
                continue
            nodes, delta, u, bound = self._terms(x, face, active, lagged)
            f_n = self.k[active] * delta
            a = np.linalg.norm(u, axis=1)
            with np.errstate(divide='ignore', invalid='ignore'):
                direction = np.where(a[:, None] > 0, u / a[:, None], 0.0)
            f_t = -(bound * _f1(a, eps))[:, None] * direction
            self._record(face, nodes, f_n[:, None] * face.normal + f_t @ face.tangents, f_n)

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        x = q.reshape(-1, 3)
        value = 0.0
        grad = np.zeros(q.size)
        blocks = np.zeros((self.n_nodes, 3, 3)) if hessian else None
        eps = FRICTION_SMOOTHING * self.dt
        for face, active, lagged in zip(self.faces, self.active, self.lagged):
            if not active.size:
                continue
            nodes, delta, u, bound = self._terms(x, face, active, lagged)
            k = self.k[active]
            a = np.linalg.norm(u, axis=1)
            value += 0.5 * float(np.sum(k * delta ** 2)) + float(np.sum(bound * _f0(a, eps)))
            f1 = _f1(a, eps)
            with np.errstate(divide='ignore', invalid='ignore'):
                over_a = np.where(a > 0, f1 / a, 2.0 / eps)  # f1(a)/a -> 2/eps as a -> 0
            g_t = (bound * over_a)[:, None] * u  # d/du of bound f0(|u|)
            local = (-k * delta)[:, None] * face.normal + g_t @ face.tangents
            np.add.at(grad.reshape(-1, 3), nodes, local)
            if hessian:
                n, t = face.normal, face.tangents
                with np.errstate(divide='ignore', invalid='ignore'):
                    uhat = np.where(a[:, None] > 0, u / a[:, None], 0.0)
                radial = np.where(a > 0, _df1(a, eps), 2.0 / eps)
                # d2/du2 of f0(|u|): f1' u^ u^T + f1/|u| (I - u^ u^T)
                h_u = (bound[:, None, None]
                       * (radial[:, None, None] * np.einsum('ki,kj->kij', uhat, uhat)
                          + over_a[:, None, None]
                          * (np.eye(2)[None] - np.einsum('ki,kj->kij', uhat, uhat))))
                block = (np.where(delta > 0, k, 0.0)[:, None, None] * np.outer(n, n)[None]
                         + np.einsum('ai,kab,bj->kij', t, h_u, t))
                np.add.at(blocks, nodes, block)
        if not hessian:
            empty = np.zeros(0, np.int64)
            return Evaluation(value, grad, empty, empty, np.zeros(0))
        return Evaluation(value, grad, self._rows, self._cols,
                          blocks[self.surface].ravel())

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """``evaluate`` for the fast solver: adds the gradient (N) into ``grad`` and the
        node blocks (N/m) into the CSC values ``data`` at ``scatter`` (n_s, 9), one element
        per surface node; returns (value in J, no low-rank terms)."""
        ev = self.evaluate(q, hessian)
        grad += ev.gradient
        if hessian:
            data[scatter.ravel()] += ev.vals  # distinct positions: one block per node
        return ev.value, []
