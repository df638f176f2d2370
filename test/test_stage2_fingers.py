"""Finger geometries and soft pads: what they change, and clear errors for bad ones."""
import math

import numpy as np
import pytest

from gripper_sim.configuration import available_fingers, load_config
from gripper_sim.core.damage import contact_modulus
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigError
from gripper_sim.geometry.fingers import finger_outline, left_facets, profile
from gripper_sim.workflows.scenario import load_scenario, run_scenario, scenario_config
from gripper_sim.workflows.window import estimates
from test_cli_offline import gripper_sim

SQUEEZE = ['world.gravity=0', 'world.table=false', 'fruit.damping.mass=20']


def _squeeze(finger, force, *overrides):
    sim = Simulation(load_config(finger=finger, overrides=SQUEEZE + list(overrides)))
    sim.command_force(force, 0.02)
    result = sim.run(1.2 if finger != 'vgroove' else 1.8)
    assert result.grip_force == pytest.approx(force, rel=0.01)
    return sim, result


def test_finger_presets_exist():
    assert {'flat', 'arc', 'vgroove', 'soft_pad'} <= set(available_fingers())


def test_vgroove_and_arc_profiles():
    config = load_config(finger='vgroove')
    h = config['gripper.jaw_height']
    facets = left_facets(config)
    assert [f.name for f in facets] == ['lower', 'upper']
    half = math.radians(0.5 * config['gripper.finger.groove_angle'])
    opening = math.acos(float(np.clip(-facets[0].normal @ facets[1].normal, -1, 1)))
    assert opening == pytest.approx(2 * half)  # the flanks meet at the V angle
    assert -profile(config)[1, 0] == pytest.approx(0.5 * h / math.tan(half))
    arc = load_config(finger='arc')
    points = profile(arc)
    radius = arc['gripper.finger.radius']
    centre = np.array([math.sqrt(radius ** 2 - 0.25 * h * h), 0.0])
    assert np.allclose(np.linalg.norm(points - centre, axis=1), radius)
    assert points[0, 0] == pytest.approx(0.0, abs=1e-15)  # rims on the front plane
    assert points[[0, -1], 1] == pytest.approx([-0.5 * h, 0.5 * h])
    for f in left_facets(arc):  # facet normals point at the arc's centre, towards the fruit
        towards = (centre - f.offset) / np.linalg.norm(centre - f.offset)
        assert f.normal @ towards == pytest.approx(1.0, abs=1e-3)
        assert f.curvature == pytest.approx(-1 / radius)
    outline = finger_outline(arc, 'right')
    assert np.all(outline[:, 0] >= -1e-15)  # the right finger is the mirror image


def test_vgroove_grip_force_is_the_closing_force_of_the_inclined_flanks():
    """Frictionless V (120 deg): each flank's normal is 30 deg off the closing axis, so
    the flanks' normal loads add up to F / cos 30 deg per jaw."""
    _, result = _squeeze('vgroove', 4.0, 'contact.jaw.static_friction=0',
                         'contact.jaw.kinetic_friction=0')
    contacts = result.damage.contacts
    assert len(contacts) == 4  # two flanks on each jaw
    for body in (0, 1):
        load = sum(c.load for c in contacts if c.body == body)
        assert load == pytest.approx(4.0 / math.cos(math.radians(30)), rel=0.01)
    assert result.in_contact_with('left_jaw') and result.in_contact_with('right_jaw')
    assert 'left_jaw.upper' in result.obstacle_names


