"""The 2D whole-step kernel against the triplet/SuperLU reference (test/reference_solver.py).

Kernels against the numpy energies (value, gradient, Hessian), the Newton kernel
against ImplicitEulerSolver.solve, and whole trajectories of Simulation(fast=True)
against Simulation(fast=False) on the reference solver (``reference_route``): positions
within 1e-9 relative every step, the same contact sets, modes and Newton iteration counts.
"""
import copy

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core import fast
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.stepper import StepConstraints
from gripper_sim.errors import ConvergenceError
from gripper_sim.workflows.grasp import GraspSequence

from gripper_sim.core import kernels  # noqa: E402 - needs numba, pinned in requirements.txt

from reference_solver import ImplicitEulerSolver, reference_route

SHELL = ['fruit.nodes=24']


def _shell(*overrides):
    config = load_config(overrides=list(overrides))
    fruit = build_fruit(config)
    model = fast.ring_model(fruit, fruit.energies)
    assert model is not None
    return fruit, model


def _perturbed(fruit, scale=2e-3, seed=0):
    rng = np.random.default_rng(seed)
    return (fruit.rest_positions + rng.normal(scale=scale, size=fruit.rest_positions.shape)
            ).ravel()


def _dense(model, band):
    n = band.shape[0]
    out = np.zeros((2 * n, 2 * n))
    kernels.band_to_dense(band, np.argsort(model['pos']), out)
    return out


@pytest.mark.parametrize('nodes', [8, 24, 64])
def test_band_order_keeps_the_ring_in_a_narrow_band(nodes):
    fruit, model = _shell(f'fruit.nodes={nodes}')
    assert sorted(model['pos']) == list(range(nodes))
    assert model['nbw'] <= 4


@pytest.mark.parametrize('name', ['stretching', 'bending', 'pressure'])
def test_energy_kernels_match_the_numpy_energies(name):
    fruit, model = _shell('fruit.nodes=24', 'fruit.pressure.turgor=3e4')
    q = _perturbed(fruit)
    n = fruit.n_nodes
    grad = np.zeros(2 * n)
    band = np.zeros((n, model['nbw'] + 1, 2, 2))
    area_grad = np.zeros(2 * n)
    energy = {'stretching': fruit.stretching, 'pressure': fruit.pressure,
              'bending': fruit.energies[1]}[name]
    if name == 'stretching':
        value = kernels.ring_stretching(q, model['edges'], model['spar'], model['pos'], True,
                                        grad, band)
        c = 0.0
    elif name == 'bending':
        value = kernels.ring_bending(q, model['triples'], model['bpar'], model['pos'], True,
                                     grad, band)
        c = 0.0
    else:
        value, c = kernels.ring_pressure(q, model['ring'], model['press'], model['pos'], True,
                                         grad, band, area_grad)
        assert c > 0
    hessian = _dense(model, band) + c * np.outer(area_grad, area_grad)
    reference = energy.hessian(q)
    assert abs(value) > 0 and np.max(np.abs(grad)) > 0
    assert value == pytest.approx(energy.value(q), rel=1e-12, abs=1e-18)
    np.testing.assert_allclose(grad, energy.gradient(q), rtol=1e-10,
                               atol=1e-12 * np.max(np.abs(grad)))
    np.testing.assert_allclose(hessian, reference, rtol=1e-9,
                               atol=1e-11 * np.max(np.abs(reference)))


@pytest.mark.parametrize('fruit_model, noise', [
    (['fruit.nodes=24', 'fruit.pressure.turgor=3e4'], 5e-4),  # the band, rank-one term
    (['fruit.model=solid'], 1e-4)],  # the sparse LDL^T
    ids=['shell', 'solid'])
