"""Study files are validated like every configuration: a clear error naming the key."""
from __future__ import annotations

import textwrap

import pytest
import yaml

from gripper_sim.configuration import package_config_dir
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.population import parse_population
from gripper_sim.workflows.study_spec import load_study
from test_cli_offline import gripper_sim

GOOD = '''
name: check
base: {fruit: apple, finger: flat, scenario_set: {transport.distance: 0.0}, set: {sim.dt: 0.002}}
axes:
  finger: [flat, vgroove]
  contact.jaw.static_friction: [0.5, 0.8]
population:
  samples: 5
  seed: 3
  distributions:
    fruit.shape.diameter: {distribution: normal, mean: 0.0635, std: 0.003}
    mass: {distribution: lognormal, mean: 0.135, std: 0.02}
    fruit.flesh.youngs_modulus: {distribution: uniform, low: 1.5e6, high: 3.0e6}
    fruit.pressure.turgor: {distribution: list, values: [2.0e4, 3.0e4, 4.0e4]}
'''


def write(tmp_path, text, name='study.yaml'):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_a_good_study_has_every_combination_and_reproducible_samples(tmp_path):
    study = load_study(write(tmp_path, GOOD))
    assert [p.values for p in study.points] == [
        {'finger': f, 'contact.jaw.static_friction': mu}
        for f in ('flat', 'vgroove') for mu in (0.5, 0.8)]
    first, again = study.population.draw(), study.population.draw()
    assert first == again and len(first) == 5
    assert len({s['fruit.shape.diameter'] for s in first}) == 5
    assert all(s['fruit.pressure.turgor'] in (2.0e4, 3.0e4, 4.0e4) for s in first)
    # the drawn mass is the mass of the simulated fruit (density scaled to it)
    from gripper_sim.workflows.window import estimates
    setup = study.trial(study.points[3], 2, first[2])
    assert estimates(setup.config)[2] == pytest.approx(first[2]['mass'], rel=1e-9)
    assert setup.config['contact.jaw.static_friction'] == 0.8
    # the kinetic friction keeps its ratio to the static one (0.4 / 0.5 in the preset)
    assert setup.config['contact.jaw.kinetic_friction'] == pytest.approx(0.64)
    assert setup.config['gripper.finger.type'] == 'vgroove'


@pytest.mark.parametrize('change, message', [
    ({'bogus': 1}, "unknown study key 'bogus'"),
    ({'axes': {'contact.jaw.static_friction': []}},
     "axis 'contact.jaw.static_friction' is empty"),
    ({'axes': {'contact.jaw.static_fricton': [0.5]}},
     "unknown axis key 'contact.jaw.static_fricton'.*did you mean"),
    ({'axes': {'contact.jaw.static_friction': [0.5, 9.0]}},
     "'contact.jaw.static_friction' = 9.0 is out of range"),
    ({'axes': {'force': [2.0, -1.0]}}, "axis 'force' values must be positive"),
    ({'axes': {'scenario.lift.height': [-0.01]}}, 'lift.height'),
    ({'population': {'samples': 4, 'distributions': {
        'fruit.shape.diameter': {'distribution': 'normal', 'mean': 0.06, 'std': -0.01}}}},
     r"population.distributions.fruit.shape.diameter.std' must not be negative"),
    ({'population': {'samples': 50, 'seed': 1, 'distributions': {
        'fruit.shape.diameter': {'distribution': 'normal', 'mean': 0.01, 'std': 0.01}}}},
     "population key 'fruit.shape.diameter' .* yields non-physical values"),
    ({'population': {'samples': 4, 'distributions': {
        'fruit.flesh.youngs_modulus': {'distribution': 'gamma', 'mean': 1}}}},
     "unknown distribution 'gamma'"),
    ({'population': {'samples': 4, 'distributions': {
        'fruit.nam': {'distribution': 'list', 'values': [1]}}}},
     "unknown population key 'fruit.nam'"),
    ({'population': {'samples': 0}}, "'population.samples' must be an integer"),
    ({'base': {'fruit': 'banana'}}, "unknown fruit 'banana'"),
    ({'base': {'set': {'sim.dtt': 0.001}}}, "unknown config key 'sim.dtt'"),
    ({'window': {'fraction': 1.5}}, "'window.fraction' must be a number in"),
])
def test_bad_study_files_name_the_key(tmp_path, change, message):
    import yaml
    data = yaml.safe_load(GOOD)
    data.update(change)
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(ConfigError, match=message):
        study = load_study(path)
        study.population.draw()


