"""Fixes from the recording audit: one recording at a time (record_path too), the latched
``/tf_static`` and ``robot_description`` in recordings, replays and the Foxglove view,
``recover`` into an unwritable folder, ``analyze`` of a run without a lift, and
``analyze`` refusing an existing output."""
from __future__ import annotations

import socket
from pathlib import Path

import pytest

import rclpy
import rclpy.executors
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from std_msgs.msg import String
from std_srvs.srv import SetBool
from tf2_msgs.msg import TFMessage

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config
from gripper_sim.convert.frames import GripperFrames
from gripper_sim.recording import qos
from gripper_sim.recording.analysis import analyze
from gripper_sim.recording.latched import LATCHED_TOPICS, latched_topic
from gripper_sim.recording.offline import SimRecorder
from gripper_sim.recording.reader import BagReader
from gripper_sim.view.foxglove import (FoxgloveView, latch_node_description,
                                       node_latched_topics, recording_view)
from gripper_sim.workflows.factory import make_simulation
from view_client import capture

pytestmark = [pytest.mark.ros]

LATCHED = {'/tf_static', '/robot_description'}
SMALL = ['--set', 'fruit.nodes=16', '--quiet']


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def check_latched_topics(bag_path: Path) -> None:
    """The bag holds ``/tf_static`` (with the table frame) and ``/robot_description``:
    one message each, logged with the first sample, offered transient local; readable
    by ``rosbags`` and listed by ``gripper-sim info``."""
    with BagReader(bag_path) as bag:
        assert LATCHED <= set(bag.topics)
        first = bag.start_time
        for name in LATCHED:
            info = bag.topics[name]
            assert info.message_count == 1, name
            assert [p['durability'] for p in info.offered_qos_profiles] == \
                ['transient_local'], name
            assert qos.adapt_for_replay(info.offered_qos_profiles)['durability'] == \
                'transient_local'
            [message] = list(bag.messages([name]))
            assert message.log_time == first
        tf = deserialize_message(next(iter(bag.messages(['/tf_static']))).data, TFMessage)
        urdf = deserialize_message(next(iter(bag.messages(['/robot_description']))).data,
                                   String)
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == \
        [('world', 'table')]
    assert '<robot name="gripper_sim">' in urdf.data
    store = get_typestore(Stores.ROS2_JAZZY)
    reader_path = bag_path if bag_path.is_dir() else None
    if reader_path is not None:
        with RosbagsReader(reader_path) as reader:
            counts = {c.topic: c.msgcount for c in reader.connections}
            assert counts['/tf_static'] == counts['/robot_description'] == 1
            for connection, _, raw in reader.messages(
                    [c for c in reader.connections if c.topic in LATCHED]):
                store.deserialize_cdr(raw, connection.msgtype)


# ------------------------------------------------------------------ offline recordings
@pytest.fixture(scope='module')
def pick_bag(tmp_path_factory):
    """A short pick with the table, recorded offline as a bag folder."""
    path = tmp_path_factory.mktemp('pick') / 'pick'
    assert main(['pick', '--force', '2', '--lift', '0.01', '--hold', '0.05', '--out',
                 str(path), *SMALL]) == 0
    return path


def test_an_offline_recording_holds_the_latched_topics(pick_bag, capsys):
    check_latched_topics(pick_bag)
    capsys.readouterr()
    assert main(['info', str(pick_bag)]) == 0
    text = capsys.readouterr().out
    assert 'Topic: /tf_static ' in text and 'Topic: /robot_description ' in text


def test_latched_topics_go_with_tf_only_and_follow_the_namespace(tmp_path):
    config = load_config(overrides=['fruit.nodes=16'])
    sim = make_simulation(config)
    without_tf = tmp_path / 'clock.mcap'
    with SimRecorder(without_tf, config, initial=sim.last, topics=['clock']):
        pass
    with BagReader(without_tf) as bag:
        assert set(bag.topics) == {'/clock'}
    spaced = tmp_path / 'spaced.mcap'
    with SimRecorder(spaced, config, initial=sim.last, namespace='/g1'):
        pass
    with BagReader(spaced) as bag:
        assert {'/tf_static', '/g1/robot_description'} <= set(bag.topics)
    assert latched_topic('robot_description') == '/robot_description'
    assert set(LATCHED_TOPICS) == {'tf_static', 'robot_description'}