def test_soft_pad_lowers_the_peak_contact_pressure_at_equal_grip_force(capsys):
    _, rigid = _squeeze('flat', 5.0)
    sim, padded = _squeeze('soft_pad', 5.0)
    ratio = padded.damage.pressure / rigid.damage.pressure
    line_ratio = (padded.deformation.peak_contact_pressure
                  / rigid.deformation.peak_contact_pressure)
    with capsys.disabled():
        print(f'\n  soft pad vs rigid flat at 5 N: peak pressure {rigid.damage.pressure / 1e3:.0f}'
              f' -> {padded.damage.pressure / 1e3:.0f} kPa ({(ratio - 1) * 100:+.0f} %); '
              f'planar line pressure {(line_ratio - 1) * 100:+.0f} %, contact length '
              f'{rigid.deformation.contact_length * 1e3:.1f} -> '
              f'{padded.deformation.contact_length * 1e3:.1f} mm')
    c = sim.config
    e_rigid = contact_modulus(c['fruit.flesh.youngs_modulus'], c['fruit.flesh.poisson_ratio'])
    e_pad = contact_modulus(c['fruit.flesh.youngs_modulus'], c['fruit.flesh.poisson_ratio'],
                            c['gripper.finger.pad.youngs_modulus'],
                            c['gripper.finger.pad.poisson_ratio'])
    # Hertz at equal load: p0 scales as E*^(2/3); the simulated loads are equal
    assert ratio == pytest.approx((e_pad / e_rigid) ** (2 / 3), rel=0.03)
    assert ratio < 0.6
    # the simulated pad spreads the contact: longer, lower line pressure
    assert padded.deformation.contact_length > 1.2 * rigid.deformation.contact_length
    assert line_ratio < 0.95
    # the pad carries the grip: no node reaches the rigid jaw behind it
    assert padded.in_contact_with('left_jaw') and padded.in_contact_with('right_jaw')


@pytest.mark.slow
def test_curved_and_v_fingers_hold_a_round_fruit_where_the_flat_one_slips():
    """At 0.8 m g / (2 mu) the flat finger cannot hold the apple (validation.md section 6);
    the V-groove and the concave arc carry part of the weight on their inclined faces."""
    scenario = load_scenario('pick_and_place').with_values(approach__height=0.0)
    outcomes = {}
    for finger in ('flat', 'vgroove', 'arc'):
        config = scenario_config(scenario, fruit='apple', finger=finger)
        force = 0.8 * estimates(config)[0]
        run = run_scenario(Simulation(config), scenario.with_values(close__force=force),
                           until='transport', stop_on_slip=True)
        outcomes[finger] = run
    assert outcomes['flat']['outcome'] in ('slipped', 'dropped')
    for finger in ('vgroove', 'arc'):
        assert outcomes[finger]['outcome'] == 'held', (finger, outcomes[finger])
        assert outcomes[finger]['slip_distance'] < 1e-3


@pytest.mark.parametrize('args,message', [
    (['window', '--finger', 'claw'], "unknown finger 'claw'"),
    (['run', 'pick_and_place', '--finger', 'claw'], "unknown finger 'claw'"),
    (['run', 'pick_and_place', '--set', 'gripper.finger.pad.enabled=true',
      '--set', 'gripper.finger.pad.thickness=0'], "'gripper.finger.pad.thickness' = 0.0 m"),
    (['squeeze', '--to-force', '2', '--set', 'gripper.finger.type=claw'],
     "'gripper.finger.type' must be one of flat, arc, vgroove"),
    (['squeeze', '--to-force', '2', '--set', 'gripper.finger.type=arc',
      '--set', 'gripper.finger.radius=0.01'], "'gripper.finger.radius' = 0.01 m is too small"),
    (['squeeze', '--to-force', '2', '--set', 'gripper.finger.pad.poisson_ratio=0.5'],
     "'gripper.finger.pad.poisson_ratio'"),
])
def test_bad_finger_configuration_is_a_clear_error(args, message):
    run = gripper_sim(*args)
    assert run.returncode == 2
    assert message in run.stderr and 'Traceback' not in run.stderr


def test_zero_thickness_pad_is_refused_in_process():
    with pytest.raises(ConfigError, match='gripper.finger.pad.thickness'):
        load_config(overrides={'gripper.finger.pad.enabled': True,
                               'gripper.finger.pad.thickness': 0.0})
