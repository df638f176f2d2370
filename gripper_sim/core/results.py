"""What one physics step reports: the per-step outputs every observer receives.

Coordinates are planar for the 2D model: column 0 is x (jaw closing axis), column 1
is z (up). Forces are in N (the out-of-plane depth is already applied), lengths in m.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from gripper_sim.core.damage import Damage


@dataclass(frozen=True)
class JawWrench:
    """Net contact wrench the fruit exerts on one jaw, in the jaw frame.

    The jaw frames are parallel to the world frame with their origin at the centre of
    the jaw face.

    Attributes:
        force: (3,) N, (fx, fy, fz).
        torque: (3,) N m, about the jaw frame origin.
    """

    force: np.ndarray
    torque: np.ndarray


@dataclass(frozen=True)
class Deformation:
    """Deformation and contact measures of the fruit.

    Attributes:
        compression: m, rest width along x minus current width along x.
        compression_ratio: compression over the rest width.
        max_skin_strain: largest engineering strain of a skin segment (signed by
            magnitude: the value of largest |strain|).
        contact_length: m, total length of fruit surface in contact with the jaws.
        peak_contact_pressure: Pa, largest contact pressure at a jaw or table node.
        node_pressure: (n_surface,) Pa, contact pressure at each surface node.
    """

    compression: float
    compression_ratio: float
    max_skin_strain: float
    contact_length: float
    peak_contact_pressure: float
    node_pressure: np.ndarray


@dataclass(frozen=True)
class Energies:
    """Energies in J: kinetic, elastic (all internal energies) and gravitational."""

    kinetic: float
    elastic: float
    gravitational: float

    @property
    def total(self) -> float:
        return self.kinetic + self.elastic + self.gravitational


@dataclass(frozen=True)
class FingerResult:
    """The deformable fingers after a step (``gripper.finger.type`` solid_pad, ...).

    Attributes:
        positions: (2 m, 2) m, the left finger's nodes, then the right finger's.
        contact_forces: (2 m, 2) N, the fruit's force on each finger node (barrier and
            friction).
        tip_displacement: (2, 2) m, each finger's tip (left, right) moved from where the
            jaw carries its rest position, in the finger's frame: x towards the fruit,
            z up (a Fin Ray finger's tip bending towards the fruit has x > 0).
        contact_length: (2,) m, the length of each finger's outline touching the fruit
            (3D: the diameter 2 sqrt(A / pi) of the circle of its contact area).
        surface_edges: (e, 2) the fingers' outline edges that may touch the fruit
            (indices into ``positions``; 3D: the edges of their surface triangles).
        contact_area: (2,) m^2, 3D: each finger's surface area touching the fruit; None
            in 2D.
        drawn_edges: (k, 2) the edges that draw the whole fingers (indices into
            ``positions``; 2D: their rods and their solids' boundaries); None: the
            ``surface_edges`` (3D: the whole surface).

    In 3D the (.., 2) arrays are (.., 3) (x, y, z).
    """

    positions: np.ndarray
    contact_forces: np.ndarray
    tip_displacement: np.ndarray
    contact_length: np.ndarray
    surface_edges: np.ndarray
    contact_area: np.ndarray | None = None
    drawn_edges: np.ndarray | None = None


@dataclass(frozen=True)
class StepResult:
    """Everything one step produces.

    Attributes:
        time: s, simulation time at the end of the step.
        step: number of steps taken since the last reset.
        positions: (n_nodes, 2) m, node positions (x, z).
        velocities: (n_nodes, 2) m/s.
        contact_forces: (n_nodes, 2) N, force each obstacle exerts on each node.
        contact_obstacle: (n_nodes,) int, index into ``obstacle_names`` of the obstacle
            a node touches, -1 for none.
        contact_sticking: (n_nodes,) bool, node in static (stuck) contact: with the
            barrier model slower along its obstacle than the friction smoothing speed,
            along a deformable finger's surface where it lies on it (not its backing).
        obstacle_names: names of the obstacles, e.g. ('left_jaw', 'right_jaw', 'table').
        surface: (n_surface,) int, indices of the surface (skin) nodes in outline order.
        left_wrench, right_wrench: net wrench the fruit exerts on each jaw.
        left_jaw_x, right_jaw_x: m, x of each jaw face.
        jaw_velocity: m/s, closing speed of each jaw (positive when closing).
        lift: m, height of the gripper (jaw centre) above the world origin.
        lift_velocity: m/s.
        gap: m, jaw separation.
        grip_force: N, mean contact normal force of the two jaws.
        slip_distance: m, vertical motion of the fruit centroid relative to the jaws
            since both jaws first gripped it (0 before that).
        slipping: fruit slides in the jaws in this step: on a jaw, nearly all of the
            contact nodes (``slip.SLIDING_FRACTION``) move along its surface relative to
            it (``slip.patches_sliding``; in 3D each node at its contact patch's fitted
            rigid motion, so a growing patch's rim slipping inwards is not slipping; a
            deformable finger's surface where the node lies on it); elastic deformation
            with the contacts stuck, or stuck in part, is not slipping.
        centroid: (2,) m, mass-weighted centroid of the fruit.
        energies: kinetic, elastic and gravitational energy.
        deformation: compression, strain and contact measures.
        newton_iterations: Newton iterations used (all sub-steps and corrections).
        substeps: number of sub-steps this step took (1 unless step halving happened).
        damage: bruising and crushing so far (``gripper_sim.core.damage.Damage``); None
            where a producer does not compute it.
        gripper_x: m, x of the gripper centre (the sideways transport axis).
        gripper_x_velocity: m/s.
        fingers: the deformable fingers (their nodes, forces, tip displacement, contact
            length), None for rigid fingers. With deformable fingers the jaw wrenches
            are what the jaws feel at the fingers' bases, ``left_jaw_x``/``right_jaw_x``
            the backings' x, and the obstacles 'left_jaw'/'right_jaw' the fingers.
    """

    time: float
    step: int
    positions: np.ndarray
    velocities: np.ndarray
    contact_forces: np.ndarray
    contact_obstacle: np.ndarray
    contact_sticking: np.ndarray
    obstacle_names: tuple
    surface: np.ndarray
    left_wrench: JawWrench
    right_wrench: JawWrench
    left_jaw_x: float
    right_jaw_x: float
    jaw_velocity: float
    lift: float
    lift_velocity: float
    gap: float
    grip_force: float
    slip_distance: float
    slipping: bool
    centroid: np.ndarray
    energies: Energies
    deformation: Deformation
    newton_iterations: int
    substeps: int
    damage: 'Damage | None' = None
    gripper_x: float = 0.0
    gripper_x_velocity: float = 0.0
    fingers: FingerResult | None = None

    def in_contact_with(self, name: str) -> bool:
        """Whether any node touches the obstacle called ``name`` (or one of its faces,
        named ``name.part``, e.g. ``left_jaw.upper`` of a V-groove finger)."""
        names = self.obstacle_names
        # list scans: several times faster than ndarray.__contains__ or np.isin on a step's
        # nodes (np.isin takes tens of us, this ~1 us)
        if name in names:
            return names.index(name) in self.contact_obstacle.tolist()
        prefix = name + '.'
        parts = [i for i, n in enumerate(names) if n.startswith(prefix)]
        if not parts:
            return False
        held = set(self.contact_obstacle.tolist())
        return any(i in held for i in parts)