@pytest.mark.parametrize('beta', [1e-4, 2e-3])
def test_newton_kernel_matches_the_reference_solver_with_contact_and_friction(fruit_model,
                                                                              noise, beta):
    """The kernel's Newton and the reference's (with its chord rule): the same iterations
    and end, with mass and stiffness damping (K_n at the step's start in both)."""
    fruit, model = _shell(*fruit_model, 'fruit.damping.mass=5',
                          f'fruit.damping.stiffness={beta}')
    from gripper_sim.core.energies import Gravity
    gravity = Gravity(fruit.masses, 9.81)
    solver = ImplicitEulerSolver(fruit.masses, list(fruit.energies) + [gravity],
                                 damping_mass=5.0, damping_stiffness=beta, tolerance=1e-9)
    solver.keep_factor = True  # the kernel's rule: a factor kept while it contracts
    n = fruit.n_nodes
    q_n = _perturbed(fruit, noise)
    rng = np.random.default_rng(3)
    v_n = rng.normal(scale=0.01, size=q_n.size)
    dt = 1e-3
    con = StepConstraints.free(n)
    start = q_n + dt * v_n
    # node 0 stuck, nodes 1 and 2 on a face of normal +x with kinetic friction
    con.filters[0] = 0.0
    for node in (1, 2):
        con.filters[node] = np.eye(2) - np.outer([1.0, 0.0], [1.0, 0.0])
    con = StepConstraints(con.filters, np.array([1, 2]), np.array([[0.0, 1.0], [0.0, 1.0]]),
                          np.array([0.3, 0.5]), np.array([0.01, 0.01]))
    reference = solver.solve(q_n, v_n, dt, start, con)
    q = np.zeros(2 * n)
    reaction = np.zeros(2 * n)
    history = np.zeros(solver.max_iterations)
    status, iterations, n_hist = kernels.newton_solve(
        q_n, v_n, dt, start, con.filters, con.friction_nodes, con.friction_tangents,
        con.friction_bounds, con.friction_obstacle_speed, solver.m, 5.0, beta, 1e-9,
        solver.max_iterations, model['edges'], model['spar'], model['triples'],
        model['bpar'], model['ring'], model['press'], model['flesh'], gravity.grad,
        model['pos'], model['nbw'], q, reaction, history, np.zeros(4),
        np.zeros(kernels.C_SIZE, np.int64), np.zeros(0, np.int64),
        np.zeros((0, kernels.PAD_SIZE)))
    assert status == kernels.OK
    assert iterations == reference.iterations
    np.testing.assert_allclose(q, reference.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(reaction, reference.reaction, rtol=1e-7,
                               atol=1e-9 * np.max(np.abs(reference.reaction)))
    np.testing.assert_allclose(history[:n_hist], reference.history, rtol=1e-5, atol=1e-9)


def _compare(fast_sim, ref_sim, steps, drive=None):
    """Step both; assert the same trajectory. Returns the number of contact steps."""
    assert fast_sim._fast is not None and ref_sim._fast is None
    in_contact = 0
    sequences = [drive(s) for s in (fast_sim, ref_sim)] if drive else None
    for k in range(steps):
        a, b = fast_sim.step(), ref_sim.step()
        if sequences:
            for seq, r in zip(sequences, (a, b)):
                seq.update(r)
            assert sequences[0].phase == sequences[1].phase, k
        scale = max(np.max(np.abs(b.positions)), 1e-3)
        assert np.max(np.abs(a.positions - b.positions)) <= 1e-9 * scale, k
        np.testing.assert_array_equal(a.contact_obstacle, b.contact_obstacle, err_msg=str(k))
        np.testing.assert_array_equal(a.contact_sticking, b.contact_sticking, err_msg=str(k))
        np.testing.assert_array_equal(fast_sim.contacts.secondary, ref_sim.contacts.secondary)
        assert a.newton_iterations == b.newton_iterations, k
        assert a.substeps == b.substeps
        vscale = max(np.max(np.abs(b.velocities)), 1e-3)
        assert np.max(np.abs(a.velocities - b.velocities)) <= 1e-6 * vscale, k
        fscale = max(np.max(np.abs(b.contact_forces)), 1e-3)
        assert np.max(np.abs(a.contact_forces - b.contact_forces)) <= 1e-6 * fscale, k
        for name in ('time', 'gap', 'lift', 'grip_force', 'slip_distance', 'left_jaw_x',
                     'right_jaw_x', 'jaw_velocity', 'lift_velocity', 'gripper_x',
                     'gripper_x_velocity'):
            assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-6, abs=1e-9), \
                (k, name)
        assert a.slipping == b.slipping
        np.testing.assert_allclose(a.centroid, b.centroid, rtol=1e-9, atol=1e-12)
        for wa, wb in ((a.left_wrench, b.left_wrench), (a.right_wrench, b.right_wrench)):
            np.testing.assert_allclose(wa.force, wb.force, rtol=1e-6, atol=1e-6 * fscale)
            np.testing.assert_allclose(wa.torque, wb.torque, rtol=1e-6, atol=1e-7 * fscale)
        for name in ('kinetic', 'elastic', 'gravitational'):
            assert getattr(a.energies, name) == pytest.approx(
                getattr(b.energies, name), rel=1e-6, abs=1e-9), (k, name)
        da, db = a.deformation, b.deformation
        for name in ('compression', 'compression_ratio', 'max_skin_strain', 'contact_length'):
            assert getattr(da, name) == pytest.approx(getattr(db, name), rel=1e-6,
                                                      abs=1e-9), (k, name)
        assert da.peak_contact_pressure == pytest.approx(db.peak_contact_pressure, rel=1e-6,
                                                         abs=1e-3)
        np.testing.assert_allclose(da.node_pressure, db.node_pressure, rtol=1e-6, atol=1e-3)
        ga, gb = a.damage, b.damage
        assert (ga is None) == (gb is None)
        if ga is not None:
            assert (ga.bruised, ga.crushed, len(ga.contacts)) == (
                gb.bruised, gb.crushed, len(gb.contacts)), k
            for name in ('bruised_length', 'pressure', 'peak_pressure', 'flesh_stress'):
                assert getattr(ga, name) == pytest.approx(getattr(gb, name), rel=1e-6,
                                                          abs=1e-6), (k, name)
            np.testing.assert_allclose(ga.node_pressure, gb.node_pressure, rtol=1e-6,
                                       atol=1e-3)
            for ca, cb in zip(ga.contacts, gb.contacts):
                assert ca.body == cb.body
                for name in ('load', 'radius', 'peak_pressure', 'equivalent_radius',
                             'modulus'):
                    assert getattr(ca, name) == pytest.approx(getattr(cb, name), rel=1e-6,
                                                              abs=1e-9), (k, name)
                np.testing.assert_allclose(ca.centre, cb.centre, rtol=0, atol=1e-9)
        in_contact += bool(np.any(a.contact_obstacle >= 0))
    return in_contact


