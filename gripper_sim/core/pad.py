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

import numpy as np
from numba import njit, vectorize

from gripper_sim.core.energies.base import Energy, Evaluation, element_dofs
from gripper_sim.core.stepper import FRICTION_SMOOTHING


def foundation_modulus(youngs_modulus: float, poisson_ratio: float) -> float:
    """K (Pa): constrained modulus of a thin bonded layer."""
    nu = poisson_ratio
    return (1 - nu) * youngs_modulus / ((1 + nu) * (1 - 2 * nu))


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

    Each outline node that may touch a pad face in a step is one row of a table
    (``pad_rows``); the force law of a row is ``pad_point``, the compiled function the
    compiled step (``kernels``) calls too.

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
        self._set_rows(np.zeros(0, np.int64), np.zeros((0, PAD_SIZE)), np.zeros(0, np.int64))

    def _set_rows(self, positions: np.ndarray, rows: np.ndarray, faces: np.ndarray) -> None:
        """The step's rows: outline positions (m,), rows (m, PAD_SIZE), obstacle index of
        each row's face (m,)."""
        self.positions, self.rows, self.row_face = positions, rows, faces
        self.nodes = self.surface[positions]

    def factor_key(self) -> tuple:
        """The step's rows (``Energy.factor_key``): (count, frozenset of their nodes)."""
        return len(self.nodes), frozenset(self.nodes.tolist())

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
        table = np.zeros((len(old_faces), PF_SIZE))
        for row, ((old, side, index), (new, _, _)) in zip(table, zip(old_faces, new_faces)):
            row[[PF_OLD_X, PF_OLD_Z]] = old.origin
            row[[PF_NEW_X, PF_NEW_Z]] = new.origin
            row[[PF_NX, PF_NZ]] = new.normal
            row[PF_HALF], row[PF_SPEED] = new.half_length, float(new.velocity @ new.tangent)
            row[PF_SIDE], row[PF_INDEX] = side, index
        self._set_rows(*pad_rows(self.x_start, self.surface, self.k, self.thickness, self.mu,
                                 table))

    def finish_step(self, q: np.ndarray) -> None:
        """Record the pad forces on the fruit at the step's end positions ``q``."""
        self._clear_forces()
        pad_forces(np.ascontiguousarray(q, dtype=float).reshape(-1, 2), self.x_start, self.dt,
                   self.nodes, self.rows, self.row_face, self.forces, self.normal_forces,
                   self.holder, self.side_force)

    # ------------------------------------------------------------------ energy
    def _terms(self, q: np.ndarray, grad: np.ndarray, hessian: bool):
        """Adds the gradient (N) into ``grad`` (2 n,); returns (value J, the rows' node
        blocks (m, 2, 2) N/m or None without ``hessian``)."""
        q = np.ascontiguousarray(q, dtype=float)
        q_n = self.x_start.reshape(-1)
        value = pad_terms(q, q_n, self.dt, self.nodes, self.rows, grad)
        if not hessian:
            return value, None
        blocks = np.empty((len(self.nodes), 2, 2))
        pad_blocks(q, q_n, self.dt, self.nodes, self.rows, blocks)
        return value, blocks

    def evaluate(self, q: np.ndarray, hessian: bool = True) -> Evaluation:
        grad = np.zeros(q.size)
        value, blocks = self._terms(q, grad, hessian)
        if blocks is None or not len(blocks):
            empty = np.zeros(0, np.int64)
            return Evaluation(value, grad, empty, empty, np.zeros(0))
        dofs = self.dofs[self.positions]
        return Evaluation(value, grad, np.repeat(dofs, 2, axis=1).ravel(),
                          np.tile(dofs, (1, 2)).ravel(), blocks.ravel())

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """``evaluate`` for the fast solver: adds the gradient (N) into ``grad`` and the
        node blocks (N/m) into the CSC values ``data`` at ``scatter`` (n_s, 4), one
        element per surface node; returns (value in J, no low-rank terms)."""
        value, blocks = self._terms(q, grad, hessian)
        if blocks is not None:
            np.add.at(data, scatter[self.positions], blocks.reshape(-1, 4))
        return value, []