# ------------------------------------------------------------------ replay: latched again
@pytest.fixture
def ros_context():
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        yield context
    finally:
        rclpy.shutdown(context=context)


def test_replay_publishes_tf_static_latched(pick_bag, ros_context):
    """A subscriber that joins after the replay published ``/tf_static`` still gets it."""
    from gripper_sim.ros.replay import Player
    node = rclpy.create_node('audit_replay', context=ros_context)
    try:
        with BagReader(pick_bag) as bag:
            player = Player(node, bag, topics=['/tf_static'], rate=1000.0)
            player.play_once()
            assert player.stats.messages == 1
            got = []
            latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
            node.create_subscription(TFMessage, '/tf_static', got.append, latched)
            executor = rclpy.executors.SingleThreadedExecutor(context=ros_context)
            executor.add_node(node)
            for _ in range(600):   # up to 60 s: it arrives when discovery is done
                executor.spin_once(timeout_sec=0.1)
                if got:
                    break
            executor.remove_node(node)
    finally:
        node.destroy_node()
    assert got and got[0].transforms[0].child_frame_id == 'table'


# ------------------------------------------------------------------ Foxglove
def test_the_view_serves_latched_topics_to_every_client_that_subscribes():
    latched = node_latched_topics('/')
    assert set(latched) == LATCHED
    view = FoxgloveView({**latched, '/clock': 'rosgraph_msgs/msg/Clock'}, port=0,
                        latched=latched)
    try:
        latch_node_description(view, GripperFrames(), '/')   # before any client
        for _ in range(2):                                     # each client gets them
            seen = capture(view.url, LATCHED, per_topic=1, timeout=60)
            tf = deserialize_message(seen.messages['/tf_static'][0][1], TFMessage)
            assert tf.transforms[0].child_frame_id == 'table'
            urdf = deserialize_message(seen.messages['/robot_description'][0][1], String)
            assert '<robot' in urdf.data
    finally:
        view.close()


def test_a_replay_view_serves_the_recorded_latched_topics_latched(pick_bag):
    with BagReader(pick_bag) as bag:
        view = recording_view(bag, port=0)
        try:
            for message in bag.messages(['/tf_static', '/clock']):
                view.log_cdr(message.topic, message.data, message.log_time)
            seen = capture(view.url, {'/tf_static'}, per_topic=1, timeout=60)
        finally:
            view.close()
    assert deserialize_message(seen.messages['/tf_static'][0][1],
                               TFMessage).transforms[0].child_frame_id == 'table'


# ------------------------------------------------------------------ the node
@pytest.fixture(scope='module')
def running(tmp_path_factory, node_and_client, new_domain_id):
    port = free_port()
    folder = tmp_path_factory.mktemp('audit_node')
    with node_and_client({'real_time_factor': 0.0, 'foxglove_port': port},
                         new_domain_id(), folder / 'node.log', cwd=folder,
                         client_name='recording_audit_client') as (process, client):
        record = client.node.create_client(SetBool, '/gripper_sim/record')
        yield process, client, record, port


@pytest.mark.slow
def test_record_path_is_refused_while_a_recording_runs(running, tmp_path):
    process, client, record, _ = running
    first = tmp_path / 'first'
    assert client.set_parameters(record_path=str(first))[0].successful  # by the parameter
    started = client.call(record, SetBool.Request(data=True))
    assert not started.success and 'already recording' in started.message
    client.set_parameters(record_path='')
    started = client.call(record, SetBool.Request(data=True))          # by ~/record
    assert started.success, started.message   # a new folder in the node's directory
    running_path = started.message.split(' to ', 1)[1]
    since = len(client.logs)
    other = tmp_path / 'other'
    result, = client.set_parameters(record_path=str(other))
    assert not result.successful
    assert running_path in result.reason and "record_path to ''" in result.reason
    assert 'record-node stop' in result.reason
    client.wait_log('already recording', since=since)
    assert not other.exists()
    assert client.set_parameters(record_path=running_path)[0].successful   # no change
    client.wait_sim_time(0.05)
    stopped = client.call(record, SetBool.Request(data=False))
    assert stopped.success and running_path in stopped.message
    check_latched_topics(Path(running_path))
    assert (first / 'metadata.yaml').is_file()
    assert process.running


