"""Bag folders as rosbag2 writes them, read back by us and by the independent ``rosbags``."""
from __future__ import annotations

import json

import pytest
import yaml

from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import Reader as RosbagsReader
from rosbags.typesys import Stores, get_typestore
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray
from sensor_msgs.msg import JointState
from std_msgs.msg import String

from gripper_sim.cli.main import main
from gripper_sim.configuration import load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.recording.analysis import analyze
from gripper_sim.recording.cdr import CdrTrimmer
from gripper_sim.recording.bag_folder import (MIN_SPLIT_SIZE, BagFolderWriter,
                                              open_bag_writer)
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.offline import SimRecorder
from gripper_sim.recording.reader import BagReader, McapFile
from gripper_sim.recording.recorder import TopicSelection

# rosbag2 (jazzy) rosbag2_storage/yaml.hpp, convert<BagMetadata>::encode, in this order.
BAG_KEYS = ['version', 'storage_identifier', 'duration', 'starting_time', 'message_count',
            'topics_with_message_count', 'compression_format', 'compression_mode',
            'relative_file_paths', 'files', 'custom_data', 'ros_distro']
TOPIC_KEYS = ['name', 'type', 'serialization_format', 'offered_qos_profiles',
              'type_description_hash']
FILE_KEYS = ['path', 'starting_time', 'duration', 'message_count']


def _joint_state(i: int) -> JointState:
    msg = JointState()
    msg.header.stamp.sec, msg.header.frame_id = i, 'world'
    msg.name = ['left_jaw_joint', 'right_jaw_joint']
    msg.position = [0.01 * i, -0.01 * i]
    msg.effort = [float(i), float(-i)]
    return msg


def write_bag(folder, n: int = 60, **options):
    """A bag of /chatter (String) and /joint_states (JointState), 10 ms apart."""
    written = []
    exact = CdrTrimmer()
    with BagFolderWriter(folder, **options) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.add_topic('/joint_states', 'sensor_msgs/msg/JointState')
        bag.set_custom_data('run', 'test')
        bag.add_metadata('gripper_sim_config', {'yaml': 'fruit: apple\n'})
        for i in range(n):
            t = 1_700_000_000_000_000_000 + 10_000_000 * i
            for topic, type_name, msg in (
                    ('/chatter', 'std_msgs/msg/String', String(data=f'hello {i} ' + 'x' * 200)),
                    ('/joint_states', 'sensor_msgs/msg/JointState', _joint_state(i))):
                data = exact.trim(type_name, serialize_message(msg))
                bag.write(topic, data, log_time=t)
                written.append((topic, t, data, msg))
    return written


