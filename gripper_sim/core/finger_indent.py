"""A finger pressed against a fixed rigid cylinder (2D: a disc), frictionless or with
Coulomb friction: the load case of published Fin Ray measurements (contact force against
the displacement of the finger's base towards a cylinder).

The finger's base is held (``finger_statics.static_equilibrium``); the disc, equivalently,
moves towards it by delta in increments (moving the base by delta towards a fixed disc is
the same relative motion: only the frame differs). The contact is the IPC barrier of the
project's finger contact (``barrier_kernels``: kappa b(s, dhat^2) / dhat^3 on the squared
gap s) between each node of the touching rods and the disc's exact circle, so the disc is
smooth: no facets (a polygon's corners would press dents into a thin strip and make the
force jump from facet to facet), and the gap of a node is the distance to the circle in
closed form. A straight element between two nodes outside the circle may dip into it by
at most l^2 / (8 R) (l the element length, R the radius: 1 mm elements on a 20 mm
cylinder, 6 um), below any figure reported here. The force on the disc is the sum of
its barrier forces (and, with friction, of its friction forces).

Friction (``DiscFriction``) is IPC's lagged friction in statics (Li et al. 2020,
"Incremental Potential Contact", ACM Trans. Graph. 39(4) 49, section 5, with the load
increment's slip in place of dt times the speed): before each increment, each touching
node's normal force lambda and the tangent of the circle at it are taken from the last
equilibrium, and the increment adds lambda mu f0(|s|) of the node's slip s along that
tangent relative to the disc (``friction_kernels.point_friction``; f0 smoothed below a
slip of ``slip_eps``: a node that slips less sticks, elastically).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gripper_sim.core.barrier import BarrierSettings
from gripper_sim.core.barrier_kernels import barrier_derivatives
from gripper_sim.core.energies.base import Energy, element_dofs
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.finger_statics import static_equilibrium
from gripper_sim.core.friction_kernels import point_friction

#: m, the slip over a load increment below which the disc's friction is smoothed (the
#: node sticks: IPC's eps_v times the step)
SLIP_EPS = 1e-6

#: a step may close at most this fraction of a node's gap to the disc (the line search's
#: first step, as a barrier's continuous-collision step)
GAP_CLOSING = 0.9


def _node_gradients(energy: Energy, q: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(k, 2) N, the gradient of ``energy`` (its ``evaluate_into``) at ``q`` (n_dof,) m
    on each of ``nodes``: the force each node exerts on the disc."""
    grad = np.zeros(q.size)
    energy.evaluate_into(q, grad, np.zeros(1), np.zeros((0, 0), np.int64), False)
    return grad.reshape(-1, 2)[nodes]