# ---------------------------------------------------------------------- compiled, per point
@vectorize(['float64(float64, float64)'], cache=True)
def _f0(y, eps):
    """IPC's f0 (m): -y^3/(3 eps^2) + y^2/eps + eps/3 below eps, y above; the integral
    of f1, C1 at eps (m)."""
    return -y ** 3 / (3 * eps ** 2) + y ** 2 / eps + eps / 3 if y < eps else y


@vectorize(['float64(float64, float64)'], cache=True)
def _f1(y, eps):
    """IPC's f1 (-): 2y/eps - y^2/eps^2 below eps, 1 above."""
    return 2 * y / eps - y ** 2 / eps ** 2 if y < eps else 1.0


@vectorize(['float64(float64, float64)'], cache=True)
def _df1(y, eps):
    """f1' (1/m)."""
    return 2 / eps - 2 * y / eps ** 2 if y < eps else 0.0


#: columns of a pad row (one per outline node that may touch a pad face in the step, as
#: ``pad_rows`` sets them): stiffness k N/m, friction bound mu * lagged normal force N,
#: pad surface origin at the end of the step (x, z) m, its normal (x, z), the jaw's speed
#: along the face m/s, the jaw side (0 left, 1 right)
PAD_K, PAD_BOUND, PAD_OX, PAD_OZ, PAD_NX, PAD_NZ, PAD_SPEED, PAD_SIDE, PAD_SIZE = range(9)
#: columns of the face table of ``pad_rows`` (one per jaw face): the rigid face's origin
#: at the start and the end of the step (x, z) m, its normal, half length m, the jaw's
#: speed along it m/s, the jaw side, the face's obstacle index
(PF_OLD_X, PF_OLD_Z, PF_NEW_X, PF_NEW_Z, PF_NX, PF_NZ, PF_HALF, PF_SPEED, PF_SIDE, PF_INDEX,
 PF_SIZE) = range(11)


@njit(cache=True, error_model='numpy')
def pad_rows(x_n, surface, k, thickness, mu, faces):
    """The pad rows of a step: for each jaw face (the rigid face behind its pad), the
    outline nodes over the pad and not far in front of it at the start of the step, with
    their normal force there lagged into the friction bound.

    Args:
        x_n: (n, 2) m, positions at the start of the step.  surface: (n_s,) int64.
        k: (n_s,) N/m, foundation stiffness per outline node.  thickness: m.  mu: -.
        faces: (n_faces, PF_SIZE) the face table (PF_* columns).

    Returns:
        (outline positions (m,) int64, rows (m, PAD_SIZE), obstacle index per row (m,)).
    """
    n_s = surface.shape[0]
    positions = np.empty(faces.shape[0] * n_s, np.int64)
    rows = np.empty((faces.shape[0] * n_s, PAD_SIZE))
    index = np.empty(faces.shape[0] * n_s, np.int64)
    m = 0
    for f in range(faces.shape[0]):
        nx, nz = faces[f, PF_NX], faces[f, PF_NZ]
        tx, tz = -nz, nx
        old_x = faces[f, PF_OLD_X] + thickness * nx
        old_z = faces[f, PF_OLD_Z] + thickness * nz
        for s in range(n_s):
            i = surface[s]
            gap = (x_n[i, 0] - old_x) * nx + (x_n[i, 1] - old_z) * nz
            along = abs((x_n[i, 0] - old_x) * tx + (x_n[i, 1] - old_z) * tz)
            if not (along <= faces[f, PF_HALF] and gap < thickness
                    and gap > -thickness - 1e-3):
                continue
            positions[m] = s
            index[m] = np.int64(faces[f, PF_INDEX])
            rows[m, PAD_K] = k[s]
            rows[m, PAD_BOUND] = mu * (k[s] * max(0.0, -gap))
            rows[m, PAD_OX] = faces[f, PF_NEW_X] + thickness * nx
            rows[m, PAD_OZ] = faces[f, PF_NEW_Z] + thickness * nz
            rows[m, PAD_NX] = nx
            rows[m, PAD_NZ] = nz
            rows[m, PAD_SPEED] = faces[f, PF_SPEED]
            rows[m, PAD_SIDE] = faces[f, PF_SIDE]
            m += 1
    return positions[:m], rows[:m], index[:m]


