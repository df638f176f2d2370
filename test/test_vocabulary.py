"""One vocabulary: every verb's JSON keys and outcome words are those of
``gripper_sim.core.vocabulary``, the node's Grasp result maps onto them, and the README's
glossary is the generated one."""
import json
from pathlib import Path

import pytest
from gripper_sim_interfaces.action import Grasp

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config
from gripper_sim.workflows.factory import make_simulation
from gripper_sim.core.vocabulary import (ACTION_RESULT_FIELDS, KEYS, OUTCOMES, analyze_key,
                                         markdown_glossary)
from gripper_sim.ros.grasp_goal import GoalRun

ROOT = Path(__file__).resolve().parents[1]
SMALL = ['--set', 'fruit.nodes=16', '--quiet']
#: keys whose values are free-form mappings (phase names, event names, per-jaw patches),
#: not vocabulary
FREE_FORM = ('phase_times', 'event_times_s', 'contact_patches_at_peak_force')


def keys_of(value, prefix=''):
    """Every key of a JSON value, nested ones included (lists of objects too)."""
    found = set()
    if isinstance(value, dict):
        for key, item in value.items():
            found.add(key)
            if key not in FREE_FORM:
                found |= keys_of(item)
    elif isinstance(value, list):
        for item in value:
            found |= keys_of(item)
    return found


def verb_json(capsys, *argv):
    main([*argv, '--json'])
    return json.loads(capsys.readouterr().out)


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    folder = tmp_path_factory.mktemp('vocabulary')
    path = folder / 'pick.mcap'
    assert main(['pick', '--force', '2', '--lift', '0.01', '--hold', '0.1', '--out', str(path),
                 *SMALL]) == 0
    return path


@pytest.mark.parametrize('argv', [
    ['squeeze', '--to-force', '1'],
    ['pick', '--force', '2', '--lift', '0.01', '--hold', '0.1'],
    ['pick', '--force', '0.05', '--lift', '0.01', '--hold', '0.1'],   # it drops
    ['run', 'pick_and_place', '--force', '2'],
    ['window', '--tolerance', '0.5'],
    ['pick', '--force', '2', '--lift', '0.01', '--hold', '0.1', '--set', 'dimension=3',
     '--set', 'fruit.mesh.subdivisions=3'],
], ids=['squeeze', 'pick', 'pick-dropped', 'run', 'window', 'pick-3d'])
def test_every_verb_reports_only_vocabulary_keys_and_words(argv, capsys):
    data = verb_json(capsys, *argv, *SMALL)
    unknown = keys_of(data) - set(KEYS)
    assert not unknown, f'{argv[0]} reports keys outside the vocabulary: {unknown}'
    summary = data.get('summary', data)
    if 'outcome' in summary:
        assert summary['outcome'] in OUTCOMES
    for trial in data.get('trials', []):
        assert trial['outcome'] in OUTCOMES and trial['verdict'] in OUTCOMES


def test_the_peaks_have_one_name_in_every_simulation_verb(capsys):
    """The same quantity under the same key: squeeze, pick and run all report the measured
    peak grip force, compression, jaw and table pressure and the damage pressure."""
    shared = {'peak_grip_force', 'peak_compression', 'peak_jaw_pressure',
              'peak_table_pressure', 'peak_damage_pressure', 'bruised', 'crushed',
              'bruised_fraction'}
    for argv in (['squeeze', '--to-force', '1'], ['pick', '--force', '2', '--hold', '0.1',
                                                  '--lift', '0.01'],
                 ['run', 'pick_and_place', '--force', '2']):
        summary = verb_json(capsys, *argv, *SMALL)['summary']
        assert shared <= set(summary), (argv[0], shared - set(summary))
        force = float(argv[argv.index('--force') + 1] if '--force' in argv else argv[2])
        assert summary['peak_grip_force'] > 0.9 * force


def test_at_a_small_force_the_jaw_pressure_is_not_the_tables(capsys):
    """Resting on the table and gripped lightly, the fruit presses the table harder than
    the jaws: the jaws' peak is reported as such, the table's apart."""
    summary = verb_json(capsys, 'pick', '--force', '0.3', '--lift', '0', '--hold', '0.1',
                        *SMALL)['summary']
    assert 0 < summary['peak_jaw_pressure'] < summary['peak_table_pressure']


def test_a_fruit_left_on_the_table_is_dropped_in_pick_as_in_run(capsys):
    pick = verb_json(capsys, 'pick', '--force', '0.05', '--lift', '0.03', '--hold', '0.1',
                     *SMALL)
    run = verb_json(capsys, 'run', 'pick_and_place', '--force', '0.05', *SMALL)
    assert pick['outcome'] == run['outcome'] == 'dropped'


def test_analyze_writes_the_vocabulary_keys_with_unit_suffixes(recording, tmp_path):
    out = tmp_path / 'analysis'
    assert main(['analyze', str(recording), '-o', str(out), '--no-figures', '--no-html',
                 '--quiet']) == 0
    summary = json.loads((out / 'summary.json').read_text())
    names = {analyze_key(key) for key in KEYS}
    unknown = keys_of(summary) - names
    assert not unknown, f'analyze reports keys outside the vocabulary: {unknown}'
    assert 'peak_grip_force_n' in summary and 'peak_damage_pressure_pa' in summary


def test_the_grasp_action_result_maps_every_field_onto_a_key():
    fields = set(Grasp.Result.get_fields_and_field_types())
    assert fields == set(ACTION_RESULT_FIELDS)
    assert set(ACTION_RESULT_FIELDS.values()) <= set(KEYS)


def test_the_grasp_action_result_carries_the_summarys_values():
    config = load_config(overrides={'fruit.nodes': 16})
    sim = make_simulation(config)
    goal = Grasp.Goal(target_force=2.0, lift_height=0.01, hold_time=0.1)
    run = GoalRun(sim, goal, config)
    while not run.done:
        run.update(sim.step())
    summary = run.summary()
    result = run.result(summary)
    assert result.outcome == summary['outcome'] == 'held' and result.success
    for field, key in ACTION_RESULT_FIELDS.items():
        value = summary[key] if key != 'dropped_at' else -1.0
        if isinstance(value, float):
            assert getattr(result, field) == pytest.approx(value, rel=1e-12), field
    assert result.max_grip_force == pytest.approx(2.0, rel=0.05)
    assert result.max_contact_pressure == summary['peak_jaw_pressure'] > 0


def test_the_readme_glossary_is_the_generated_one():
    readme = (ROOT / 'README.md').read_text()
    assert markdown_glossary() in readme, \
        'README glossary is stale: run python scripts/update_readme_config.py'
