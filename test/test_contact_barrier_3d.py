"""The barrier contact model (``contact.model: ipc``, ``core.barrier``) in 3D.

The cross-check with the modified mass method on the 3D rigid-plate validation cases (a
Hertz sphere between plates, a pressurised membrane pressed by plates, the friction
hold): force and contact radius within 5 % of each other, and no surface node ever
behind a plate (checked at every step). The energy
itself (a surface of triangles against finite differences, its fixed pattern, its
collision-free step bound) is checked with the 2D one in ``test_contact_barrier.py``.
"""
import ipctk
import numpy as np
import pytest

from helpers import lift_newton_iterations

from gripper_sim.configuration import load_config
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import GraspSequence, run_grasp

MODELS = ('mmm', 'ipc')
RADIUS = 0.03
#: quasi-static plates: light, damped fruit, no gravity, no table, a large step; the jaws
#: start 0.1 mm off the fruit (the barrier needs a positive gap)
QUASI_STATIC = ['dimension=3', 'world.gravity=0', 'world.table=false', 'fruit.density=50',
                'fruit.damping.mass=20', 'sim.dt=0.05', 'sim.max_contact_passes=30',
                f'fruit.shape.diameter={2 * RADIUS}', f'gripper.initial_gap={2 * RADIUS + 1e-4}']

def _watch_plates(sim):
    """A list whose one entry is kept, after every step, at how far the surface node
    deepest behind a plate (jaws, table) within the plate's extent has been behind it
    (m; negative: the smallest gap in front of the plates so far)."""
    deepest = [-np.inf]

    def check(result):
        x = result.positions[result.surface]
        for plate in sim.faces_at(sim.gripper_state):
            facing = plate.covers(x)
            if np.any(facing):
                deepest[0] = max(deepest[0], float(-np.min(plate.gap(x[facing]))))

    sim.add_observer(check)
    return deepest


def _press(sim, gap, speed, settle):
    """Close to ``gap`` (m) at ``speed`` (m/s), then hold ``settle`` s; (last result, the
    deepest a surface node went behind a plate over every step, m)."""
    deepest = _watch_plates(sim)
    sim.command_gap(gap, speed)
    while sim.gripper_state.gap > gap + 1e-12:
        sim.step()
    result = sim.run(settle)
    return result, deepest[0]


def _hertz_sphere(model):
    """A coarse linear-tet solid sphere pressed by D = 0.02 R between plates."""
    sim = make_simulation(load_config(overrides=QUASI_STATIC + [
        'fruit.model=solid', 'fruit.skin.enabled=false', 'fruit.mesh.subdivisions=4',
        'fruit.mesh.jaw_refinement=0.4', 'fruit.mesh.order=1',
        'fruit.flesh.youngs_modulus=1e6', 'fruit.flesh.poisson_ratio=0.3',
        f'contact.model={model}']))
    return _press(sim, sim.fruit.rest_width - 0.02 * RADIUS, 0.005 * RADIUS / 0.05, 0.1)


def _membrane(model):
    """A coarse pressurised membrane sphere pressed by 0.05 R per plate."""
    sim = make_simulation(load_config(overrides=QUASI_STATIC + [
        'fruit.model=shell', 'fruit.pressure.turgor=2e4', 'fruit.pressure.bulk_modulus=0',
        'fruit.skin.youngs_modulus=1e6', 'fruit.skin.thickness=1e-4',
        'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=0.5',
        f'contact.model={model}']))
    return _press(sim, sim.fruit.rest_width - 0.1 * RADIUS, 0.004, 0.2)


def _assert_agree(results):
    (mmm, mmm_deepest), (ipc, ipc_deepest) = results
    assert mmm.grip_force > 0.5
    assert ipc.grip_force == pytest.approx(mmm.grip_force, rel=0.05)
    for ipc_radius, mmm_radius in zip(ipc.deformation.jaw_contact_radii,
                                      mmm.deformation.jaw_contact_radii):
        assert mmm_radius > 0 and ipc_radius == pytest.approx(mmm_radius, rel=0.05)
    assert ipc.deformation.contact_area == pytest.approx(mmm.deformation.contact_area,
                                                         rel=0.05)
    assert mmm_deepest < 1e-9  # the modified mass method holds nodes on the plate
    assert ipc_deepest < 0  # the barrier never lets one touch it


