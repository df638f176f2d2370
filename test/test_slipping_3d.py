"""``slipping`` in 3D: the fruit slides at the jaw contacts, not merely deforms in the
jaws (the 3D facade's ``slip.jaw_contacts_sliding`` with the nodes' positions)."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.slip import jaw_contacts_sliding
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.workflows.grasp import GraspSequence

MU = 0.5
#: a coarse skin (362 vertices), the jaws a step or two from the apple
COARSE = ['dimension=3', 'fruit.mesh.subdivisions=6', 'gripper.initial_gap=0.0645']


def _both_jaws_hold(sim, result) -> bool:
    sides = sim._obstacles(sim._grip)[1]
    held = result.contact_obstacle[result.contact_obstacle >= 0]
    return bool(np.any(sides[held] == 0) and np.any(sides[held] == 1))


@pytest.mark.parametrize('contact', ['mmm', 'ipc'])
def test_a_3d_squeeze_on_the_table_is_not_slipping(contact):
    """The jaws close on the apple resting on the table to 10 N in force mode: as each
    contact patch grows (to 6-16 nodes a jaw within two 20 ms steps) most of its nodes slip
    towards its centre, which the per-node rule read as slipping; the patch as a whole
    does not slide."""
    sim = Simulation3D(load_config(overrides=COARSE + [f'contact.model={contact}']))
    sim.command_force(10.0)
    closed_at = None
    for _ in range(12):
        result = sim.step()
        if closed_at is None and _both_jaws_hold(sim, result):
            closed_at = result.step
        elif closed_at is not None:
            slipping = result.slipping
            assert not slipping, (result.step, result.grip_force)
    assert closed_at is not None and closed_at <= 4
    assert result.grip_force > 8.0
    assert np.count_nonzero(result.contact_obstacle == 0) >= 6


def test_a_3d_fruit_lifted_with_too_weak_a_grip_is_slipping():
    """2 mu F = 0.8 m g: while the jaws rise at 2 cm/s or more they slide up along the
    apple, which stays behind (its first lifting step only stretches it, the contacts
    stuck; the last ones, the jaws stopping, slide no more)."""
    config = load_config(overrides=COARSE + [f'contact.jaw.static_friction={MU}',
                                             f'contact.jaw.kinetic_friction={MU}'])
    sim = Simulation3D(config)
    force = 0.8 * sim.fruit.total_mass * config['world.gravity'] / (2 * MU)
    sequence = GraspSequence(sim, force, lift_height=0.01, hold_time=0.1)
    rising = []
    while sequence.phase != 'done':
        result = sim.step()
        sequence.update(result)
        if sequence.phase == 'lifting' and result.lift_velocity >= 0.02:
            assert _both_jaws_hold(sim, result)
            rising.append(result.slipping)
    assert len(rising) >= 8 and all(rising), rising
    assert result.slip_distance > 5e-3


def test_a_patch_slides_by_its_rigid_motion_not_its_deformation():
    """A left-jaw patch (normal +x, still) of a centre and a ring of 8 nodes, 5 mm across:
    its rim slipping inwards at 5 mm/s is no sliding; the patch moving down or turning
    about the grip axis at that speed is."""
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = np.stack([np.zeros(8), np.cos(angles), np.sin(angles)], axis=1)
    positions = np.vstack([np.zeros(3), 5e-3 * ring])
    holder, jaw_of_face = np.zeros(9, int), np.array([0])
    normals, still = np.array([[1.0, 0.0, 0.0]]), np.zeros((1, 3))

    def sliding(velocities):
        return jaw_contacts_sliding(velocities, holder, jaw_of_face, normals, still,
                                    positions)

    inwards = np.vstack([np.zeros(3), -5e-3 * ring])
    inwards[:, 0] = 0.02  # closing: along the normal, no sliding either
    assert not sliding(inwards)
    assert jaw_contacts_sliding(inwards, holder, jaw_of_face, normals, still)  # per node
    assert sliding(inwards + [0.0, 0.0, -5e-3])
    turning = np.cross([1.0, 0.0, 0.0], positions)  # 1 rad/s: 5 mm/s at the ring
    assert sliding(turning) and not sliding(1e-2 * turning)
