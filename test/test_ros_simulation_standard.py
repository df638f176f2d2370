"""A generic simulator client drives the node through simulation_interfaces only: the
features it lists, pause, step N (time advances by exactly N dt), SimulateSteps with
feedback and cancel, reset, stop, play; the entities, their states, the spawnable fruits,
replacing the fruit by another and the spawns and deletes refused (the standard's
finer points: test_ros_sim_standard_audit)."""
import pytest
from action_msgs.msg import GoalStatus
from simulation_interfaces.action import SimulateSteps
from simulation_interfaces.msg import (EntityCategory, EntityFilters, Result, SimulationState,
                                       SimulatorFeatures)
from simulation_interfaces.srv import (DeleteEntity, GetEntities, GetEntityState,
                                       GetSimulationState, GetSimulatorFeatures, GetSpawnables,
                                       ResetSimulation, SetSimulationState, SpawnEntity,
                                       StepSimulation)

from gripper_sim.ros.process import pick_domain_id

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(12)
DT_NS = 1_000_000   # physics.sim.dt 1 ms; /clock and the state every step
IMPLEMENTED = {SimulatorFeatures.SIMULATION_RESET, SimulatorFeatures.SIMULATION_STATE_GETTING,
               SimulatorFeatures.SIMULATION_STATE_SETTING,
               SimulatorFeatures.SIMULATION_STATE_PAUSE,
               SimulatorFeatures.STEP_SIMULATION_SINGLE,
               SimulatorFeatures.STEP_SIMULATION_MULTIPLE,
               SimulatorFeatures.STEP_SIMULATION_ACTION,
               SimulatorFeatures.ENTITY_STATE_GETTING, SimulatorFeatures.ENTITY_CATEGORIES,
               SimulatorFeatures.SPAWNABLES, SimulatorFeatures.SPAWNING}
APPLE_RADIUS, PLUM_RADIUS = 0.0635 / 2, 0.045 / 2   # m, config/fruits


class Standard:
    """Service clients of the standard, on the test client's node."""

    def __init__(self, client):
        self.client = client
        node = client.node
        self.features = node.create_client(GetSimulatorFeatures, '/get_simulator_features')
        self.reset = node.create_client(ResetSimulation, '/reset_simulation')
        self.step = node.create_client(StepSimulation, '/step_simulation')
        self.get_state = node.create_client(GetSimulationState, '/get_simulation_state')
        self.set_state = node.create_client(SetSimulationState, '/set_simulation_state')
        self.simulate = client.action_client(SimulateSteps, '/simulate_steps')
        self.entities = node.create_client(GetEntities, '/get_entities')
        self.entity_state = node.create_client(GetEntityState, '/get_entity_state')
        self.spawnables = node.create_client(GetSpawnables, '/get_spawnables')
        self.spawn = node.create_client(SpawnEntity, '/spawn_entity')
        self.delete = node.create_client(DeleteEntity, '/delete_entity')
        services = (self.features, self.reset, self.step, self.get_state, self.set_state,
                    self.entities, self.entity_state, self.spawnables, self.spawn,
                    self.delete)
        client.spin_until(lambda: all(s.service_is_ready() for s in services)
                          and self.simulate.server_is_ready(), 60,
                          'the simulation_interfaces services')

    def call(self, service, **fields):
        return self.client.call(service, service.srv_type.Request(**fields))

    def state(self) -> int:
        response = self.call(self.get_state)
        assert response.result.result == Result.RESULT_OK
        return response.state.state

    def go(self, state: int):
        return self.call(self.set_state, state=SimulationState(state=state)).result

    def entity(self, name: str):
        response = self.call(self.entity_state, entity=name)
        assert response.result.result == Result.RESULT_OK, response.result.error_message
        return response.state

    def clock_ns(self) -> int:
        stamp = self.client.latest['clock'].clock
        return stamp.sec * 1_000_000_000 + stamp.nanosec

    def wait_clock(self, ns: int):
        self.client.spin_until(lambda: 'clock' in self.client.latest and self.clock_ns() == ns,
                               60, f'/clock at {ns} ns')


#: the node of these tests: 1 ms steps, every step published, as fast as it can
NODE_PARAMETERS = {'physics.sim.dt': 0.001, 'publish_rate': 1000.0, 'clock_rate': 1000.0,
                   'real_time_factor': 0.0}


