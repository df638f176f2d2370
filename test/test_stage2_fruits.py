"""The fruit library: six presets, sourced figures, masses as the data say, the fruits verb."""
import json
import re

import numpy as np

import pytest

from gripper_sim.configuration import available_fruits, fruit_preset_path, load_config
from gripper_sim.core.fruit import build_fruit
from test_cli_offline import gripper_sim

LIBRARY = ('apple', 'tomato', 'peach', 'orange', 'plum', 'strawberry')

#: mass ranges (g) of fruit-data.md; the orange is left out: its reported mean mass
#: (~215 g) and mean axes (84/77/76 mm) at 1.03 g/cm3 disagree (see orange.yaml)
MASS_G = {'apple': (134, 137), 'tomato': (66, 150), 'peach': (125, 150),
          'plum': (40, 70), 'strawberry': (10, 30)}


def test_library_has_the_six_fruits():
    assert set(LIBRARY) <= set(available_fruits())


@pytest.mark.parametrize('name', LIBRARY)
def test_every_figure_has_a_source_comment(name):
    """Every numeric value in the preset carries a comment (a source or 'estimate')."""
    lines = fruit_preset_path(name).read_text().splitlines()
    numeric = re.compile(r'^\s*([a-z_]+):\s*[-+0-9.][-+0-9.eE]*\s*(#.*)?$')
    settings = ('nodes',)  # the discretisation is a model setting, not a figure
    missing = [line for line in lines if numeric.match(line) and '#' not in line
               and numeric.match(line).group(1) not in settings]
    assert not missing, f'{name}: figures without a source comment: {missing}'
    assert len([line for line in lines if numeric.match(line)]) >= 8


@pytest.mark.parametrize('name', LIBRARY)
def test_preset_builds_with_the_keys_of_the_issue(name):
    config = load_config(fruit=name)
    fruit = build_fruit(config)
    assert config['fruit.name'] == name
    for key in ('fruit.density', 'fruit.flesh.youngs_modulus', 'fruit.flesh.poisson_ratio',
                'fruit.skin.youngs_modulus', 'contact.jaw.static_friction',
                'contact.pad.friction', 'fruit.bruise_pressure', 'fruit.failure_stress'):
        assert config[key] > 0, key
    assert fruit.total_mass > 0 and fruit.rest_width > 0
    if name in MASS_G:
        low, high = MASS_G[name]
        assert low * 0.95 <= fruit.total_mass * 1e3 <= high * 1.06, fruit.total_mass


def test_strawberry_is_a_spline_profile_lying_on_its_side():
    config = load_config(fruit='strawberry')
    assert config['fruit.shape.type'] == 'spline' and config['fruit.model'] == 'solid'
    upright = build_fruit(dict(config, **{'fruit.shape.angle': 0.0}))
    outline = upright.rest_positions[upright.surface]
    width, height = np.ptp(outline[:, 0]), np.ptp(outline[:, 1])
    assert 0.025 <= width <= 0.035 and height > width  # the drawn berry is taller than wide
    lying = build_fruit(config)
    assert lying.rest_width == pytest.approx(height, rel=1e-3)  # laid on its side


def test_fruits_verb_lists_key_figures():
    run = gripper_sim('fruits', '--json')
    assert run.returncode == 0, run.stderr
    rows = {row['name']: row for row in json.loads(run.stdout)}
    assert set(LIBRARY) <= set(rows)
    for name in LIBRARY:
        config = load_config(fruit=name)
        row = rows[name]
        assert row['youngs_modulus'] == config['fruit.flesh.youngs_modulus']
        assert row['bruise_pressure'] == config['fruit.bruise_pressure']
        assert row['mass'] == pytest.approx(build_fruit(config).total_mass)
    text = gripper_sim('fruits')
    assert text.returncode == 0
    for name in LIBRARY:
        assert name in text.stdout
