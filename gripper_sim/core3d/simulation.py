"""The 3D simulation facade: a 3D fruit between two jaws, stepped in time.

Same commands, observers and step order as the 2D ``gripper_sim.core.simulation``
(gripper kinematics advance, predictor-corrector contact passes around the implicit
Euler Newton solve, commit, measure, observers), with the 2D core's stepper
(``ImplicitEulerSolver(dim=3)``, through ``PatternCachingSolver`` which only assembles
its Hessian faster), contact state and gripper kinematics.

Contact in 3D (modified mass method, Baraff & Witkin 1998): a surface node held by a
plate is STICK (all three directions prescribed: it moves with the plate), SLIP (the
normal prescribed; kinetic friction mu_k R_n opposite its tangential slip velocity, a
smoothed Coulomb cone in the plate's tangent plane) or IMPACT (restitution). A stuck
node starts slipping when its tangential reaction |R_t| exceeds mu_s R_n; a slipping
node sticks again when its slip speed vanishes. Detection: a box test per plate (broad
phase) and one vectorised gap test of every free surface node (narrow phase).

Jaws: flat plates, or the 2D finger profiles (arc, vgroove) extruded along y as flat
facets (``core3d.fingers3d``); a soft pad is an elastic-foundation energy on the jaw
faces (``core3d.fingers_pad``). The grip force of shaped fingers is the force along the
closing axis x, summed over a jaw's facets; wrench torques are about the centre of each
jaw's front plane.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Callable, Mapping

import numpy as np

from gripper_sim.core import contact as cm
from gripper_sim.core.energies import Gravity
from gripper_sim.core.facade import DYNAMIC_KEYS, SimulationFacade  # noqa: F401 (re-export)
from gripper_sim.core.fast_solver import SYMMETRIC_LU_OPTIONS, PatternCachingSolver
from gripper_sim.core.gripper import GripperKinematics, GripperState
from gripper_sim.core.results import Deformation, Energies, JawWrench, StepResult
from gripper_sim.core.stepper import FRICTION_SMOOTHING, StepConstraints
from gripper_sim.core3d import fingers3d, meshes
from gripper_sim.core3d.damage import DamageTracker3D
from gripper_sim.core3d.fingers_pad import PadLayer3D
from gripper_sim.core3d.fruit import FruitModel3D, build_fruit3d
from gripper_sim.core3d.obstacles import Plate
from gripper_sim.errors import ConfigError

LEFT, RIGHT = 0, 1

#: a contact pass adds, of the free nodes that ended inside a face, those at least this
#: fraction of the deepest one's depth; the others, if still inside after the next
#: solve, come in the next pass. Holding every penetrating node at once (a resting
#: fruit's whole cap after its first 20 ms step) and releasing the pulling ones ring by
#: ring took twice the passes and Newton iterations
DEEPEST_FIRST = 0.7

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

    def __init__(self, config: Mapping[str, Any]):
        self.config = dict(config)
        if int(self.config.get('dimension', 2)) != 3:
            raise ConfigError("config key 'dimension' must be 3 for the 3D simulation")
        self.fruit: FruitModel3D = build_fruit3d(self.config)
        self.dt = float(self.config['sim.dt'])
        c = self.config
        rest = self.fruit.rest_positions
        if c['fruit.initial_height'] is not None:
            centre_z = c['fruit.initial_height']
        elif c['world.table']:
            centre_z = c['world.table_height'] - rest[:, 2].min()
        else:
            centre_z = 0.0
        self.initial_positions = rest + np.array([0.0, 0.0, centre_z])
        self.initial_gap = (c['gripper.initial_gap'] if c['gripper.initial_gap'] is not None
                            else min(self.fruit.rest_width + 0.01, c['gripper.max_gap']))
        if self.initial_gap > c['gripper.max_gap']:
            raise ConfigError("config key 'gripper.initial_gap' exceeds 'gripper.max_gap'")
        self.initial_lift = (c['gripper.initial_lift'] if c['gripper.initial_lift'] is not None
                             else centre_z)
        self.gravity = Gravity(self.fruit.masses, c['world.gravity'], dim=3)
        self._plain_jaws = (c['gripper.finger.type'] == 'flat'
                            and not c['gripper.finger.pad.enabled'])
        self._pad = self._make_pad() if c['gripper.finger.pad.enabled'] else None
        self.solver = PatternCachingSolver(
            self.fruit.masses, list(self.fruit.energies) + [self.gravity]
            + ([self._pad] if self._pad is not None else []),
            damping_mass=c['fruit.damping.mass'], damping_stiffness=c['fruit.damping.stiffness'],
            tolerance=c['sim.newton_tolerance'], max_iterations=c['sim.max_newton_iterations'],
            dim=3, lu_options=SYMMETRIC_LU_OPTIONS)
        # first guess of d force / d gap for the force regulator (it adapts): a Hertz
        # contact of the flesh at a 1 % approach
        radius = 0.5 * self.fruit.rest_width
        self.kinematics = GripperKinematics(
            c['gripper.max_gap'], c['gripper.lift_acceleration'],
            c['gripper.force_time_constant'],
            initial_stiffness=0.1 * c['fruit.flesh.youngs_modulus'] * radius,
            transport_acceleration=c.get('gripper.transport_acceleration', 1.0))
        self._observers: list[Callable[[StepResult3D], None]] = []
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self) -> None:
        """Back to the initial state and commands, time 0."""
        n = self.fruit.n_nodes
        self.solver.reset()
        self.q = self.initial_positions.copy()
        self.v = np.tile([self.config['fruit.initial_velocity.x'], 0.0,
                          self.config['fruit.initial_velocity.z']], (n, 1)).astype(float)
        self.contacts = cm.ContactState.empty(n)
        self.contact_forces = np.zeros((n, 3))
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
            x_speed=self.config.get('gripper.transport_speed', 0.1))
        self._jaw_force = (0.0, 0.0)
        self._damage = DamageTracker3D(self.fruit, self.config)
        if self._pad is not None:
            self._pad.begin_step(self.q, self._pad_faces(self._grip),
                                 self._pad_faces(self._grip), self.dt)
            self._pad.finish_step(self.q.ravel())
        self._last = self._measure(0, 1)

    # ------------------------------------------------------------------ geometry
    def _make_faces(self) -> list[Plate]:
        c = self.config
        jaw = dict(half_extents=np.array([0.5 * c['gripper.jaw_width'],
                                          0.5 * c['gripper.jaw_height']]),
                   thickness=c['gripper.jaw_thickness'],
                   static_friction=c['contact.jaw.static_friction'],
                   kinetic_friction=c['contact.jaw.kinetic_friction'])
        jaw_tangents = np.stack([_Y, _Z])
        if self._plain_jaws:
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

    def _faces(self, grip: GripperState) -> list[Plate]:
        faces = [replace(f) for f in self._faces_template]
        for index, side in enumerate(self._face_side):
            sign = -1.0 if side == LEFT else 1.0
            faces[index].origin = self._jaw_origin(grip, side) + self._face_offsets[index]
            faces[index].velocity = np.array([grip.x_rate + sign * 0.5 * grip.gap_rate, 0.0,
                                              grip.lift_rate])
        return faces

    @staticmethod
    def _jaw_origin(grip: GripperState, side: int) -> np.ndarray:
        """(3,) m, centre of the jaw's front plane (where the gap is measured)."""
        sign = -1.0 if side == LEFT else 1.0
        return np.array([grip.x + sign * 0.5 * grip.gap, 0.0, grip.lift])

    def _jaw_faces(self, side: int) -> list[int]:
        """Obstacle indices of the faces of jaw ``side`` (LEFT or RIGHT)."""
        return [i for i, s in enumerate(self._face_side) if s == side]

    def _make_pad(self) -> PadLayer3D:
        c, fruit = self.config, self.fruit
        areas = meshes.vertex_areas(fruit.rest_positions, fruit.triangles, fruit.n_nodes)
        return PadLayer3D(fruit.surface, areas[fruit.surface],
                          c['gripper.finger.pad.thickness'],
                          c['gripper.finger.pad.youngs_modulus'],
                          c['gripper.finger.pad.poisson_ratio'], c['contact.pad.friction'],
                          fruit.n_nodes)

    def _pad_faces(self, grip: GripperState) -> list:
        faces = self._faces(grip)
        return [(faces[i], side, i) for i, side in enumerate(self._face_side)]

    @property
    def obstacle_names(self) -> tuple:
        return tuple(f.name for f in self._faces_template)

    # ------------------------------------------------------------------ stepping
    def _substep(self, dt: float) -> int:
        if self._pad is None:
            return self._substep_hard(dt)
        grip_new = self._advance_gripper(dt)
        self._pad.begin_step(self.q, self._pad_faces(self._grip), self._pad_faces(grip_new), dt)
        iterations = self._substep_hard(dt)
        self._pad.finish_step(self.q.ravel())
        hard = self._jaw_force
        self._jaw_force = (hard[0] + float(self._pad.side_force[0]),
                           hard[1] + float(self._pad.side_force[1]))
        return iterations

    def _substep_hard(self, dt: float) -> int:
        """One step with the hard contacts (the pads, if any, set up by the caller)."""
        grip_new = self._advance_gripper(dt)
        old_faces, new_faces = self._faces(self._grip), self._faces(grip_new)
        x_n, v_n = self.q, self.v
        q_n = x_n.ravel()
        x_pred = x_n + dt * v_n
        contacts = self.contacts.copy()
        n = self.fruit.n_nodes
        released = np.zeros(n, bool)
        slipped = np.zeros(n, bool)
        iterations = 0
        for _ in range(self.config['sim.max_contact_passes']):
            q_start, constraints = self._constraints(contacts, x_n, x_pred, old_faces,
                                                     new_faces, dt)
            solution = self.solver.solve(q_n, v_n.ravel(), dt, q_start.ravel(), constraints)
            iterations += solution.iterations
            x = solution.q.reshape(-1, 3)
            reaction = solution.reaction.reshape(-1, 3)
            if not self._update_contacts(contacts, x, x_n, v_n, reaction, old_faces, new_faces,
                                         dt, released, slipped):
                break
        v = (x - x_n) / dt
        forces = np.zeros((n, 3))
        for index, face in enumerate(new_faces):
            nodes = np.flatnonzero(contacts.obstacle == index)
            if not nodes.size:
                continue
            nrm = face.normal
            stuck = contacts.mode[nodes] == cm.STICK
            v_t = v[nodes] - np.outer(v[nodes] @ nrm, nrm)
            v_t[stuck] = face.velocity - (face.velocity @ nrm) * nrm
            v_n_new = face.velocity @ nrm + contacts.bounce_speed[nodes]
            v[nodes] = v_t + v_n_new[:, None] * nrm
            forces[nodes] = reaction[nodes]
        for node in np.flatnonzero(contacts.secondary >= 0):
            face = new_faces[contacts.secondary[node]]
            v[node] += (face.velocity @ face.normal - v[node] @ face.normal) * face.normal
        contacts.release(np.flatnonzero(contacts.mode == cm.IMPACT))
        self.q, self.v, self.contacts, self.contact_forces = x, v, contacts, forces
        self._grip = grip_new
        self._time += dt
        self._jaw_force = self._closing_forces(forces, contacts.obstacle, new_faces)
        return iterations

    def _closing_forces(self, forces, obstacle, faces) -> tuple:
        """(left, right) N, each jaw's hard-contact force on the fruit along its closing
        axis (the plate normal for flat jaws), summed over its faces."""
        if self._plain_jaws:
            return tuple(float(np.sum(forces[obstacle == side] @ faces[side].normal))
                         for side in (LEFT, RIGHT))
        return tuple(sign * float(np.sum(forces[np.isin(obstacle, self._jaw_faces(side)), 0]))
                     for side, sign in ((LEFT, 1.0), (RIGHT, -1.0)))

    def _constraints(self, contacts: cm.ContactState, x_n, x_pred, old_faces, new_faces,
                     dt: float):
        """Start positions (n, 3) with held nodes at their targets, and the step filters."""
        n = self.fruit.n_nodes
        start = x_pred.copy()
        filters = np.tile(np.eye(3), (n, 1, 1))
        fr_nodes, fr_tangents, fr_bounds, fr_speed = [], [], [], []
        v_corr = self.config['contact.max_correction_speed']
        for index, face in enumerate(new_faces):
            nodes = np.flatnonzero(contacts.obstacle == index)
            if not nodes.size:
                continue
            nrm, tan = face.normal, face.tangents
            mode = contacts.mode[nodes]
            penetration = np.maximum(0.0, -old_faces[index].gap(x_n[nodes]))
            target = -np.maximum(0.0, penetration - v_corr * dt)
            impact = mode == cm.IMPACT
            target[impact] = contacts.impact_gap[nodes[impact]]
            start[nodes] += (target - face.gap(start[nodes]))[:, None] * nrm
            stuck = mode == cm.STICK
            if np.any(stuck):
                held = nodes[stuck]
                along = x_n[held] @ tan.T + dt * (tan @ face.velocity)  # (k, 2)
                start[held] += (along - start[held] @ tan.T) @ tan
                filters[held] = 0.0
            filters[nodes[~stuck]] = np.eye(3) - np.outer(nrm, nrm)
            sliding = nodes[mode == cm.SLIP]
            if sliding.size and face.kinetic_friction > 0:
                fr_nodes.append(sliding)
                fr_tangents.append(np.broadcast_to(tan, (sliding.size, 2, 3)))
                fr_bounds.append(face.kinetic_friction * np.maximum(
                    contacts.normal_force[sliding], 0.0))
                fr_speed.append(np.broadcast_to(tan @ face.velocity, (sliding.size, 2)))
        for node in np.flatnonzero(contacts.secondary >= 0):
            # the second face's normal gap, set by a move that keeps the first one's gap
            # (along u = P n, P the node's filter); the filter stays a symmetric
            # projector, now also orthogonal to n (at a V's edge: onto the edge line)
            face = new_faces[contacts.secondary[node]]
            u = filters[node] @ face.normal
            uu = float(u @ u)
            if uu < 1e-12:
                continue
            start[node] += (0.0 - face.gap(start[node][None])[0]) / uu * u
            filters[node] = filters[node] - np.outer(u, u) / uu
        if fr_nodes:
            con = StepConstraints(filters, np.concatenate(fr_nodes), np.concatenate(fr_tangents),
                                  np.concatenate(fr_bounds), np.concatenate(fr_speed))
        else:
            con = StepConstraints.free(n, dim=3)
            con.filters = filters
        return start, con

    def _update_contacts(self, contacts: cm.ContactState, x, x_n, v_n, reaction, old_faces,
                         new_faces, dt, released, slipped) -> bool:
        """Correct the contact set after a solve; True if it changed (solve again)."""
        changed = False
        threshold = self.config['contact.release_threshold']
        for index, face in enumerate(new_faces):
            nodes = np.flatnonzero(contacts.obstacle == index)
            if not nodes.size:
                continue
            nrm, tan = face.normal, face.tangents
            r_n = reaction[nodes] @ nrm
            r_t = np.linalg.norm(reaction[nodes] @ tan.T, axis=1)
            mode = contacts.mode[nodes]
            pulling = (r_n < -threshold) & (mode != cm.IMPACT)
            if np.any(pulling):
                contacts.release(nodes[pulling])
                released[nodes[pulling]] = True
                changed = True
            keep = ~pulling
            stuck = keep & (mode == cm.STICK)
            to_slip = stuck & (r_t > face.static_friction * r_n)
            if np.any(to_slip):
                contacts.mode[nodes[to_slip]] = cm.SLIP
                slipped[nodes[to_slip]] = True
                changed = True
            sliding = keep & (mode == cm.SLIP)
            if np.any(sliding):
                rel = np.linalg.norm(((x[nodes] - x_n[nodes]) / dt - face.velocity) @ tan.T,
                                     axis=1)
                to_stick = (sliding & (rel < 2 * FRICTION_SMOOTHING)
                            & ~slipped[nodes] & (face.static_friction > 0))
                if np.any(to_stick):
                    contacts.mode[nodes[to_stick]] = cm.STICK
                    changed = True
                lag = contacts.normal_force[nodes]
                stale = sliding & ~to_stick & (np.abs(r_n - lag) > 0.02 * np.abs(lag) + 1e-9)
                if np.any(stale) and face.kinetic_friction > 0:
                    changed = True
            contacts.normal_force[nodes[keep]] = r_n[keep]
        for node in np.flatnonzero(contacts.secondary >= 0):
            face = new_faces[contacts.secondary[node]]
            if reaction[node] @ face.normal < -threshold:
                contacts.secondary[node] = -1
                changed = True
        if self._add_corners(contacts, x, new_faces):
            changed = True
        if self._add_penetrating(contacts, x, x_n, v_n, old_faces, new_faces, dt, released):
            changed = True
        return changed

    def _add_corners(self, contacts, x, new_faces) -> bool:
        """Held nodes pushed into a second face (a corner) get it as a secondary hold."""
        held = np.flatnonzero((contacts.obstacle >= 0) & (contacts.secondary < 0))
        added = False
        for index, face in enumerate(new_faces):
            nodes = held[contacts.obstacle[held] != index]
            if not nodes.size:
                continue
            inside = nodes[face.covers(x[nodes]) & (face.gap(x[nodes]) < 0)]
            if inside.size:
                contacts.secondary[inside] = index
                contacts.mode[inside[contacts.mode[inside] == cm.STICK]] = cm.SLIP
                held = np.setdiff1d(held, inside)
                added = True
        return added

    def _add_penetrating(self, contacts, x, x_n, v_n, old_faces, new_faces, dt, released) -> bool:
        surface = self.fruit.surface
        candidates = surface[(contacts.obstacle[surface] < 0) & ~released[surface]]
        if not candidates.size:
            return False
        pts = x[candidates]
        low, high = pts.min(axis=0), pts.max(axis=0)
        depth = np.zeros(candidates.size)
        chosen = -np.ones(candidates.size, np.int64)
        for index, face in enumerate(new_faces):
            if not face.may_touch(low, high):  # broad phase
                continue
            gap = face.gap(pts)
            inside = face.covers(pts) & (gap < 0) & (-gap > depth)
            depth[inside] = -gap[inside]
            chosen[inside] = index
        hit = chosen >= 0
        if not np.any(hit):
            return False
        for face_index in np.unique(chosen[hit]):
            # the deepest first: shallower nodes often come free once these are held
            on = chosen == face_index
            hit &= ~on | (depth >= DEEPEST_FIRST * depth[on].max())
        nodes, index = candidates[hit], chosen[hit]
        contacts.obstacle[nodes] = index
        mu_s = np.array([f.static_friction for f in new_faces])
        contacts.mode[nodes] = np.where(mu_s[index] > 0, cm.STICK, cm.SLIP)
        contacts.normal_force[nodes] = 0.0
        v_min = max(5.0 * self.config['world.gravity'] * dt, 1e-3)
        for face_index in np.unique(index):
            face, old = new_faces[face_index], old_faces[face_index]
            if face.restitution <= 0:
                continue
            sel = nodes[index == face_index]
            gap_start = old.gap(x_n[sel])
            gap_end = face.gap(x[sel])
            with np.errstate(divide='ignore', invalid='ignore'):
                tau = np.where(gap_start > 0, np.clip(gap_start / (gap_start - gap_end), 0, 1),
                               0.0)
            v_start = (v_n[sel] - face.velocity) @ face.normal
            v_end = ((x[sel] - x_n[sel]) / dt - face.velocity) @ face.normal
            approach = -(v_start + tau * (v_end - v_start))
            bouncing = approach > v_min
            b = sel[bouncing]
            contacts.mode[b] = cm.IMPACT
            contacts.bounce_speed[b] = face.restitution * approach[bouncing]
            contacts.impact_gap[b] = contacts.bounce_speed[b] * (1.0 - tau[bouncing]) * dt
        return True

    # ------------------------------------------------------------------ outputs
    def _measure(self, iterations: int, substeps: int) -> StepResult3D:
        x, v, forces = self.q, self.v, self.contact_forces
        fruit, grip = self.fruit, self._grip
        faces = self._faces(grip)
        n = fruit.n_nodes
        obstacle = self.contacts.obstacle.copy()
        if self._pad is not None:
            forces = forces + self._pad.forces
            on_pad = (obstacle < 0) & (self._pad.holder >= 0)
            obstacle[on_pad] = self._pad.holder[on_pad]
        normal = np.zeros(n)
        for index, face in enumerate(faces):
            nodes = np.flatnonzero(obstacle == index)
            normal[nodes] = forces[nodes] @ face.normal
        sides = [np.isin(obstacle, self._jaw_faces(side)) for side in (LEFT, RIGHT)]
        wrenches = []
        for side in (LEFT, RIGHT):
            on_jaw = -forces[sides[side]]
            r = x[sides[side]] - self._jaw_origin(grip, side)
            torque = meshes.cross_rows(r, on_jaw).sum(axis=0)
            wrenches.append(JawWrench(on_jaw.sum(axis=0), torque))
        if self._plain_jaws:
            left_n = float(np.sum(normal[sides[LEFT]]))
            right_n = float(np.sum(normal[sides[RIGHT]]))
        else:  # along the closing axis
            left_n, right_n = -wrenches[LEFT].force[0], wrenches[RIGHT].force[0]
        masses = fruit.masses
        centroid = masses @ x / masses.sum()
        centroid_velocity = masses @ v / masses.sum()
        on_left, on_right = sides
        both = bool(np.any(on_left) and np.any(on_right))
        jaw_contact = on_left | on_right
        slip = self._slip_distance(float(centroid[2] - grip.lift), both,
                                   bool(np.any(jaw_contact)))
        slipping = bool(np.any(jaw_contact) and
                        abs(centroid_velocity[2] - grip.lift_rate) > 1e-3)
        elastic = sum(e.value(x.ravel()) for e in fruit.energies)
        energies = Energies(kinetic=float(0.5 * np.sum(masses * np.sum(v * v, axis=1))),
                            elastic=float(elastic),
                            gravitational=float(self.gravity.value(x.ravel())))
        deformation = self._deformation(x, normal, on_left, on_right)
        damage = self._damage.update(x, deformation.node_pressure,
                                     deformation.compression_ratio)
        return StepResult3D(
            time=self._time, step=self._step, positions=x.copy(), velocities=v.copy(),
            contact_forces=forces.copy(), contact_obstacle=obstacle,
            contact_sticking=self.contacts.mode == cm.STICK,
            obstacle_names=self.obstacle_names, surface=fruit.surface,
            left_wrench=wrenches[LEFT], right_wrench=wrenches[RIGHT],
            left_jaw_x=grip.x - 0.5 * grip.gap, right_jaw_x=grip.x + 0.5 * grip.gap,
            jaw_velocity=-0.5 * grip.gap_rate, lift=grip.lift, lift_velocity=grip.lift_rate,
            gap=grip.gap, grip_force=0.5 * (left_n + right_n), slip_distance=slip,
            slipping=slipping, centroid=centroid, energies=energies,
            deformation=deformation, newton_iterations=iterations, substeps=substeps,
            damage=damage,
            gripper_x=grip.x, gripper_x_velocity=grip.x_rate, triangles=fruit.triangles)

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
        faces = self._faces(self._grip)
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
