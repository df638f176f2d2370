"""The simulation_interfaces audit: the node answers as the standard's definitions say:
filters are POSIX extended regular expressions, and the features list
ENTITY_CATEGORIES."""
import pytest
from simulation_interfaces.msg import (EntityCategory, EntityFilters, Result, SimulationState,
                                       SimulatorFeatures)

from gripper_sim.ros.entities import PatternError, compile_filter
from gripper_sim.ros.process import pick_domain_id
from test_ros_simulation_standard import Standard

DOMAIN = pick_domain_id(14)
NAMES = ['fruit', 'left_jaw', 'right_jaw', 'table', 'a.b', 'x-y', 'a\\b']


@pytest.fixture(scope='module')
def standard(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('audit') / 'node.log'
    parameters = {'physics.sim.dt': 0.001, 'publish_rate': 1000.0, 'clock_rate': 1000.0,
                  'real_time_factor': 0.0}
    with node_and_client(parameters, DOMAIN, log, client_name='audit_client') as (_, client):
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
