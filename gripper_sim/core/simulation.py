"""The simulation facade: fruit + gripper + world, stepped in time.

One step, in a fixed order: the gripper kinematics advance (constraints move), the
predictor-corrector loop solves the implicit Euler step with the current contact set
and updates the set until it is consistent, the state is committed, measures are taken
and observers are called.
"""
from __future__ import annotations

from typing import Any, Callable, Mapping

import numpy as np

from gripper_sim.configuration import validate
from gripper_sim.core.facade import SimulationFacade
from gripper_sim.core import barrier
from gripper_sim.core.damage import DamageTracker
from gripper_sim.core.deferred import build_deferred
from gripper_sim.core.energies import Gravity
from gripper_sim.core.finger_body import FingerBody
from gripper_sim.core.fast import FastPath
from gripper_sim.core.fruit import FruitModel, build_fruit
from gripper_sim.core.gripper import GripperKinematics
from gripper_sim.core.measures import (deformation, deformation_of, faces_contact_length,
                                       held_length, tributary_lengths)
from gripper_sim.core.multistep import MultiStep
from gripper_sim.core.obstacles import FlatFace
from gripper_sim.core.pad import PadLayer
from gripper_sim.core.results import StepResult
from gripper_sim.core.soft_fingers import (SoftFingers, check_soft_fingers, finger_body,
                                           is_deformable)
from gripper_sim.errors import ConfigError
from gripper_sim.geometry import fingers

LEFT, RIGHT = 0, 1


