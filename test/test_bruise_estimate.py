"""The bruise estimate (``core.damage``) against what the simulation resolves, for rigid
fingers, the soft pad layer and deformable fingers (solid pad, Fin Ray).

The estimate is Hertz's 3D peak pressure; its in-plane part is a plane-strain Hertz
contact (half-width a1, peak 2 F' / (pi a1)) that the planar simulation resolves itself.
So the check is: at a given grip force, the plane-strain contact with the estimate's
in-plane radius R1' and modulus E* has the peak line pressure the simulation shows
(``Deformation.peak_contact_pressure``, node force over tributary length and depth).
On a rigid or padded face R1' is the fruit's and E* the materials'; on a deformable
finger R1' is measured from the patch (the finger's wrap).
"""
import math

import numpy as np
import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.damage import DamageTracker, line_contact, measured_half_width
from gripper_sim.core.fruit import build_fruit
from gripper_sim.core.measures import tributary_lengths
from gripper_sim.core.simulation import Simulation

SQUEEZE = ['world.gravity=0', 'world.table=false', 'fruit.damping.mass=20']
#: a solid fruit (plane-strain neo-Hookean flesh: Hertz applies to it) fine enough that
#: a patch spans several nodes
SOLID = ['fruit.model=solid', 'fruit.nodes=128']
FORCE = 10.0  # N
#: |planar peak of the estimate / simulated peak line pressure - 1| allowed: the node
#: forces sample the pressure over tributary lengths of about a third of the half-width
TOLERANCE = 0.25


def test_the_half_width_of_a_sampled_elliptical_pressure_is_recovered():
    a = 3e-3
    s = np.linspace(-a, a, 41)[1:-1]
    spacing = s[1] - s[0]
    force = np.sqrt(1 - (s / a) ** 2) * spacing
    assert measured_half_width(s, force, np.full(s.size, spacing)) == pytest.approx(a, rel=0.01)
    # one node: its force spread evenly over its tributary length l, a = l / sqrt(3)
    assert measured_half_width(np.zeros(1), np.ones(1), np.full(1, 3e-3)) == pytest.approx(
        3e-3 / math.sqrt(3))


def _tracker_on_a_deformable_finger(config):
    fruit = build_fruit(config)
    tracker = DamageTracker(fruit, config, face_groups=[0, 1], face_curvature=[0.0, 0.0],
                            face_padded=[True, True], pad_material=(0.6e6, 0.45),
                            face_deformable=[True, True])
    return fruit, tracker


@pytest.mark.parametrize('spread', [1.0, 2.0])
def test_a_deformable_finger_patch_gives_hertz_with_its_measured_width(spread):
    """Node forces laid out as plane-strain Hertz of the fruit's radius and the combined
    modulus (two elastic bodies): the estimate is Hertz with R1' = R1; a patch ``spread``
    times as wide (a finger that wraps) has R1' = spread^2 R1 and the lower p0."""
    config = load_config(overrides=['fruit.nodes=512'])
    fruit, tracker = _tracker_on_a_deformable_finger(config)
    x = fruit.rest_positions
    ring = fruit.surface
    right = ring[int(np.argmax(x[ring, 0]))]
    radius = 1.0 / tracker.rest_curvature[int(np.argmax(x[ring, 0]))]
    load = 5.0
    half_width, _ = line_contact(load / fruit.depth, radius, tracker.pad_modulus)
    half_width *= spread
    s = np.linalg.norm(x - x[right], axis=1)
    on = np.zeros(fruit.n_nodes, bool)
    on[ring] = (s[ring] < half_width) & (x[ring, 0] > 0)
    share = np.zeros(fruit.n_nodes)
    share[ring] = tributary_lengths(fruit, x) * np.sqrt(
        np.maximum(0, 1 - (s[ring] / half_width) ** 2))
    share[~on] = 0.0
    normal = load * share / share.sum()
    obstacle = np.where(on, 0, -1)
    assert on.sum() >= 10
    [(contact, _, near)] = tracker.contacts(x, normal, obstacle)
    k2 = tracker.rest_curvature[near]
    in_plane = contact.equivalent_radius ** 2 * k2  # Re = sqrt(R1' R2)
    assert in_plane == pytest.approx(spread ** 2 * radius, rel=0.03)
    assert contact.modulus == pytest.approx(tracker.pad_modulus)
    re = math.sqrt(spread ** 2 * radius / k2)
    a = (3 * load * re / (4 * contact.modulus)) ** (1 / 3)
    assert contact.peak_pressure == pytest.approx(3 * load / (2 * math.pi * a * a), rel=0.03)


def _squeeze(finger, *overrides):
    config = load_config(finger=finger, overrides=SQUEEZE + list(overrides))
    touching = Simulation(config).touching_gap
    sim = Simulation(load_config(finger=finger, overrides=SQUEEZE + list(overrides) + [
        f'gripper.initial_gap={touching + 0.001}']))
    sim.command_force(FORCE, 0.02)
    result = sim.run(1.2)
    assert result.grip_force == pytest.approx(FORCE, rel=0.01)
    return sim, result


def _planar_peak_of_the_estimate(sim, contact) -> float:
    """Pa, the peak of the plane-strain Hertz contact with the estimate's in-plane radius
    R1' = Re^2 / R2 and modulus at the patch's load per depth."""
    near = int(np.argmin(np.linalg.norm(sim.q[sim.fruit.surface] - contact.centre, axis=1)))
    in_plane = contact.equivalent_radius ** 2 * sim._damage.rest_curvature[near]
    return line_contact(contact.load / sim.fruit.depth, in_plane, contact.modulus)[1]


@pytest.fixture(scope='module')
def squeezes():
    return {finger: _squeeze(finger, *SOLID)
            for finger in ('flat', 'soft_pad', 'solid_pad', 'fin_ray')}


@pytest.mark.parametrize('finger', ['flat', 'soft_pad', 'solid_pad', 'fin_ray'])
def test_the_estimate_has_the_simulated_peak_pressure_in_the_plane(squeezes, finger, capsys):
    sim, result = squeezes[finger]
    contacts = [c for c in result.damage.contacts if c.body in (0, 1)]
    assert len(contacts) >= 2  # both jaws
    heaviest = max(contacts, key=lambda c: c.load)
    estimate = _planar_peak_of_the_estimate(sim, heaviest)
    simulated = result.deformation.peak_contact_pressure
    with capsys.disabled():
        print(f'\n  {finger} at {FORCE:.0f} N (solid apple): simulated peak line pressure '
              f'{simulated / 1e3:.1f} kPa, estimate in the plane {estimate / 1e3:.1f} kPa '
              f'({(estimate / simulated - 1) * 100:+.0f} %), Hertz p0 '
              f'{result.damage.pressure / 1e3:.0f} kPa')
    assert abs(estimate / simulated - 1) < TOLERANCE


def test_a_wrapping_finger_lowers_the_estimate_as_it_lowers_the_simulated_pressure(squeezes):
    """The Fin Ray's and the solid pad's estimates fall below the flat finger's by about as
    much as their simulated line pressures do (p0 goes as the in-plane peak^(2/3))."""
    flat = squeezes['flat'][1]
    for finger in ('solid_pad', 'fin_ray'):
        soft = squeezes[finger][1]
        line = soft.deformation.peak_contact_pressure / flat.deformation.peak_contact_pressure
        assert line < 0.9
        assert soft.damage.pressure < flat.damage.pressure