def test_grasp_and_lift_trajectory_matches_the_reference_path():
    overrides = ['gripper.initial_gap=0.0645', 'gripper.close_speed=0.05',
                 'gripper.lift_acceleration=5', 'gripper.lift_speed=0.05']
    config = load_config(overrides=overrides)
    fast_sim, ref_sim = (Simulation(config, fast=True),
                         reference_route(Simulation(config, fast=False)))
    phases = []

    def drive(sim):
        seq = GraspSequence(sim, 3.0, lift_height=0.005, hold_time=0.05)
        phases.append(seq)
        return seq

    assert _compare(fast_sim, ref_sim, 450, drive) > 300
    assert phases[0].phase in ('lifting', 'holding', 'done')
    assert fast_sim.last.lift > fast_sim.initial_lift + 1e-3


@pytest.mark.parametrize('finger', [['gripper.finger.type=vgroove'],
                                    ['gripper.finger.type=arc'],
                                    ['gripper.finger.pad.enabled=true'],
                                    ['fruit.model=solid', 'gripper.finger.type=vgroove']],
                         ids=['vgroove', 'arc', 'pad', 'solid-vgroove'])
def test_shaped_fingers_and_pads_match_the_reference_path(finger):
    """Several faces per jaw (the facets of a V-groove or an arc), soft pads and the solid
    (neo-Hookean) fruit on the kernel: the same grasp-and-lift trajectory as the
    reference path."""
    overrides = ['fruit.nodes=32', *finger, 'gripper.initial_gap=0.0645',
                 'gripper.close_speed=0.05', 'gripper.lift_acceleration=5',
                 'gripper.lift_speed=0.05']
    config = load_config(overrides=overrides)
    fast_sim, ref_sim = (Simulation(config, fast=True),
                         reference_route(Simulation(config, fast=False)))
    assert fast_sim._fast.applies()
    faces_held = set()

    def drive(sim):
        return GraspSequence(sim, 3.0, lift_height=0.005, hold_time=0.05)

    def record(result):
        faces_held.update(result.contact_obstacle[result.contact_obstacle >= 0].tolist())

    fast_sim.add_observer(record)
    assert _compare(fast_sim, ref_sim, 400, drive) > 250
    assert fast_sim._fast.counts[kernels.C_SUBSTEPS] > 350
    jaw_faces = [i for i, name in enumerate(fast_sim.obstacle_names) if 'jaw' in name]
    if 'pad' in finger[0]:  # the pads carry the grip
        assert np.any(fast_sim._pad.normal_forces > 0.1)
    else:
        assert len(faces_held & set(jaw_faces)) >= 4  # at least two facets of each jaw
    assert fast_sim.last.grip_force > 2.0


