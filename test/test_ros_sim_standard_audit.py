"""The simulation_interfaces audit: the node answers as the standard's definitions say.
spawn_entity names the new fruit as SpawnEntity.srv does (a taken name is NAME_NOT_UNIQUE
unless allow_renaming, an invalid one NAME_INVALID, file:// URIs), a reset with
SCOPE_SPAWNED brings back the start-up fruit, filters are POSIX extended regular
expressions, and the features list ENTITY_CATEGORIES."""
import pytest
from simulation_interfaces.msg import (EntityCategory, EntityFilters, Result, SimulationState,
                                       SimulatorFeatures)
from simulation_interfaces.srv import ResetSimulation, SetSimulationState, SpawnEntity

from gripper_sim import configuration
from gripper_sim.ros.entities import PatternError, compile_filter
from gripper_sim.ros.process import pick_domain_id
from test_ros_simulation_standard import APPLE_RADIUS, NODE_PARAMETERS, PLUM_RADIUS, Standard

DOMAIN = pick_domain_id(14)
NAMES = ['fruit', 'left_jaw', 'right_jaw', 'table', 'a.b', 'x-y', 'a\\b']
SCOPE = ResetSimulation.Request


@pytest.fixture(scope='module')
def standard(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('audit') / 'node.log'
    with node_and_client(NODE_PARAMETERS, DOMAIN, log,
                         client_name='audit_client') as (_, client):
        standard = Standard(client)
        assert standard.go(SimulationState.STATE_PAUSED).result == Result.RESULT_OK
        yield standard


def matching(pattern: str) -> list[str]:
    compiled = compile_filter(pattern)
    return [name for name in NAMES if compiled.search(name)]


@pytest.mark.parametrize('pattern, names', [
    ('^[[:alpha:]]+_jaw$', ['left_jaw', 'right_jaw']),
    ('^[[:lower:]]+$', ['fruit', 'table']),
    ('[[:punct:]]', ['left_jaw', 'right_jaw', 'a.b', 'x-y', 'a\\b']),
    ('[\\]', ['a\\b']),                 # a backslash in brackets is itself
    ('a\\.b', ['a.b']),
    ('[]x-]', ['x-y']),                 # ']' first and '-' last are literals
    ('^[^[:upper:][:punct:]]+$', ['fruit', 'table']),
    ('^(fruit|table)$', ['fruit', 'table'])])
def test_filters_are_posix_extended(pattern, names):
    assert matching(pattern) == names


@pytest.mark.parametrize('pattern, reason', [
    ('\\1', 'backreference'), ('\\d', '[[:digit:]]'), ('(?i)JAW', "Python's syntax"),
    ('[[:letter:]]', "unknown character class '[:letter:]'"), ('[abc', 'not closed'),
    ('[z-a]', 'reversed'), ('(jaw', 'missing )')])
def test_an_invalid_filter_says_why(pattern, reason):
    with pytest.raises(PatternError) as error:
        compile_filter(pattern)
    assert reason in str(error.value)


@pytest.mark.ros
@pytest.mark.slow
def test_features_list_entity_categories(standard):
    features = standard.call(standard.features).features.features
    assert SimulatorFeatures.ENTITY_CATEGORIES in features
    robots = standard.call(standard.entities, filters=EntityFilters(
        categories=[EntityCategory(category=EntityCategory.CATEGORY_ROBOT)]))
    assert list(robots.entities) == ['left_jaw', 'right_jaw']


@pytest.mark.ros
@pytest.mark.slow
def test_get_entities_with_a_posix_filter(standard):
    call = standard.call
    jaws = call(standard.entities, filters=EntityFilters(filter='^[[:alpha:]]+_jaw$'))
    assert jaws.result.result == Result.RESULT_OK
    assert list(jaws.entities) == ['left_jaw', 'right_jaw']
    python_only = call(standard.entities, filters=EntityFilters(filter='\\w+_jaw'))
    assert python_only.result.result == Result.RESULT_OPERATION_FAILED
    assert 'POSIX' in python_only.result.error_message


def spawn(standard, **fields):
    return standard.call(standard.spawn, **fields)


def rest_height(standard, name: str) -> float:
    """m, the fruit ``name``'s centroid above the table surface."""
    return (standard.entity(name).pose.position.z -
            standard.entity('table').pose.position.z)


def entities(standard) -> list[str]:
    return list(standard.call(standard.entities).entities)


@pytest.mark.ros
@pytest.mark.slow
def test_spawn_names_the_fruit_as_the_standard_says(standard, tmp_path):
    assert standard.call(standard.reset).result.result == Result.RESULT_OK
    standard.wait_clock(0)
    assert standard.call(standard.step, steps=3).result.result == Result.RESULT_OK
    standard.wait_clock(3_000_000)
    refusals = [
        (dict(name='fruit', uri='plum'), SpawnEntity.Response.NAME_NOT_UNIQUE,
         "'fruit' is taken"),
        (dict(name='table', uri='plum'), SpawnEntity.Response.NAME_NOT_UNIQUE, 'is taken'),
        (dict(name='bad name!', uri='plum', allow_renaming=True),
         SpawnEntity.Response.NAME_INVALID, "invalid name 'bad name!'"),
        (dict(uri='package://gripper_sim/config/fruits/plum.yaml'),
         SpawnEntity.Response.UNSUPPORTED_FORMAT, "scheme 'package'"),
        (dict(uri='plum.urdf'), SpawnEntity.Response.UNSUPPORTED_FORMAT, "'.urdf'"),
        (dict(resource_string='fruit: {name: plum}'), Result.RESULT_FEATURE_UNSUPPORTED,
         'resource_string')]
    for fields, code, text in refusals:
        refused = spawn(standard, **fields)
        assert refused.result.result == code, (fields, refused.result.error_message)
        assert text in refused.result.error_message, refused.result.error_message
    assert standard.clock_ns() == 3_000_000   # nothing was replaced
    assert entities(standard) == ['fruit', 'left_jaw', 'right_jaw', 'table']

    free = spawn(standard, name='fruit2', uri='plum')
    assert free.result.result == Result.RESULT_OK, free.result.error_message
    assert free.entity_name == 'fruit2'
    standard.wait_clock(0)
    assert entities(standard) == ['fruit2', 'left_jaw', 'right_jaw', 'table']
    assert rest_height(standard, 'fruit2') == pytest.approx(PLUM_RADIUS, rel=0.1)
    gone = standard.call(standard.entity_state, entity='fruit')
    assert gone.result.result == Result.RESULT_NOT_FOUND

    apple_uri = (configuration.package_config_dir() / 'fruits' / 'apple.yaml').as_uri()
    renamed = spawn(standard, name='fruit2', uri=apple_uri, allow_renaming=True)
    assert renamed.result.result == Result.RESULT_OK, renamed.result.error_message
    assert renamed.entity_name == 'fruit2_1'
    assert rest_height(standard, 'fruit2_1') == pytest.approx(APPLE_RADIUS, rel=0.1)

    by_preset = spawn(standard, uri='plum')   # no name: the preset's fruit.name
    assert (by_preset.result.result, by_preset.entity_name) == (Result.RESULT_OK, 'plum')
    again = spawn(standard, uri='plum')
    assert again.result.result == SpawnEntity.Response.NAME_NOT_UNIQUE
    again = spawn(standard, uri='plum', allow_renaming=True)
    assert (again.result.result, again.entity_name) == (Result.RESULT_OK, 'plum_1')

    unnamed = tmp_path / 'unnamed.yaml'
    unnamed.write_text('fruit:\n  shape:\n    diameter: 0.05\n')
    nameless = spawn(standard, uri=str(unnamed))
    assert nameless.result.result == SpawnEntity.Response.NAME_INVALID
    generated = spawn(standard, uri=str(unnamed), allow_renaming=True)
    assert (generated.result.result, generated.entity_name) == (Result.RESULT_OK, 'fruit')

    refused = standard.call(standard.delete, entity='fruit')
    assert refused.result.result == Result.RESULT_OPERATION_FAILED
    assert 'exactly one fruit' in refused.result.error_message


@pytest.mark.ros
@pytest.mark.slow
def test_a_reset_with_scope_spawned_brings_back_the_start_up_fruit(standard):
    call = standard.call
    assert call(standard.reset, scope=SCOPE.SCOPE_ALL).result.result == Result.RESULT_OK
    standard.wait_clock(0)
    start_up_height = rest_height(standard, 'fruit')
    assert start_up_height == pytest.approx(APPLE_RADIUS, rel=0.1)

    for scope in (SCOPE.SCOPE_ALL, SCOPE.SCOPE_DEFAULT,
                  SCOPE.SCOPE_TIME | SCOPE.SCOPE_STATE | SCOPE.SCOPE_SPAWNED):
        for preset in ('strawberry', 'plum'):   # the start-up values of both presets' keys
            assert spawn(standard, uri=preset).result.result == Result.RESULT_OK
        assert entities(standard)[0] == 'plum'
        reset = call(standard.reset, scope=scope)
        assert reset.result.result == Result.RESULT_OK, (scope, reset.result.error_message)
        standard.wait_clock(0)
        assert entities(standard) == ['fruit', 'left_jaw', 'right_jaw', 'table'], scope
        assert rest_height(standard, 'fruit') == pytest.approx(start_up_height, abs=1e-9)

    assert spawn(standard, uri='plum').result.result == Result.RESULT_OK
    kept = call(standard.reset, scope=SCOPE.SCOPE_TIME | SCOPE.SCOPE_STATE)
    assert kept.result.result == Result.RESULT_OK
    assert entities(standard)[0] == 'plum'   # no SCOPE_SPAWNED: the spawned fruit stays
    only_spawned = call(standard.reset, scope=SCOPE.SCOPE_SPAWNED)
    assert only_spawned.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    assert entities(standard)[0] == 'plum'
    assert standard.go(SimulationState.STATE_STOPPED).result == Result.RESULT_OK
    assert entities(standard)[0] == 'plum'   # a stop resets time and state only
    assert standard.go(SimulationState.STATE_PAUSED).result in (
        Result.RESULT_OK, SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