@pytest.mark.slow
def test_the_live_view_serves_tf_static_and_robot_description(running):
    _, _, _, port = running
    seen = capture(f'ws://127.0.0.1:{port}', LATCHED, per_topic=1)
    tf = deserialize_message(seen.messages['/tf_static'][0][1], TFMessage)
    assert [(t.header.frame_id, t.child_frame_id) for t in tf.transforms] == \
        [('world', 'table')]
    urdf = deserialize_message(seen.messages['/robot_description'][0][1], String)
    assert '<robot name="gripper_sim">' in urdf.data


# ------------------------------------------------------------------ recover
def test_recover_into_a_folder_it_cannot_write_is_an_error(pick_bag, tmp_path, capsys):
    """The audit's case: /sys refuses every user, root too."""
    source = tmp_path / 'cut.mcap'
    data = (pick_bag / 'pick_0.mcap').read_bytes()
    source.write_bytes(data[:len(data) // 2])
    capsys.readouterr()
    assert main(['recover', str(source), '/sys/f.mcap']) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: cannot create /sys/f.mcap: ') and 'Traceback' not in err


# ------------------------------------------------------------------ analyze
@pytest.fixture(scope='module')
def squeeze_recording(tmp_path_factory):
    path = tmp_path_factory.mktemp('squeeze') / 's1.mcap'
    assert main(['squeeze', '--to-force', '1', '--out', str(path), *SMALL]) == 0
    return path


def test_a_run_without_a_lift_is_neither_held_nor_slipped(squeeze_recording, tmp_path,
                                                          capsys):
    result = analyze(squeeze_recording, tmp_path / 'a', figures=False)
    s = result.summary
    assert s['gripped'] is True
    assert s['held'] is None and s['slipped'] is None and s['held_slip_distance_m'] is None
    capsys.readouterr()
    assert main(['analyze', str(squeeze_recording), '-o', str(tmp_path / 'b'),
                 '--no-html', '--quiet']) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith('held:'))
    assert line.startswith('held: n/a   slipped: n/a (not lifted'), line
    assert 'end of the hold' not in line


def test_a_lifted_run_is_still_judged(pick_bag, tmp_path):
    s = analyze(pick_bag, tmp_path / 'a', figures=False).summary
    assert s['held'] is True and s['slipped'] is False
    assert s['held_slip_distance_m'] is not None


def test_analyze_refuses_an_existing_output_and_a_missing_parent(squeeze_recording,
                                                                 tmp_path, capsys):
    existing = tmp_path / 'existing'
    existing.mkdir()
    (existing / 'mine.txt').write_text('keep me')
    missing = tmp_path / 'no' / 'such'
    for argv, why in ((['-o', str(existing)], f'{existing} already exists'),
                      (['-o', str(missing)], f'directory {missing.parent} does not exist')):
        capsys.readouterr()
        assert main(['analyze', str(squeeze_recording), *argv, '--no-figures',
                     '--quiet']) == 2
        err = capsys.readouterr().err
        assert err.startswith('error: ') and why in err and 'Traceback' not in err, err
    assert not missing.parent.exists()
    assert sorted(p.name for p in existing.iterdir()) == ['mine.txt']
    # the default folder too, the second time
    default = squeeze_recording.with_name('s1_analysis')
    assert main(['analyze', str(squeeze_recording), '--no-figures', '--quiet']) == 0
    assert main(['analyze', str(squeeze_recording), '--no-figures', '--quiet']) == 2
    assert f'{default} already exists' in capsys.readouterr().err
    # --force writes into it
    assert main(['analyze', str(squeeze_recording), '-o', str(existing), '--no-figures',
                 '--quiet', '--force']) == 0
    assert (existing / 'summary.json').is_file()
    assert (existing / 'mine.txt').read_text() == 'keep me'