def test_steps_the_kernel_cannot_do_take_the_generic_path_with_pads(monkeypatch):
    """A step the kernel reports it cannot factorise (kernels.UNSUPPORTED: a filter that
    is not symmetric, which the contact passes no longer give, so the test makes every
    step report it) is done by the generic path, the pads set up and recorded for it:
    the same trajectory as a simulation on the generic path alone (the same solver), and
    the steps are counted."""
    overrides = ['fruit.nodes=32', 'gripper.finger.pad.enabled=true',
                 'gripper.initial_gap=0.0645', 'gripper.close_speed=0.05']
    config = load_config(overrides=overrides)
    sims = Simulation(config, fast=True), Simulation(config)
    sims[1]._fast = None  # the generic path with the compiled solver, as the fallback's
    monkeypatch.setattr(kernels, 'substep', lambda *args: kernels.UNSUPPORTED)
    for sim in sims:
        sim.command_force(2.0)
    assert _compare(*sims, 150) > 50
    assert sims[0]._fast.fallbacks >= 150  # every substep, the force drive's trials too
    assert sims[0].last.grip_force > 0.5
    np.testing.assert_allclose(sims[0]._pad.forces, sims[1]._pad.forces, rtol=0, atol=1e-9)


def test_sliding_grasp_matches_the_reference_path():
    """A grip too weak to carry the fruit: it slides down the jaws while they lift, with
    the same trajectory (kinetic friction, slip distance) on both paths."""
    overrides = ['fruit.nodes=32', 'sim.dt=0.00025', 'gripper.initial_gap=0.0645',
                 'gripper.close_speed=0.05', 'gripper.lift_acceleration=5',
                 'gripper.lift_speed=0.05']
    config = load_config(overrides=overrides)
    sims = Simulation(config, fast=True), reference_route(Simulation(config, fast=False))
    sliding = []

    def drive(sim):
        return GraspSequence(sim, 0.5, lift_height=0.01, hold_time=0.2)

    sims[0].add_observer(lambda result: sliding.append(result.slipping))
    _compare(*sims, 1400, drive)
    assert sum(sliding) > 50
    assert sims[0].last.slip_distance > 1e-4
    assert sims[0].last.slip_distance == pytest.approx(sims[1].last.slip_distance, rel=1e-9)


def test_damped_shell_dropped_on_the_table_matches_the_reference_path():
    config = load_config(overrides=['fruit.nodes=32', 'fruit.initial_height=0.045',
                                    'fruit.damping.mass=2', 'fruit.damping.stiffness=1e-4',
                                    'contact.restitution=0.3', 'fruit.initial_velocity.x=0.1'])
    assert _compare(Simulation(config, fast=True),
                    reference_route(Simulation(config, fast=False)), 250) > 50


def test_bouncing_point_in_a_corner_matches_the_reference_path():
    config = load_config(overrides=[
        'fruit.model=point', 'contact.restitution=0.5', 'fruit.initial_height=0.005',
        'gripper.initial_lift=5', 'world.walls=true', 'world.wall_half_width=0.01',
        'fruit.initial_velocity.x=0.6', 'contact.table.static_friction=0',
        'contact.table.kinetic_friction=0'])
    fast_sim = Simulation(config, fast=True)
    # it slides from wall to wall on the table, each rebound at half the speed, until it
    # arrives too slowly to bounce (1.1 s)
    assert _compare(fast_sim, reference_route(Simulation(config, fast=False)), 1500) > 100
    assert fast_sim.contacts.secondary[0] >= 0  # held by the table and pushed into a wall


