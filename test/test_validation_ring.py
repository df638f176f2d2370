"""Closed-form checks of the shell model: thin ring in bending, pressurised membrane."""
import numpy as np
import pytest

from helpers import quasi_static_sim

RING_COEFFICIENT = np.pi / 4 - 2 / np.pi  # 0.14878 (Roark; validation.md section 1)


def hollow_ring_error(radius, skin_modulus, thickness, nodes, deflection_ratio=0.005):
    sim = quasi_static_sim(radius, f'fruit.skin.youngs_modulus={skin_modulus}',
                           f'fruit.skin.thickness={thickness}', f'fruit.nodes={nodes}',
                           'fruit.pressure.turgor=0', 'fruit.pressure.bulk_modulus=0')
    dv = deflection_ratio * radius
    sim.command_gap(2 * radius - dv, speed=dv / 0.5)
    result = sim.run(3.0)
    load = result.grip_force
    predicted = RING_COEFFICIENT * load * radius ** 3 / sim.fruit.bending_stiffness
    assert load > 0
    return result.deformation.compression / predicted - 1.0


@pytest.mark.parametrize('radius,skin_modulus,thickness',
                         [(0.03, 1e7, 1e-3), (0.05, 5e6, 2e-3)])
def test_hollow_ring_small_deflection_matches_roark(radius, skin_modulus, thickness):
    error = hollow_ring_error(radius, skin_modulus, thickness, nodes=64)
    assert abs(error) < 0.03


def test_hollow_ring_error_shrinks_with_resolution():
    errors = [abs(hollow_ring_error(0.03, 1e7, 1e-3, n)) for n in (32, 64, 128)]
    assert errors[0] > errors[1] > errors[2]


@pytest.mark.parametrize('approach_ratio', [0.05, 0.1])
def test_pressurised_membrane_force_is_pressure_times_contact_length(approach_ratio):
    radius, depth = 0.03, 0.01
    sim = quasi_static_sim(radius, 'fruit.skin.youngs_modulus=1e9', 'fruit.skin.thickness=1e-5',
                           'fruit.nodes=256', 'fruit.pressure.turgor=2e4',
                           'fruit.pressure.bulk_modulus=0')
    approach = approach_ratio * radius
    sim.command_gap(2 * radius - 2 * approach, speed=2 * approach / 0.5)
    result = sim.run(3.0)
    pressure = sim.fruit.pressure.pressure(result.positions.ravel())
    contact_per_jaw = result.deformation.contact_length / 2
    assert contact_per_jaw > 0.002
    assert result.grip_force == pytest.approx(pressure * contact_per_jaw * depth, rel=0.05)
