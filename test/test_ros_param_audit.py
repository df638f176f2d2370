"""The node's parameters as a ROS 2 user meets them (an audit with rclpy clients):

- every listed parameter can be read: a nullable physics key left unset is a parameter
  whose value is not set (``PARAMETER_NOT_SET``), not one that empties a whole
  ``GetParameters`` answer;
- a start-up override naming no parameter of the node (a misspelt one) is a warning
  naming the closest parameter, and the node runs on;
- an integer for a floating-point parameter is that number, stored as a double (at
  start-up and later); any other wrong type ends the start-up with a message naming the
  type the parameter must have and how to write it.
"""
import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters
from rclpy.parameter import Parameter, parameter_value_to_python

from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigError
from gripper_sim.ros.node import SimNode
from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment
from ros_client import ros_context

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(81)
IN_PROCESS_DOMAIN = pick_domain_id(83)
# -p name:=value as a user types them: 0 is an integer, 0.08 a double
STARTED_WITH = {'real_time_factor': 0, 'physics.gripper.initial_gap': 0.08,
                'physics.fruit.node': 96, 'publish_rat': 5.0}


@pytest.fixture(scope='module')
def running(tmp_path_factory, node_and_client):
    """The node in a subprocess, started with ``STARTED_WITH``, and its client with the
    parameter services' clients."""
    log = tmp_path_factory.mktemp('param_audit') / 'node.log'
    with node_and_client(STARTED_WITH, DOMAIN, log,
                         client_name='param_audit_client') as (process, client):
        services = {kind: client.node.create_client(kind, f'/gripper_sim/{name}')
                    for kind, name in ((ListParameters, 'list_parameters'),
                                       (GetParameters, 'get_parameters'),
                                       (DescribeParameters, 'describe_parameters'))}
        yield process, client, services


def get_parameters(client, services, names):
    return client.call(services[GetParameters], GetParameters.Request(names=names)).values


def test_every_listed_parameter_can_be_read(running):
    process, client, services = running
    names = list(client.call(services[ListParameters], ListParameters.Request()).result.names)
    values = get_parameters(client, services, names)
    assert len(values) == len(names) > 100
    unset = {name for name, value in zip(names, values)
             if value.type == ParameterType.PARAMETER_NOT_SET}
    assert {'physics.fruit.depth', 'physics.fruit.failure_strain'} <= unset
    assert all(name.startswith('physics.') for name in unset)
    # set at start-up, a nullable key holds its value
    initial_gap, = get_parameters(client, services, ['physics.gripper.initial_gap'])
    assert parameter_value_to_python(initial_gap) == 0.08
    described, = client.call(services[DescribeParameters], DescribeParameters.Request(
        names=['physics.fruit.depth'])).descriptors
    assert 'not set = 2/3 of the diameter' in described.description
    assert process.running, process.log()


def test_a_misspelt_start_up_parameter_is_a_warning_naming_the_closest_one(running):
    process, client, services = running
    for given, meant in (('physics.fruit.node', 'physics.fruit.nodes'),
                         ('publish_rat', 'publish_rate')):
        text = (f"parameter '{given}' given at start-up is ignored: this node has no such "
                f"parameter (did you mean '{meant}'?)")
        assert process.wait_for_log(text, 5), process.log()
        line = next(line for line in process.log().splitlines() if text in line)
        assert '[WARN]' in line
    assert process.running, process.log()


def test_an_integer_for_a_floating_point_parameter_is_stored_as_a_double(running):
    process, client, services = running
    # at start-up: -p real_time_factor:=0
    factor, = get_parameters(client, services, ['real_time_factor'])
    assert (factor.type, factor.double_value) == (ParameterType.PARAMETER_DOUBLE, 0.0)
    # later: ros2 param set /gripper_sim publish_rate 50
    result, = client.set_parameters(publish_rate=50)
    assert result.successful, result.reason
    rate, = get_parameters(client, services, ['publish_rate'])
    assert (rate.type, rate.double_value) == (ParameterType.PARAMETER_DOUBLE, 50.0)
    result, = client.set_parameters(publish_rate=100.0)
    assert result.successful, result.reason


def test_a_wrong_type_at_start_up_names_the_type_it_must_have(tmp_path):
    process = node_process({'physics.fruit.nodes': 'abc'},
                           env=ros_environment(pick_domain_id(82)),
                           log_path=tmp_path / 'node.log').start()
    process.process.wait(120)
    text = process.log()
    assert process.process.returncode == 2, text
    assert ("cannot start: parameter 'physics.fruit.nodes' = 'abc' is invalid: it must be "
            'an integer, e.g. 64') in text, text
    assert 'Traceback' not in text and 'double' not in text


# ------------------------------------------------------------- in this process
@pytest.fixture
def context():
    with ros_context(IN_PROCESS_DOMAIN) as context:
        yield context


def make_node(context, **parameters):
    overrides = [Parameter(name, value=value) for name, value in
                 {'foxglove_port': 0, **parameters}.items()]
    return SimNode(context=context, simulation_factory=Simulation, start=False,
                   parameter_overrides=overrides, watchdog_period=0.0)


@pytest.mark.parametrize('name, value, message', [
    ('real_time_factor', 'abc', "'abc' is invalid: it must be a floating-point number, "
                                'e.g. 1.0'),
    ('physics.fruit.nodes', 96.0, 'is invalid: it must be an integer: write 96, not 96.0'),
    ('physics.fruit.nodes', 'abc', 'it must be an integer, e.g. 64'),
    ('physics.fruit.depth', 'x', 'it must be a floating-point number'),
    ('publish_clock', 1, 'it must be true or false'),
    ('fruit', 123, "it must be a string: quote it ('123')"),
    ('real_time_factor', 5000.0, 'is out of range: it must be in [0.0, 1000.0]'),
])
def test_a_start_up_value_of_the_wrong_type_says_which_type(context, name, value, message):
    with pytest.raises(ConfigError) as caught:
        make_node(context, **{name: value})
    assert str(caught.value).startswith(f"parameter '{name}' = {value!r} ")
    assert message in str(caught.value) and 'Exception' not in str(caught.value)


def test_integers_for_doubles_and_unset_parameters_in_the_node(context):
    node = make_node(context, real_time_factor=1, **{'physics.fruit.depth': 0.05})
    try:
        factor = node.get_parameter('real_time_factor')
        assert (factor.type_, factor.value) == (Parameter.Type.DOUBLE, 1.0)
        assert node.physics.real_time_factor == 1.0
        assert node.params.config['fruit.depth'] == 0.05
        # a dynamic physics key, set with an integer: a double in the parameter and core
        result, = node.set_parameters([Parameter('physics.gripper.close_speed', value=1)])
        assert result.successful, result.reason
        speed = node.get_parameter('physics.gripper.close_speed')
        assert (speed.type_, speed.value) == (Parameter.Type.DOUBLE, 1.0)
        assert node.params.config['gripper.close_speed'] == 1.0
        # not set, and it stays declared: unsetting a parameter is refused
        unset = node.get_parameter('physics.gripper.initial_gap')
        assert (unset.type_, unset.value) == (Parameter.Type.NOT_SET, None)
        result, = node.set_parameters([Parameter('physics.gripper.initial_gap')])
        assert not result.successful
        assert node.has_parameter('physics.gripper.initial_gap')
    finally:
        node.destroy_node()