def test_the_cli_says_error_and_exits_2_on_a_bad_study(tmp_path):
    path = write(tmp_path, '''
        name: bad
        axes: {contact.jaw.static_friction: []}
        ''')
    run = gripper_sim('study', str(path), '--out', str(tmp_path / 'out'))
    assert run.returncode == 2
    assert run.stderr.strip() == ("error: axis 'contact.jaw.static_friction' is empty: give "
                                  'it at least one value')
    negative = write(tmp_path, '''
        population:
          samples: 3
          distributions:
            fruit.density: {distribution: normal, mean: 900, std: -10}
        ''', 'neg.yaml')
    run = gripper_sim('study', str(negative), '--out', str(tmp_path / 'out'))
    assert run.returncode == 2 and 'std' in run.stderr and 'Traceback' not in run.stderr


def test_list_distribution_uses_every_measured_value_when_it_can():
    population = parse_population({'samples': 4, 'seed': 9, 'distributions': {
        'fruit.density': {'distribution': 'list', 'values': [800, 850, 900, 950]}}})
    drawn = sorted(s['fruit.density'] for s in population.draw())
    assert drawn == [800, 850, 900, 950]


def test_the_example_studies_load():
    from gripper_sim.configuration import package_config_dir
    names = sorted(p.stem for p in (package_config_dir() / 'studies').glob('*.yaml'))
    assert names
    for name in names:
        study = load_study(name)
        assert study.points and len(study.population.draw()) == study.population.samples


def test_studies_run_without_ros():
    import subprocess
    import sys
    code = ('import sys; import gripper_sim.workflows.study, gripper_sim.cli.study, '
            'gripper_sim.workflows.study_report; print("rclpy" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == 'False'


def test_a_fruit_preset_file_is_a_study_fruit(tmp_path):
    """A preset written by `gripper-sim calibrate` (any fruit preset file) is a study's
    base fruit like a built-in name."""
    preset = yaml.safe_load((package_config_dir() / 'fruits' / 'plum.yaml').read_text())
    preset['fruit']['name'] = 'my_plum'
    preset['fruit']['density'] = 987.0
    (tmp_path / 'my_plum.yaml').write_text(yaml.safe_dump(preset))
    study_file = tmp_path / 'study.yaml'
    study_file.write_text(textwrap.dedent(f"""\
        name: preset_fruit
        base: {{fruit: {tmp_path / 'my_plum.yaml'}, finger: flat}}
        axes: {{force: [1.0, 2.0]}}
        population: {{samples: 2, seed: 1, distributions:
          {{fruit.shape.diameter: {{distribution: normal, mean: 0.05, std: 0.001}}}}}}
        """))
    study = load_study(study_file)
    config = study.trial(study.points[0], 0, {}).config
    assert config['fruit.name'] == 'my_plum' and config['fruit.density'] == 987.0


def test_an_unknown_study_name_lists_the_installed_studies():
    """A misspelt study name says it is neither a file nor an installed study, and names
    the installed ones (as an unknown scenario does)."""
    with pytest.raises(ConfigError) as error:
        load_study('apple_frictio')
    message = str(error.value)
    installed = sorted(p.stem for p in (package_config_dir() / 'studies').glob('*.yaml'))
    assert 'apple_friction' in installed
    assert "no study file 'apple_frictio'" in message
    assert all(name in message for name in installed), message
