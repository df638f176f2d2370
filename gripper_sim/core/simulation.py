"""The simulation facade: fruit + gripper + world, stepped in time.

One step, in a fixed order: the gripper kinematics advance (constraints move), the
predictor-corrector loop solves the implicit Euler step with the current contact set
and updates the set until it is consistent, the state is committed, measures are taken
and observers are called.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Any, Callable, Mapping

import numpy as np

from gripper_sim.core import contact as cm
from gripper_sim.core.facade import DYNAMIC_KEYS, SimulationFacade  # noqa: F401 (re-export)
from gripper_sim.core import fingers
from gripper_sim.core.damage import DamageTracker
from gripper_sim.core.energies import Gravity
from gripper_sim.core.fast import FastPath
from gripper_sim.core.fast_solver import SYMMETRIC_LU_OPTIONS, PatternCachingSolver
from gripper_sim.core.fruit import FruitModel, build_fruit
from gripper_sim.core.gripper import GripperKinematics, GripperState
from gripper_sim.core.measures import deformation, face_contact_length
from gripper_sim.core.obstacles import FlatFace
from gripper_sim.core.pad import PadLayer
from gripper_sim.core.results import Energies, JawWrench, StepResult
from gripper_sim.errors import ConfigError

LEFT, RIGHT = 0, 1


class Simulation(SimulationFacade):
    """A parallel-jaw gripper and a deformable fruit.

    Args:
        config: validated flat configuration from ``gripper_sim.configuration.load_config``.
        fast: step with the numba kernels (``gripper_sim.core.fast``) when they cover the
            fruit model; None (default) = whenever numba is installed, False = always the
            generic numpy/scipy path (the reference), True = require the fast path.

    Commands take effect on the next step. Invalid commands raise ``CommandError``
    and leave the simulation unchanged.
    """

    dimension = 2

    def __init__(self, config: Mapping[str, Any], fast: bool | None = None):
        self.config = dict(config)
        self.fruit: FruitModel = build_fruit(self.config)
        self.dt = float(self.config['sim.dt'])
        c = self.config
        rest = self.fruit.rest_positions
        if c['fruit.initial_height'] is not None:
            centre_z = c['fruit.initial_height']
        elif c['world.table']:
            centre_z = c['world.table_height'] - rest[:, 1].min()
        else:
            centre_z = 0.0
        self.initial_positions = rest + np.array([0.0, centre_z])
        self.initial_gap = (c['gripper.initial_gap'] if c['gripper.initial_gap'] is not None
                            else min(self.fruit.rest_width + 0.01, c['gripper.max_gap']))
        if self.initial_gap > c['gripper.max_gap']:
            raise ConfigError("config key 'gripper.initial_gap' exceeds 'gripper.max_gap'")
        self.initial_lift = (c['gripper.initial_lift'] if c['gripper.initial_lift'] is not None
                             else centre_z)
        self.gravity = Gravity(self.fruit.masses, c['world.gravity'])
        self._facets = fingers.left_facets(c)
        self._plain_jaws = (c['gripper.finger.type'] == 'flat'
                            and not c['gripper.finger.pad.enabled'])
        self._pad = self._make_pad() if c['gripper.finger.pad.enabled'] else None
        self.solver = PatternCachingSolver(
            self.fruit.masses, list(self.fruit.energies) + [self.gravity]
            + ([self._pad] if self._pad is not None else []),
            damping_mass=c['fruit.damping.mass'], damping_stiffness=c['fruit.damping.stiffness'],
            tolerance=c['sim.newton_tolerance'], max_iterations=c['sim.max_newton_iterations'],
            dim=2, lu_options=SYMMETRIC_LU_OPTIONS, fast=None if fast is not False else False)
        self.kinematics = GripperKinematics(
            c['gripper.max_gap'], c['gripper.lift_acceleration'],
            c['gripper.force_time_constant'],
            initial_stiffness=c['fruit.flesh.youngs_modulus'] * self.fruit.depth,
            transport_acceleration=c['gripper.transport_acceleration'])
        self._observers: list[Callable[[StepResult], None]] = []
        self._fast = (FastPath.create(self) if fast is not False and self._plain_jaws
                      else None)
        if fast and self._fast is None:
            raise ConfigError('the fast path needs numba, a shell or point fruit model and '
                              'a flat finger without a pad')
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the initial state and commands, time 0."""
        n = self.fruit.n_nodes
        self.solver.reset()
        self.q = self.initial_positions.copy()
        self.v = np.tile([self.config['fruit.initial_velocity.x'],
                          self.config['fruit.initial_velocity.z']], (n, 1)).astype(float)
        self.contacts = cm.ContactState.empty(n)
        self.contact_forces = np.zeros((n, 2))
        self._time = 0.0
        self._step = 0
        self._slip_reference: float | None = None
        self._held_slip = 0.0
        self._faces_template = self._make_faces()
        self._grip = GripperState(
            gap=self.initial_gap, gap_rate=0.0, lift=self.initial_lift, lift_rate=0.0,
            mode='position', target_gap=self.initial_gap, target_force=0.0,
            speed=self.config['gripper.close_speed'], target_lift=self.initial_lift,
            lift_speed=self.config['gripper.lift_speed'],
            stiffness=self.kinematics.initial_stiffness,
            x_speed=self.config['gripper.transport_speed'])
        self._jaw_force = (0.0, 0.0)
        self._damage = DamageTracker(
            self.fruit, self.config, face_groups=self._face_groups(),
            face_curvature=self._face_curvatures(),
            face_padded=[self._pad is not None and i < len(self._face_side)
                         for i in range(len(self._faces_template))])
        if self._pad is not None:
            self._pad.begin_step(self.q, self._pad_faces(self._grip),
                                 self._pad_faces(self._grip), self.dt)
            self._pad.finish_step(self.q.ravel())
        self._last = self._measure(0, 1)

    # ------------------------------------------------------------------ geometry
    def _make_faces(self) -> list[FlatFace]:
        c = self.config
        jaw = dict(half_length=0.5 * c['gripper.jaw_height'], thickness=c['gripper.jaw_thickness'],
                   static_friction=c['contact.jaw.static_friction'],
                   kinetic_friction=c['contact.jaw.kinetic_friction'])
        if self._plain_jaws:
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
        """The jaw faces of a shaped finger or a padded one (``gripper_sim.core.fingers``):
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
        from gripper_sim.core.measures import tributary_lengths
        c = self.config
        rest = self.fruit.rest_positions
        return PadLayer(self.fruit.surface, tributary_lengths(self.fruit, rest),
                        self.fruit.depth, c['gripper.finger.pad.thickness'],
                        c['gripper.finger.pad.youngs_modulus'],
                        c['gripper.finger.pad.poisson_ratio'], c['contact.pad.friction'],
                        self.fruit.n_nodes)

    # ------------------------------------------------------------------ stepping
    def _substep(self, dt: float) -> int:
        if self._fast is not None and self._fast.applies():
            return self._fast.substep(dt)
        return super()._substep(dt)

    # ------------------------------------------------------------------ outputs
    def _measure(self, iterations: int, substeps: int) -> StepResult:
        if self._fast is not None and self._fast.applies():  # all fields, damage included
            return self._fast.measure(iterations, substeps)
        result = self._measure_reference(iterations, substeps)
        if self._pad is not None:
            result = self._with_pad(result)
        grip = self._grip
        return replace(result, damage=self._assess_damage(result),
                       left_jaw_x=grip.x - 0.5 * grip.gap, right_jaw_x=grip.x + 0.5 * grip.gap,
                       gripper_x=grip.x, gripper_x_velocity=grip.x_rate)

    def _with_pad(self, result: StepResult) -> StepResult:
        """The step result with the pads' forces on the fruit added (``core.pad``)."""
        pad, grip = self._pad, self._grip
        x = result.positions
        forces = result.contact_forces + pad.forces
        obstacle = result.contact_obstacle.copy()
        on_pad = (obstacle < 0) & (pad.holder >= 0)
        obstacle[on_pad] = pad.holder[on_pad]
        wrenches = []
        for side, sign, hard in ((LEFT, -1.0, result.left_wrench),
                                 (RIGHT, 1.0, result.right_wrench)):
            nodes = np.flatnonzero(np.isin(pad.holder, self._jaw_faces(side)))
            f = pad.forces[nodes]
            r = x[nodes] - np.array([grip.x + sign * 0.5 * grip.gap, grip.lift])
            torque = float(np.sum(r[:, 1] * -f[:, 0] - r[:, 0] * -f[:, 1]))
            wrenches.append(JawWrench(hard.force - np.array([f[:, 0].sum(), 0.0, f[:, 1].sum()]),
                                      hard.torque + np.array([0.0, torque, 0.0])))
        grip_force = 0.5 * (-wrenches[LEFT].force[0] + wrenches[RIGHT].force[0])
        normals = np.array([f.normal for f in self._faces_template]).reshape(-1, 2)
        held = obstacle >= 0
        normal = np.zeros(len(obstacle))
        normal[held] = np.einsum('ij,ij->i', forces[held], normals[obstacle[held]])
        jaw = np.isin(obstacle, self._jaw_faces(LEFT) + self._jaw_faces(RIGHT))
        from gripper_sim.core.measures import tributary_lengths
        trib = tributary_lengths(self.fruit, x)
        pad_length = float(np.sum(trib[on_pad[self.fruit.surface]]))
        shape = deformation(self.fruit, x, normal, jaw,
                            result.deformation.contact_length + pad_length)
        on_left = bool(np.any(np.isin(obstacle, self._jaw_faces(LEFT))))
        on_right = bool(np.any(np.isin(obstacle, self._jaw_faces(RIGHT))))
        slip = self._slip_distance(float(result.centroid[1] - grip.lift),
                                   on_left and on_right, on_left or on_right)
        return replace(result, contact_forces=forces, contact_obstacle=obstacle,
                       left_wrench=wrenches[LEFT], right_wrench=wrenches[RIGHT],
                       grip_force=grip_force, deformation=shape, slip_distance=slip)

    def _assess_damage(self, result: StepResult):
        """Bruising and crushing after this step (``gripper_sim.core.damage``)."""
        normals = np.array([f.normal for f in self._faces_template]).reshape(-1, 2)
        obstacle = result.contact_obstacle
        held = obstacle >= 0
        normal = np.zeros(len(obstacle))
        normal[held] = np.einsum('ij,ij->i', result.contact_forces[held], normals[obstacle[held]])
        return self._assess_damage_of(result.positions, normal, obstacle,
                                      result.deformation.compression_ratio)

    def _assess_damage_of(self, positions, normal, obstacle, compression_ratio: float):
        """``_assess_damage`` from positions (n, 2) m, normal reactions (n,) N, holding
        obstacles (n,) and the compression ratio."""
        stress = 0.0
        if self.fruit.flesh is not None:
            stress = float(np.max(self.fruit.flesh.von_mises(positions.ravel()), initial=0.0))
        return self._damage.update(positions, normal, obstacle, compression_ratio, stress)

    def _measure_reference(self, iterations: int, substeps: int) -> StepResult:
        x, v, forces = self.q, self.v, self.contact_forces
        fruit, grip = self.fruit, self._grip
        faces = self._faces(grip)
        normal = np.zeros(fruit.n_nodes)
        wrenches = []
        obstacle = self.contacts.obstacle
        if self._plain_jaws:
            on_side = [obstacle == LEFT, obstacle == RIGHT]
        else:
            on_side = [np.isin(obstacle, self._jaw_faces(side)) for side in (LEFT, RIGHT)]
        for side in (LEFT, RIGHT):
            nodes = np.flatnonzero(on_side[side])
            on_jaw = -forces[nodes].sum(axis=0)
            sign = -1.0 if side == LEFT else 1.0
            r = x[nodes] - (faces[side].origin if self._plain_jaws else
                            np.array([grip.x + sign * 0.5 * grip.gap, grip.lift]))
            torque_y = float(np.sum(r[:, 1] * -forces[nodes, 0] - r[:, 0] * -forces[nodes, 1]))
            wrenches.append(JawWrench(np.array([on_jaw[0], 0.0, on_jaw[1]]),
                                      np.array([0.0, torque_y, 0.0])))
        for index, face in enumerate(faces):
            nodes = np.flatnonzero(self.contacts.obstacle == index)
            normal[nodes] = forces[nodes] @ face.normal
        if self._plain_jaws:
            left_n = float(np.sum(normal[self.contacts.obstacle == LEFT]))
            right_n = float(np.sum(normal[self.contacts.obstacle == RIGHT]))
        else:  # each jaw's force along the closing axis
            left_n = float(np.sum(forces[on_side[LEFT], 0]))
            right_n = -float(np.sum(forces[on_side[RIGHT], 0]))
        jaw_contact = on_side[LEFT] | on_side[RIGHT]
        masses = fruit.masses
        centroid = masses @ x / masses.sum()
        centroid_velocity = masses @ v / masses.sum()
        both = bool(np.any(on_side[LEFT]) and np.any(on_side[RIGHT]))
        slip = self._slip_distance(float(centroid[1] - grip.lift), both,
                                   bool(np.any(jaw_contact)))
        slipping = bool(np.any(jaw_contact) and
                        abs(centroid_velocity[1] - grip.lift_rate) > 1e-3)
        elastic = sum(e.value(x.ravel()) for e in fruit.energies)
        energies = Energies(kinetic=float(0.5 * np.sum(masses * np.sum(v * v, axis=1))),
                            elastic=float(elastic),
                            gravitational=float(self.gravity.value(x.ravel())))
        return StepResult(
            time=self._time, step=self._step, positions=x.copy(), velocities=v.copy(),
            contact_forces=forces.copy(), contact_obstacle=self.contacts.obstacle.copy(),
            contact_sticking=self.contacts.mode == cm.STICK,
            obstacle_names=self.obstacle_names, surface=fruit.surface,
            left_wrench=wrenches[LEFT], right_wrench=wrenches[RIGHT],
            left_jaw_x=-0.5 * grip.gap, right_jaw_x=0.5 * grip.gap,
            jaw_velocity=-0.5 * grip.gap_rate, lift=grip.lift, lift_velocity=grip.lift_rate,
            gap=grip.gap, grip_force=0.5 * (left_n + right_n), slip_distance=slip,
            slipping=slipping, centroid=centroid, energies=energies,
            deformation=deformation(fruit, x, normal, jaw_contact, sum(
                face_contact_length(fruit, x, faces[index], self.contacts.obstacle == index)
                for index in range(len(self._face_side)))),
            newton_iterations=iterations, substeps=substeps)
