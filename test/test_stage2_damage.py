"""Damage: Hertz contact pressure per resolved contact, bruised length, crushing."""
import math

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.damage import hertz
from gripper_sim.core.simulation import Simulation

SQUEEZE = ['world.gravity=0', 'world.table=false', 'fruit.damping.mass=20']


def _squeeze_to(sim, force):
    sim.command_gap(0.0, 0.01)
    while True:
        result = sim.step()
        if result.grip_force >= force:
            return result


def test_peak_pressure_is_hertz_of_each_jaw_load():
    sim = Simulation(load_config(overrides=SQUEEZE))
    result = _squeeze_to(sim, 8.0)
    damage = result.damage
    assert len(damage.contacts) == 2
    e, nu = 2.0e6, 0.385
    e_star = e / (1 - nu ** 2)
    radius = 0.0635 / 2
    for contact, jaw in zip(sorted(damage.contacts, key=lambda c: c.centre[0]),
                            (result.left_wrench, result.right_wrench)):
        # the load is the jaw's normal force, the radius the apple's
        assert contact.load == pytest.approx(abs(jaw.force[0]), rel=1e-6)
        assert contact.equivalent_radius == pytest.approx(radius, rel=0.01)
        p0 = (6 * contact.load * e_star ** 2 / (math.pi ** 3 * radius ** 2)) ** (1 / 3)
        assert contact.peak_pressure == pytest.approx(p0, rel=0.02)
    assert damage.pressure == max(c.peak_pressure for c in damage.contacts)
    assert not damage.bruised and damage.bruised_length == 0.0
    # node pressures: the peak at the contact centre, none away from the jaws
    assert damage.node_pressure.max() <= damage.pressure * (1 + 1e-12)
    assert damage.node_pressure.max() > 0.5 * damage.pressure
    free = result.contact_obstacle[result.surface] < 0
    assert np.all(damage.node_pressure[free] == 0)


def test_bruise_starts_at_the_threshold_and_stays():
    sim = Simulation(load_config(overrides=SQUEEZE))
    threshold = sim.config['fruit.bruise_pressure']
    sim.command_gap(0.0, 0.01)
    before = None
    while True:
        result = sim.step()
        if result.damage.bruised:
            break
        before = result
    assert before.damage.peak_pressure <= threshold < result.damage.peak_pressure
    # squeeze further: the bruise grows as the Hertz patch above the threshold
    result = _squeeze_to(sim, 30.0)
    damage = result.damage
    patch = sum(2 * c.radius * math.sqrt(1 - (threshold / c.peak_pressure) ** 2)
                for c in damage.contacts)
    assert damage.bruised_length == pytest.approx(patch, rel=0.05)
    perimeter = math.pi * 0.0635
    assert damage.bruised_fraction == pytest.approx(damage.bruised_length / perimeter,
                                                    rel=0.01)
    # open the jaws: the pressure goes, the bruise stays
    sim.command_gap(sim.initial_gap, 0.05)
    result = sim.run(0.5)
    assert result.damage.pressure == 0.0
    assert result.damage.bruised
    assert result.damage.bruised_length == pytest.approx(damage.bruised_length)


def test_crushed_when_compression_exceeds_the_failure_strain():
    sim = Simulation(load_config(overrides=SQUEEZE + ['fruit.failure_strain=0.03',
                                                      'fruit.failure_stress=1e9']))
    sim.command_gap(0.0, 0.01)
    while True:
        result = sim.step()
        if result.deformation.compression_ratio > 0.03:
            break
        assert not result.damage.crushed
    assert result.damage.crushed


def test_solid_flesh_crushed_by_its_von_mises_stress():
    overrides = SQUEEZE + ['fruit.model=solid', 'fruit.nodes=32', 'fruit.failure_stress=40e3']
    sim = Simulation(load_config(overrides=overrides))
    result = _squeeze_to(sim, 6.0)
    von_mises = sim.fruit.flesh.von_mises(result.positions.ravel()).max()
    hertz_stress = 0.62 * result.damage.pressure
    assert result.damage.flesh_stress == pytest.approx(max(von_mises, hertz_stress))
    assert result.damage.crushed == (result.damage.peak_flesh_stress > 40e3)
    assert result.damage.crushed


def test_hertz_helper_matches_the_closed_form():
    a, p0 = hertz(20.0, 0.03, 2.0e6)
    assert a == pytest.approx((3 * 20.0 * 0.03 / (4 * 2.0e6)) ** (1 / 3))
    assert p0 == pytest.approx(3 * 20.0 / (2 * math.pi * a * a))
    assert hertz(0.0, 0.03, 2e6) == (0.0, 0.0)
