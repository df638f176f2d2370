"""``slipping``: the fruit slides at the jaw contacts, not merely deforms in the jaws."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.slip import SLIDING_SPEED, jaw_contacts_sliding
from gripper_sim.workflows.grasp import GraspSequence

MU = 0.5


def _pick(ratio: float, fast: bool):
    """Grip so that 2 mu N = ratio m g, lift 2 cm and hold 0.3 s; every step's result."""
    config = load_config(overrides=[f'contact.jaw.static_friction={MU}',
                                    f'contact.jaw.kinetic_friction={MU}'])
    sim = Simulation(config, fast=fast)
    force = ratio * sim.fruit.total_mass * config['world.gravity'] / (2 * MU)
    sequence = GraspSequence(sim, force, lift_height=0.02, hold_time=0.3)
    steps = []
    while sequence.phase != 'done':
        result = sim.step()
        sequence.update(result)
        steps.append((sequence.phase, result))
    return sim, steps


@pytest.mark.parametrize('fast', [True, False])
def test_a_held_fruit_that_sags_in_the_jaws_is_not_slipping(fast):
    sim, steps = _pick(3.0, fast)
    masses = sim.fruit.masses
    sagging = 0
    for _, result in steps:
        on_jaws = np.isin(result.contact_obstacle, (0, 1))
        centroid_speed = masses @ result.velocities[:, 1] / masses.sum()
        if (np.any(on_jaws) and np.all(result.contact_sticking[on_jaws])
                and abs(centroid_speed - result.lift_velocity) > SLIDING_SPEED):
            sagging += 1  # every jaw node stuck, the body moving in the jaws
        assert not result.slipping, (result.time, result.slip_distance)
    assert sagging > 20  # the elastic motion the centroid measure took for slip
    assert steps[-1][1].slip_distance < 1e-3


def test_a_pick_below_the_hold_minimum_is_slipping():
    _, steps = _pick(0.8, fast=True)
    lifting = [result.slipping for phase, result in steps if phase == 'lifting']
    assert np.mean(lifting) > 0.8
    assert steps[-1][1].slip_distance > 5e-3


def test_slipping_needs_most_of_a_jaws_contact_nodes_to_slide_along_it():
    # 3D: one jaw (face 0, normal +x, moving up at 0.1 m/s), the table (face 1, no jaw)
    normals = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    face_velocities = np.array([[0.0, 0.0, 0.1], [0.0, 0.0, 0.0]])
    jaw_of_face = np.array([0, -1])
    holder = np.array([0, 0, 0, 1, 1, -1])
    with_jaw = np.tile([0.0, 0.0, 0.1], (6, 1))
    with_jaw[3:5] = [0.5, 0.5, 0.0]  # sliding on the table: not the jaw's business
    with_jaw[0, 0] = 0.3  # along the jaw's normal (squeezing): not sliding
    assert not jaw_contacts_sliding(with_jaw, holder, jaw_of_face, normals, face_velocities)
    one = with_jaw.copy()
    one[1, 2] = 0.0  # one of three jaw nodes slides down the jaw
    assert not jaw_contacts_sliding(one, holder, jaw_of_face, normals, face_velocities)
    two = one.copy()
    two[2, 1] = 0.1  # and another sideways: most of them
    assert jaw_contacts_sliding(two, holder, jaw_of_face, normals, face_velocities)
    assert not jaw_contacts_sliding(two, -np.ones(6, int), jaw_of_face, normals,
                                    face_velocities)
