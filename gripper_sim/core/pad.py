"""A soft pad on the jaw faces: a thin elastic layer between the fruit and the rigid jaw.

The pad (``gripper.finger.pad.*``: thickness t, Young modulus E_p, Poisson ratio nu_p)
lies on every facet of the jaw face; its free surface is where the rigid face would be
(``gap`` is still measured between the free surfaces) and the rigid jaw is t behind it.
It is modelled as an elastic foundation (Winkler layer; Johnson, Contact Mechanics,
1985, "the elastic foundation model"): a point of the fruit's surface that indents the
pad by delta feels the pressure

    p = K delta / t,   K = (1 - nu_p) E_p / ((1 + nu_p) (1 - 2 nu_p))

(K the constrained modulus of a thin layer bonded to a rigid base). For fruit node i
with tributary length l_i (rest) and the depth b this is the energy
``E = sum_i k_i delta_i^2 / 2`` with ``k_i = K l_i b / t``. Friction with the pad is a
smoothed Coulomb law with one coefficient mu (``contact.pad.friction``) and the normal
force lagged from the start of the step, as in IPC (Li et al. 2020, "Incremental
Potential Contact", the lagged friction potential): ``D_i = mu lambda_i f0(|u_i|)``
with u_i the node's tangential displacement relative to the pad over the step,
f0'(y) = f1(y) = 2y/eps - y^2/eps^2 below eps = v_eps dt and 1 above (v_eps =
``stepper.FRICTION_SMOOTHING``): static friction up to a creep of v_eps.

Both terms join the implicit step as one ``Energy`` whose faces are set before each
sub-step (``begin_step``). A node that goes through the whole pad meets the rigid jaw
behind it, which the ordinary (hard) contact handles.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gripper_sim.core.energies.base import Energy, Evaluation, element_dofs
from gripper_sim.core.stepper import FRICTION_SMOOTHING


def foundation_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """K (Pa): constrained modulus of a thin bonded layer."""
    nu = poisson_ratio
    return (1 - nu) * youngs_modulus / ((1 + nu) * (1 - 2 * nu))


@dataclass
class _PadFace:
    """A pad surface during one step: origin (2,), normal (2,), tangent (2,), half
    length, tangential speed of the jaw (m/s), jaw side (0 left, 1 right), obstacle index."""

    origin: np.ndarray
    normal: np.ndarray
    tangent: np.ndarray
    half_length: float
    speed: float
    side: int
    index: int


class PadState(Energy):
    """What the 2D and 3D pads share: the foundation stiffness per surface node, the
    step's pad faces, and the forces the pads exerted at the end of the last step.

    Args:
        surface: (n_s,) surface node indices.  area: (n_s,) m^2, rest area each surface
        node presses the pad with.  thickness: m, pad thickness t.  youngs_modulus,
        poisson_ratio: of the pad.  friction: mu, pad-fruit.  n_nodes: fruit nodes.
        dim: 2 or 3.
    """

    elastic = False

    def __init__(self, surface, area, thickness: float, youngs_modulus: float,
                 poisson_ratio: float, friction: float, n_nodes: int, dim: int):
        self.surface = np.asarray(surface, dtype=np.int64)
        self.thickness = float(thickness)
        self.modulus = foundation_modulus(youngs_modulus, poisson_ratio)
        self.k = self.modulus * np.asarray(area, dtype=float) / self.thickness
        self.mu = float(friction)
        self.n_nodes = n_nodes
        self.dim = dim
        self.faces: list = []
        self.active: list[np.ndarray] = []
        self.lagged: list[np.ndarray] = []
        self.x_start = np.zeros((n_nodes, dim))
        self.dt = 1.0
        self._clear_forces()

    def _clear_forces(self) -> None:
        """Zero ``forces`` (n_nodes, dim) N, ``normal_forces`` (n_nodes,) N, ``holder``
        (n_nodes,) obstacle index pressing each node hardest (-1: none) and
        ``side_force`` (2,) N, each jaw's push along the closing axis."""
        self.forces = np.zeros((self.n_nodes, self.dim))
        self.normal_forces = np.zeros(self.n_nodes)
        self.holder = -np.ones(self.n_nodes, np.int64)
        self.side_force = np.zeros(2)
        self._best = np.zeros(self.n_nodes)

    def _record(self, face, nodes: np.ndarray, force: np.ndarray, f_n: np.ndarray) -> None:
        """Add one face's ``force`` (k, dim) N and normal force ``f_n`` (k,) N on
        ``nodes`` (k,) to the recorded pad forces."""
        self.forces[nodes] += force
        self.normal_forces[nodes] += f_n
        sign = 1.0 if face.side == 0 else -1.0
        self.side_force[face.side] += sign * float(np.sum(force[:, 0]))
        stronger = (f_n > 0) & (f_n > self._best[nodes])
        self.holder[nodes[stronger]] = face.index
        self._best[nodes[stronger]] = f_n[stronger]


