"""The fast path of ``Simulation``: shell, point and solid fruit models, flat, arc or
V-groove fingers (one face or several per jaw), with or without soft pads.

``FastPath`` runs a whole step - gripper faces, contact constraints, Newton, contact
set updates, then the step's measures and damage of the end state - in one numba
kernel call (``gripper_sim.core.kernels.substep``), and builds the StepResult from its
numbers (the parts observers rarely read - velocities, contact forces and sticking,
slipping, centroid, jaw wrenches, energies, damage contact patches - on first read),
instead of the generic route (the contact passes in Python around
``fast_solver.PatternCachingSolver``). It gives the same results as the triplet/SuperLU
reference solver of the tests on that route (test/test_fast_path.py: trajectories within
1e-9, same contact sets and Newton iterations) and is chosen by ``Simulation`` when the
contact model is the default one, the fruit's energies are the ring energies
(stretching, bending, enclosed-area pressure), the solid's neo-Hookean triangles and
gravity, and the obstacles move as the kernels model them (``FastPath.applies``: the
jaws' faces with the gripper, the rest fixed). Soft pads (``pad.PadLayer``): the kernel
sets the layer up for the step, adds its energy to the Newton solve and records its
forces, as the layer's ``begin_step``, ``evaluate`` and ``finish_step`` do. The contact
passes are the shared compiled ones (``contact_kernels``), whose filters are symmetric
projectors, so a node held by two faces (a V-groove flank and the table) stays in the
kernel; a step whose filter were not symmetric would be done by the generic path
(``kernels.UNSUPPORTED``, a guard; ``FastPath.fallbacks`` counts such steps). The node-block band of a ring is its interleaved outline (half-bandwidth 4); a
meshed solid's Newton matrix is a sparse one (``sparse_ldl``: minimum-degree order, sparse
LDL^T), its energies assembled into it through precomputed scatter maps.
``Simulation(config, fast=False)`` turns it off: the generic route (``core.contact_passes``
around ``fast_solver.PatternCachingSolver``) then steps the 2D fruit, as it does for a
barrier contact model or deformable fingers.

A run that nobody watches step by step runs many of these steps in one call, the jaw
drive and the run's bookkeeping included (``core.multistep``, ``Simulation.advance``),
on this class's constants and scratch space.

numba's compiled kernels are cached on disk (``cache=True``, next to the sources);
``gripper_sim.workflows.compile_kernels`` compiles them once, at install time
(``make install`` does). A cold compile takes ~15-20 s of CPU.
"""
from __future__ import annotations

import dataclasses
import time
from typing import TYPE_CHECKING

import numpy as np

from gripper_sim.core import contact as cm
from gripper_sim.core.damage import Contact, Damage, DamageTracker
from gripper_sim.core.deferred import build, build_deferred
from gripper_sim.core.energies import (EnclosedAreaPressure, NeoHookeanTriangles, RingBending,
                                       Stretching)
from gripper_sim.core.measures import tributary_lengths
from gripper_sim.core.results import Deformation, Energies, JawWrench, StepResult
from gripper_sim.core.slip import jaw_contacts_sliding
from gripper_sim.core.stepper import NEWTON_FAILURES, NewtonFailure

from gripper_sim.core import kernels, sparse_ldl

if TYPE_CHECKING:
    from gripper_sim.core.simulation import Simulation

#: the StepResult fields observers rarely read, which ``FastPath.measure`` builds on first
#: read (``core.deferred``)
RARELY_READ = ('velocities', 'contact_forces', 'contact_sticking', 'slipping', 'centroid',
               'left_wrench', 'right_wrench', 'energies')


def _empty_model():
    return dict(edges=np.zeros((0, 2), np.int64), spar=np.zeros((0, 2)),
                triples=np.zeros((0, 3), np.int64), bpar=np.zeros((0, 2)),
                ring=np.zeros(0, np.int64), press=np.zeros(4),
                flesh=(np.zeros((0, 3), np.int64), np.zeros((0, 2, 2)), np.zeros(0), np.zeros(2),
                       np.zeros((0, 36), np.int64), _solid_skin(None, None, None, None),
                       sparse_ldl.analyse(0, np.zeros((0, 2), np.int64), 2).arrays))


