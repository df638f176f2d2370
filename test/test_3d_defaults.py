"""The 3D defaults: what ``--set dimension=3`` alone gives (the benchmark's set-up)."""
import json

import pytest

from gripper_sim.cli.main import main
from gripper_sim.config_doc import markdown_table
from gripper_sim.configuration import SCHEMA, load_config


def test_dimension_3_takes_the_3d_defaults_and_2d_keeps_its_own():
    planar = load_config()
    spatial = load_config(overrides=['dimension=3'])
    assert planar['sim.dt'] == SCHEMA['sim.dt'].default == 1e-3
    assert spatial['sim.dt'] == SCHEMA['sim.dt'].default_3d == 0.02
    assert spatial['fruit.mesh.subdivisions'] == 8 and spatial['fruit.mesh.jaw_refinement'] == 1


def test_a_value_given_anywhere_wins_over_the_3d_default(tmp_path):
    assert load_config(overrides=['dimension=3', 'sim.dt=0.001'])['sim.dt'] == 0.001
    assert load_config(overrides={'sim.dt': 0.005, 'dimension': 3})['sim.dt'] == 0.005
    path = tmp_path / 'run.yaml'
    path.write_text('dimension: 3\nsim:\n  dt: 0.004\n', encoding='utf-8')
    assert load_config(config_file=path)['sim.dt'] == 0.004
    path.write_text('dimension: 3\n', encoding='utf-8')
    assert load_config(config_file=path)['sim.dt'] == 0.02
    # a file that asks for 3D, overridden back to 2D on the command line: 2D defaults
    assert load_config(config_file=path, overrides=['dimension=2'])['sim.dt'] == 1e-3


def test_the_configuration_table_shows_the_3d_default():
    row = next(line for line in markdown_table().splitlines() if line.startswith('| `sim.dt`'))
    assert '0.001 (3D: 0.02)' in row


def _squeeze(capsys, *extra):
    assert main(['squeeze', '--to-force', '2', '--json', '--set', 'dimension=3', *extra]) == 0
    return json.loads(capsys.readouterr().out)['summary']


@pytest.mark.slow
def test_default_3d_squeeze_agrees_with_a_small_step(capsys):
    """The README's promise for the 20 ms default: the peak force within 3 % of a 5 ms
    step (a squeeze stops up to one step past its target), contact area and pressure
    within 1 %."""
    default = _squeeze(capsys)
    fine = _squeeze(capsys, '--set', 'sim.dt=0.005')
    assert default['peak_grip_force'] >= 2.0
    assert default['peak_grip_force'] == pytest.approx(fine['peak_grip_force'], rel=0.03)
    for key in ('contact_area_at_peak_force', 'peak_jaw_pressure'):
        assert default[key] == pytest.approx(fine[key], rel=0.01), key
