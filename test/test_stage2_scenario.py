"""The whole pick-and-place from a scenario file: placed, dropped (and when), bad files."""
import json

import pytest
import yaml

from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigError
from gripper_sim.workflows.scenario import (PHASES, grasp_height, load_scenario, run_scenario,
                                       scenario_config, scenario_from_mapping)
from gripper_sim.workflows.window import estimates
from test_cli_offline import gripper_sim


def test_default_scenario_places_the_apple_at_the_target():
    run = gripper_sim('run', 'pick_and_place', '--json')
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    summary = data['summary']
    assert data['outcome'] == summary['outcome'] == 'placed'
    assert summary['placed'] and not summary['dropped'] and not summary['bruised']
    scenario = load_scenario('pick_and_place')
    assert summary['final_centroid'][0] == pytest.approx(scenario['transport.distance'],
                                                         abs=0.005)
    # every phase ran, in order
    times = summary['phase_times']
    assert list(times) == list(PHASES)
    assert all(a < b for a, b in zip(list(times.values()), list(times.values())[1:]))
    assert summary['slip_distance'] < 1e-3
    assert summary['damage']['peak_pressure'] > 0
    assert max(data['force']) == pytest.approx(scenario['close.force'], rel=0.3)
    # the jaws let go: the last samples have no grip force
    assert data['force'][-1] == 0.0


def test_slip_distance_stays_at_its_held_value_after_the_release():
    """Slip is motion relative to the jaws while they hold the fruit: once the jaws have
    opened and retreated upwards it keeps its last held value instead of growing with
    the retreat (it read 20 mm after a clean placement)."""
    sim = Simulation(scenario_config(load_scenario('pick_and_place')))
    results = []
    summary = run_scenario(sim, load_scenario('pick_and_place'),
                           on_step=lambda result, phase: results.append(result))
    assert summary['outcome'] == 'placed'
    held = [r for r in results if r.in_contact_with('left_jaw') or r.in_contact_with('right_jaw')]
    free_after = results[results.index(held[-1]) + 1:]
    assert len(free_after) > 10                          # the jaws were clear for a while
    assert {r.slip_distance for r in free_after} == {held[-1].slip_distance}
    lift_change = max(r.lift for r in free_after) - min(r.lift for r in free_after)
    assert lift_change > 5e-3                            # the retreat did move the jaws up
    # (the ~1 mm left is the jaws sliding down the fruit as the table takes it)
    assert held[-1].slip_distance < 0.5 * lift_change


def test_too_weak_a_grip_drops_the_fruit_and_says_when():
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, fruit='apple')
    force = 0.4 * estimates(config)[0]
    sim = Simulation(config)
    seen = []
    summary = run_scenario(sim, scenario.with_values(close__force=force),
                           on_step=lambda result, phase: seen.append((result.time, phase)))
    assert summary['outcome'] == 'dropped'
    assert summary['dropped'] and not summary['placed']
    lift_start = summary['phase_times']['lift']
    assert lift_start < summary['dropped_at'] <= seen[-1][0]
    assert summary['dropped_phase'] in ('lift', 'transport')
    assert 'dropped at t =' in summary['message']
    # the run ended at the drop: no lowering, opening or placing
    assert 'open' not in summary['phase_times']


@pytest.mark.slow
def test_position_closing_and_a_transport_to_the_left():
    scenario = load_scenario('pick_and_place')
    config = scenario_config(scenario, fruit='apple')
    sim = Simulation(config)
    gap = sim.fruit.rest_width - 0.003
    summary = run_scenario(sim, scenario.with_values(close__mode='position', close__gap=gap,
                                                     transport__distance=-0.06))
    assert summary['outcome'] == 'placed', summary
    assert summary['final_centroid'][0] == pytest.approx(-0.06, abs=0.005)
    assert summary['max_grip_force'] > 1.0


def test_grasp_height_keeps_the_jaws_above_the_table():
    apple = load_config(fruit='apple')
    assert grasp_height(apple) == pytest.approx(0.0635 / 2)
    strawberry = load_config(fruit='strawberry')
    assert grasp_height(strawberry) == pytest.approx(0.5 * 0.04 + 1e-3)


@pytest.mark.parametrize('data,message', [
    ({'lift': {'heigth': 0.03}}, "unknown scenario key 'lift.heigth'"),
    ({'lift': {'height': -1}}, "'lift.height' = -1"),
    ({'close': {'mode': 'position'}}, "'close.gap'"),
    ({'close': {'mode': 'squeeze'}}, "'close.mode' must be one of force, position"),
    ({'transport': {'speed': 0}}, "'transport.speed' = 0"),
    ({'set': [1, 2]}, "'set'"),
])
def test_bad_scenario_is_refused_naming_the_key(data, message):
    with pytest.raises(ConfigError, match=message.replace('(', r'\(').replace(')', r'\)')):
        scenario_from_mapping(data, 'test')


def test_bad_scenario_files_from_the_cli(tmp_path):
    path = tmp_path / 'bad.yaml'
    path.write_text(yaml.safe_dump({'close': {'force': 'lots'}}))
    run = gripper_sim('run', str(path))
    assert run.returncode == 2
    assert "scenario key 'close.force'" in run.stderr and 'Traceback' not in run.stderr
    unknown = gripper_sim('run', 'no_such_scenario')
    assert unknown.returncode == 2 and "unknown scenario 'no_such_scenario'" in unknown.stderr
    override = tmp_path / 'override.yaml'
    override.write_text(yaml.safe_dump({'set': {'fruit.nodez': 3}}))
    bad_key = gripper_sim('run', str(override))
    assert bad_key.returncode == 2 and "unknown config key 'fruit.nodez'" in bad_key.stderr
    force = gripper_sim('run', 'pick_and_place', '--force', '500')
    assert force.returncode == 2 and 'gripper.max_force' in force.stderr