def _solid_skin(model: dict | None, pattern, edges, triples) -> tuple:
    """The skin's arrays of a meshed solid's sparse assembly (``kernels._solid_energies``):
    stretching rest lengths (n_e,) m, stiffnesses EA/L (n_e,) N/m, scatter (n_e, 16);
    bending rest angles (n_t,) rad, stiffnesses EI/l (n_t,) N m, scatter (n_t, 36)."""
    if model is None:
        return (np.zeros(0), np.zeros(0), np.zeros((0, 16), np.int64), np.zeros(0),
                np.zeros(0), np.zeros((0, 36), np.int64))
    return (np.ascontiguousarray(model['spar'][:, 0]), np.ascontiguousarray(model['spar'][:, 1]),
            pattern.scatter(edges).reshape(-1, 16),
            np.ascontiguousarray(model['bpar'][:, 0]), np.ascontiguousarray(model['bpar'][:, 1]),
            pattern.scatter(triples).reshape(-1, 36))


def ring_model(fruit, energies) -> dict | None:
    """Kernel arrays of the fruit's energies, or None if the kernels do not cover them.

    Args:
        fruit: the FruitModel.  energies: the fruit's internal energies.

    Returns:
        dict with edges (n_e, 2), spar (n_e, 2) [L, EA/L], triples (n_t, 3),
        bpar (n_t, 2) [phi0, k], ring (n_r,), press (4,) [A0, b, p0, K], flesh (the
        neo-Hookean triangles of a solid fruit and its sparse Newton matrix, see
        ``kernels._energies``), pos (n,) band positions (a solid's: its sparse order) and
        nbw (node half-bandwidth; 0 for a solid).
    """
    n = fruit.n_nodes
    model = _empty_model()
    seen = set()
    flesh = None
    for energy in energies:
        kind = type(energy)
        if kind in seen or kind not in (Stretching, RingBending, EnclosedAreaPressure,
                                        NeoHookeanTriangles):
            return None
        seen.add(kind)
        if kind is NeoHookeanTriangles:
            flesh = energy
            continue
        if kind is Stretching:
            model['edges'] = np.ascontiguousarray(energy.edges, dtype=np.int64)
            model['spar'] = np.ascontiguousarray(
                np.stack([energy.rest, energy.ea / energy.rest], axis=1))
        elif kind is RingBending:
            triples = np.ascontiguousarray(energy.triples, dtype=np.int64)
            # the kernel shares edge terms between neighbouring triples of a closed ring
            if len(triples) < 3 or not np.array_equal(triples[:, :2],
                                                      np.roll(triples, 1, axis=0)[:, 1:]):
                return None
            model['triples'] = triples
            model['bpar'] = np.ascontiguousarray(np.stack([energy.phi0, energy.k], axis=1))
        else:
            model['ring'] = np.ascontiguousarray(energy.ring, dtype=np.int64)
            model['press'] = np.array([energy.a0, energy.b, energy.p0, energy.k])
    pairs = [model['edges'], model['triples'][:, [0, 1]], model['triples'][:, [1, 2]],
             model['triples'][:, [0, 2]]]
    ring = model['ring']
    if len(ring):
        pairs.append(np.stack([ring, np.roll(ring, -1)], axis=1))
    if flesh is not None:
        tri = np.asarray(flesh.tri, dtype=np.int64)
        pairs += [tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [0, 2]]]
    for pair in pairs:
        if len(pair) and (pair.min() < 0 or pair.max() >= n):
            return None
    if flesh is not None:
        if len(ring):
            return None  # a pressurised solid: its rank-one term is the band's alone
        return _solid_model(model, flesh, pairs, n)
    # band order: a ring's outline interleaved (0, N-1, 1, N-2, ...)
    surface = np.asarray(fruit.surface, dtype=np.int64)
    pos = np.empty(n, np.int64)
    if n == 1:
        pos[:] = 0
    elif len(surface) == n and set(surface.tolist()) == set(range(n)):
        pos[surface] = kernels.band_order(n)
    else:
        return None  # energies on nodes off the outline without a mesh
    nbw = 0
    for pair in pairs:
        if len(pair):
            nbw = max(nbw, int(np.max(np.abs(pos[pair[:, 0]] - pos[pair[:, 1]]))))
    model['pos'] = pos
    model['nbw'] = nbw
    return model