def test_step_halving_and_convergence_failure_match_the_reference_path():
    # three Newton iterations at most and a fast impact: steps are halved (the
    # NewtonFailure path) and at last the solver gives up, at the same step on both paths
    config = load_config(overrides=['fruit.nodes=32', 'sim.max_newton_iterations=3',
                                    'gripper.initial_gap=0.0645', 'gripper.close_speed=0.1'])
    sims = Simulation(config, fast=True), reference_route(Simulation(config, fast=False))
    for sim in sims:
        sim.command_gap(0.03)  # position mode: the jaws hit the fruit at full speed
    halved = 0
    for step in range(200):
        outcomes = []
        for sim in sims:
            try:
                outcomes.append(sim.step())
            except ConvergenceError as err:
                outcomes.append(str(err))
        if isinstance(outcomes[0], str) or isinstance(outcomes[1], str):
            assert outcomes[0] == outcomes[1]
            break
        a, b = outcomes
        assert a.substeps == b.substeps and a.newton_iterations == b.newton_iterations
        np.testing.assert_allclose(a.positions, b.positions, rtol=0,
                                   atol=1e-9 * np.max(np.abs(b.positions)))
        halved += a.substeps > 1
    else:
        pytest.fail('the solver never gave up')
    assert halved >= 1
    assert sims[0].time == sims[1].time  # the failed step left both states unchanged


def test_parameter_changes_while_running_match_the_reference_path():
    config = load_config(overrides=['fruit.nodes=32', 'gripper.initial_gap=0.0645',
                                    'gripper.close_speed=0.05', 'fruit.bruise_pressure=5e4'])
    sims = Simulation(config, fast=True), reference_route(Simulation(config, fast=False))
    for sim in sims:
        sim.command_force(3.0)
    assert _compare(*sims, 150) > 50
    for sim in sims:
        sim.set_parameter('contact.jaw.kinetic_friction', 0.05)
        sim.set_parameter('contact.jaw.static_friction', 0.1)
        sim.command_lift(sim.gripper_state.lift + 0.01)
        sim.command_transport(0.01)  # sideways: the jaws leave x = 0
    assert _compare(*sims, 150) > 50
    assert sims[0].last.gripper_x > 1e-4
    assert sims[0].last.damage.bruised_length > 0  # low bruise threshold: the cover grows


#: every 2D set-up (with the default contact model)
SETUPS = [
    [],
    ['fruit.model=point'],
    ['gripper.finger.type=arc'],
    ['gripper.finger.type=vgroove'],
    ['gripper.finger.pad.enabled=true'],
    ['fruit.model=solid'],
    ['fruit.model=solid', 'gripper.finger.type=arc'],
    ['fruit.model=solid', 'gripper.finger.type=vgroove'],
    ['fruit.model=solid', 'gripper.finger.pad.enabled=true'],
]


@pytest.mark.parametrize('overrides', SETUPS, ids=[' '.join(o) or 'default' for o in SETUPS])
def test_every_setup_takes_the_whole_step_kernel(overrides):
    """Every 2D set-up - shell, point and solid fruits; flat, arc and V-groove fingers;
    soft pads - steps in the whole-step kernel, not on the generic solver (which settled
    the fruit on the table before the first step, as in every route)."""
    sim = Simulation(load_config(overrides=overrides + ['fruit.nodes=32']))
    settling_passes = sim.solver.stats['passes']
    sim.command_force(1.0)
    for _ in range(5):
        sim.step()
    assert sim._fast is not None and sim._fast.applies()
    assert sim._fast.counts[kernels.C_SUBSTEPS] >= 5
    assert sim._fast.fallbacks == 0
    assert sim.solver.stats['passes'] == settling_passes
    Simulation(load_config(overrides=overrides), fast=True)  # no error: the kernel covers it


def test_faces_the_kernels_do_not_model_fall_back_to_the_reference_path(monkeypatch):
    original = Simulation.faces_at

    def table_moves_with_the_gripper(self, grip):
        faces = list(original(self, grip))  # read only: the table is the template's own
        faces[2] = copy.copy(faces[2])
        faces[2].origin = faces[2].origin + np.array([0.0, 1e-3 * grip.lift])
        return faces

    monkeypatch.setattr(Simulation, 'faces_at', table_moves_with_the_gripper)
    sim = Simulation(load_config())
    assert sim._fast is not None and not sim._fast.applies()
    sim.step()  # the reference path
    assert sim._fast.counts.sum() == 0
