"""The 3D simulation facade: a 3D fruit between two jaws, stepped in time.

Same commands, observers and step order as the 2D ``gripper_sim.core.simulation``
(gripper kinematics advance, predictor-corrector contact passes around the implicit
Euler Newton solve, commit, measure, observers), with the 2D core's stepper
(``PatternCachingSolver(dim=3)``), contact state and gripper kinematics.

Contact in 3D (modified mass method, Baraff & Witkin 1998): a surface node held by a
plate is STICK (all three directions prescribed: it moves with the plate), SLIP (the
normal prescribed; kinetic friction mu_k R_n opposite its tangential slip velocity, a
smoothed Coulomb cone in the plate's tangent plane) or IMPACT (restitution). A stuck
node starts slipping when its tangential reaction |R_t| exceeds mu_s R_n; a slipping
node sticks again when its slip speed vanishes. Detection: a box test per plate (broad
phase) and one vectorised gap test of every free surface node (narrow phase).

Jaws: flat plates, or the 2D finger profiles (arc, vgroove) extruded along y as flat
facets (``core3d.fingers3d``); a soft pad is an elastic-foundation energy on the jaw
faces (``core3d.fingers_pad``); a deformable finger (solid pad) is a body of the state
on each jaw (``core3d.soft_fingers3d``), touching the fruit through the barrier
(``core3d.soft_barrier``) in the facade's soft-finger step. The grip force of shaped
fingers is the force along the closing axis x, summed over a jaw's facets; wrench torques
are about the centre of each jaw's front plane.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping

import numpy as np

from gripper_sim.configuration import validate
from gripper_sim.core.barrier import (START_GAP_FRACTION, BarrierContact, BarrierSettings,
                                      check_supported)
from gripper_sim.core.contact_passes import ContactSettings
from gripper_sim.core.contact_passes import load_kernels as load_contact_kernels
from gripper_sim.core.energies import Gravity
from gripper_sim.core.facade import SimulationFacade
from gripper_sim.core.gripper import GripperKinematics
from gripper_sim.core.results import Deformation, StepResult
from gripper_sim.core.soft_fingers import check_soft_fingers, is_deformable
from gripper_sim.core3d import fingers3d, meshes
from gripper_sim.core3d.damage import DamageTracker3D
from gripper_sim.core3d.fingers_pad import PadLayer3D
from gripper_sim.core3d.fruit import FruitModel3D, build_fruit3d
from gripper_sim.core3d.layered_mesher import vertex_edge_lengths
from gripper_sim.core3d.rolling_hold import RollingHold
from gripper_sim.core.obstacles import Plate
from gripper_sim.core3d.soft_barrier import SoftBarrier3D
from gripper_sim.core3d.soft_fingers3d import (SoftFingers3D, finger_body3d,
                                              fruit_barrier_settings)
from gripper_sim.errors import ConfigError

LEFT, RIGHT = 0, 1

_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])


@dataclass(frozen=True)
class Deformation3D(Deformation):
    """``Deformation`` of the 3D model; ``contact_length`` is the sum over the two jaws
    of the equivalent contact patch diameters 2 sqrt(A / pi).

    Attributes:
        contact_area: m^2, surface area in contact with the two jaws (the vertex areas,
            a third of each adjacent triangle, of the held surface nodes).
        jaw_contact_areas: (2,) m^2, left and right jaw.
        jaw_contact_radii: (2,) m, radius of each jaw's contact patch: where the gap of
            the first free surface nodes around the patch extrapolates to zero (a smooth
            surface leaves a flat face as gap ~ (rho - a)^2: sqrt(gap) is fitted linearly
            in the distance rho from the patch centre); sqrt(A / pi) if that fails and
            for shaped or padded fingers.
    """

    contact_area: float = 0.0
    jaw_contact_areas: tuple = (0.0, 0.0)
    jaw_contact_radii: tuple = (0.0, 0.0)


@dataclass(frozen=True)
class StepResult3D(StepResult):
    """``StepResult`` of the 3D model: positions, velocities and contact forces are
    (n_nodes, 3) (x, y, z), the centroid (3,); ``surface`` lists the skin nodes.

    Attributes:
        triangles: (n_tri, 3) skin triangles (node indices), outward.
    """

    triangles: np.ndarray = None  # type: ignore[assignment]

    dimension = 3


class Simulation3D(SimulationFacade):
    """A parallel-jaw gripper (flat plates or shaped/padded fingers) and a 3D fruit.

    Args:
        config: validated flat configuration with ``dimension`` 3.

    Commands take effect on the next step. Invalid commands raise ``CommandError``
    and leave the simulation unchanged.
    """

    dimension = 3
    #: a contact pass adds, of the free nodes that ended inside a face, those at least
    #: this fraction of the deepest one's depth; the others, if still inside after the
    #: next solve, come in the next pass. Holding every penetrating node at once (a
    #: resting fruit's whole cap after its first 20 ms step) and releasing the pulling
    #: ones ring by ring took twice the passes and Newton iterations
    deepest_first = 0.7
    #: s, 40 of the default 3D time step, as the 2D settle's 40 ms are of the 2D one: with
    #: the barrier model the resting patch spreads at the friction's creep speed, and in
    #: 40 ms steps the coarse apple still sank 0.2 um a step after 60 of them
    settle_longest_step = 0.8

    def __init__(self, config: Mapping[str, Any]):
        self.config = validate(config)
        if int(self.config.get('dimension', 2)) != 3:
            raise ConfigError("config key 'dimension' must be 3 for the 3D simulation")
        check_supported(self.config, 3, None)
        self.fruit: FruitModel3D = build_fruit3d(self.config)
        self.dt = float(self.config['sim.dt'])
        c = self.config
        if is_deformable(c):
            check_soft_fingers(c, None)
            self._soft = SoftFingers3D(finger_body3d(c), self.fruit.n_nodes,
                                       c['contact.jaw.static_friction'],
                                       c['contact.jaw.kinetic_friction'])
        self._place_fruit()
        self.gravity = Gravity(self.fruit.masses, c['world.gravity'], dim=3)
        if self._soft is not None:
            self._soft.check_fit(c, self.initial_gap, self.touching_gap, self.fruit.rest_width)
            self._barrier = self._soft_barrier()
        elif c['contact.model'] == 'ipc':
            self._barrier = BarrierContact(
                self.fruit.n_nodes, self.fruit.surface, self.fruit.skin_edges,
                BarrierSettings.from_config(c), dimension=3, triangles=self.fruit.triangles)
        if self._barrier is not None and self._starts_on_table():
            # a barrier needs a positive gap: the fruit starts just above the table
            self.initial_positions[:, 2] += START_GAP_FRACTION * self._barrier.settings.dhat
        self._plain_jaws = (c['gripper.finger.type'] == 'flat'
                            and not c['gripper.finger.pad.enabled'])
        self._pad = self._make_pad() if c['gripper.finger.pad.enabled'] else None
        self.solver = self._make_solver()
        if self._soft is None and self._barrier is None and self._pad is None:
            # (the pads and barriers are set up for a step only by reset())
            self.solver.load_kernels(self.initial_positions.ravel(), self.dt)
        # first guess of d force / d gap for the force regulator (it adapts): a Hertz
        # contact of the flesh at a 1 % approach; a solid fruit's at the commanded force
        radius = 0.5 * self.fruit.rest_width
        modulus = c['fruit.flesh.youngs_modulus'] / (1.0 - c['fruit.flesh.poisson_ratio'] ** 2)
        self.kinematics = GripperKinematics(
            c['gripper.max_gap'], c['gripper.lift_acceleration'],
            initial_stiffness=0.1 * c['fruit.flesh.youngs_modulus'] * radius,
            transport_acceleration=c['gripper.transport_acceleration'],
            max_speed=c['gripper.max_speed'], damping=c['gripper.force_damping'],
            min_gap=self.smallest_gap,
            hertz_modulus=(4.0 / 3.0 * modulus * math.sqrt(radius)
                           if c['fruit.model'] == 'solid' else 0.0))
        self._observers: list[Callable[[StepResult3D], None]] = []
        self.reset()
        if self._soft is None and self._barrier is None:
            load_contact_kernels(self.solver.m, self.fruit.surface, self.q,
                                 self.faces_at(self._grip), self.dt,
                                 ContactSettings.from_config(self.config, self.deepest_first))
        if self._settles():
            self._settle()

    def _settle_energies(self) -> list:
        """The settle holds a 3D fruit's rolling (``core3d.rolling_hold``): a faceted skin
        would roll onto a facet, and with ``contact.model: ipc`` creep without end."""
        n_dof = 3 * (self.fruit.n_nodes + (self._soft.n_nodes if self._soft else 0))
        return [RollingHold(self.fruit.masses, n_dof)]

    def _make_damage(self) -> DamageTracker3D:
        return DamageTracker3D(self.fruit, self.config)

    def _soft_barrier(self) -> SoftBarrier3D:
        """The barrier of the fruit and the deformable fingers (``core3d.soft_barrier``),
        its pattern's pairs from the fruit centred between the jaws at rest."""
        fruit, soft = self.fruit, self._soft
        outline = (self.initial_positions - self._in_plane(0.0, self.initial_lift))
        with np.errstate(invalid='ignore'):  # the solid's inner nodes have no skin edge
            spacing = vertex_edge_lengths(fruit.rest_positions, fruit.triangles)
        return SoftBarrier3D(
            fruit.n_nodes + soft.n_nodes, fruit.surface, fruit.skin_edges, fruit.triangles,
            fruit_barrier_settings(self.config), soft.soft_bodies,
            soft.contact_pairs(fruit.surface, outline[fruit.surface], spacing[fruit.surface]))

    # ------------------------------------------------------------------ geometry
    def _make_faces(self) -> list[Plate]:
        c = self.config
        jaw = dict(half_extents=np.array([0.5 * c['gripper.jaw_width'],
                                          0.5 * c['gripper.jaw_height']]),
                   thickness=c['gripper.jaw_thickness'],
                   static_friction=c['contact.jaw.static_friction'],
                   kinetic_friction=c['contact.jaw.kinetic_friction'])
        jaw_tangents = np.stack([_Y, _Z])
        if self._soft is not None:  # the deformable fingers are no faces
            faces, self._face_side, self._face_offsets = [], [], []
        elif self._plain_jaws:
            faces = [Plate('left_jaw', np.zeros(3), _X.copy(), jaw_tangents, **jaw),
                     Plate('right_jaw', np.zeros(3), -_X, jaw_tangents, **jaw)]
            self._face_side, self._face_offsets = [LEFT, RIGHT], [np.zeros(3), np.zeros(3)]
        else:
            pad = c['gripper.finger.pad.thickness'] if self._pad is not None else 0.0
            faces, self._face_side, self._face_offsets = fingers3d.jaw_facet_plates(c, pad)
        ground = dict(static_friction=c['contact.table.static_friction'],
                      kinetic_friction=c['contact.table.kinetic_friction'],
                      restitution=c['contact.restitution'])
        if c['world.table']:
            faces.append(Plate('table', np.array([0.0, 0.0, c['world.table_height']]),
                               _Z.copy(), np.stack([_X, _Y]), **ground))
        if c['world.walls']:
            w = c['world.wall_half_width']
            faces.append(Plate('left_wall', np.array([-w, 0.0, 0.0]), _X.copy(),
                               jaw_tangents, **ground))
            faces.append(Plate('right_wall', np.array([w, 0.0, 0.0]), -_X, jaw_tangents,
                               **ground))
        return faces

    def _make_pad(self) -> PadLayer3D:
        c, fruit = self.config, self.fruit
        areas = meshes.vertex_areas(fruit.rest_positions, fruit.triangles, fruit.n_nodes)
        return PadLayer3D(fruit.surface, areas[fruit.surface],
                          c['gripper.finger.pad.thickness'],
                          c['gripper.finger.pad.youngs_modulus'],
                          c['gripper.finger.pad.poisson_ratio'], c['contact.pad.friction'],
                          fruit.n_nodes)

    # ------------------------------------------------------------------ outputs
    def _measure(self, iterations: int, substeps: int) -> StepResult3D:
        x = self.q
        forces, obstacle = self.contact_forces_and_holders()
        fields, normal, (on_left, on_right) = self._common_measures(
            x, self.v, forces, obstacle, iterations, substeps)
        deformation = self._deformation(x, normal, on_left, on_right)
        damage = self._damage.update(x, deformation.node_pressure,
                                     deformation.compression_ratio)
        return StepResult3D(**fields, deformation=deformation, damage=damage,
                            triangles=self.fruit.triangles)

    def _deformation(self, x, normal, on_left, on_right) -> Deformation3D:
        fruit = self.fruit
        surface = fruit.surface
        compression = fruit.rest_width - float(np.ptp(x[surface, 0]))
        if fruit.membrane is not None:
            strains = fruit.membrane.strains(x.ravel())
        else:
            e = x[fruit.skin_edges[:, 1]] - x[fruit.skin_edges[:, 0]]
            r = fruit.rest_positions
            e0 = r[fruit.skin_edges[:, 1]] - r[fruit.skin_edges[:, 0]]
            strains = np.linalg.norm(e, axis=1) / np.linalg.norm(e0, axis=1) - 1.0
        max_strain = float(strains[np.argmax(np.abs(strains))]) if strains.size else 0.0
        areas = meshes.vertex_areas(x, fruit.triangles, fruit.n_nodes)
        jaw_areas = (float(areas[on_left].sum()), float(areas[on_right].sum()))
        faces = self.faces_at(self._grip)
        if self._plain_jaws and self._barrier is not None:  # a barrier gap off the faces
            faces = self._barrier.touching_faces(faces, x, self.contacts.obstacle)
        radii = tuple(self._patch_radius(x, faces[side], held, area) if self._plain_jaws
                      else math.sqrt(area / math.pi)
                      for side, held, area in ((LEFT, on_left, jaw_areas[0]),
                                               (RIGHT, on_right, jaw_areas[1])))
        with np.errstate(divide='ignore', invalid='ignore'):
            pressure = np.where(areas[surface] > 0,
                                np.maximum(normal[surface], 0.0) / areas[surface], 0.0)
        return Deformation3D(
            compression=compression, compression_ratio=compression / fruit.rest_width,
            max_skin_strain=max_strain,
            contact_length=sum(2 * math.sqrt(a / math.pi) for a in jaw_areas),
            peak_contact_pressure=float(pressure.max(initial=0.0)), node_pressure=pressure,
            contact_area=sum(jaw_areas), jaw_contact_areas=jaw_areas, jaw_contact_radii=radii)

    def _patch_radius(self, x, face: Plate, held: np.ndarray, area: float) -> float:
        """Contact patch radius (m) on one plate, see ``Deformation3D``."""
        if not np.any(held):
            return 0.0
        fallback = math.sqrt(area / math.pi)
        surface = self.fruit.surface
        centre = x[held].mean(axis=0)
        rho = np.linalg.norm((x[surface] - centre) @ face.tangents.T, axis=1)
        gap = face.gap(x[surface])
        is_held = held[surface]
        r1 = float(rho[is_held].max())
        edges = self.fruit.skin_edges
        near = held[edges[:, 0]] | held[edges[:, 1]]
        h = float(np.median(np.linalg.norm(x[edges[near, 1]] - x[edges[near, 0]], axis=1)))
        ring = (~is_held) & (gap > 0) & (rho > r1) & (rho < r1 + 2.5 * h) & \
            (np.abs(gap) < 0.5 * self.fruit.rest_width)
        if np.count_nonzero(ring) < 3:
            return fallback
        slope, intercept = _line_fit(rho[ring], np.sqrt(gap[ring]))
        if slope <= 0:
            return fallback
        return float(min(max(-intercept / slope, r1), r1 + h))


def _line_fit(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares (slope, intercept) of y = slope x + intercept, x and y (k,), k >= 2."""
    xm, ym = float(x.mean()), float(y.mean())
    dx = x - xm
    spread = float(dx @ dx)
    slope = float(dx @ (y - ym)) / spread if spread > 0 else 0.0
    return slope, ym - slope * xm