@njit(cache=True, error_model='numpy', inline='always')
def pad_point(px, pz, px0, pz0, row, dt):
    """One pad point's force law (module docstring): the node at (px, pz) m that was at
    (px0, pz0) at the start of the step against the pad of ``row`` (PAD_* columns) over
    ``dt`` s.

    Returns:
        (energy J, gradient (gx, gz) N, normal stiffness h_n N/m (its Hessian is
        h_n n n^T + h_t t t^T), tangential stiffness h_t N/m, normal force f_n N).
    """
    eps = FRICTION_SMOOTHING * dt
    k, bound = row[PAD_K], row[PAD_BOUND]
    nx, nz = row[PAD_NX], row[PAD_NZ]
    tx, tz = -nz, nx
    gap = (px - row[PAD_OX]) * nx + (pz - row[PAD_OZ]) * nz
    delta = max(0.0, -gap)
    u = ((px - px0) * tx + (pz - pz0) * tz) - row[PAD_SPEED] * dt
    a = abs(u)
    value = 0.5 * k * delta ** 2 + bound * _f0(a, eps)
    g_n = -k * delta  # d E / d gap, along the normal
    g_t = bound * _f1(a, eps) * (1.0 if u > 0 else -1.0 if u < 0 else 0.0)
    h_n = k if gap < 0 else 0.0
    h_t = bound * _df1(a, eps)
    return value, g_n * nx + g_t * tx, g_n * nz + g_t * tz, h_n, h_t, k * delta


@njit(cache=True, error_model='numpy')
def pad_terms(q, q_n, dt, nodes, rows, grad):
    """The pads' energy (J) at q (2n,) m from q_n (2n,) m: adds its gradient (N) into
    ``grad`` (2n,).  nodes: (m,) the rows' nodes.  rows: (m, PAD_SIZE)."""
    value = 0.0
    for e in range(nodes.shape[0]):
        i = nodes[e]
        v, gx, gz, _h_n, _h_t, _f_n = pad_point(q[2 * i], q[2 * i + 1], q_n[2 * i],
                                                q_n[2 * i + 1], rows[e], dt)
        value += v
        grad[2 * i] += gx
        grad[2 * i + 1] += gz
    return value


@njit(cache=True, error_model='numpy')
def pad_blocks(q, q_n, dt, nodes, rows, blocks):
    """The rows' Hessian node blocks (m, 2, 2) N/m into ``blocks``."""
    for e in range(nodes.shape[0]):
        i = nodes[e]
        _v, _gx, _gz, h_n, h_t, _f_n = pad_point(q[2 * i], q[2 * i + 1], q_n[2 * i],
                                                 q_n[2 * i + 1], rows[e], dt)
        nx, nz = rows[e, PAD_NX], rows[e, PAD_NZ]
        tx, tz = -nz, nx
        blocks[e, 0, 0] = h_n * nx * nx + h_t * tx * tx
        blocks[e, 0, 1] = h_n * nx * nz + h_t * tx * tz
        blocks[e, 1, 0] = h_n * nz * nx + h_t * tz * tx
        blocks[e, 1, 1] = h_n * nz * nz + h_t * tz * tz


@njit(cache=True, error_model='numpy')
def pad_forces(x, x_n, dt, nodes, rows, row_face, forces, normal, holder, side_force):
    """The pads' forces on the fruit at the step's end positions x (n, 2) m from x_n
    (n, 2) m: forces (n, 2) N (minus the gradient), normal (n,) N, holder (n,) the face
    (``row_face`` (m,)) pressing each node hardest (-1: none), side_force (2,) N each
    jaw's pads' push along the closing axis; all zeroed first."""
    forces[:, :] = 0.0
    normal[:] = 0.0
    holder[:] = -1
    side_force[:] = 0.0
    best = np.zeros(x.shape[0])
    for e in range(nodes.shape[0]):
        i = nodes[e]
        _v, gx, gz, _h_n, _h_t, f_n = pad_point(x[i, 0], x[i, 1], x_n[i, 0], x_n[i, 1],
                                                rows[e], dt)
        forces[i, 0] -= gx
        forces[i, 1] -= gz
        normal[i] += f_n
        side = np.int64(rows[e, PAD_SIDE])
        side_force[side] += -gx if side == 0 else gx
        if f_n > 0 and f_n > best[i]:
            holder[i] = row_face[e]
            best[i] = f_n
