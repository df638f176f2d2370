"""What the header prints is the physics the user gets: a configuration file layers over a
fruit preset, ``--set fruit=NAME`` selects one, and a key that has no effect in the set-up
is a one-line warning naming the key that does."""
import warnings

import pytest

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config, no_effect_reason, to_yaml
from gripper_sim.workflows.scenario import load_scenario, scenario_config
from gripper_sim.errors import ConfigError, ConfigWarning

SMALL = ['--set', 'fruit.nodes=16']


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def no_warnings(**kwargs):
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        return load_config(**kwargs)


def test_a_file_without_fruit_starts_from_the_default_fruits_preset(tmp_path):
    path = write(tmp_path, 'dt.yaml', 'sim:\n  dt: 0.0005\n')
    config = no_warnings(config_file=path)
    assert config == load_config(overrides={'sim.dt': 0.0005})
    assert config['fruit.name'] == 'apple'
    assert config['fruit.pressure.turgor'] == load_config()['fruit.pressure.turgor'] > 0


def test_fruit_and_config_combine_the_file_layered_over_the_preset(tmp_path):
    path = write(tmp_path, 'dt.yaml', 'sim:\n  dt: 0.0005\n')
    config = no_warnings(fruit='plum', config_file=path)
    assert config == load_config(fruit='plum', overrides={'sim.dt': 0.0005})


def test_fruit_and_config_on_the_command_line(tmp_path, capsys):
    path = write(tmp_path, 'dt.yaml', 'sim:\n  dt: 0.002\n')
    assert main(['squeeze', '--fruit', 'plum', '--config', path, '--to-force', '0.5',
                 '--quiet', *SMALL]) == 0
    captured = capsys.readouterr()
    assert captured.out.startswith('squeeze of plum (shell model, 2D)')
    assert captured.err == ''


def test_set_fruit_selects_the_preset():
    assert no_warnings(overrides=['fruit=plum']) == load_config(fruit='plum')
    assert no_warnings(overrides={'fruit': 'plum', 'sim.dt': 0.002}) == load_config(
        fruit='plum', overrides={'sim.dt': 0.002})


def test_a_choice_that_replaces_another_is_a_warning(tmp_path):
    path = write(tmp_path, 'plum.yaml', 'fruit: plum\n')
    with pytest.warns(ConfigWarning, match=r"--fruit peach replaces the config file's "
                      r"'fruit: plum': the fruit preset is 'peach'"):
        config = load_config(fruit='peach', config_file=path)
    assert config == load_config(fruit='peach')
    with pytest.warns(ConfigWarning, match=r'--set fruit=plum replaces --fruit apple'):
        assert load_config(fruit='apple', overrides=['fruit=plum'])['fruit.name'] == 'plum'


def test_renaming_the_fruit_to_another_preset_is_a_warning():
    with pytest.warns(ConfigWarning, match=r"'fruit.name' = plum only renames the 'apple' "
                      r'preset .* --fruit plum or --set fruit=plum'):
        load_config(overrides=['fruit.name=plum'])
    no_warnings(overrides=['fruit.name=my_apple'])   # a name of one's own is fine


def test_jaw_friction_under_a_pad_is_a_warning_naming_the_pad_friction():
    with pytest.warns(ConfigWarning) as caught:
        load_config(finger='soft_pad', overrides={'contact.jaw.static_friction': 0.9,
                                                  'contact.jaw.kinetic_friction': 0.8})
    lines = [str(w.message) for w in caught]
    assert len(lines) == 2
    for key, line in zip(('static', 'kinetic'), lines):
        assert line.startswith(f"config key 'contact.jaw.{key}_friction' has no effect")
        assert "'contact.pad.friction'" in line
    # the preset's own jaw friction (every fruit has one) is no user's choice: no warning
    no_warnings(finger='soft_pad')
    no_warnings(overrides={'contact.jaw.static_friction': 0.9})   # no pad: it applies


def test_keys_without_effect_name_what_has_one():
    flat = load_config()
    assert 'gripper.finger.pad.enabled' in no_effect_reason('contact.pad.friction', flat)
    assert "'gripper.finger.type' = arc" in no_effect_reason('gripper.finger.radius', flat)
    assert no_effect_reason('fruit.pressure.turgor', flat) is None
    solid = load_config(overrides={'fruit.model': 'solid'})
    assert 'shell model' in no_effect_reason('fruit.pressure.turgor', solid)


