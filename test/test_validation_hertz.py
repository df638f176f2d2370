"""Solid disk between plates: Hertz contact half-width (plane strain).

The contact edge lies between the last held surface node and the first free one, so
the surface spacing must be small against the half-width (here ~0.37 mm against
2.3-3 mm: 512 surface nodes on a 30 mm disk).
"""
import numpy as np
import pytest

from helpers import quasi_static_sim


@pytest.mark.slow
@pytest.mark.parametrize('force', [1.5, 2.6])
def test_solid_disk_contact_half_width_matches_hertz(force):
    radius, modulus, poisson, depth = 0.03, 1e6, 0.3, 0.01
    sim = quasi_static_sim(radius, 'fruit.model=solid', 'fruit.skin.enabled=false',
                           'fruit.nodes=512', f'fruit.flesh.youngs_modulus={modulus}',
                           f'fruit.flesh.poisson_ratio={poisson}')
    sim.command_force(force, speed=0.004)
    result = sim.run(1.5)
    assert result.grip_force == pytest.approx(force, rel=1e-3)
    force_per_depth = result.grip_force / depth
    plane_strain_modulus = modulus / (1 - poisson ** 2)
    hertz_half_width = np.sqrt(4 * force_per_depth * radius / (np.pi * plane_strain_modulus))
    measured = result.deformation.contact_length / 4  # two jaws, full width each
    assert measured == pytest.approx(hertz_half_width, rel=0.10)
