"""Numpy reference of the 2D soft pad layer (``gripper_sim.core.pad``), for the tests only.

The simulation evaluates the pad with compiled functions (``pad_rows``, ``pad_point``) on
both routes; this is the same layer written again in numpy from the module docstring
(elastic foundation, lagged smoothed friction), face by face, for the tests to check the
compiled one against (equal to round-off).
"""
from __future__ import annotations

import numpy as np

from gripper_sim.core.energies.base import Evaluation
from gripper_sim.core.stepper import FRICTION_SMOOTHING


def f0(y, eps):
    return np.where(y < eps, -y ** 3 / (3 * eps ** 2) + y ** 2 / eps + eps / 3, y)


def f1(y, eps):
    return np.where(y < eps, 2 * y / eps - y ** 2 / eps ** 2, 1.0)


def df1(y, eps):
    return np.where(y < eps, 2 / eps - 2 * y / eps ** 2, 0.0)


class PadStep:
    """One step of a ``PadLayer``'s pads: the faces and the nodes that may touch them.

    Args:
        pad: the PadLayer (for its surface, k, thickness, mu).  x_n: (n, 2) m.
        old_faces, new_faces: as ``PadLayer.begin_step``.  dt: s.
    """

    def __init__(self, pad, x_n, old_faces, new_faces, dt):
        self.pad, self.x_n, self.dt = pad, np.asarray(x_n, dtype=float), dt
        self.faces = []  # (origin, normal, tangent, speed, side, index, active, lagged)
        xs = self.x_n[pad.surface]
        for (old, side, index), (new, _, _) in zip(old_faces, new_faces):
            old_origin = old.origin + pad.thickness * old.normal
            gap = (xs - old_origin) @ old.normal
            along = np.abs((xs - old_origin) @ old.tangent)
            near = ((along <= old.half_length) & (gap < pad.thickness)
                    & (gap > -pad.thickness - 1e-3))
            self.faces.append((new.origin + pad.thickness * new.normal, new.normal,
                               new.tangent, float(new.velocity @ new.tangent), side, index,
                               np.flatnonzero(near), pad.k[near] * np.maximum(0.0, -gap[near])))

    def _face(self, x, face):
        """(nodes, value J, gradient (k, 2) N, blocks (k, 2, 2) N/m, normal force (k,) N)."""
        origin, n, t, speed, _, _, active, lagged = face
        pad = self.pad
        eps = FRICTION_SMOOTHING * self.dt
        nodes = pad.surface[active]
        k = pad.k[active]
        gap = (x[nodes] - origin) @ n
        delta = np.maximum(0.0, -gap)
        u = ((x[nodes] - self.x_n[nodes]) @ t) - speed * self.dt
        a = np.abs(u)
        bound = pad.mu * lagged
        value = 0.5 * float(np.sum(k * delta ** 2)) + float(np.sum(bound * f0(a, eps)))
        local = (-k * delta)[:, None] * n + (bound * f1(a, eps) * np.sign(u))[:, None] * t
        h_n = np.where(delta > 0, k, 0.0)
        h_t = bound * df1(a, eps)
        blocks = (h_n[:, None, None] * np.outer(n, n)[None]
                  + h_t[:, None, None] * np.outer(t, t)[None])
        return nodes, value, local, blocks, k * delta

    def evaluate(self, q: np.ndarray) -> Evaluation:
        """Value J, gradient (2n,) N and Hessian triplets N/m at q (2n,) m."""
        x = q.reshape(-1, 2)
        grad = np.zeros(q.size)
        value, rows, cols, vals = 0.0, [], [], []
        for face in self.faces:
            nodes, v, local, blocks, _ = self._face(x, face)
            value += v
            np.add.at(grad, 2 * nodes, local[:, 0])
            np.add.at(grad, 2 * nodes + 1, local[:, 1])
            dofs = np.stack([2 * nodes, 2 * nodes + 1], axis=1)
            rows.append(np.repeat(dofs, 2, axis=1).ravel())
            cols.append(np.tile(dofs, (1, 2)).ravel())
            vals.append(blocks.ravel())
        return Evaluation(value, grad, np.concatenate(rows), np.concatenate(cols),
                          np.concatenate(vals))

    def forces(self, q: np.ndarray):
        """(forces (n, 2) N, normal forces (n,) N, holder (n,), side force (2,) N) the
        pads exert at q (2n,) m."""
        x = q.reshape(-1, 2)
        n = len(x)
        forces, normal = np.zeros((n, 2)), np.zeros(n)
        holder, best, side_force = -np.ones(n, np.int64), np.zeros(n), np.zeros(2)
        for face in self.faces:
            side, index = face[4], face[5]
            nodes, _, local, _, f_n = self._face(x, face)
            forces[nodes] -= local
            normal[nodes] += f_n
            side_force[side] -= (1.0 if side == 0 else -1.0) * float(np.sum(local[:, 0]))
            stronger = (f_n > 0) & (f_n > best[nodes])
            holder[nodes[stronger]] = index
            best[nodes[stronger]] = f_n[stronger]
        return forces, normal, holder, side_force
