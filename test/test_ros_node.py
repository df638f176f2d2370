"""The gripper_sim node in a subprocess, driven through real rclpy clients.

Topics and types, jaw commands by topic, pause/step/reset, parameters, and every kind
of bad input rejected with a logged reason while the node keeps running.
"""
import math
import subprocess
import sys
import time

import numpy as np
import pytest

from gripper_sim.convert import messages
from gripper_sim_interfaces.srv import Step
from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment
from ros_client import SimClient

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(0)
EXPECTED_TYPES = {
    '/gripper_sim/fruit/nodes': 'sensor_msgs/msg/PointCloud2',
    '/gripper_sim/fruit/state': 'gripper_sim_interfaces/msg/FruitState',
    '/gripper_sim/left_jaw/wrench': 'geometry_msgs/msg/WrenchStamped',
    '/gripper_sim/right_jaw/wrench': 'geometry_msgs/msg/WrenchStamped',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/gripper_sim/markers': 'visualization_msgs/msg/MarkerArray',
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/tf': 'tf2_msgs/msg/TFMessage',
    '/tf_static': 'tf2_msgs/msg/TFMessage',
    '/robot_description': 'std_msgs/msg/String',
    '/gripper_sim/jaw/gap_command': 'std_msgs/msg/Float64',
    '/gripper_sim/jaw/force_command': 'std_msgs/msg/Float64',
    '/gripper_sim/lift/command': 'std_msgs/msg/Float64',
}


