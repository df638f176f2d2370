"""A 2D Fin Ray coarser than the fruit's outline is warned about: its contact breaks into
patches and the bruise estimate overstates the pressure (docs/fin_ray_convergence.md)."""
import warnings

import pytest

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigWarning
from gripper_sim.geometry.fin_ray import COARSEST_ELEMENT, FinRayGeometry, outline_spacing


def config_warnings(*overrides):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        config = load_config(overrides=['gripper.finger.type=fin_ray', *overrides])
    return config, [str(w.message) for w in caught if issubclass(w.category, ConfigWarning)]


@pytest.mark.parametrize('overrides', [
    [], ['fruit.nodes=128'], ['fruit.nodes=192'], ['fruit.nodes=256'],
    ['fruit.nodes=256', 'gripper.finger.fin_ray.element_length=0.001'],
    ['dimension=3', 'fruit.nodes=256'], ['gripper.finger.fin_ray.element_length=0.004']])
def test_a_finger_as_fine_as_the_fruit_is_not_warned_about(overrides):
    assert not [w for w in config_warnings(*overrides)[1] if 'element_length' in w]


def test_a_finger_coarser_than_the_fruit_names_the_key_and_the_length_to_set():
    config, lines = config_warnings('fruit.nodes=256',
                                    'gripper.finger.fin_ray.element_length=0.002')
    line, = [w for w in lines if 'element_length' in w]
    assert "'gripper.finger.fin_ray.element_length' = 2 mm" in line
    assert 'fruit.nodes = 256' in line and 'bruise estimate overstates' in line
    # the length it suggests is what the simulation's outline allows
    outline = Simulation(config).fruit.rest_positions
    spacing = float(((outline[1] - outline[0]) ** 2).sum() ** 0.5)
    assert f'at most {COARSEST_ELEMENT * spacing * 1e3:.3g} mm' in line
    finest = 0.999 * COARSEST_ELEMENT * spacing
    _, finer = config_warnings('fruit.nodes=256',
                               f'gripper.finger.fin_ray.element_length={finest}')
    assert not [w for w in finer if 'element_length' in w]



@pytest.mark.parametrize('overrides, length', [
    ([], 0.004), (['fruit.nodes=128'], 0.002), (['fruit.nodes=192'], 0.001),
    (['fruit.nodes=256'], 0.001), (['fruit.nodes=512'], 0.0005),
    (['fruit=strawberry'], 0.002), (['dimension=3'], 0.002),
    (['fruit.nodes=256', 'gripper.finger.fin_ray.element_length=0.003'], 0.003)])
def test_a_null_element_length_follows_the_fruit_outline(overrides, length):
    config, _ = config_warnings(*overrides)
    assert config['gripper.finger.fin_ray.element_length'] in (None, length)
    assert FinRayGeometry.from_config(config).element_length == length
    if config['dimension'] == 2 and config['gripper.finger.fin_ray.element_length'] is None:
        # the coarsest of the halvings of 4 mm that keeps one patch a jaw
        assert length <= COARSEST_ELEMENT * outline_spacing(config) < 2 * length or \
            length == 0.004


def test_the_simulated_finger_is_built_at_the_followed_length():
    coarse = Simulation(config_warnings()[0]).step().fingers.positions
    fine = Simulation(config_warnings('gripper.finger.fin_ray.element_length=0.002')[0]
                      ).step().fingers.positions
    assert len(coarse) < 0.6 * len(fine)   # 57 nodes a finger against 104


def test_a_fruit_finer_than_the_finest_followed_length_is_warned_about():
    _, lines = config_warnings('fruit.nodes=2048')
    line, = [w for w in lines if 'element_length' in w]
    assert "element_length' = null: 0.5 mm" in line