def test_hertz_sphere_agrees_between_the_contact_models():
    _assert_agree([_hertz_sphere(model) for model in MODELS])


def test_pressed_membrane_agrees_between_the_contact_models():
    _assert_agree([_membrane(model) for model in MODELS])


def _pick(model, ratio):
    """The coarse 3D apple gripped so that 2 mu N = ratio m g, lifted 2 cm, held 1 s (the
    friction hold of the 3D validation); (simulation, summary, the deepest a surface node
    went behind a plate or the table over every step, m)."""
    sim = make_simulation(load_config(overrides=[
        'dimension=3', 'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=1',
        'sim.dt=0.005', 'contact.jaw.static_friction=0.5', 'contact.jaw.kinetic_friction=0.5',
        f'contact.model={model}']))
    deepest = _watch_plates(sim)
    weight = sim.fruit.total_mass * sim.config['world.gravity']
    summary = run_grasp(sim, GraspSequence(sim, ratio * weight / (2 * 0.5), lift_height=0.02,
                                           hold_time=1.0))
    return sim, summary, deepest[0]


@pytest.mark.slow
@pytest.mark.parametrize('ratio,outcome', [(1.5, 'held'), (0.8, 'not held')])
def test_friction_hold_and_slip_agree_between_the_contact_models(ratio, outcome):
    """Held at ratio 1.5 (it rises with the jaws, the same grip force), not at 0.8 (the
    same slip distance) with either model; no node behind a jaw or the table."""
    runs = {model: _pick(model, ratio) for model in MODELS}
    (mmm, mmm_summary, mmm_deepest), (ipc, ipc_summary, ipc_deepest) = runs.values()
    assert mmm_summary['outcome'] == ipc_summary['outcome']
    assert mmm_deepest < 1e-9 and ipc_deepest < 0
    if outcome == 'held':
        assert mmm_summary['outcome'] == 'held'
        rise = [sim.last.centroid[2] - sim.initial_positions[:, 2].mean() for sim in (mmm, ipc)]
        assert rise[0] > 0.015 and rise[1] == pytest.approx(rise[0], rel=0.05)
        assert ipc.last.grip_force == pytest.approx(mmm.last.grip_force, rel=0.05)
    else:
        assert mmm_summary['outcome'] in ('slipped', 'dropped')
        assert ipc_summary['slip_distance'] == pytest.approx(mmm_summary['slip_distance'],
                                                             rel=0.05)


def _lift_iterations_3d(carried: bool, monkeypatch) -> tuple:
    """(Newton iterations of the lift, grip force N, the fruit's rise m) of the default 3D
    apple with the barrier (``lift_newton_iterations``)."""
    iterations, sim = lift_newton_iterations(
        load_config(overrides=['dimension=3', 'contact.model=ipc']), carried, monkeypatch)
    return (iterations, sim.last.grip_force,
            sim.last.centroid[2] - sim.initial_positions[:, 2].mean())


@pytest.mark.slow
def test_a_held_fruit_starts_its_lift_steps_carried_with_the_gripper(monkeypatch):
    """From x_n every node of a held fruit starts a whole step's lift behind its jaws,
    across the lagged friction's kink: 9 Newton iterations a step. Carried with the
    gripper (the fruit's velocities plus the gripper's change of speed in the step) the
    lift takes well under three quarters of them, to the same answer."""
    carried = _lift_iterations_3d(True, monkeypatch)
    plain = _lift_iterations_3d(False, monkeypatch)
    print(f'  3D lift, Newton iterations: {carried[0]} (from x_n {plain[0]})')
    assert carried[0] < 0.75 * plain[0]
    assert carried[1] == pytest.approx(plain[1], rel=1e-4)
    assert carried[2] == pytest.approx(plain[2], rel=1e-4)


# ---------------------------------------------------------------------- bad configurations
@pytest.mark.parametrize('override,match', [
    ('gripper.finger.pad.enabled=true', 'soft pads'),
    ('contact.restitution=0.5', 'restitution')])
def test_ipc_in_3d_refuses_what_it_does_not_model(override, match):
    with pytest.raises(ConfigError, match=f"config key 'contact.model'.*{match}"):
        Simulation3D(load_config(overrides=['dimension=3', 'contact.model=ipc', override]))