def _metadata(folder) -> dict:
    return yaml.safe_load((folder / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def test_a_bag_folder_has_rosbag2s_layout_and_metadata(tmp_path):
    folder = tmp_path / 'run1'
    written = write_bag(folder)
    assert sorted(p.name for p in folder.iterdir()) == ['metadata.yaml', 'run1_0.mcap']
    meta = _metadata(folder)
    assert list(meta) == BAG_KEYS
    assert meta['version'] == 9 and meta['storage_identifier'] == 'mcap'
    assert meta['ros_distro'] == 'jazzy' and meta['custom_data'] == {'run': 'test'}
    assert meta['compression_format'] == '' and meta['compression_mode'] == ''
    assert meta['relative_file_paths'] == ['run1_0.mcap']
    assert meta['message_count'] == len(written)
    times = [t for _, t, _, _ in written]
    assert meta['starting_time']['nanoseconds_since_epoch'] == min(times)
    assert meta['duration']['nanoseconds'] == max(times) - min(times)
    [file_info] = meta['files']
    assert list(file_info) == FILE_KEYS and file_info['message_count'] == len(written)
    for entry in meta['topics_with_message_count']:
        assert list(entry['topic_metadata']) == TOPIC_KEYS
        assert entry['topic_metadata']['type_description_hash'].startswith('RIHS01_')
        assert entry['topic_metadata']['offered_qos_profiles'][0]['reliability'] == 'reliable'
        assert entry['message_count'] == len(written) // 2
    # the file carries the same document in its rosbag2 record
    with McapFile(folder / 'run1_0.mcap') as part:
        record = yaml.safe_load(dict(part.metadata)['rosbag2']['serialized_metadata'])
    assert record == meta


def test_rosbags_reads_every_message_of_our_bag(tmp_path):
    folder = tmp_path / 'run2'
    written = write_bag(folder, n=40)
    with RosbagsReader(folder) as reader:
        assert reader.message_count == len(written)
        got = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    assert got == [(topic, t, data) for topic, t, data, _ in written]
    with AnyReader([folder]) as reader:
        decoded = [(c.topic, reader.deserialize(raw, c.msgtype))
                   for c, _, raw in reader.messages()]
    assert len(decoded) == len(written)
    for (topic, msg), (w_topic, _, _, original) in zip(decoded, written):
        assert topic == w_topic
        if topic == '/chatter':
            assert msg.data == original.data
        else:
            assert list(msg.name) == original.name
            assert list(msg.position) == list(original.position)
            assert list(msg.effort) == list(original.effort)
            assert msg.header.frame_id == 'world'


@pytest.mark.parametrize('split', [{'max_bag_size': MIN_SPLIT_SIZE},
                                   {'max_bag_duration': 0.25}])
def test_split_bags_round_trip_and_counts_match_the_files(tmp_path, split):
    folder = tmp_path / 'split'
    written = write_bag(folder, n=400, compression='none', chunk_size=16 * 1024, **split)
    meta = _metadata(folder)
    names = meta['relative_file_paths']
    assert len(names) >= 3
    assert names == [f'split_{i}.mcap' for i in range(len(names))]
    assert sorted(p.name for p in folder.iterdir()) == sorted(names + ['metadata.yaml'])
    total = 0
    per_topic: dict[str, int] = {}
    for name, info in zip(names, meta['files']):
        with McapFile(folder / name) as part:
            assert info['path'] == name
            assert info['message_count'] == part.message_count > 0
            assert info['starting_time']['nanoseconds_since_epoch'] == part.start_time
            assert info['duration']['nanoseconds'] == part.end_time - part.start_time
            assert dict(part.metadata)['gripper_sim_config'] == {'yaml': 'fruit: apple\n'}
            if 'max_bag_duration' in split:
                assert part.end_time - part.start_time <= 0.25e9
            for topic, t in part.topics.items():
                per_topic[topic] = per_topic.get(topic, 0) + t.message_count
            total += part.message_count
    assert total == meta['message_count'] == len(written)
    assert {t['topic_metadata']['name']: t['message_count']
            for t in meta['topics_with_message_count']} == per_topic
    with BagReader(folder) as bag:
        assert bag.message_count == len(written)
        got = [(m.topic, m.log_time, m.data) for m in bag.messages()]
    assert got == [(topic, t, data) for topic, t, data, _ in written]
    with RosbagsReader(folder) as reader:
        assert [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()] == got


def test_compression_on_and_off(tmp_path):
    written = {'packed': write_bag(tmp_path / 'packed', compression='zstd'),
               'plain': write_bag(tmp_path / 'plain', compression='none')}
    with BagReader(tmp_path / 'packed') as packed, BagReader(tmp_path / 'plain') as plain:
        assert packed.compression == {'zstd'} and plain.compression == {''}
        for name, bag in (('packed', packed), ('plain', plain)):
            assert [m.data for m in bag.messages()] == [w[2] for w in written[name]]
    size = {name: (tmp_path / name / f'{name}_0.mcap').stat().st_size
            for name in ('packed', 'plain')}
    assert size['packed'] < size['plain']
    with pytest.raises(RecordingError, match='compression must be one of'):
        BagFolderWriter(tmp_path / 'bad', compression='gzip')


def test_writer_refuses_existing_folders_and_impossible_splits(tmp_path):
    (tmp_path / 'taken').mkdir()
    with pytest.raises(RecordingError, match='existing directory'):
        BagFolderWriter(tmp_path / 'taken').open()
    with pytest.raises(RecordingError, match='does not exist'):
        BagFolderWriter(tmp_path / 'missing' / 'bag').open()
    with pytest.raises(RecordingError, match='too small'):
        BagFolderWriter(tmp_path / 'tiny', max_bag_size=100)
    with pytest.raises(RecordingError, match='cannot be split'):
        open_bag_writer(tmp_path / 'one.mcap', max_bag_size=MIN_SPLIT_SIZE)
    assert not (tmp_path / 'tiny').exists()


def test_topic_selection_follows_ros2_bag_record():
    pick = TopicSelection.build(['/a'], regex=r'/sim/.*', exclude=r'.*/nodes')
    assert pick.wants('/a') and pick.wants('/sim/fruit/state')
    assert not pick.wants('/sim/fruit/nodes') and not pick.wants('/b')
    assert not pick.wants('/x/sim/y')   # a pattern matches the whole name
    # hidden topics (an action's internals, a node's _instance) only when named
    assert not pick.wants('/sim/_instance') and not pick.wants('/sim/grasp/_action/feedback')
    assert TopicSelection.build(['/sim/_instance']).wants('/sim/_instance')
    every = TopicSelection.build(all_topics=True, exclude=r'/rosout')
    assert every.wants('/tf') and not every.wants('/rosout') and not every.wants('/_hidden')
    with pytest.raises(RecordingError, match='not a valid regular expression'):
        TopicSelection.build(regex='(')
    with pytest.raises(RecordingError, match='give topics'):
        TopicSelection.build(exclude='/x')


def test_cli_info_and_recover_take_a_bag_folder(tmp_path, capsys):
    folder = tmp_path / 'bag'
    written = write_bag(folder, n=300, max_bag_size=MIN_SPLIT_SIZE, compression='none',
                        chunk_size=8 * 1024)
    assert main(['info', '--json', str(folder)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['bag_folder'] and info['messages'] == len(written)
    assert [p.rsplit('/', 1)[1] for p in info['files']] == _metadata(folder)[
        'relative_file_paths']
    assert main(['info', str(folder)]) == 0
    assert 'bag_1.mcap' in capsys.readouterr().out
    # as a killed recorder leaves it: no metadata.yaml, the last file cut short
    (folder / 'metadata.yaml').unlink()
    last = folder / _metadata_names(info)[-1]
    last.write_bytes(last.read_bytes()[:-2000])
    assert main(['info', str(folder)]) == 2
    assert 'recover' in capsys.readouterr().err
    fixed = tmp_path / 'fixed'
    assert main(['recover', str(folder), str(fixed)]) == 0
    out = capsys.readouterr().out
    assert 'cut short' in out and str(fixed / 'metadata.yaml') in out
    report_meta = _metadata(fixed)
    with RosbagsReader(fixed) as reader:
        got = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
        assert reader.message_count == report_meta['message_count'] == len(got)
    assert got == [(topic, t, data) for topic, t, data, _ in written][:len(got)]
    assert len(got) > len(written) // 2


def _metadata_names(info: dict) -> list[str]:
    return [p.rsplit('/', 1)[1] for p in info['files']]


def test_a_simulation_recorded_to_a_folder_analyses_like_a_file(tmp_path):
    config = load_config(overrides={'fruit.bruise_pressure': 2.0e5})
    sim = Simulation(config)
    folder, single = tmp_path / 'sim_bag', tmp_path / 'sim.mcap'
    with SimRecorder(folder, sim.config, initial=sim.last) as a, \
            SimRecorder(single, sim.config, initial=sim.last) as b:
        sim.add_observer(a.on_step)
        sim.add_observer(b.on_step)
        sim.command_force(3.0)
        while sim.time < 0.1:
            sim.step()
    assert (folder / 'metadata.yaml').is_file() and (folder / 'sim_bag_0.mcap').is_file()
    with RosbagsReader(folder) as reader:
        assert reader.message_count == a.writer.message_count
    from_folder = analyze(folder, tmp_path / 'a', figures=False).summary
    from_file = analyze(single, tmp_path / 'b', figures=False).summary
    assert from_folder.pop('file') == str(folder) and from_file.pop('file') == str(single)
    assert from_folder == from_file
    assert main(['analyze', '--no-figures', str(folder)]) == 0
    assert (tmp_path / 'sim_bag_analysis').is_dir()


def test_rosbags_decodes_every_topic_of_a_simulation_bag(tmp_path):
    config = load_config()
    sim = Simulation(config)
    folder = tmp_path / 'every_topic'
    with SimRecorder(folder, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        sim.command_force(2.0)
        for _ in range(5):
            sim.step()
    ours: dict[str, list] = {}
    with BagReader(folder) as bag:
        for raw in bag.messages():
            ours.setdefault(raw.topic, []).append(raw.data)
        types = {name: info.type for name, info in bag.topics.items()}
    with AnyReader([folder]) as reader:
        theirs: dict[str, int] = {}
        for connection, _, raw in reader.messages():
            reader.deserialize(raw, connection.msgtype)   # every message decodes
            theirs[connection.topic] = theirs.get(connection.topic, 0) + 1
    assert theirs == {topic: len(data) for topic, data in ours.items()}
    latched = {'/tf_static', '/robot_description'}   # once, at the start
    assert len(ours) == len(types)
    assert all(len(v) == (1 if t in latched else 6) for t, v in ours.items())
    state = deserialize_message(ours['/joint_states'][-1], JointState)
    assert len(state.name) == len(state.position) > 0


def test_trimmer_cuts_rclpys_stale_tail_to_where_rosbags_ends_the_message():
    store = get_typestore(Stores.ROS2_JAZZY)
    trimmer = CdrTrimmer()
    cases = []
    for k in range(4):
        for values in ([], [1.0], [1.0, 2.0]):
            msg = JointState()
            msg.header.frame_id, msg.name = 'w' * k, ['j'] * k
            msg.position, msg.effort = values, values[:1]
            cases.append(('sensor_msgs/msg/JointState', msg))
    for k in range(5):
        marker = Marker(ns='n' * k, text='t' * k, points=[Point(x=float(i)) for i in range(k)])
        cases.append(('visualization_msgs/msg/MarkerArray', MarkerArray(markers=[marker] * k)))
    longer = 0
    for type_name, msg in cases:
        data = serialize_message(msg)
        exact = trimmer.trim(type_name, data)
        longer += len(data) > len(exact)
        msgdef = store.get_msgdef(type_name)
        _, end = msgdef.deserialize_cdr_le(memoryview(data)[4:], 0, msgdef.cls, store)
        assert len(exact) == 4 + end
        store.deserialize_cdr(exact, type_name)          # the strict reader accepts it
        assert deserialize_message(exact, type(msg)) == msg
    assert longer > 0    # rclpy did append stale bytes to some of them
    assert trimmer.trim('std_msgs/msg/String', b'\x00\x01\x00\x00\x10') == \
        b'\x00\x01\x00\x00\x10'                          # cut short: kept as it is