class PadLayer(PadState):
    """The pads of both jaws as one energy of the fruit node positions.

    Args:
        surface: (n_s,) surface node indices (outline order).
        tributary: (n_s,) m, rest tributary length of each surface node.
        depth: m, out-of-plane depth b.
        thickness: m, pad thickness t.  youngs_modulus, poisson_ratio: of the pad.
        friction: mu, pad-fruit friction coefficient.
        n_nodes: number of fruit nodes.
    """

    def __init__(self, surface, tributary, depth: float, thickness: float,
                 youngs_modulus: float, poisson_ratio: float, friction: float, n_nodes: int):
        super().__init__(surface, np.asarray(tributary, dtype=float) * depth, thickness,
                         youngs_modulus, poisson_ratio, friction, n_nodes, dim=2)
        #: each surface node one element of the Hessian's pattern (its 2x2 node block)
        self.dofs = element_dofs(self.surface[:, None])

    # ------------------------------------------------------------------ per step
    def begin_step(self, x_n: np.ndarray, old_faces, new_faces, dt: float) -> None:
        """Set the pad surfaces for a step from ``x_n`` over ``dt``.

        Args:
            x_n: (n_nodes, 2) m, positions at the start of the step.
            old_faces, new_faces: lists of (FlatFace of the rigid jaw behind the pad, jaw
                side, obstacle index) at the start and end of the step.
        """
        self.x_start = np.array(x_n, dtype=float)
        self.dt = float(dt)
        self.faces, self.active, self.lagged = [], [], []
        xs = self.x_start[self.surface]
        for (old, side, index), (new, _, _) in zip(old_faces, new_faces):
            origin = new.origin + self.thickness * new.normal
            pad = _PadFace(origin, new.normal, new.tangent, new.half_length,
                           float(new.velocity @ new.tangent), side, index)
            old_origin = old.origin + self.thickness * old.normal
            gap = (xs - old_origin) @ old.normal
            along = np.abs((xs - old_origin) @ old.tangent)
            # nodes over the pad and not far in front of it can touch it during the step
            near = (along <= old.half_length) & (gap < self.thickness) & \
                (gap > -self.thickness - 1e-3)
            self.faces.append(pad)
            self.active.append(np.flatnonzero(near))
            self.lagged.append(self.k[near] * np.maximum(0.0, -gap[near]))

    def finish_step(self, q: np.ndarray) -> None:
        """Record the pad forces on the fruit at the step's end positions ``q``."""
        x = q.reshape(-1, 2)
        self._clear_forces()
        for face, active, lagged in zip(self.faces, self.active, self.lagged):
            if not active.size:
                continue
            nodes = self.surface[active]
            f_n, f_t = self._node_forces(x[nodes], face, active, lagged)
            self._record(face, nodes, f_n[:, None] * face.normal + f_t[:, None] * face.tangent,
                         f_n)

    def _node_forces(self, x, face, active, lagged):
        """Normal (penalty) and tangential (friction) force on the nodes, N."""
        gap = (x - face.origin) @ face.normal
        f_n = self.k[active] * np.maximum(0.0, -gap)
        u = ((x - self.x_start[self.surface[active]]) @ face.tangent) - face.speed * self.dt
        f_t = -self.mu * lagged * _f1(np.abs(u), FRICTION_SMOOTHING * self.dt) * np.sign(u)
        return f_n, f_t

    # ------------------------------------------------------------------ energy
    def _face_terms(self, x: np.ndarray, face, active: np.ndarray, lagged: np.ndarray,
                    hessian: bool):
        """One pad face's energy (J), its gradient (k, 2) N on the active surface nodes and
        their Hessian blocks (k, 2, 2) N/m (None without ``hessian``)."""
        eps = FRICTION_SMOOTHING * self.dt
        nodes = self.surface[active]
        k = self.k[active]
        gap = (x[nodes] - face.origin) @ face.normal
        delta = np.maximum(0.0, -gap)
        u = ((x[nodes] - self.x_start[nodes]) @ face.tangent) - face.speed * self.dt
        a = np.abs(u)
        bound = self.mu * lagged
        value = 0.5 * float(np.sum(k * delta ** 2)) + float(np.sum(bound * _f0(a, eps)))
        g_n = -k * delta  # d E / d gap, along the normal
        g_t = bound * _f1(a, eps) * np.sign(u)
        local = g_n[:, None] * face.normal + g_t[:, None] * face.tangent
        if not hessian:
            return value, local, None
        h_n = np.where(delta > 0, k, 0.0)
        h_t = bound * _df1(a, eps)
        n, t = face.normal, face.tangent
        blocks = (h_n[:, None, None] * np.outer(n, n)[None]
                  + h_t[:, None, None] * np.outer(t, t)[None])
        return value, local, blocks

    def _accumulate(self, q: np.ndarray, grad: np.ndarray, hessian: bool):
        """Adds every face's gradient (N) into ``grad`` (2 n,); returns (value in J,
        [(active surface indices (k,), Hessian blocks (k, 2, 2) N/m)] if ``hessian``)."""
        x = q.reshape(-1, 2)
        value = 0.0
        parts = []
        for face, active, lagged in zip(self.faces, self.active, self.lagged):
            if not active.size:
                continue
            nodes = self.surface[active]
            face_value, local, blocks = self._face_terms(x, face, active, lagged, hessian)
            value += face_value
            np.add.at(grad, 2 * nodes, local[:, 0])
            np.add.at(grad, 2 * nodes + 1, local[:, 1])
            if hessian:
                parts.append((active, blocks))
        return value, parts

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        grad = np.zeros(q.size)
        value, parts = self._accumulate(q, grad, hessian)
        if not parts:
            empty = np.zeros(0, np.int64)
            return Evaluation(value, grad, empty, empty, np.zeros(0))
        dofs = [self.dofs[active] for active, _ in parts]
        return Evaluation(value, grad,
                          np.concatenate([np.repeat(d, 2, axis=1).ravel() for d in dofs]),
                          np.concatenate([np.tile(d, (1, 2)).ravel() for d in dofs]),
                          np.concatenate([blocks.ravel() for _, blocks in parts]))

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """``evaluate`` for the fast solver: adds the gradient (N) into ``grad`` and the
        node blocks (N/m) into the CSC values ``data`` at ``scatter`` (n_s, 4), one
        element per surface node; returns (value in J, no low-rank terms)."""
        value, parts = self._accumulate(q, grad, hessian)
        for active, blocks in parts:
            np.add.at(data, scatter[active], blocks.reshape(-1, 4))
        return value, []


def _f0(y, eps):
    """IPC's f0: y^3/(3 eps^2) ... integral of f1, C1 at eps (m)."""
    return np.where(y < eps, -y ** 3 / (3 * eps ** 2) + y ** 2 / eps + eps / 3, y)


def _f1(y, eps):
    return np.where(y < eps, 2 * y / eps - y ** 2 / eps ** 2, 1.0)


def _df1(y, eps):
    return np.where(y < eps, 2 / eps - 2 * y / eps ** 2, 0.0)