def test_ipc_in_3d_takes_the_barrier_step():
    sim = Simulation3D(load_config(overrides=['dimension=3', 'fruit.mesh.subdivisions=4',
                                              'contact.model=ipc']))
    assert sim._barrier in sim.solver.energies
    assert sim._barrier.dofs.shape == (sim.fruit.triangles.shape[0], 9)


def _on_the_table():
    """(the barrier, the fruit's positions q (3 n,) m) of the default apple resting on the
    table (3D, ``ipc``, a coarse mesh) after its first step."""
    sim = Simulation3D(load_config(overrides=['dimension=3', 'fruit.mesh.subdivisions=4',
                                              'contact.model=ipc']))
    sim.step()
    return sim._barrier, sim.q.ravel().copy()


def test_the_line_search_takes_the_tables_plane_in_closed_form():
    """A fall of 1 mm towards the table: the step bound is 0.8 of the time the nearest
    vertex takes to reach the table's plane, as Tight Inclusion's CCD over every
    candidate finds it (to its tolerance), and the CCD is left none of the table's."""
    barrier, q = _on_the_table()
    n_v = barrier.vertex_nodes.size
    dq = np.zeros((q.size // 3, 3))
    dq[:, 2] = -1e-3
    heights = q.reshape(-1, 3)[barrier.vertex_nodes, 2]
    assert 0 < heights.min() < barrier.settings.dhat
    bound = barrier.max_step(q, dq.ravel())
    assert bound == pytest.approx(0.8 * heights.min() / 1e-3, rel=1e-12)
    v0 = barrier.vertices(q.reshape(-1, 3))
    v1 = barrier.vertices((q + dq.ravel()).reshape(-1, 3))
    candidates = ipctk.Candidates()
    candidates.build(barrier._mesh, v0, v1, 0.51 * barrier.settings.dhat)
    exact = candidates.compute_collision_free_stepsize(
        barrier._mesh, v0, v1, narrow_phase_ccd=barrier.line_search_ccd)
    assert bound == pytest.approx(exact, rel=1e-2)
    _, others = barrier._plane_step(candidates, v0, v1)
    table = len(barrier._mesh.faces) - 2, len(barrier._mesh.faces) - 1  # the last face's
    assert len(candidates.fv_candidates) > len(others.fv_candidates)
    assert not {c.face_id for c in others.fv_candidates} & set(table)
    assert n_v == v0.shape[0] - 4 * 3  # the jaws' and the table's corners after them


def test_a_vertex_behind_the_table_leaves_the_table_to_the_ccd():
    barrier, q = _on_the_table()
    x = q.reshape(-1, 3)
    x[barrier.vertex_nodes[0], 2] = -1e-7
    dq = np.zeros_like(x)
    dq[:, 2] = -1e-4
    v0, v1 = barrier.vertices(x), barrier.vertices(x + dq)
    candidates = ipctk.Candidates()
    candidates.build(barrier._mesh, v0, v1, 0.51 * barrier.settings.dhat)
    bound, others = barrier._plane_step(candidates, v0, v1)
    assert bound == 1.0
    assert len(others.fv_candidates) == len(candidates.fv_candidates)
    assert len(others.ee_candidates) == len(candidates.ee_candidates)


@pytest.mark.parametrize('force', [40.0, 120.0])
def test_ipc_force_drive_holds_its_command_on_the_3d_solid_apple(force):
    """A barrier step is solved once, at the gap the drive predicts from its stiffness.
    The 3D solid apple's first guess was 0.1 E R, a third of its contact's stiffness at
    40 N: each step passed the goal by more than it aimed to change, and the grip force
    alternated between 0.5 and 69 N for as long as it was held. The guess is now Hertz's
    at the commanded force, and a step that overshoots raises it
    (``jaw_drive.adapted_stiffness``). At 120 N the first overshoot (129 N) is taken
    back by a step opening the jaws on the squeezed fruit, which converges now that the
    nodes touching them start where they take them (``barrier_kernels.push_ahead``)."""
    sim = Simulation3D(load_config(overrides=['dimension=3', 'fruit.model=solid',
                                              'contact.model=ipc']))
    sim.command_force(force)
    while sim.step().grip_force < 0.99 * force:
        assert sim.last.time < 1.0
    forces = np.array([sim.step().grip_force for _ in range(12)])
    assert np.all(np.abs(forces[2:] - force) < 0.01 * force), forces