@pytest.fixture(scope='module')
def standard(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('standard') / 'node.log'
    with node_and_client(NODE_PARAMETERS, DOMAIN, log,
                         client_name='standard_client') as (_, client):
        yield Standard(client)


def test_the_features_are_exactly_those_implemented(standard):
    features = standard.call(standard.features).features
    assert set(features.features) == IMPLEMENTED and len(features.features) == len(IMPLEMENTED)
    assert list(features.spawn_formats) == ['yaml']


def test_pause_step_n_reset_stop_and_play(standard):
    assert standard.state() == SimulationState.STATE_PLAYING
    response = standard.call(standard.step, steps=5)
    assert response.result.result == Result.RESULT_INCORRECT_STATE   # playing: no step

    assert standard.go(SimulationState.STATE_PAUSED).result == Result.RESULT_OK
    assert standard.state() == SimulationState.STATE_PAUSED
    again = standard.go(SimulationState.STATE_PAUSED)
    assert again.result == SetSimulationState.Response.ALREADY_IN_TARGET_STATE

    assert standard.call(standard.reset).result.result == Result.RESULT_OK
    standard.wait_clock(0)
    assert standard.call(standard.step, steps=25).result.result == Result.RESULT_OK
    standard.wait_clock(25 * DT_NS)
    assert standard.call(standard.step, steps=1).result.result == Result.RESULT_OK
    standard.wait_clock(26 * DT_NS)
    assert standard.state() == SimulationState.STATE_PAUSED
    assert standard.clock_ns() == 26 * DT_NS   # paused: nothing beyond the steps asked

    only_time = standard.call(standard.reset, scope=ResetSimulation.Request.SCOPE_TIME)
    assert only_time.result.result == Result.RESULT_FEATURE_UNSUPPORTED
    assert 'scope' in only_time.result.error_message
    zero = standard.call(standard.step, steps=0)
    assert zero.result.result == Result.RESULT_OPERATION_FAILED
    assert 'steps must be in' in zero.result.error_message

    assert standard.go(SimulationState.STATE_STOPPED).result == Result.RESULT_OK
    standard.wait_clock(0)
    assert standard.state() == SimulationState.STATE_STOPPED
    quitting = standard.go(SimulationState.STATE_QUITTING)
    assert quitting.result == SetSimulationState.Response.INCORRECT_TRANSITION

    assert standard.go(SimulationState.STATE_PLAYING).result == Result.RESULT_OK
    assert standard.state() == SimulationState.STATE_PLAYING
    standard.client.spin_until(lambda: standard.clock_ns() > 50 * DT_NS, 60, 'time to run')


def test_simulate_steps_reports_progress_and_stops_when_canceled(standard):
    client = standard.client
    assert standard.go(SimulationState.STATE_PAUSED).result in (
        Result.RESULT_OK, SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
    assert standard.call(standard.reset).result.result == Result.RESULT_OK
    standard.wait_clock(0)

    feedback = []
    handle = client.send_goal(standard.simulate, SimulateSteps.Goal(steps=40), feedback)
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.result.result == Result.RESULT_OK
    standard.wait_clock(40 * DT_NS)
    client.spin_until(lambda: feedback and feedback[-1].completed_steps == 40, 30,
                      'the last feedback')
    assert feedback[-1].remaining_steps == 0

    feedback = []   # the first goal's feedback, also any still on its way, stays in its list
    long = client.send_goal(standard.simulate, SimulateSteps.Goal(steps=1_000_000), feedback)
    client.spin_until(lambda: feedback and feedback[-1].completed_steps > 0, 60, 'progress')
    assert all(f.completed_steps + f.remaining_steps == 1_000_000 for f in feedback)
    client.cancel(long)
    status, result = client.result(long)
    assert status == GoalStatus.STATUS_CANCELED
    assert result.result.result == Result.RESULT_OPERATION_FAILED
    assert 'canceled by the client' in result.result.error_message
    stopped_at = standard.clock_ns()
    assert standard.state() == SimulationState.STATE_PAUSED
    assert 40 * DT_NS < stopped_at < 1_000_040 * DT_NS

    assert standard.go(SimulationState.STATE_PLAYING).result == Result.RESULT_OK
    refused = client.send_goal(standard.simulate, SimulateSteps.Goal(steps=5))
    status, result = client.result(refused)
    assert status == GoalStatus.STATUS_ABORTED
    assert result.result.result == Result.RESULT_INCORRECT_STATE


def test_entities_their_states_and_replacing_the_fruit(standard, tmp_path):
    call = standard.call
    assert standard.go(SimulationState.STATE_PAUSED).result in (
        Result.RESULT_OK, SetSimulationState.Response.ALREADY_IN_TARGET_STATE)
    assert call(standard.reset).result.result == Result.RESULT_OK
    standard.wait_clock(0)

    listed = call(standard.entities)
    assert listed.result.result == Result.RESULT_OK
    assert list(listed.entities) == ['fruit', 'left_jaw', 'right_jaw', 'table']
    jaws = call(standard.entities, filters=EntityFilters(filter='jaw$'))
    assert list(jaws.entities) == ['left_jaw', 'right_jaw']
    robot = call(standard.entities, filters=EntityFilters(
        categories=[EntityCategory(category=EntityCategory.CATEGORY_ROBOT)]))
    assert list(robot.entities) == ['left_jaw', 'right_jaw']
    bad_regex = call(standard.entities, filters=EntityFilters(filter='(jaw'))
    assert bad_regex.result.result == Result.RESULT_OPERATION_FAILED
    assert 'invalid filter regex' in bad_regex.result.error_message

    table, fruit = standard.entity('table'), standard.entity('fruit')
    left, right = standard.entity('left_jaw'), standard.entity('right_jaw')
    assert fruit.header.frame_id == 'world' and table.header.frame_id == 'world'
    assert (fruit.header.stamp.sec, fruit.header.stamp.nanosec) == (0, 0)
    # at rest on the table, as a reset leaves it
    rest_height = fruit.pose.position.z - table.pose.position.z
    assert rest_height == pytest.approx(APPLE_RADIUS, rel=0.1)
    assert abs(fruit.twist.linear.z) < 1e-6 and abs(fruit.twist.linear.x) < 1e-6
    assert left.pose.position.z == pytest.approx(right.pose.position.z)
    assert abs(left.pose.position.x - right.pose.position.x) > 2 * APPLE_RADIUS   # open
    missing = call(standard.entity_state, entity='pear')
    assert missing.result.result == Result.RESULT_NOT_FOUND
    assert "no entity 'pear'" in missing.result.error_message

    spawnables = call(standard.spawnables)
    assert spawnables.result.result == Result.RESULT_OK
    by_uri = {s.uri: s.description for s in spawnables.spawnables}
    assert {'apple', 'plum'} <= set(by_uri) and '45.0 mm' in by_uri['plum']

    plum = call(standard.spawn, uri='plum')   # named by the preset
    assert plum.result.result == Result.RESULT_OK, plum.result.error_message
    assert plum.entity_name == 'plum'
    standard.wait_clock(0)
    replaced = standard.entity('plum')
    assert (replaced.header.stamp.sec, replaced.header.stamp.nanosec) == (0, 0)
    plum_height = replaced.pose.position.z - standard.entity('table').pose.position.z
    assert plum_height == pytest.approx(PLUM_RADIUS, rel=0.1)
    assert call(standard.step, steps=3).result.result == Result.RESULT_OK
    standard.wait_clock(3 * DT_NS)   # the plum runs

    refusals = {
        'taken': (dict(name='plum', uri='plum'), SpawnEntity.Response.NAME_NOT_UNIQUE,
                  "the name 'plum' is taken"),
        'unknown': (dict(uri='banana'), Result.RESULT_NOT_FOUND, "unknown fruit 'banana'"),
        'no uri': (dict(), SpawnEntity.Response.NO_RESOURCE, 'no uri'),
        'missing file': (dict(uri=str(tmp_path / 'none.yaml')), Result.RESULT_NOT_FOUND,
                         'not found')}
    broken = tmp_path / 'broken.yaml'
    broken.write_text('fruit:\n  density: -5.0\n')
    refusals['bad file'] = (dict(name='broken', uri=str(broken)),
                            SpawnEntity.Response.RESOURCE_PARSE_ERROR, 'density')
    for label, (fields, code, text) in refusals.items():
        refused = call(standard.spawn, **fields)
        assert refused.result.result == code, label
        assert text in refused.result.error_message, (label, refused.result.error_message)
    assert standard.clock_ns() == 3 * DT_NS   # a refused spawn leaves the plum running

    for name in ('plum', 'left_jaw', 'table'):
        refused = call(standard.delete, entity=name)
        assert refused.result.result == Result.RESULT_OPERATION_FAILED
        assert 'cannot be deleted' in refused.result.error_message or 'world' in \
            refused.result.error_message
    assert call(standard.delete, entity='pear').result.result == Result.RESULT_NOT_FOUND

    back = call(standard.spawn, name='fruit', uri='apple')   # 'fruit' is free again
    assert (back.result.result, back.entity_name) == (Result.RESULT_OK, 'fruit')
    standard.wait_clock(0)
    apple_height = standard.entity('fruit').pose.position.z - table.pose.position.z
    assert apple_height == pytest.approx(APPLE_RADIUS, rel=0.1)