@pytest.fixture(scope='module')
def running(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('node') / 'node.log'
    with node_and_client({'real_time_factor': 0.0}, DOMAIN, log) as process_and_client:
        yield process_and_client


@pytest.fixture
def client(running, restarted):
    return restarted(running)


def gap_of(client):
    return client.latest['fruit/state'].gap


def test_every_topic_is_published_with_its_type_and_sane_values(client):
    client.wait_sim_time(0.05)
    client.spin_until(lambda: all(s in client.latest for s in messages.TOPICS), 60,
                      'a message on every topic')
    types = dict(client.node.get_topic_names_and_types())
    for topic, kind in EXPECTED_TYPES.items():
        assert kind in types.get(topic, []), (topic, types.get(topic))

    state = client.latest['fruit/state']
    assert state.header.frame_id == 'world' and state.node_count == 64
    assert state.gap == pytest.approx(0.0635 + 0.010, abs=1e-6)   # initial gap
    assert 0.0 <= state.kinetic_energy < 1e-3 and math.isfinite(state.elastic_energy)
    assert state.centroid.z == pytest.approx(0.0635 / 2, abs=2e-3)  # resting on the table

    cloud = client.latest['fruit/nodes']
    points = messages.read_point_cloud(cloud)
    assert cloud.header.frame_id == 'world' and points.shape == (64, 6)
    assert np.all(np.isfinite(points)) and np.all(points[:, 1] == 0.0)
    radii = np.hypot(points[:, 0], points[:, 2] - state.centroid.z)
    assert np.all(np.abs(radii - 0.0635 / 2) < 2e-3)

    joints = client.latest['joint_states']
    assert list(joints.name) == ['left_jaw_joint', 'right_jaw_joint', 'lift_joint',
                                 'transport_joint']
    assert joints.position[0] + joints.position[1] == pytest.approx(state.gap, abs=1e-9)
    assert client.latest['left_jaw/wrench'].header.frame_id == 'left_jaw'
    assert client.latest['right_jaw/wrench'].header.frame_id == 'right_jaw'
    namespaces = {m.ns for m in client.latest['markers'].markers}
    assert {'fruit_outline', 'jaws', 'table', 'jaw_forces'} <= namespaces

    # sim time stamps: /clock and the headers advance together
    first = client.latest['clock'].clock
    client.wait_sim_time(0.1)
    later = client.latest['clock'].clock
    assert (later.sec, later.nanosec) > (first.sec, first.nanosec)


def test_closing_by_topic_raises_the_wrench_and_the_joint_effort(client):
    assert abs(client.latest['left_jaw/wrench'].wrench.force.x) < 1e-6
    client.publish('gap', 0.058)
    client.spin_until(lambda: abs(client.latest['left_jaw/wrench'].wrench.force.x) > 1.0
                      and abs(client.latest['right_jaw/wrench'].wrench.force.x) > 1.0,
                      60, 'the jaw wrenches to rise')
    left, right = client.latest['left_jaw/wrench'], client.latest['right_jaw/wrench']
    assert left.wrench.force.x < 0 < right.wrench.force.x   # the fruit pushes the jaws out
    client.spin_until(lambda: gap_of(client) < 0.0581, 60, 'the gap to close')
    client.catch_up(['joint_states'])   # the joint states of that step, or a later one
    joints = client.latest['joint_states']
    assert joints.effort[0] > 1.0 and joints.effort[1] > 1.0
    assert client.latest['fruit/state'].left_jaw_contact


def test_force_command_settles_at_the_force_and_lift_moves_the_gripper(client):
    client.publish('force', 5.0)
    client.spin_until(lambda: abs(client.latest['fruit/state'].grip_force - 5.0) < 0.1,
                      60, 'a 5 N grip')
    lift0 = client.latest['joint_states'].position[2]
    client.publish('lift', lift0 + 0.01)
    client.spin_until(lambda: client.latest['joint_states'].position[2] > lift0 + 0.009,
                      60, 'the lift to rise')
    client.catch_up(['fruit/state'], since='joint_states')
    assert client.latest['fruit/state'].centroid.z > 0.0635 / 2 + 0.005   # fruit came along


def test_pause_step_and_reset(client):
    refused = client.step(10)
    assert not refused.success and 'pause' in refused.message
    client.publish('gap', 0.06)
    paused = client.pause(True)
    assert paused.success
    client.wait_sim_time(0.0)
    t0 = client.step(1).sim_time          # a reference point while paused
    response = client.step(25)
    assert response.success
    assert response.sim_time == pytest.approx(t0 + 0.025, abs=1e-9)
    client.spin_until(lambda: client.sim_time() >= response.sim_time - 0.01 - 1e-9, 30,
                      'the stepped state to be published')
    assert not client.step(0).success
    reset = client.reset()
    assert reset.success
    client.spin_until(lambda: client.sim_time() == 0.0, 30, 'the t = 0 state')
    assert gap_of(client) == pytest.approx(0.0735, abs=1e-6)
    # still paused after a reset: time does not move until stepped
    assert client.step(3).sim_time == pytest.approx(0.003, abs=1e-9)
    client.pause(False)
    client.wait_sim_time(0.05)


def test_a_second_step_request_is_refused_at_once_not_queued(client):
    """Through the node's executor: a ~/step meanwhile is answered (refused) while the
    first runs, and none is left to run after the ~/pause that interrupts the first."""
    client.pause(True)
    long_step = client.step_client.call_async(Step.Request(steps=1_000_000))
    start = client.sim_time()
    client.spin_until(lambda: client.sim_time() > start + 0.02, 60, 'the long step to run')
    second = client.step(5)
    assert not long_step.done()
    assert not second.success and 'in progress' in second.message
    paused = client.pause(True)
    client.spin_until(long_step.done, 60, 'the interrupted step to answer')
    assert 'stopped after' in long_step.result().message
    at_pause = float(paused.message.split('t = ')[1].split()[0])
    settle = time.monotonic() + 1.0
    client.spin_until(lambda: time.monotonic() > settle, 5, 'a second')
    # one step on from where the pause left it: nothing ran after the pause's answer
    assert client.step(1).sim_time == pytest.approx(at_pause + 0.001, abs=1e-9)
    client.pause(False)


@pytest.mark.parametrize('what, value', [
    ('gap', float('nan')), ('gap', -0.01), ('gap', float('inf')), ('gap', 5.0),
    ('force', float('nan')), ('force', -3.0), ('force', 1e9), ('lift', float('nan')),
])
def test_bad_commands_are_rejected_with_a_reason_and_the_node_keeps_running(
        client, what, value):
    since = len(client.logs)
    gap_before = gap_of(client)
    client.publish(what, value)
    log = client.wait_log('rejected', since=since)
    assert what in log.msg
    client.wait_sim_time(0.05)                          # still stepping
    assert gap_of(client) == pytest.approx(gap_before, abs=1e-9)   # nothing moved
    state = client.latest['fruit/state']
    assert math.isfinite(state.gap) and math.isfinite(state.grip_force)


def test_parameters_are_validated_with_reasons(client):
    since = len(client.logs)
    ok, = client.set_parameters(physics__contact__jaw__static_friction=0.8)
    assert ok.successful
    too_high, = client.set_parameters(physics__contact__jaw__kinetic_friction=0.9)
    assert not too_high.successful and 'must not exceed' in too_high.reason
    for name, value in (('publish_rate', -5.0), ('publish_rate', 0.0),
                        ('real_time_factor', float('nan')),
                        ('physics__contact__jaw__static_friction', 7.0)):
        result, = client.set_parameters(**{name: value})
        assert not result.successful and result.reason, (name, value)
    read_only, = client.set_parameters(physics__fruit__nodes=32)
    assert not read_only.successful and 'read-only' in read_only.reason
    wrong_type, = client.set_parameters(publish_rate='fast')
    assert not wrong_type.successful
    client.wait_log('rejected', since=since)
    client.wait_sim_time(0.05)
    restore, = client.set_parameters(physics__contact__jaw__static_friction=0.5)
    assert restore.successful


def test_publish_rate_is_a_live_parameter(client):
    # At real time, as a user's client sees it: as fast as possible the node can publish
    # faster than this client reads, and the depth-10 history here drops the surplus.
    ok, = client.set_parameters(publish_rate=50.0)
    assert ok.successful
    assert client.set_parameters(real_time_factor=1.0)[0].successful
    try:
        client.wait_sim_time(0.05)
        start_count = client.counts['fruit/state']
        client.wait_sim_time(1.0)
        received = client.counts['fruit/state'] - start_count
        states = list(client.states)[-received:]
    finally:
        client.set_parameters(publish_rate=100.0)
        client.set_parameters(real_time_factor=0.0)
    # 50 per s of sim time: every state on the 50 Hz grid, 20 ms apart (a multiple of
    # that only where this client missed one, under load) as a rule
    stamps = [s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec for s in states]
    gaps = [b - a for a, b in zip(stamps, stamps[1:])]
    assert len(gaps) >= 20, stamps
    assert all(gap > 0 and gap % 20_000_000 == 0 for gap in gaps), gaps
    assert sorted(gaps)[len(gaps) // 2] == 20_000_000, gaps


# publish_rate 1e-307 is inside (0, 1000] but has no whole number of steps: it was a
# traceback (OverflowError) at start-up; the range is now [0.001, 1000]
@pytest.mark.parametrize('name, value', [('physics.sim.dt', 5.0), ('publish_rate', 1e-307)])
def test_a_bad_start_up_parameter_fails_cleanly(tmp_path, name, value):
    process = node_process({name: value}, env=ros_environment(DOMAIN + 1),
                           log_path=tmp_path / 'bad.log').start()
    process.process.wait(120)
    text = process.log()
    assert process.process.returncode == 2, text
    assert f"cannot start: parameter '{name}'" in text and 'Traceback' not in text


def test_malformed_ros_arguments_fail_cleanly():
    run = subprocess.run([sys.executable, '-m', 'gripper_sim.ros.node', '--ros-args', '-p'],
                         env=ros_environment(DOMAIN + 1), capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith('error: Failed to parse ROS arguments')
    assert 'Traceback' not in run.stderr


def test_an_unknown_fruit_fails_cleanly(tmp_path):
    process = node_process(fruit='durian', env=ros_environment(DOMAIN + 1),
                           log_path=tmp_path / 'fruit.log').start()
    process.process.wait(120)
    text = process.log()
    assert process.process.returncode == 2 and "unknown fruit 'durian'" in text, text
    assert 'Traceback' not in text


def test_params_file_sets_structural_parameters(tmp_path):
    params = tmp_path / 'params.yaml'
    params.write_text('gripper_sim:\n  ros__parameters:\n    publish_rate: 50.0\n'
                      '    physics:\n      fruit:\n        nodes: 32\n')
    domain = pick_domain_id(2)
    process = node_process(env=ros_environment(domain), log_path=tmp_path / 'p.log',
                           extra=['--params-file', str(params),
                                  '-p', 'real_time_factor:=0.0']).start()
    client = SimClient(domain, name='params_file_client')
    try:
        client.spin_until(lambda: 'fruit/nodes' in client.latest
                          and 'fruit/state' in client.latest, 120, 'the node cloud and state')
        assert client.latest['fruit/nodes'].width == 32
        assert client.latest['fruit/state'].node_count == 32
    finally:
        client.close()
        assert process.stop() == 0, process.log()