def test_the_cli_prints_each_warning_once_on_one_line(tmp_path, capsys):
    path = write(tmp_path, 'pad.yaml', 'contact:\n  jaw: {static_friction: 0.9}\n')
    assert main(['squeeze', '--config', path, '--set', 'gripper.finger.pad.enabled=true',
                 '--to-force', '0.5', '--quiet', *SMALL]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err == ["warning: config key 'contact.jaw.static_friction' has no effect: a soft "
                   "pad covers the jaws ('gripper.finger.pad.enabled'): the friction there "
                   "is 'contact.pad.friction'"]


def test_a_scenario_warns_once_and_its_fruit_is_the_fallback(tmp_path):
    scenario = load_scenario('pick_and_place')
    path = write(tmp_path, 'dt.yaml', 'sim:\n  dt: 0.002\n')
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        config = scenario_config(scenario.with_values(fruit='plum'), config_file=path)
    assert config['fruit.name'] == 'plum' and config['sim.dt'] == 0.002
    with warnings.catch_warnings():   # the command line overrides the scenario quietly
        warnings.simplefilter('error', ConfigWarning)
        assert scenario_config(scenario, fruit='peach')['fruit.name'] == 'peach'
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter('always')
        scenario_config(scenario, overrides=['fruit.name=plum'])
    assert len(caught) == 1 and 'only renames' in str(caught[0].message)


@pytest.mark.parametrize('argv, message', [
    (['--set', 'fruit=3'], "override 'fruit=3': fruit must be a fruit preset name"),
    (['--set', 'fruit=kiwi'], "unknown fruit 'kiwi' (known fruits:"),
    (['--set', 'fruits=plum'], "unknown config key 'fruits' (did you mean 'fruit'?)"),
    (['--set', 'finger=claw'], "unknown finger 'claw' (known fingers:"),
])
def test_bad_preset_choices_are_one_line_errors(argv, message, capsys):
    assert main(['squeeze', '--to-force', '1', *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: ') and message in err and err.count('\n') == 1


def test_a_bad_fruit_in_the_file_is_an_error(tmp_path):
    path = write(tmp_path, 'kiwi.yaml', 'fruit: kiwi\n')
    with pytest.raises(ConfigError, match="unknown fruit 'kiwi'"):
        load_config(config_file=path)


def test_a_saved_configuration_loads_again_without_warnings(tmp_path):
    """A full configuration written out (as ``to_yaml`` or a recording writes it) restates
    every key at the value it has anyway: loading it back warns about nothing; a key
    changed in it still warns."""
    config = load_config()
    path = write(tmp_path, 'saved.yaml', to_yaml(config))
    no_warnings(config_file=path)
    changed = write(tmp_path, 'changed.yaml', to_yaml({**config, 'contact.pad.friction': 0.6}))
    with pytest.warns(ConfigWarning, match="'contact.pad.friction' has no effect"):
        load_config(config_file=changed)


def test_a_preset_calibrated_in_3d_warns_when_run_in_2d(tmp_path):
    """``gripper-sim calibrate`` records the dimension it fitted in (``calibration:``); a
    run in the other dimension is told, one it was fitted for is not."""
    preset = tmp_path / 'my_peach.yaml'
    preset.write_text('fruit:\n  name: my_peach\n  flesh:\n    youngs_modulus: 9.9e5\n'
                      'calibration:\n  base_fruit: peach\n  model: solid\n  dimension: 3\n')
    with pytest.warns(ConfigWarning, match=r"calibrated in 3D \(solid model\); this run is "
                                           r"2D.*--set dimension=3"):
        config = load_config(fruit=str(preset))
    assert config['fruit.flesh.youngs_modulus'] == pytest.approx(9.9e5)
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        assert load_config(fruit=str(preset), overrides=['dimension=3'])['dimension'] == 3
    plain = tmp_path / 'plain.yaml'
    plain.write_text('fruit:\n  name: plain\n')   # no record: nothing to say
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        load_config(fruit=str(plain))


def test_squeeze_and_pick_headers_name_the_finger(capsys):
    """The squeeze's and the pick's first lines name the finger, as run's and window's do."""
    assert main(['squeeze', '--finger', 'vgroove', '--to-force', '0.5', '--quiet',
                 *SMALL]) == 0
    assert capsys.readouterr().out.startswith(
        'squeeze of apple (shell model, 2D) with the vgroove finger, ')
    main(['pick', '--finger', 'vgroove', '--force', '3', '--lift', '0.005', '--hold', '0.05',
          '--quiet', *SMALL])
    assert capsys.readouterr().out.startswith('pick of apple (2D) with the vgroove finger '
                                              'at 3 N: ')


@pytest.mark.parametrize('key', ['fruit.bruise_pressure', 'fruit.failure_stress'])
def test_a_damage_threshold_given_in_mpa_is_refused_with_its_unit(key, capsys):
    """0.26 (MPa written where the key is in Pa) would make every touch bruise or crush."""
    with pytest.raises(ConfigError, match=rf"'{key}' = 0.26 Pa is out of range: it must "
                                          r'be >= 1000.0 Pa'):
        load_config(overrides=[f'{key}=0.26'])
    assert load_config(overrides=[f'{key}=0.26e6'])[key] == 0.26e6
    assert main(['squeeze', '--to-force', '1', '--set', f'{key}=0.26', *SMALL]) == 2
    assert 'out of range' in capsys.readouterr().err
