"""Closed-form checks of the shell model: thin ring in bending, pressurised membrane."""
import pytest

from helpers import hollow_ring_error, membrane


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
    force, pressure_times_length, contact_per_jaw = membrane(approach_ratio)
    assert contact_per_jaw > 0.002
    assert force == pytest.approx(pressure_times_length, rel=0.05)
