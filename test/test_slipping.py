"""``slipping``: the fruit slides at the jaw contacts, not merely deforms in the jaws."""
import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.core.slip import (SLIDING_FRACTION, SLIDING_SPEED, jaw_contacts_sliding,
                                   surface_motion)
from gripper_sim.workflows.grasp import GraspSequence

MU = 0.5


def _pick(ratio: float, fast: bool | None, overrides: tuple = ()):
    """Grip so that 2 mu N = ratio m g, lift 2 cm and hold 0.3 s, the configuration keys
    ``overrides`` ('KEY=VALUE') set, on the fast path or not (``fast``: None, where it
    applies); every step's result."""
    config = load_config(overrides=[f'contact.jaw.static_friction={MU}',
                                    f'contact.jaw.kinetic_friction={MU}', *overrides])
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


def test_slipping_needs_nearly_all_of_a_jaws_contact_nodes_to_slide_along_it():
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
    two[2, 1] = 0.1  # and another sideways: most of them, the third stuck (partial slip)
    assert not jaw_contacts_sliding(two, holder, jaw_of_face, normals, face_velocities)
    assert SLIDING_FRACTION > 2 / 3
    two[0, 2] = 0.05  # all three: the fruit slides in this jaw
    assert jaw_contacts_sliding(two, holder, jaw_of_face, normals, face_velocities)
    assert not jaw_contacts_sliding(two, -np.ones(6, int), jaw_of_face, normals,
                                    face_velocities)


def _squeezed_on_the_table(overrides: list, force: float, steps: int):
    """The jaws 1 mm from the apple resting on the table, closed to ``force`` N in force
    mode: (each step's result while both jaws hold it, the last result)."""
    config = load_config(overrides=overrides)
    config = config.replaced({'gripper.initial_gap': Simulation(config).touching_gap + 0.001})
    sim = Simulation(config)
    sim.command_force(force)
    held = []
    for _ in range(steps):
        result = sim.step()
        if result.in_contact_with('left_jaw') and result.in_contact_with('right_jaw'):
            held.append(result)
    return held, result


@pytest.mark.parametrize('overrides', [[], ['contact.model=ipc']], ids=['mmm', 'ipc'])
def test_a_2d_fruit_bulging_up_the_jaws_is_not_slipping(overrides):
    """Squeezed to 60 N on the table, the apple bulges up the flat jaws: the upper part of
    each patch slides up while the rest sticks (partial slip). When more than half of a
    jaw's nodes counted, it read slipping on 25 of these 300 steps (19 with ``ipc``); now
    only the first touches (a single node a jaw sliding as the jaws meet the fruit)."""
    held, last = _squeezed_on_the_table(overrides, 60.0, 300)
    slipping = [result.step for result in held if result.slipping]
    assert len(held) > 200 and len(slipping) <= 5, slipping
    assert all(np.count_nonzero(result.contact_obstacle == 0) == 1
               for result in held if result.step in slipping)
    assert last.grip_force == pytest.approx(60.0, rel=0.01)


@pytest.mark.parametrize('finger', ['fin_ray', 'solid_pad'])
def test_a_deformable_finger_carries_the_nodes_stuck_to_it(finger):
    """Squeezed to 20 N, the apple's contact nodes move along the fingers' backings as the
    fingers bend and their fronts wrap the fruit. Read against the backing (before
    2026-12-06) the squeeze was slipping on 126 of these 300 steps with the Fin Ray and 54
    with the solid pads, though the nodes are stuck to the finger's surface. Against the
    surface only the first touches remain (7 and 3 steps: a node sliding as a finger's
    front rolls onto the fruit). ``contact_sticking`` reads against the surface too: of
    the nodes the fingers hold over these steps 92 % (Fin Ray) and 95 % (solid pads)
    stick, 20 % and 71 % read against the backing (before 2026-12-06)."""
    held, last = _squeezed_on_the_table([f'gripper.finger.type={finger}'], 20.0, 300)
    slipping = [result.step for result in held if result.slipping]
    assert len(held) > 200 and len(slipping) <= 10, slipping
    assert last.grip_force == pytest.approx(20.0, rel=0.01)
    on_fingers = [np.isin(result.contact_obstacle, (0, 1)) for result in held]
    stuck = sum(np.count_nonzero(result.contact_sticking[on])
                for result, on in zip(held, on_fingers))
    assert stuck > 0.85 * sum(np.count_nonzero(on) for on in on_fingers)


def test_a_fin_ray_pick_below_the_hold_minimum_is_slipping():
    """The Fin Ray's fingers hold the apple at 2 mu N = 0.8 m g: it slides down them while
    they rise (read against the fingers' surface)."""
    _, steps = _pick(0.8, fast=None, overrides=('gripper.finger.type=fin_ray',))
    lifting = [result.slipping for phase, result in steps if phase == 'lifting']
    assert np.mean(lifting) > 0.8, lifting
