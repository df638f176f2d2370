"""In-node recording (``NodeRecording``) on the real SimNode, stepped by hand."""
from __future__ import annotations

import os
import re

import pytest
import yaml

import rclpy
import gripper_sim_interfaces.msg  # noqa: F401
from rclpy.parameter import Parameter
from rosbags.rosbag2 import Reader as RosbagsReader
from std_srvs.srv import SetBool

from gripper_sim.configuration import to_yaml  # noqa: E402
from gripper_sim.convert import messages  # noqa: E402
from gripper_sim.recording.node_recording import NodeRecording  # noqa: E402
from gripper_sim.recording.offline import CONFIG_METADATA  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.ros.process import free_domain_id, ros_environment  # noqa: E402

pytestmark = pytest.mark.ros

#: the latched topics a recording holds once (``recording.latched``)
LATCHED = {'/tf_static', '/robot_description'}

_ENV_KEYS = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID', 'RMW_IMPLEMENTATION',
             'FASTRTPS_DEFAULT_PROFILES_FILE')


@pytest.fixture
def sim_node():
    from gripper_sim.ros.node import SimNode
    domain = free_domain_id(os.getpid())
    env = ros_environment(domain)
    saved = {k: os.environ.get(k) for k in _ENV_KEYS}
    for key in _ENV_KEYS:
        os.environ[key] = env[key]
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = SimNode(start=False, context=context,
                   parameter_overrides=[rclpy.parameter.Parameter('real_time_factor',
                                                                  value=0.0),
                                        rclpy.parameter.Parameter('foxglove_port', value=0)])
    try:
        yield node
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


def test_every_physics_step_is_recorded_and_recording_restarts(sim_node, tmp_path):
    recording = NodeRecording(sim_node)
    ok, message = recording.start(tmp_path / 'first.mcap')
    assert ok, message
    assert not recording.start(tmp_path / 'other.mcap')[0]  # one at a time
    with sim_node.lock:
        sim_node.sim.command_force(3.0)
    results = [sim_node.advance() for _ in range(40)]
    assert all(r is not None for r in results)
    ok, message = recording.stop()
    assert ok and 'first.mcap' in message
    assert recording.stop() == (False, 'not recording')
    for _ in range(5):
        sim_node.advance()            # not recorded
    ok, _ = recording.start(tmp_path / 'second.mcap')
    assert ok
    more = [sim_node.advance() for _ in range(10)]
    recording.stop()

    state_topic = messages.resolved_topic('fruit/state', sim_node.get_name(),
                                          sim_node.get_namespace())
    with BagReader(tmp_path / 'first.mcap') as bag:
        assert set(bag.topics) == {messages.resolved_topic(s, sim_node.get_name(),
                                                           sim_node.get_namespace())
                                   for s in messages.TOPICS} | LATCHED
        states = [m for _, m in bag.decoded_messages([state_topic])]
        config = yaml.safe_load(bag.metadata_named(CONFIG_METADATA)['yaml'])
        assert bag.metadata_named(CONFIG_METADATA)['source'] == 'node'
    # the initial state, then every physics step, whatever the publish rate
    assert len(states) == len(results) + 1
    assert [s.grip_force for s in states[1:]] == [r.grip_force for r in results]
    assert config == yaml.safe_load(to_yaml(sim_node.params.config))
    with BagReader(tmp_path / 'second.mcap') as bag:
        states = [m for _, m in bag.decoded_messages([state_topic])]
    assert [s.gap for s in states[1:]] == [r.gap for r in more]


def test_start_reports_bad_paths_and_reset_keeps_log_order(sim_node, tmp_path):
    recording = NodeRecording(sim_node)
    ok, message = recording.start(tmp_path / 'missing_dir' / 'x.mcap')
    assert not ok and 'does not exist' in message
    (tmp_path / 'taken.mcap').write_bytes(b'keep me')
    ok, message = recording.start(tmp_path / 'taken.mcap')
    assert not ok and 'already exists' in message
    assert (tmp_path / 'taken.mcap').read_bytes() == b'keep me'
    ok, _ = recording.start(tmp_path / 'reset.mcap')
    assert ok
    for _ in range(5):
        sim_node.advance()
    sim_node.reset_simulation('test reset')  # the path ~/reset and failure recovery take
    for _ in range(5):
        sim_node.advance()
    recording.stop()
    with BagReader(tmp_path / 'reset.mcap') as bag:
        raw = list(bag.messages(['/clock']))
    log_times = [m.log_time for m in raw]
    # initial, 5 steps, the state after the reset, 5 steps
    assert len(raw) == 12 and log_times == sorted(log_times)
    assert len(set(log_times)) == len(log_times)


def test_record_path_names_the_bag_folder_and_an_existing_directory_is_refused(
        sim_node, tmp_path):
    existing = tmp_path / 'existing'
    existing.mkdir()
    result, = sim_node.set_parameters([Parameter('record_path', value=str(existing))])
    assert not result.successful and 'existing directory' in result.reason, result.reason
    assert sim_node.get_parameter('record_path').value == ''
    assert list(tmp_path.iterdir()) == [existing] and not any(existing.iterdir())

    bag = tmp_path / 'run1'
    result, = sim_node.set_parameters([Parameter('record_path', value=str(bag))])
    assert result.successful, result.reason
    assert sim_node.recording_control.recording.path == bag           # the parameter names what is written
    assert sim_node.get_parameter('record_path').value == str(bag)
    for _ in range(10):
        sim_node.advance()
    result, = sim_node.set_parameters([Parameter('record_path', value='')])
    assert result.successful
    assert sorted(p.name for p in bag.iterdir()) == ['metadata.yaml', 'run1_0.mcap']
    with RosbagsReader(bag) as reader:
        counts = {c.topic: c.msgcount for c in reader.connections}
    assert set(counts) == {messages.resolved_topic(s, sim_node.get_name(),
                                                   sim_node.get_namespace())
                           for s in messages.TOPICS} | LATCHED
    # the start state, then 10 steps; the latched topics once
    assert {n for t, n in counts.items() if t not in LATCHED} == {11}
    assert {counts[t] for t in LATCHED} == {1}


def test_record_service_without_record_path_reports_the_folder_it_writes(
        sim_node, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    started = sim_node.recording_control._on_record(SetBool.Request(data=True), SetBool.Response())
    assert started.success, started.message
    [folder] = list(tmp_path.iterdir())
    assert re.fullmatch(r'gripper_sim_\d{8}_\d{6}(_\d+)?', folder.name), folder.name
    assert str(folder) in started.message
    assert sim_node.get_parameter('record_path').value == str(folder)
    sim_node.advance()
    stopped = sim_node.recording_control._on_record(SetBool.Request(data=False), SetBool.Response())
    assert stopped.success and str(folder) in stopped.message
    with BagReader(folder) as bag:
        assert bag.is_folder and bag.message_count == 2 * len(messages.TOPICS) + len(LATCHED)