class DiscBarrier(Energy):
    """Frictionless contact of some nodes with a fixed rigid disc (2D).

    Args:
        nodes: (k,) the nodes that may touch it.
        n_nodes: nodes of the state (q holds 2 n_nodes coordinates: x, z).
        radius: m, the disc's radius plus the distance of the touching surface from the
            nodes (a rod's half thickness: its nodes are on its centre line).
        settings: the barrier's dhat (m) and stiffness kappa (N).

    Attributes:
        centre: (2,) m, the disc's centre (set it between solves).
    """

    elastic = False

    def __init__(self, nodes: np.ndarray, n_nodes: int, radius: float,
                 settings: BarrierSettings):
        self.nodes = np.asarray(nodes, dtype=np.int64)
        self.n_nodes = int(n_nodes)
        self.radius = float(radius)
        self.dhat = float(settings.dhat)
        self.kappa = float(settings.stiffness)
        self.centre = np.zeros(2)
        self.dofs = element_dofs(self.nodes[:, None])

    def relative(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((k, 2) m the nodes relative to the centre, (k,) m their distances from it)."""
        rel = q.reshape(-1, 2)[self.nodes] - self.centre
        return rel, np.hypot(rel[:, 0], rel[:, 1])

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """Adds the gradient (N) into ``grad`` and, with ``hessian``, each node's 2 x 2
        Hessian (N/m, its positive part: the normal stiffness; the tangential term,
        negative on a convex obstacle, is dropped) into ``data`` at ``scatter`` (k, 4);
        returns (value J, no rank-one terms); value inf for a node on or in the disc."""
        rel, dist = self.relative(q)
        gap = dist - self.radius
        if np.any(gap <= 0.0):
            return math.inf, []
        active = np.flatnonzero(gap < self.dhat)
        d = gap[active]
        s = d * d
        values, first, second = barrier_derivatives(s, self.dhat ** 2,
                                                    self.kappa / self.dhat ** 3)
        value = float(np.sum(values))
        normal = rel[active] / dist[active, None]
        slope = 2.0 * d * first                          # J/m, d(energy)/d(gap)
        np.add.at(grad, self.dofs[active], slope[:, None] * normal)
        if hessian:
            curvature = np.maximum(4.0 * s * second + 2.0 * first, 0.0)
            blocks = curvature[:, None, None] * normal[:, :, None] * normal[:, None, :]
            np.add.at(data, scatter[active], blocks.reshape(-1, 4))
        return value, []

    def max_step(self, q: np.ndarray, dq: np.ndarray) -> float:
        """The largest fraction of ``dq`` over which no node closes more than
        ``GAP_CLOSING`` of its gap to the disc (1: none approaches that far)."""
        rel, dist = self.relative(q)
        move = dq.reshape(-1, 2)[self.nodes]
        limit = self.radius + (1.0 - GAP_CLOSING) * (dist - self.radius)
        a = np.sum(move * move, axis=1)
        b = 2.0 * np.sum(rel * move, axis=1)
        c = dist * dist - limit * limit
        disc = b * b - 4.0 * a * c
        hits = (a > 0) & (b < 0) & (disc >= 0)
        if not np.any(hits):
            return 1.0
        t = (-b[hits] - np.sqrt(disc[hits])) / (2.0 * a[hits])
        return float(min(1.0, t.min()))

    def node_forces(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) N, the force each of ``nodes`` exerts on the disc (x, z): its barrier
        gradient (the node is pushed by minus it)."""
        return _node_gradients(self, q, self.nodes)

    def force(self, q: np.ndarray) -> np.ndarray:
        """(2,) N, the force the nodes exert on the disc (x, z)."""
        return self.node_forces(q).sum(axis=0)

    def push_out(self, x: np.ndarray) -> np.ndarray:
        """(n, 2) m: positions ``x`` with every touching node closer to the disc than
        dhat / 2 moved out along its normal to dhat / 2 from it (a feasible start for a
        solve after the disc moved)."""
        x = x.copy()
        rel, dist = self.relative(x.ravel())
        inside = dist - self.radius < 0.5 * self.dhat
        normal = rel[inside] / np.maximum(dist[inside], 1e-300)[:, None]
        x[self.nodes[inside]] = self.centre + normal * (self.radius + 0.5 * self.dhat)
        return x


class DiscFriction(Energy):
    """Coulomb friction between a ``DiscBarrier``'s nodes and its disc, lagged at the
    start of each load increment (module docstring).

    Args:
        disc: the contact whose nodes, normal forces and centre it follows.
        coefficient: mu, the friction coefficient (> 0).
        slip_eps: m, the slip below which friction is smoothed.
    """

    elastic = False

    def __init__(self, disc: DiscBarrier, coefficient: float, slip_eps: float = SLIP_EPS):
        self.disc = disc
        self.coefficient = float(coefficient)
        self.slip_eps = float(slip_eps)
        self.dofs = disc.dofs
        k = len(disc.nodes)
        self._forces = np.zeros(k)
        self._tangents = np.zeros((k, 2))
        self._start = np.zeros((k, 2))
        self._centre = np.zeros(2)

    def lag(self, q: np.ndarray) -> None:
        """Takes the normal forces, tangents and start positions from the equilibrium
        ``q`` (n_dof,) m, the disc where it is now (before it moves on)."""
        rel, dist = self.disc.relative(q)
        self._forces = np.hypot(*self.disc.node_forces(q).T)
        self._tangents = np.stack([-rel[:, 1], rel[:, 0]], axis=1) / dist[:, None]
        self._start = q.reshape(-1, 2)[self.disc.nodes].copy()
        self._centre = self.disc.centre.copy()

    def evaluate_into(self, q: np.ndarray, grad: np.ndarray, data: np.ndarray,
                      scatter: np.ndarray, hessian: bool = True):
        """Adds the gradient (N) into ``grad`` and, with ``hessian``, each node's 2 x 2
        Hessian (N/m) into ``data`` at ``scatter`` (k, 4); returns (value J, no rank-one
        terms)."""
        moved = (q.reshape(-1, 2)[self.disc.nodes] - self._start
                 - (self.disc.centre - self._centre))
        slips = np.sum(moved * self._tangents, axis=1)
        along, stiffness = np.empty_like(slips), np.empty_like(slips)
        value = point_friction(slips, self._forces, self.coefficient, self.slip_eps, along,
                               stiffness)
        np.add.at(grad, self.dofs, along[:, None] * self._tangents)
        if hessian:
            blocks = (stiffness[:, None, None] * self._tangents[:, :, None]
                      * self._tangents[:, None, :])
            np.add.at(data, scatter, blocks.reshape(-1, 4))
        return value, []

    def node_forces(self, q: np.ndarray) -> np.ndarray:
        """(k, 2) N, the friction force each node exerts on the disc (x, z)."""
        return _node_gradients(self, q, self.disc.nodes)


@dataclass(frozen=True)
class Indentation:
    """Attributes:
        delta: (s,) m, the disc's travel towards the finger (the base's towards the
            disc) after each increment.
        force: (s, 2) N, the force of the finger on the disc (x, z), in equilibrium
            (normal and friction forces).
        pressing: (s,) N, the sum of the magnitudes of the nodes' normal forces on the
            disc (the contact pressure integrated over the contact; |force| at most
            without friction).
        reaction: (2,) N, the base's reaction on the finger at the last delta (minus the
            last ``force``, up to the solver's tolerance: a check).
        positions: (s, n_nodes, 2) m, the finger's shapes.
        centres: (s, 2) m, the disc's centres.
    """

    delta: np.ndarray
    force: np.ndarray
    pressing: np.ndarray
    reaction: np.ndarray
    positions: np.ndarray
    centres: np.ndarray


def front_beam_disc(body: FingerBody, front_nodes: np.ndarray, height: float,
                    radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disc touching a finger's front beam at delta 0, for ``indent_disc``.

    Args:
        body: the finger (its front beam facing +x, as ``geometry.fin_ray.layout`` lays
            a Fin Ray out).
        front_nodes: (f,) the front beam's nodes from the tip to the base corner
            (``layout(...).front_nodes``).
        height: m, the disc's centre from the base corner along the beam.
        radius: m, the disc's radius plus the touching surface's offset from the nodes.

    Returns:
        (the nodes that may touch it (k,): the front beam's off the base; the disc's
        centre (2,) m; the beam's outward unit normal (2,)).
    """
    x0 = body.rest_positions
    corner, tip = x0[front_nodes[-1]], x0[front_nodes[0]]
    along = (tip - corner) / np.linalg.norm(tip - corner)
    normal = np.array([-along[1], along[0]])
    if normal[0] < 0:
        normal = -normal
    return (np.setdiff1d(front_nodes, body.base_nodes), corner + height * along
            + radius * normal, normal)


def indent_disc(body: FingerBody, nodes: np.ndarray, centre: np.ndarray, radius: float,
                direction: np.ndarray, travel: float, increments: int,
                settings: BarrierSettings, self_contact: BarrierSettings | None = None,
                tolerance: float = 1e-8, friction: float = 0.0,
                slip_eps: float = SLIP_EPS) -> Indentation:
    """The finger with its base held and a fixed disc moved by ``travel`` along
    ``direction`` into it in ``increments`` equal steps, a static equilibrium at each.

    Args:
        body: a 2D finger (``FingerBody``); its base nodes stay at rest.
        nodes: (k,) the nodes that may touch the disc (e.g. the front beam's).
        centre: (2,) m, the disc's centre at delta 0 (touching, not pressing).
        radius: m, the disc's radius plus the touching surface's offset from the nodes.
        direction: (2,) the unit direction the disc moves in.
        travel: m, the last delta.
        increments: steps from 0 to ``travel`` (each a Newton solve from the last shape).
        settings: the disc contact's barrier (dhat m, stiffness N).
        self_contact: the finger's self-contact barrier; None: none.
        tolerance: m, Newton's tolerance on the largest update (a stiff barrier's
            force follows a node's gap at kappa / dhat scale: 1e-9 m is at the roundoff
            floor of a steel finger, where Newton finds no descent).
        friction: mu of the disc contact (0: frictionless; ``DiscFriction``).
        slip_eps: m, the slip below which its friction is smoothed.

    Raises:
        NewtonFailure: no equilibrium found.
        ValueError: a negative or non-finite ``friction``.
    """
    if not (math.isfinite(friction) and friction >= 0.0):
        raise ValueError(f'friction coefficient {friction}: must be a number >= 0')
    disc = DiscBarrier(nodes, body.n_nodes, radius, settings)
    drag = DiscFriction(disc, friction, slip_eps) if friction > 0.0 else None
    contact = [disc] if drag is None else [disc, drag]
    centre = np.asarray(centre, dtype=float)
    direction = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    rows: list[tuple] = []

    def move(fraction: float, x: np.ndarray) -> np.ndarray:
        """The disc to this increment's place; the start: the last shape moved on as
        the last increment moved it (a linear predictor), nodes still in the disc
        pushed out of it; the friction lagged at the last equilibrium."""
        if rows and drag is not None:
            drag.lag(rows[-1][3].ravel())
        disc.centre = centre + fraction * travel * direction
        if len(rows) >= 2:
            x = 2.0 * rows[-1][3] - rows[-2][3]
            x[body.base_nodes] = body.rest_positions[body.base_nodes]
        return disc.push_out(x)

    def record(x: np.ndarray) -> None:
        normal = disc.node_forces(x.ravel())
        total = normal.sum(axis=0)
        if drag is not None:
            total = total + drag.node_forces(x.ravel()).sum(axis=0)
        rows.append((len(rows) + 1, total, np.hypot(*normal.T).sum(), x.copy(),
                     disc.centre.copy()))

    disc.centre = centre.copy()
    final = static_equilibrium(body, np.zeros_like(body.rest_positions),
                               increments=increments, hold=0, tolerance=tolerance,
                               self_contact=self_contact, elastic=body.rod_energies() + contact,
                               before_increment=move, on_increment=record)
    steps, force, pressing, positions, centres = zip(*rows)
    return Indentation(travel * np.array(steps) / increments, np.array(force),
                       np.array(pressing), final.base_reaction, np.array(positions),
                       np.array(centres))