def _solid_model(model: dict, flesh: NeoHookeanTriangles, pairs: list, n: int) -> dict:
    """``model`` completed for a meshed solid: its Newton matrix is a sparse one of 2 x 2
    node blocks (``sparse_ldl``, minimum-degree order) that the energies are assembled
    into through scatter maps: flesh = (tri, dm_inv, volume, [mu, lambda], the triangles'
    scatter (n_tri, 36), the skin's arrays (``_solid_skin``), the pattern's kernel arrays
    (``SparsePattern.arrays``)); pos its order, nbw 0."""
    tri = np.ascontiguousarray(flesh.tri, dtype=np.int64)
    pattern = sparse_ldl.analyse(n, np.concatenate([pair for pair in pairs if len(pair)]), 2)
    model['flesh'] = (tri, np.ascontiguousarray(flesh.dm_inv, dtype=float),
                      np.ascontiguousarray(flesh.volume, dtype=float),
                      np.array([flesh.mu, flesh.lam], dtype=float), pattern.scatter(tri),
                      _solid_skin(model, pattern, model['edges'], model['triples']),
                      pattern.arrays)
    model['pos'] = pattern.position
    model['nbw'] = 0
    return model


class FastPath:
    """Steps and measures a ``Simulation`` with the numba kernels.

    Built by ``Simulation.__init__`` through ``FastPath.create``; holds only constant
    arrays and scratch space - the state stays the simulation's: the path reads it through
    the simulation's public properties and hands a step's end back through
    ``Simulation.commit_step`` (``core.multistep``: ``commit_advance``).
    """

    def __init__(self, sim: 'Simulation', model: dict):
        fruit = sim.fruit
        n = fruit.n_nodes
        self.sim = sim
        self.model = model
        solver = sim.solver
        self.masses2 = np.ascontiguousarray(solver.m, dtype=float)
        self.masses = np.ascontiguousarray(fruit.masses, dtype=float)
        self.gravity_grad = np.ascontiguousarray(sim.gravity.grad, dtype=float)
        self.surface = np.ascontiguousarray(fruit.surface, dtype=np.int64)
        self.skin_edges = np.ascontiguousarray(fruit.skin_edges, dtype=np.int64).reshape(-1, 2)
        rest = fruit.rest_positions
        seg0 = rest[self.skin_edges[:, 1]] - rest[self.skin_edges[:, 0]]
        self.rest_segments = np.ascontiguousarray(np.hypot(seg0[:, 0], seg0[:, 1]))
        self.fpar = np.zeros(8)
        self.fpar[kernels.F_ALPHA] = solver.alpha
        self.fpar[kernels.F_BETA] = solver.beta
        self.fpar[kernels.F_TOL] = solver.tolerance
        self.ipar = np.array([solver.max_iterations, 1], np.int64)
        self.history = np.zeros(solver.max_iterations)
        self.out = np.zeros(9)
        self.measures = np.zeros(kernels.M_SIZE)
        #: work done so far (see kernels.C_*): solves, evaluations, factorisations
        self.counts = np.zeros(kernels.C_SIZE, np.int64)
        self.n = n
        self._template = None
        #: the simulation's face set (``faces_template``) as ``applies`` last took it: the
        #: one the per-face-set caches here are kept for
        self._checked = None
        #: the simulation's pad layer (None: no pads) and whether its jaws are plain flat
        #: faces, both fixed when it is built
        self._pad = sim.pad
        self._plain_jaws = sim.plain_jaws
        self._tracker = None
        self._tracker_seen = None
        self._damage_faces = None
        self._no_pad = np.zeros(0)
        #: the pad outputs of a step without pads (the kernel leaves them alone)
        self._no_pad_out = (np.empty((0, 2)), np.empty(0), np.empty(0, np.int64), np.empty(2))
        self._no_damage = (np.zeros((0, 3)), np.zeros(0), np.zeros(3), np.zeros(0),
                           np.zeros(0), np.zeros(0), np.zeros((0, kernels.P_SIZE)),
                           np.zeros(3))
        self._names_of = None
        #: (face_par, each face's jaw (k,), normals (k, 2)) for ``_sliding``
        self._jaw_faces_kept = None
        self._names_cache: tuple = ()
        self._applies = False
        self.face_par = np.zeros((0, kernels.FP_SIZE))
        #: steps the generic path did because the kernel cannot (kernels.UNSUPPORTED)
        self.fallbacks = 0
        self.face_dyn = np.zeros((0, 6))
        self._energy_args = (model['edges'], model['spar'], model['triples'], model['bpar'],
                             model['ring'], model['press'], model['flesh'], self.gravity_grad)
        #: wall time (s) spent per part while ``timing`` is True
        self.timers = {'glue': 0.0, 'kernel': 0.0, 'measures': 0.0}
        self._measured = None
        self.timing = False
        self._config_seen = None
        #: the kernel steps the fruit's flesh (and measures its von Mises stress)
        self.flesh_in_kernel = len(model['flesh'][0]) > 0
        #: the substep kernel's scratch space, allocated once (``kernels.substep_scratch``)
        self.scratch = kernels.substep_scratch(model['pos'], model['nbw'], model['flesh'])
        tri, dm_inv, volume, lame, tri_scatter, skin, pattern = model['flesh']
        #: the fruit's constant arrays as the substep kernel takes them
        self.constants = kernels.pack_constants(
            [self.masses2, self.masses, self.rest_segments, model['spar'], model['bpar'],
             model['press'], self.gravity_grad, dm_inv, volume, lame, skin[0], skin[1],
             skin[3], skin[4]],
            [self.surface, self.skin_edges, model['pos'], model['edges'], model['triples'],
             model['ring'], tri, tri_scatter, skin[2], skin[5], *pattern])

    @classmethod
    def create(cls, sim: 'Simulation') -> 'FastPath | None':
        """The fast path for ``sim``, or None when it does not apply."""
        solver_energies = list(sim.solver.energies)
        expected = list(sim.fruit.energies) + [sim.gravity]
        if sim.pad is not None:
            expected.append(sim.pad)
        if len(solver_energies) != len(expected) or any(
                a is not b for a, b in zip(solver_energies, expected)):
            return None  # another energy in the step (a barrier): not modelled here
        model = ring_model(sim.fruit, sim.fruit.energies)
        if model is None:
            return None
        return cls(sim, model)

    # ------------------------------------------------------------------ faces
    def applies(self) -> bool:
        """Whether the kernels model the simulation's obstacles: the jaws' faces moving
        with the gripper as ``Simulation.faces_at`` moves them, the others fixed (table,
        walls). Checked once per face set (``reset`` and ``set_parameter`` make a new
        one); the face set it takes is the one ``face_arrays``, ``obstacle_names`` and
        ``damage_supported`` work on (the simulation asks before every step and
        measure)."""
        template = self.sim.faces_template
        if template is not self._checked:
            self._applies = self._faces_match(template)
            self._checked = template
        return self._applies

    def _faces_match(self, template) -> bool:
        sim = self.sim
        if len(template) < 2:
            return False
        try:  # an arbitrary gripper state: do the faces move as the kernel moves them?
            grip = dataclasses.replace(sim.gripper_state, gap=0.031, lift=0.17, x=0.013,
                                       gap_rate=-0.007, lift_rate=0.011, x_rate=0.005)
            faces = sim.faces_at(grip)
        except (TypeError, ValueError, AttributeError):
            return False
        if len(faces) != len(template):
            return False
        sides, offsets = sim.face_sides, sim.face_offsets
        for k, (face, rest) in enumerate(zip(faces, template)):
            if k < len(sides):
                sign = -1.0 if sides[k] == 0 else 1.0
                origin = (grip.x + sign * (0.5 * grip.gap) + offsets[k][0],
                          grip.lift + offsets[k][1])
                velocity = (grip.x_rate + sign * (0.5 * grip.gap_rate), grip.lift_rate)
            else:
                origin, velocity = tuple(rest.origin), tuple(rest.velocity)
            if not (np.allclose(face.origin, origin, rtol=0, atol=1e-15)
                    and np.allclose(face.velocity, velocity, rtol=0, atol=1e-15)
                    and np.array_equal(face.normal, rest.normal)
                    and face.half_length == rest.half_length
                    and face.thickness == rest.thickness):
                return False
        return True

    def face_arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """The obstacles as the kernels take them, kept per face set: (face_par (k,
        ``kernels.FP_SIZE``): normal, half length m, thickness m, friction coefficients,
        restitution, jaw side (-1: fixed) and offset m from the jaw's origin; face_dyn
        (k, 6): origin m at the step's start and end, velocity m/s)."""
        template = self._checked
        if template is not self._template:
            sides, offsets = self.sim.face_sides, self.sim.face_offsets
            self.face_par = np.array(
                [[f.normal[0], f.normal[1], f.half_length, f.thickness, f.static_friction,
                  f.kinetic_friction, f.restitution]
                 + ([sides[k], offsets[k][0], offsets[k][1]] if k < len(sides)
                    else [-1.0, 0.0, 0.0])
                 for k, f in enumerate(template)], dtype=float).reshape(-1, kernels.FP_SIZE)
            dyn = np.zeros((len(template), 6))
            for k, f in enumerate(template):
                dyn[k, 0:2] = f.origin
                dyn[k, 2:4] = f.origin
                dyn[k, 4:6] = f.velocity
            self.face_dyn = dyn
            self._template = template
        return self.face_par, self.face_dyn

    # ------------------------------------------------------------------ stepping
    def prepare(self, dt: float) -> None:
        """The substep kernel's parameters ``fpar`` and ``ipar`` for a step of ``dt`` s."""
        sim = self.sim
        fpar = self.fpar
        fpar[0] = dt
        fpar[4] = sim.gravity.g
        fpar[7] = sim.fruit.depth
        if sim.config is not self._config_seen:  # a frozen Parameters: read once per config
            config = self._config_seen = sim.config
            fpar[5] = config['contact.release_threshold']
            fpar[6] = config['contact.max_correction_speed']
            self.ipar[1] = config['sim.max_contact_passes']

    def forget_factor(self) -> None:
        """Drop the Newton factorisation the kernel keeps (``kernels.forget_kept``)."""
        kernels.forget_kept(self.scratch[0])

    def pad_arguments(self, pad) -> tuple:
        """The substep kernel's pad arguments for the pad layer ``pad`` (None: no pads):
        (stiffnesses (n,) N/m per node, [thickness m, friction coefficient], the outputs:
        (forces (n, 2) N, normal forces (n,) N, holder (n,), side forces (2,) N)), the
        outputs fresh arrays that ``record_pad`` gives the layer after the step."""
        if pad is None:
            return self._no_pad, self._no_pad, self._no_pad_out
        n = self.n
        return (pad.k, np.array([pad.thickness, pad.mu]),
                (np.empty((n, 2)), np.empty(n), np.empty(n, np.int64), np.empty(2)))

    def keep_end_measures(self, x: np.ndarray, normal: np.ndarray, pressure: np.ndarray,
                          damage: tuple) -> None:
        """Keep what the kernel measured at the end state ``x`` (n, 2) m (normal forces
        (n,) N, node pressures (n_s,) Pa, the step measures and the flesh's largest von
        Mises stress from ``measures`` and ``out``, the damage arguments ``damage``) for
        ``measure`` of that state."""
        self._measured = (x, normal, pressure, self.measures.tolist(), damage,
                          float(self.out[8]))

    def forget_end_measures(self) -> None:
        """The state did not come from the kernel: ``measure`` measures it afresh."""
        self._measured = None

    def substep(self, dt: float) -> int | None:
        """``Simulation._substep`` on the kernels, committed to the simulation
        (``commit_step``); returns Newton iterations, or None for a step the kernel cannot
        do (``kernels.UNSUPPORTED``, counted in ``fallbacks``; nothing changed: the
        caller does it on the generic path).

        Raises:
            NewtonFailure: as the reference solver (the caller halves the step).
        """
        sim = self.sim
        timing = self.timing
        if timing:
            t0 = time.perf_counter()
        grip = sim.gripper_state
        grip_new = sim.gripper_after(dt)
        face_par, face_dyn = self.face_arrays()
        self.prepare(dt)
        c = sim.contacts
        obstacle, mode, secondary = c.obstacle.copy(), c.mode.copy(), c.secondary.copy()
        normal_force, bounce, secondary_bounce = (c.normal_force.copy(), c.bounce_speed.copy(),
                                                  c.secondary_bounce.copy())
        n = self.n
        x, v, forces = np.empty((n, 2)), np.empty((n, 2)), np.empty((n, 2))
        normal, pressure = np.empty(n), np.empty(len(self.surface))
        x_n = sim.q if sim.q.flags.c_contiguous else np.ascontiguousarray(sim.q)
        v_n = sim.v if sim.v.flags.c_contiguous else np.ascontiguousarray(sim.v)
        pad = self._pad
        damage = self.damage_inputs()
        pad_k, pad_scalars, pad_out = self.pad_arguments(pad)
        if timing:
            t1 = time.perf_counter()
        status = kernels.substep(
            x_n, v_n, obstacle, mode, normal_force, bounce, secondary, secondary_bounce,
            face_par, face_dyn, (grip.gap, grip.lift, grip.x, grip_new.gap, grip_new.lift,
                                 grip_new.x, grip_new.gap_rate, grip_new.lift_rate,
                                 grip_new.x_rate),
            *self.constants, self.fpar, self.ipar, x, v, forces, self.history, self.out, normal,
            pressure, self.measures, self.counts, *damage, pad_k, pad_scalars, *pad_out,
            *self.scratch)
        if timing:
            t2 = time.perf_counter()
        out = self.out
        if status != kernels.OK:
            self.forget_end_measures()
            if status == kernels.UNSUPPORTED:
                self.fallbacks += 1
                return None
            history = [float(h) for h in self.history[:int(out[1])]]
            raise NewtonFailure(NEWTON_FAILURES[status].format(sim.solver.max_iterations),
                                history)
        contacts = build(cm.ContactState, dict(
            obstacle=obstacle, mode=mode, normal_force=normal_force, bounce_speed=bounce,
            secondary=secondary, secondary_bounce=secondary_bounce))
        # the jaw forces with the pads' push included
        sim.commit_step(x, v, contacts, forces, grip_new, (float(out[2]), float(out[3])), dt)
        record_pad(pad, pad_out)
        self.keep_end_measures(x, normal, pressure, damage)
        if timing:
            t3 = time.perf_counter()
            self.timers['glue'] += (t1 - t0) + (t3 - t2)
            self.timers['kernel'] += t2 - t1
        return int(out[0])

    # ------------------------------------------------------------------ outputs
    def measure(self, iterations: int, substeps: int) -> StepResult:
        """``Simulation._measure`` (damage included), from the numbers the substep kernel
        measured at its end (or from the measures kernel when the state did not come
        from a substep)."""
        if self.timing:
            t0 = time.perf_counter()
        sim = self.sim
        fruit, grip = sim.fruit, sim.gripper_state
        x, v = sim.q, sim.v
        contacts = sim.contacts
        # every contact force (the pads' included) and the obstacle holding each node
        forces, holder = sim.contact_forces_and_holders()
        measured = self._measured
        damage_of_x = flesh_stress = None
        if measured is not None and measured[0] is x:
            _, normal, pressure, values, damage_of_x, flesh_stress = measured
        else:
            values, normal, pressure = self._measure_kernel(forces, holder)
            pad = self._pad
            if pad is not None:  # the hard contacts' length, plus the pads'
                on_pad = (contacts.obstacle < 0) & (pad.holder >= 0)
                values[kernels.M_CONTACT_LENGTH] = (
                    self._measure_kernel(sim.contact_forces, contacts.obstacle)[0][
                        kernels.M_CONTACT_LENGTH]
                    + float(np.sum(tributary_lengths(fruit, x)[on_pad[fruit.surface]])))
        (lfx, lfz, lty, rfx, rfz, rty, left_n, right_n, cx, cz, _cvx, _cvz, any_left, any_right,
         kinetic, elastic, gravitational, width, max_strain, contact_length,
         peak) = values
        if not self._plain_jaws:  # shaped fingers: each jaw's force along the closing axis
            left_n, right_n = -lfx, rfx
        both = any_left > 0 and any_right > 0
        touching = any_left > 0 or any_right > 0
        slip = sim.measure_slip(cz - grip.lift, both, touching)
        face_par = self.face_arrays()[0]
        compression = fruit.rest_width - width
        ratio = compression / fruit.rest_width if fruit.rest_width > 0 else 0.0
        half = 0.5 * grip.gap
        positions = x.copy()
        damage = self._damage(positions, normal, holder, ratio, damage_of_x, flesh_stress)

        mode = contacts.mode

        def rarely_read():
            return dict(
                velocities=v.copy(), contact_forces=forces.copy(),
                contact_sticking=mode == cm.STICK,
                slipping=touching and self._sliding(v, holder, grip, face_par),
                centroid=np.array([cx, cz]),
                left_wrench=build(JawWrench, dict(force=np.array([lfx, 0.0, lfz]),
                                                   torque=np.array([0.0, lty, 0.0]))),
                right_wrench=build(JawWrench, dict(force=np.array([rfx, 0.0, rfz]),
                                                    torque=np.array([0.0, rty, 0.0]))),
                energies=build(Energies, dict(kinetic=kinetic, elastic=elastic,
                                               gravitational=gravitational)))

        result = build_deferred(StepResult, dict(
            time=sim.time, step=sim.step_count, positions=positions, contact_obstacle=holder,
            obstacle_names=self.obstacle_names(), surface=fruit.surface,
            left_jaw_x=grip.x - half, right_jaw_x=grip.x + half,
            jaw_velocity=-0.5 * grip.gap_rate, lift=grip.lift, lift_velocity=grip.lift_rate,
            gap=grip.gap, grip_force=0.5 * (left_n + right_n), slip_distance=slip,
            deformation=build(Deformation, dict(
                compression=compression, compression_ratio=ratio, max_skin_strain=max_strain,
                contact_length=contact_length, peak_contact_pressure=peak,
                node_pressure=pressure)),
            newton_iterations=iterations, substeps=substeps, damage=damage,
            gripper_x=grip.x, gripper_x_velocity=grip.x_rate), RARELY_READ, rarely_read)
        if self.timing:
            self.timers['measures'] += time.perf_counter() - t0
        return result

    def _sliding(self, v: np.ndarray, obstacle: np.ndarray, grip,
                 face_par: np.ndarray) -> bool:
        """``StepResult.slipping`` (``slip.jaw_contacts_sliding``) of the nodes at velocities
        ``v`` (n, 2) on the kernels' faces ``face_par`` with the gripper state ``grip``: 0
        and 1 the jaws, moving with the gripper (each face's jaw and normal kept per
        ``face_par``)."""
        kept = self._jaw_faces_kept
        if kept is None or kept[0] is not face_par:
            kept = self._jaw_faces_kept = (face_par,
                                           face_par[:, kernels.FP_JAW].astype(np.int64),
                                           np.ascontiguousarray(face_par[:, :2]))
        _, jaw_of_face, normals = kept
        half = 0.5 * grip.gap_rate
        jaw_velocities = np.array([[grip.x_rate - half, grip.lift_rate],
                                   [grip.x_rate + half, grip.lift_rate]])
        return jaw_contacts_sliding(v, obstacle, jaw_of_face, normals,
                                    jaw_velocities[jaw_of_face])

    def obstacle_names(self) -> tuple:
        """``Simulation.obstacle_names``, kept per face set."""
        template = self._checked
        if self._names_of is not template:
            self._names_cache = self.sim.obstacle_names
            self._names_of = template
        return self._names_cache

    def damage_inputs(self) -> tuple:
        """Arguments of the substep kernel's damage part (empty ones skip it)."""
        if not self.damage_supported():
            return self._no_damage
        n_s = len(self.surface)
        return (self._damage_face, self._damage_rest, self._damage_par, self._tracker.covered,
                np.empty(n_s), np.empty(n_s), np.empty((n_s, kernels.P_SIZE)), np.empty(3))

    def damage_supported(self) -> bool:
        """Whether the damage kernel models the simulation's damage tracker (its arrays are
        then kept)."""
        sim = self.sim
        tracker = sim.damage_tracker
        template = self._checked
        if tracker is not self._tracker_seen or template is not self._damage_faces:
            # checked once per tracker (reset makes a new one) and face set
            self._tracker_seen = tracker
            self._damage_faces = template
            if (type(tracker) is not DamageTracker
                    or len(tracker.groups) != len(template)
                    or not np.array_equal(tracker.ring, self.surface)):
                self._tracker = None
            else:
                self._tracker = tracker
                self._damage_face = np.array(
                    [tracker.groups, tracker.curvature, tracker.padded],
                    dtype=float).T.copy().reshape(-1, 3)
                self._damage_rest = np.ascontiguousarray(tracker.rest_curvature, dtype=float)
                self._damage_par = np.array([tracker.bruise_pressure, tracker.rigid_modulus,
                                             tracker.pad_modulus])
        return self._tracker is not None

    def _damage(self, positions, normal, obstacle, ratio, computed=None, flesh_stress=None):
        """``Simulation.assess_damage``: the per-step part of ``DamageTracker.update`` from
        the substep kernel (``computed``: its damage arguments, ``flesh_stress``: the
        flesh's largest von Mises stress Pa, for the state it ended in) or else the
        ``damage_update`` kernel; the tracker keeps the state."""
        sim = self.sim
        if not self.damage_supported():
            return sim.assess_damage(positions, normal, obstacle, ratio)
        tracker = self._tracker  # the simulation's
        if (computed is not None and computed[3] is tracker.covered
                and computed[0] is self._damage_face):
            _, _, _, _, covered, node_pressure, table, d_out = computed
            count, pressure, length = int(d_out[0]), float(d_out[1]), float(d_out[2])
        else:
            covered = tracker.covered.copy()
            node_pressure = np.empty(len(self.surface))
            table = np.zeros((len(self.surface), kernels.P_SIZE))
            face = self._damage_face
            count, pressure, length = kernels.damage_update(
                positions, normal, obstacle, self.surface, face[:, 0].astype(np.int64),
                np.ascontiguousarray(face[:, 1]), np.ascontiguousarray(face[:, 2]),
                self._damage_rest, tracker.bruise_pressure, tracker.rigid_modulus,
                tracker.pad_modulus, covered, node_pressure, table)

        def patches():
            return dict(contacts=tuple(
                build(Contact, dict(body=int(b), load=load, centre=np.array([cx, cz]),
                                     radius=a, peak_pressure=p0, equivalent_radius=re,
                                     modulus=modulus))
                for b, load, cx, cz, a, p0, re, modulus in table[:count].tolist()))

        # the rest of DamageTracker.update (with the solid's von Mises stress)
        flesh = sim.fruit.flesh
        if flesh is None:
            flesh_stress = 0.0
        elif flesh_stress is None or not self.flesh_in_kernel:
            flesh_stress = float(np.max(flesh.von_mises(positions.ravel()), initial=0.0))
        stress = tracker.record(covered, pressure, flesh_stress, ratio)
        perimeter = tracker.perimeter
        return build_deferred(Damage, dict(
            bruised=tracker.peak_pressure > tracker.bruise_pressure, bruised_length=length,
            bruised_fraction=length / perimeter if perimeter > 0 else 0.0, pressure=pressure,
            peak_pressure=tracker.peak_pressure, flesh_stress=stress,
            peak_flesh_stress=tracker.peak_flesh_stress, crushed=tracker.crushed,
            node_pressure=node_pressure), ('contacts',), patches)

    def _measure_kernel(self, forces: np.ndarray, holder: np.ndarray):
        """``step_measures`` of the present state with contact forces (n, 2) N and the
        obstacle (n,) holding each node: (values (list), normal (n,) N, pressure (n_s,)
        Pa)."""
        sim = self.sim
        grip = sim.gripper_state
        face_par, _ = self.face_arrays()
        origins = np.array([[grip.x - 0.5 * grip.gap, grip.lift],
                            [grip.x + 0.5 * grip.gap, grip.lift]])
        normal = np.empty(self.n)
        pressure = np.empty(len(self.surface))
        out = np.empty(kernels.M_SIZE)
        edges, spar, triples, bpar, ring, press, flesh, gravity_grad = self._energy_args
        kernels.step_measures(
            np.ascontiguousarray(sim.q, dtype=float), np.ascontiguousarray(sim.v, dtype=float),
            np.ascontiguousarray(forces, dtype=float), holder,
            self.masses, self.surface, self.skin_edges, self.rest_segments, face_par, origins,
            sim.fruit.depth, edges, spar, triples, bpar, ring, press, flesh, gravity_grad, False,
            np.zeros(4), normal, pressure, out)
        return out.tolist(), normal, pressure


def record_pad(pad, outputs: tuple) -> None:
    """Give the pad layer ``pad`` (None: no pads) the outputs of a kernel's step
    (``FastPath.pad_arguments``): what ``PadLayer.finish_step`` records."""
    if pad is not None:
        pad.forces, pad.normal_forces, pad.holder, pad.side_force = outputs