class Simulation(SimulationFacade):
    """A parallel-jaw gripper and a deformable fruit.

    Args:
        config: validated flat configuration from ``gripper_sim.configuration.load_config``.
        fast: step with the whole-step kernel (``gripper_sim.core.fast``) where it covers
            the set-up (the default contact model, rigid fingers); None (default) = where
            it does, True = require it, False = never: the generic route (the contact
            passes of ``core.contact_passes`` around the one Newton solver,
            ``fast_solver.PatternCachingSolver``, as for a barrier or deformable fingers).
        finger: a deformable finger's body to put on the jaws instead of the configured
            finger (a new geometry, a test body); None: ``gripper.finger.type``'s.

    Commands take effect on the next step. Invalid commands raise ``CommandError``
    and leave the simulation unchanged.
    """

    dimension = 2

    def __init__(self, config: Mapping[str, Any], fast: bool | None = None,
                 finger: FingerBody | None = None):
        self.config = validate(config)
        self.fruit: FruitModel = build_fruit(self.config)
        self.dt = float(self.config['sim.dt'])
        c = self.config
        if is_deformable(c) or finger is not None:
            check_soft_fingers(c, fast)
            if finger is None:
                finger = finger_body(c, self.fruit.depth)
            self._soft = SoftFingers(finger, self.fruit.n_nodes,
                                     c['contact.jaw.static_friction'],
                                     c['contact.jaw.kinetic_friction'],
                                     barrier.BarrierSettings.from_config(c))
        self._place_fruit()
        if self._soft is not None:
            self._soft.check_fit(c, self.initial_gap, self.touching_gap,
                                 self.fruit.rest_width)
        self.gravity = Gravity(self.fruit.masses, c['world.gravity'])
        self._facets = fingers.left_facets(c) if self._soft is None else []
        self._plain_jaws = (c['gripper.finger.type'] == 'flat' and self._soft is None
                            and not c['gripper.finger.pad.enabled'])
        self._pad = self._make_pad() if c['gripper.finger.pad.enabled'] else None
        barrier.check_supported(c, self.dimension, fast)
        if c['contact.model'] == 'ipc' or self._soft is not None:
            soft = self._soft
            outline = (self.initial_positions
                       - self._in_plane(0.0, self.initial_lift))[self.fruit.surface]
            self._barrier = barrier.BarrierContact(
                self.fruit.n_nodes + (soft.n_nodes if soft else 0), self.fruit.surface,
                self.fruit.skin_edges, barrier.BarrierSettings.from_config(c),
                bodies=soft.soft_bodies if soft else (),
                pairs=soft.contact_pairs(self.fruit.surface, outline) if soft else None)
            if self._starts_on_table():
                # a barrier needs a positive gap: the fruit starts just above the table
                self.initial_positions[:, 1] += barrier.START_GAP_FRACTION * c['contact.ipc.dhat']
        self.solver = self._make_solver()
        self.kinematics = GripperKinematics(
            c['gripper.max_gap'], c['gripper.lift_acceleration'],
            initial_stiffness=c['fruit.flesh.youngs_modulus'] * self.fruit.depth,
            transport_acceleration=c['gripper.transport_acceleration'],
            max_speed=c['gripper.max_speed'], damping=c['gripper.force_damping'],
            min_gap=self.smallest_gap)
        self._observers: list[Callable[[StepResult], None]] = []
        self._fast = (FastPath.create(self) if fast is not False and self._barrier is None
                      else None)
        self._multistep: MultiStep | None = None
        if fast and self._fast is None:
            raise ConfigError('fast=True: the whole-step kernel needs the default contact model '
                              'and rigid fingers')
        self.reset()
        if self._settles():
            self._settle()

    def _make_damage(self) -> DamageTracker:
        if self._soft is not None:  # the obstacles: the two fingers, then the faces
            n = len(self._faces_template) + 2
            body = self._soft.body
            return DamageTracker(self.fruit, self.config, face_groups=list(range(n)),
                                 face_curvature=[0.0] * n,
                                 face_padded=[i < 2 for i in range(n)],
                                 pad_material=(body.youngs_modulus, body.poisson_ratio),
                                 face_deformable=[i < 2 for i in range(n)])
        return DamageTracker(
            self.fruit, self.config, face_groups=self._face_groups(),
            face_curvature=self._face_curvatures(),
            face_padded=[self._pad is not None and i < len(self._face_side)
                         for i in range(len(self._faces_template))])

    # ------------------------------------------------------------------ geometry
    def _make_faces(self) -> list[FlatFace]:
        c = self.config
        jaw = dict(half_length=0.5 * c['gripper.jaw_height'], thickness=c['gripper.jaw_thickness'],
                   static_friction=c['contact.jaw.static_friction'],
                   kinetic_friction=c['contact.jaw.kinetic_friction'])
        if self._soft is not None:  # the deformable fingers are no faces
            faces, self._face_side, self._face_offsets = [], [], []
        elif self._plain_jaws:
            faces = [FlatFace('left_jaw', np.zeros(2), np.array([1.0, 0.0]), **jaw),
                     FlatFace('right_jaw', np.zeros(2), np.array([-1.0, 0.0]), **jaw)]
            self._face_side, self._face_offsets = [LEFT, RIGHT], [np.zeros(2), np.zeros(2)]
        else:
            faces, self._face_side, self._face_offsets = self._jaw_facet_faces(jaw)
        ground = dict(static_friction=c['contact.table.static_friction'],
                      kinetic_friction=c['contact.table.kinetic_friction'],
                      restitution=c['contact.restitution'])
        if c['world.table']:
            faces.append(FlatFace('table', np.array([0.0, c['world.table_height']]),
                                  np.array([0.0, 1.0]), **ground))
        if c['world.walls']:
            w = c['world.wall_half_width']
            faces.append(FlatFace('left_wall', np.array([-w, 0.0]), np.array([1.0, 0.0]),
                                  **ground))
            faces.append(FlatFace('right_wall', np.array([w, 0.0]), np.array([-1.0, 0.0]),
                                  **ground))
        return faces

    def _jaw_facet_faces(self, jaw: dict):
        """The jaw faces of a shaped finger or a padded one (``gripper_sim.geometry.fingers``):
        faces, the jaw side of each, and each one's offset from its jaw's origin."""
        faces, sides, offsets = [], [], []
        back = self.config['gripper.finger.pad.thickness'] if self._pad is not None else 0.0
        for side, name in ((LEFT, 'left_jaw'), (RIGHT, 'right_jaw')):
            for facet in self._facets:
                f = facet if side == LEFT else facet.mirrored()
                label = f'{name}.{f.name}' if f.name else name
                faces.append(FlatFace(label, np.zeros(2), f.normal.copy(),
                                      **dict(jaw, half_length=f.half_length)))
                sides.append(side)
                offsets.append(f.offset - back * f.normal)  # the rigid jaw behind the pad
        return faces, sides, offsets

    def _face_groups(self) -> list[int]:
        """Per obstacle, the body it belongs to (faces of a jaw share one)."""
        n = len(self._faces_template)
        return [self._face_side[i] if i < len(self._face_side) else i for i in range(n)]

    def _face_curvatures(self) -> list[float]:
        n = len(self._faces_template)
        jaw = [f.curvature for f in self._facets] * 2 if not self._plain_jaws else [0.0, 0.0]
        return jaw + [0.0] * (n - len(jaw))

    def _make_pad(self) -> PadLayer:
        c = self.config
        rest = self.fruit.rest_positions
        return PadLayer(self.fruit.surface, tributary_lengths(self.fruit, rest),
                        self.fruit.depth, c['gripper.finger.pad.thickness'],
                        c['gripper.finger.pad.youngs_modulus'],
                        c['gripper.finger.pad.poisson_ratio'], c['contact.pad.friction'],
                        self.fruit.n_nodes)

    def _forget_factor(self) -> None:
        if self._fast is not None:
            self._fast.forget_factor()

    # ------------------------------------------------------------------ stepping
    def _substep(self, dt: float) -> int:
        """``SimulationFacade._substep`` on the fast path where it applies, else (and for
        a step its kernel cannot do) on the generic path (every step of ``_settle``)."""
        if self._fast is not None and not self._settling and self._fast.applies():
            iterations = self._fast.substep(dt)
            if iterations is not None:
                return iterations
        return super()._substep(dt)

    def advance(self, rules) -> 'tuple[StepResult, Any] | None':
        """``SimulationFacade.advance`` on the compiled multi-step advance
        (``core.multistep``) where it applies."""
        if self._fast is None:
            return None
        if self._multistep is None:
            self._multistep = MultiStep(self._fast)
        return self._multistep.advance(rules)

    # ------------------------------------------------------------------ outputs
    def _measure(self, iterations: int, substeps: int) -> StepResult:
        if self._fast is not None and self._fast.applies():  # all fields, damage included
            return self._fast.measure(iterations, substeps)
        x = self.q
        forces, obstacle = self.contact_forces_and_holders()
        held = self._held_measures(x, obstacle) if self._soft is not None else None
        fields, rarely_read, normal, (on_left, on_right) = self._step_measures(
            x, self.v, forces, obstacle, iterations, substeps, held)
        fruit = self.fruit
        if held is not None:  # the fruit's outline in pairs with the fingers, its measures
            shape = deformation_of(fruit, *held[5], held[4])
        else:
            on_jaws = on_left | on_right
            shape = deformation(fruit, x, normal, on_jaws, self._contact_length(x, on_jaws))
        fields.update(deformation=shape, damage=self.assess_damage(
            x, normal, obstacle, shape.compression_ratio))
        return build_deferred(StepResult, fields, self.DEFERRED_MEASURES, rarely_read)

    def _contact_length(self, x: np.ndarray, on_jaws: np.ndarray) -> float:
        """m, the fruit's outline in contact with the jaws at positions ``x`` (n, 2) m,
        ``on_jaws`` (n,) the nodes they hold: with deformable fingers its nodes in pairs
        with them, else along the jaws' faces (a gap off them with the barrier); plus
        the pads' (if any)."""
        fruit = self.fruit
        if self._soft is not None:
            length = held_length(fruit, x, on_jaws)
        else:
            jaws = self.faces_at(self._grip)[:len(self._face_side)]
            length = faces_contact_length(fruit, x, jaws, self.contacts.obstacle,
                                          self._barrier is not None)
        if self._pad is not None:
            on_pad = (self.contacts.obstacle < 0) & (self._pad.holder >= 0)
            length += held_length(fruit, x, on_pad)
        return length

    def assess_damage(self, positions, normal, obstacle, compression_ratio: float):
        """Bruising and crushing after this step (``gripper_sim.core.damage``) from
        positions (n, 2) m, normal contact forces (n,) N, holding obstacles (n,) and the
        compression ratio; the damage tracker (``damage_tracker``) keeps its peaks."""
        stress = 0.0
        if self.fruit.flesh is not None:
            stress = float(np.max(self.fruit.flesh.von_mises(positions.ravel()), initial=0.0))
        return self._damage.update(positions, normal, obstacle, compression_ratio, stress)
