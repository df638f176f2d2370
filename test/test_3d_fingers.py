"""3D fingers: the 2D profiles (flat, arc, V-groove) extruded along y, and soft pads."""
import math

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.damage import contact_modulus
from gripper_sim.core3d.simulation import Simulation3D
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.workflows.grasp import GraspSequence, run_grasp
from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config

#: a coarse uniform shell (162 nodes), as the 3D friction test
COARSE = ['dimension=3', 'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=1']
SQUEEZE = ['world.gravity=0', 'world.table=false', 'fruit.damping.mass=20']


def test_3d_finger_faces_are_the_2d_profile_extruded_along_y():
    for finger, count in (('vgroove', 2), ('arc', 8)):
        sim = make_simulation(load_config(finger=finger, overrides=COARSE))
        assert isinstance(sim, Simulation3D)
        names = sim.obstacle_names
        assert sum(n.startswith('left_jaw') for n in names) == count
        assert sum(n.startswith('right_jaw') for n in names) == count
        faces = sim.faces_at(sim.gripper_state)
        for face in faces[:2 * count]:
            assert face.normal[1] == 0.0  # normals in the x-z plane
            assert face.half_extents[0] == pytest.approx(0.5 * sim.config['gripper.jaw_width'])


def test_3d_vgroove_grip_force_is_the_closing_force_of_the_inclined_flanks():
    """Frictionless 120 deg V: each flank's normal is 30 deg off the closing axis, so the
    flank normal loads of a jaw add up to F / cos 30 deg; the wrench is the contact sum."""
    sim = make_simulation(load_config(finger='vgroove', overrides=COARSE + SQUEEZE + [
        'sim.dt=0.01', 'contact.jaw.static_friction=0', 'contact.jaw.kinetic_friction=0']))
    sim.command_force(4.0, 0.02)
    result = sim.run(1.8)
    assert result.grip_force == pytest.approx(4.0, rel=0.01)
    faces = sim.faces_at(sim.gripper_state)
    for side, prefix in ((0, 'left_jaw'), (1, 'right_jaw')):
        flanks = [i for i, n in enumerate(result.obstacle_names) if n.startswith(prefix)]
        load = 0.0
        for index in flanks:
            held = result.contact_obstacle == index
            assert np.any(held), f'{result.obstacle_names[index]} carries no load'
            load += float(np.sum(result.contact_forces[held] @ faces[index].normal))
        assert load == pytest.approx(4.0 / math.cos(math.radians(30)), rel=0.02)
    assert result.left_wrench.force[0] == pytest.approx(-4.0, rel=0.01)
    assert result.right_wrench.force[0] == pytest.approx(4.0, rel=0.01)


def _pick(finger, ratio):
    """Grip at 2 mu F = ratio m g, lift 2 cm, hold 0.5 s (the 3D friction test)."""
    config = load_config(finger=finger, overrides=COARSE + [
        'sim.dt=0.005', 'contact.jaw.static_friction=0.5', 'contact.jaw.kinetic_friction=0.5'])
    sim = make_simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    summary = run_grasp(sim, GraspSequence(sim, ratio * weight / (2 * 0.5), lift_height=0.02,
                                           hold_time=0.5))
    return sim, summary, weight


@pytest.mark.slow
def test_3d_curved_and_v_fingers_hold_a_round_fruit_where_the_flat_one_slips():
    """At 0.8 m g / (2 mu) friction alone cannot carry the fruit: the flat plates let it
    slip; the V-groove and the concave arc carry part of the weight on their inclined
    faces, and the jaws' wrenches then carry all of it."""
    _, flat, _ = _pick('flat', 0.8)
    assert flat['outcome'] in ('slipped', 'dropped')
    for finger in ('vgroove', 'arc'):
        sim, summary, weight = _pick(finger, 0.8)
        assert summary['outcome'] == 'held', (finger, summary)
        assert summary['slip_distance'] < 1e-3
        result = sim.last
        carried = -(result.left_wrench.force[2] + result.right_wrench.force[2])
        assert carried == pytest.approx(weight, rel=0.02)
        # a symmetric grasp: no net moment about the gripper's closing axis
        assert abs(result.left_wrench.torque[0] + result.right_wrench.torque[0]) < \
            0.01 * weight * sim.fruit.rest_width


def test_3d_soft_pad_lowers_the_peak_contact_pressure_at_equal_grip_force(capsys):
    """Solid apple at 5 N: the pad (an elastic foundation, E = 1 MPa) spreads the load."""
    solid = ['dimension=3', 'fruit.model=solid', 'fruit.skin.enabled=false',
             'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=0.4', 'sim.dt=0.02']
    results = {}
    for finger in ('flat', 'soft_pad'):
        sim = make_simulation(load_config(finger=finger, overrides=SQUEEZE + solid))
        sim.command_force(5.0, 0.02)
        results[finger] = sim.run(1.2)
        hard = np.count_nonzero(sim.contacts.obstacle >= 0)
        assert results[finger].grip_force == pytest.approx(5.0, rel=0.01)
    rigid, padded = results['flat'], results['soft_pad']
    ratio = padded.deformation.peak_contact_pressure / rigid.deformation.peak_contact_pressure
    c = sim.config
    e_rigid = contact_modulus(c['fruit.flesh.youngs_modulus'], c['fruit.flesh.poisson_ratio'])
    e_pad = contact_modulus(c['fruit.flesh.youngs_modulus'], c['fruit.flesh.poisson_ratio'],
                            c['gripper.finger.pad.youngs_modulus'],
                            c['gripper.finger.pad.poisson_ratio'])
    with capsys.disabled():
        print(f'\n  3D soft pad vs rigid flat at 5 N: peak pressure '
              f'{rigid.deformation.peak_contact_pressure / 1e3:.0f} -> '
              f'{padded.deformation.peak_contact_pressure / 1e3:.0f} kPa ({ratio:.2f}; Hertz '
              f'(E*_pad / E*)^(2/3) = {(e_pad / e_rigid) ** (2 / 3):.2f}), contact area '
              f'{rigid.deformation.contact_area * 1e6:.0f} -> '
              f'{padded.deformation.contact_area * 1e6:.0f} mm^2')
    assert ratio < 0.75
    assert padded.deformation.contact_area > rigid.deformation.contact_area
    assert padded.damage.peak_pressure < rigid.damage.peak_pressure
    # the pad carries the grip: no node reaches the rigid jaw behind it
    assert padded.in_contact_with('left_jaw') and padded.in_contact_with('right_jaw')
    assert hard == 0


@pytest.mark.slow
@pytest.mark.parametrize('finger', ['flat', 'arc'])
def test_3d_pick_and_transport_keeps_the_fruit(finger):
    """The pick-and-place scenario in 3D (coarse shell apple) up to the end of the 8 cm
    sideways carry: the fruit travels with the jaws."""
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, finger=finger, overrides=COARSE + ['sim.dt=0.005'])
    sim = make_simulation(config)
    start = sim.last.centroid.copy()
    run = run_scenario(sim, scenario, until='transport', stop_on_slip=True)
    assert run['outcome'] == 'held', run
    moved = sim.last.centroid - start
    assert moved[0] == pytest.approx(scenario['transport.distance'], abs=2e-3)
    assert moved[2] > 0.5 * scenario['lift.height']
