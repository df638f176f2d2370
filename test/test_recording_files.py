"""The MCAP writer, reader and recovery, on messages serialized here (no ROS graph).

Round trips compare exactly: every message read back with the ``mcap`` library and
``mcap-ros2-support``'s decoder, and with rclpy's deserializer, equals what was written.
"""
from __future__ import annotations

import hashlib
import re
import shutil
import struct

import pytest
import yaml

import rclpy  # noqa: F401

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point, WrenchStamped  # noqa: E402
from mcap.reader import make_reader  # noqa: E402
from mcap.records import Chunk, MessageIndex, Statistics  # noqa: E402
from mcap.stream_reader import StreamReader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from sensor_msgs.msg import JointState, PointCloud2, PointField  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

from gripper_sim.cli.main import main  # noqa: E402
from gripper_sim.recording import qos, schemas  # noqa: E402
from gripper_sim.recording.errors import RecordingError  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.recording.recover import recover  # noqa: E402
from gripper_sim.recording.writer import BagWriter  # noqa: E402

pytestmark = pytest.mark.ros


def _fruit_state_class():
    try:
        from gripper_sim_interfaces.msg import FruitState
    except ImportError:
        return None
    return FruitState


def sample_messages(i: int) -> dict[str, tuple[str, object]]:
    """Messages of several types whose contents depend on ``i``."""
    stamp = Time(sec=i // 10, nanosec=(i % 10) * 100_000_000)
    wrench = WrenchStamped()
    wrench.header.stamp = stamp
    wrench.header.frame_id = 'left_jaw'
    wrench.wrench.force.x = -0.5 * i
    wrench.wrench.torque.z = 1e-3 * i
    cloud = PointCloud2()
    cloud.header.stamp = stamp
    cloud.header.frame_id = 'world'
    cloud.height, cloud.width = 1, i % 7
    cloud.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                    for k, n in enumerate('xyz')]
    cloud.point_step, cloud.row_step = 12, 12 * (i % 7)
    cloud.data = bytes((i * 31 + k) % 256 for k in range(12 * (i % 7)))
    joints = JointState()
    joints.header.stamp = stamp
    joints.name = ['left_jaw_joint', 'right_jaw_joint']
    joints.position = [0.01 * i, -0.01 * i]
    joints.effort = [float(i), float(-i)]
    markers = MarkerArray()
    marker = Marker()
    marker.header.frame_id = 'world'
    marker.ns = 'outline'
    marker.id = i
    marker.type = Marker.LINE_STRIP
    marker.points = [Point(x=0.001 * k, y=0.0, z=0.002 * i) for k in range(i % 5)]
    markers.markers.append(marker)
    out = {
        '/chatter': ('std_msgs/msg/String', String(data=f'hello {i} ' + 'é' * (i % 3))),
        '/sim/left_jaw/wrench': ('geometry_msgs/msg/WrenchStamped', wrench),
        '/sim/fruit/nodes': ('sensor_msgs/msg/PointCloud2', cloud),
        '/joint_states': ('sensor_msgs/msg/JointState', joints),
        '/sim/markers': ('visualization_msgs/msg/MarkerArray', markers),
        '/clock': ('rosgraph_msgs/msg/Clock', Clock(clock=stamp)),
    }
    fruit_state = _fruit_state_class()
    if fruit_state is not None:
        state = fruit_state()
        state.header.stamp = stamp
        state.compression = 1e-4 * i
        state.grip_force = 0.25 * i
        state.bruised = bool(i % 2)
        state.centroid = Point(x=0.0, y=0.0, z=0.03 + 1e-5 * i)
        out['/sim/fruit/state'] = ('gripper_sim_interfaces/msg/FruitState', state)
    return out


def write_sample_bag(path, n: int = 40, **kwargs):
    """Write ``n`` rounds of sample messages; return [(topic, log_ns, pub_ns, msg, cdr)].

    The CDR bytes are kept as written: serializing twice may differ in padding bytes.
    """
    written = []
    with BagWriter(path, **kwargs) as bag:
        for topic, (type_name, _) in sample_messages(0).items():
            bag.add_topic(topic, type_name)
        for i in range(n):
            for k, (topic, (_, msg)) in enumerate(sample_messages(i).items()):
                log_ns = 1_700_000_000_000_000_000 + i * 10_000_000 + k
                pub_ns = log_ns - 1000
                cdr = serialize_message(msg)
                bag.write(topic, cdr, log_time=log_ns, publish_time=pub_ns)
                written.append((topic, log_ns, pub_ns, msg, cdr))
    return written


def _fields_equal(decoded, original) -> None:
    """Compare an mcap_ros2 decoded message with the rclpy original, field by field."""
    for name in original.get_fields_and_field_types():
        want = getattr(original, name)
        got = getattr(decoded, name)
        if hasattr(want, 'get_fields_and_field_types'):
            _fields_equal(got, want)
        elif isinstance(want, (list, tuple)) and want and \
                hasattr(want[0], 'get_fields_and_field_types'):
            assert len(got) == len(want)
            for g, w in zip(got, want):
                _fields_equal(g, w)
        elif isinstance(want, (bytes, bytearray)) or name == 'data' and \
                not isinstance(want, str):
            assert bytes(got) == bytes(want)
        else:
            got_list = list(got) if hasattr(got, '__len__') and not isinstance(got, str) \
                else got
            want_list = list(want) if hasattr(want, '__len__') and not isinstance(want, str) \
                else want
            assert got_list == want_list, name


# ---------------------------------------------------------------------- schemas
def test_schema_text_holds_every_nested_definition_once():
    text = schemas.message_definition('geometry_msgs/msg/WrenchStamped')
    root = schemas.find_msg_file('geometry_msgs/msg/WrenchStamped').read_text()
    assert text.startswith(root)
    blocks = text.split(schemas.SEPARATOR + '\n')
    names = [b.splitlines()[0] for b in blocks[1:]]
    assert sorted(names) == sorted({'MSG: std_msgs/Header', 'MSG: builtin_interfaces/Time',
                                    'MSG: geometry_msgs/Wrench',
                                    'MSG: geometry_msgs/Vector3'})
    for block in blocks[1:]:
        first, _, body = block.partition('\n')
        pkg, name = first[len('MSG: '):].split('/')
        assert body == schemas.find_msg_file(f'{pkg}/msg/{name}').read_text()


def test_schema_dependencies_skip_constants_arrays_and_bounds():
    text = ('uint8 MODE_A=1\nstring NAME = "x"\nstring<=8 short\nint32[<=4] few\n'
            'Header header\nPoint[] points\nother_pkg/Thing[3] things  # comment\n')
    assert schemas.dependencies(text, 'my_pkg') == [
        ('std_msgs', 'Header'), ('my_pkg', 'Point'), ('other_pkg', 'Thing')]


def test_missing_definition_is_a_clear_error():
    with pytest.raises(RecordingError, match='no message definition'):
        schemas.message_definition('no_such_pkg/msg/Nothing')
    with pytest.raises(RecordingError, match='not a message type name'):
        schemas.message_definition('String')


def test_type_hash_matches_rclpy():
    from rclpy.type_hash import TypeHash  # noqa: F401 - only to be sure rclpy has it
    value = schemas.type_hash('std_msgs/msg/String')
    assert re.fullmatch(r'RIHS01_[0-9a-f]{64}', value)
    assert schemas.type_hash('std_msgs/msg/String') != \
        schemas.type_hash('geometry_msgs/msg/WrenchStamped')


# ---------------------------------------------------------------------- round trip
def test_round_trip_with_mcap_ros2_decoder_and_rclpy(tmp_path):
    path = tmp_path / 'round.mcap'
    written = write_sample_bag(path, n=30)
    types = {topic: t for topic, (t, _) in sample_messages(0).items()}
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        got = [(ch.topic, m.log_time, m.publish_time, m.data, dec)
               for _s, ch, m, dec in reader.iter_decoded_messages(log_time_order=True)]
    assert len(got) == len(written)
    for (topic, log_ns, pub_ns, msg, cdr), (g_topic, g_log, g_pub, data, dec) in \
            zip(written, got):
        assert (g_topic, g_log, g_pub) == (topic, log_ns, pub_ns)
        assert data == cdr
        _fields_equal(dec, msg)
        cls = type(msg)
        assert deserialize_message(data, cls) == msg
        assert types[topic].endswith('/' + cls.__name__)
    log_times = [g[1] for g in got]
    assert log_times == sorted(log_times)


def test_reader_yields_what_was_written(tmp_path):
    path = tmp_path / 'r.mcap'
    written = write_sample_bag(path, n=25)
    with BagReader(path) as bag:
        assert bag.message_count == len(written)
        assert bag.start_time == written[0][1] and bag.end_time == written[-1][1]
        for topic, info in bag.topics.items():
            assert info.message_count == sum(1 for w in written if w[0] == topic)
        raw = list(bag.messages())
        assert [(m.topic, m.log_time, m.publish_time) for m in raw] == \
            [(w[0], w[1], w[2]) for w in written]
        only = list(bag.messages(['/chatter']))
        assert [m.data for m in only] == [w[4] for w in written if w[0] == '/chatter']
        decoded = list(bag.decoded_messages(['/sim/left_jaw/wrench']))
        forces = [d.wrench.force.x for _, d in decoded]
        assert forces == [w[3].wrench.force.x for w in written
                          if w[0] == '/sim/left_jaw/wrench']
        with pytest.raises(RecordingError, match="no topic '/nope'"):
            list(bag.messages(['/nope']))


# ---------------------------------------------------------------------- layout
def test_file_is_laid_out_like_rosbag2(tmp_path):
    path = tmp_path / 'layout.mcap'
    written = write_sample_bag(path, n=10)
    with open(path, 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.profile == 'ros2'
    assert summary.statistics.message_count == len(written)
    assert {s.encoding for s in summary.schemas.values()} == {'ros2msg'}
    for channel in summary.channels.values():
        assert channel.message_encoding == 'cdr'
        schema = summary.schemas[channel.schema_id]
        assert re.fullmatch(r'[a-z_]+/msg/[A-Za-z0-9]+', schema.name)
        profiles = yaml.safe_load(channel.metadata['offered_qos_profiles'])
        assert isinstance(profiles, list) and profiles
        assert profiles[0]['reliability'] == 'reliable'
        assert profiles[0]['history'] == 'keep_last'
        assert set(profiles[0]['deadline']) == {'sec', 'nsec'}
        assert channel.metadata['topic_type_hash'] == schemas.type_hash(schema.name)
    assert {c.compression for c in summary.chunk_indexes} == {'zstd'}
    assert all(c.message_index_offsets for c in summary.chunk_indexes)
    bag_meta = yaml.safe_load(metadata['rosbag2']['serialized_metadata'])
    info = bag_meta
    assert info['version'] == 9 and info['ros_distro'] == 'jazzy'
    assert info['storage_identifier'] == 'mcap'
    assert info['message_count'] == len(written)
    assert info['starting_time']['nanoseconds_since_epoch'] == written[0][1]
    assert info['duration']['nanoseconds'] == written[-1][1] - written[0][1]
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in info['topics_with_message_count']}
    assert counts == {topic: sum(1 for w in written if w[0] == topic)
                      for topic in {w[0] for w in written}}
    assert info['relative_file_paths'] == [path.name]
    # every record type rosbag2's reader looks for is there
    kinds = {type(r) for r in StreamReader(str(path), emit_chunks=True).records}
    assert {Chunk, MessageIndex, Statistics} <= kinds


def test_qos_yaml_round_trip():
    profile = qos.default_profile(reliability='best_effort', durability='transient_local',
                                  depth=5)
    profile['deadline'] = 1_500_000_000
    profile['liveliness_lease_duration'] = qos.INFINITE_NS
    text = qos.to_yaml([profile, qos.default_profile()])
    parsed = qos.from_yaml(text)
    assert parsed == [qos.normalize(profile), qos.normalize(qos.default_profile())]
    loaded = yaml.safe_load(text)
    assert loaded[0]['deadline'] == {'sec': 1, 'nsec': 500_000_000}
    assert loaded[0]['liveliness_lease_duration'] == {'sec': 9223372036, 'nsec': 854775807}
    # integer policies, as metadata version <= 8 stores them, are understood too
    legacy = qos.from_yaml('- history: 1\n  depth: 3\n  reliability: 2\n  durability: 1\n'
                           '  liveliness: 1\n  avoid_ros_namespace_conventions: false\n')
    assert legacy[0]['reliability'] == 'best_effort'
    assert legacy[0]['durability'] == 'transient_local'
    rclpy_profile = qos.to_rclpy(parsed[0])
    assert qos.from_rclpy(rclpy_profile)['reliability'] == 'best_effort'
    assert rclpy_profile.depth == 5


def test_writer_refuses_to_overwrite_and_checks_input(tmp_path):
    path = tmp_path / 'once.mcap'
    write_sample_bag(path, n=1)
    before = path.read_bytes()
    with pytest.raises(RecordingError, match='already exists'):
        BagWriter(path).open()
    assert path.read_bytes() == before
    with BagWriter(tmp_path / 'x.mcap') as bag:
        with pytest.raises(RecordingError, match='add_topic first'):
            bag.write('/none', b'', log_time=1)
        bag.add_topic('/a', 'std_msgs/msg/String')
        with pytest.raises(RecordingError, match='already recorded with type'):
            bag.add_topic('/a', 'std_msgs/msg/Bool')
        with pytest.raises(RecordingError, match='integer of ns'):
            bag.write('/a', serialize_message(String()), log_time=1.5)
    with pytest.raises(RecordingError, match='closed'):
        bag.write('/a', b'', log_time=1)


# ---------------------------------------------------------------------- flushing
class FakeClock:
    def __init__(self):
        self.now = 0.0

    def __call__(self):
        return self.now


def _messages_on_disk(path) -> int:
    from gripper_sim.recording.recover import scan
    from mcap.records import Message
    return sum(isinstance(r, Message) for r in scan(path).records)


def test_chunks_reach_the_disk_within_the_flush_interval(tmp_path):
    path = tmp_path / 'flush.mcap'
    clock = FakeClock()
    bag = BagWriter(path, flush_interval=0.5, clock=clock)
    bag.open()
    bag.add_topic('/chatter', 'std_msgs/msg/String')
    for i in range(10):
        bag.write('/chatter', serialize_message(String(data=str(i))), log_time=i)
    assert _messages_on_disk(path) == 0          # still in the open chunk
    assert not bag.flush_if_due()
    clock.now = 0.6
    assert bag.flush_if_due()                     # a timer tick writes the chunk
    assert _messages_on_disk(path) == 10
    for i in range(10, 15):
        bag.write('/chatter', serialize_message(String(data=str(i))), log_time=i)
    clock.now = 1.2
    bag.write('/chatter', serialize_message(String(data='15')), log_time=15)
    assert _messages_on_disk(path) == 16          # the write itself flushed
    bag.close()


# ---------------------------------------------------------------------- recovery
def _killed_file(path, n_rounds: int = 30):
    """A file as a killed recorder leaves it: flushed chunks, no summary, no footer."""
    clock = FakeClock()
    bag = BagWriter(path, flush_interval=1.0, clock=clock)
    bag.open()
    bag.add_metadata('config', {'yaml': 'fruit: apple\n'})
    for topic, (type_name, _) in sample_messages(0).items():
        bag.add_topic(topic, type_name)
    written = []
    for i in range(n_rounds):
        clock.now = 0.1 * i
        for k, (topic, (_, msg)) in enumerate(sample_messages(i).items()):
            t = 1_000_000 + 1000 * i + k
            cdr = serialize_message(msg)
            bag.write(topic, cdr, log_time=t)
            written.append((topic, t, cdr))
    bag._stream.flush()  # what the OS has; the object is then abandoned, as by SIGKILL
    flushed = _messages_on_disk(path)
    bag._stream.close()
    bag._writer = None
    return written, flushed


def test_recover_a_killed_recording_keeps_every_flushed_message(tmp_path):
    src = tmp_path / 'killed.mcap'
    written, flushed = _killed_file(src)
    assert 0 < flushed < len(written)
    digest = hashlib.sha256(src.read_bytes()).hexdigest()
    with pytest.raises(RecordingError, match='recover'):
        BagReader(src).open()
    dst = tmp_path / 'fixed.mcap'
    report = recover(src, dst)
    assert hashlib.sha256(src.read_bytes()).hexdigest() == digest
    assert report.messages == flushed and not report.complete
    with BagReader(dst) as bag:
        got = [(m.topic, m.log_time, m.data) for m in bag.messages()]
        assert bag.metadata_named('config') == {'yaml': 'fruit: apple\n'}
        assert bag.bag_metadata()['message_count'] == flushed
        for topic, info in bag.topics.items():
            assert info.type == sample_messages(0)[topic][0]
            assert info.offered_qos_profiles
    assert got == sorted(written[:flushed], key=lambda w: w[1])


def test_recover_at_every_cut_point_gives_a_prefix(tmp_path):
    src = tmp_path / 'full.mcap'
    written, flushed = _killed_file(src, n_rounds=25)
    data = src.read_bytes()
    previous = -1
    cuts = sorted(set(range(0, len(data), max(1, len(data) // 60))) | {len(data)})
    for cut in cuts:
        piece = tmp_path / 'piece.mcap'
        piece.write_bytes(data[:cut])
        out = tmp_path / 'out.mcap'
        out.unlink(missing_ok=True)
        try:
            report = recover(piece, out)
        except RecordingError as err:
            assert re.search(r'nothing to recover|empty|truncated|no readable', str(err))
            count = 0
        else:
            count = report.messages
            with BagReader(out) as bag:
                got = [(m.topic, m.log_time, m.data) for m in bag.messages()]
            assert got == written[:count]
        assert count >= previous
        previous = count
    assert previous == flushed


def test_recover_a_closed_file_copies_everything(tmp_path):
    src = tmp_path / 'closed.mcap'
    written = write_sample_bag(src, n=12)
    dst = tmp_path / 'copy.mcap'
    report = recover(src, dst)
    assert report.complete and report.messages == len(written)
    with BagReader(src) as a, BagReader(dst) as b:
        assert [(m.topic, m.log_time, m.publish_time, m.data) for m in a.messages()] == \
            [(m.topic, m.log_time, m.publish_time, m.data) for m in b.messages()]
        assert {t: (i.type, i.type_hash, i.offered_qos_profiles)
                for t, i in a.topics.items()} == \
            {t: (i.type, i.type_hash, i.offered_qos_profiles) for t, i in b.topics.items()}
    with pytest.raises(RecordingError, match='is the input file'):
        recover(src, src)
    with pytest.raises(RecordingError, match='already exists'):
        recover(src, dst)


# ---------------------------------------------------------------------- bad input
def _corrupt_chunk(src, dst):
    """Copy ``src`` with one byte flipped inside the first chunk's compressed data."""
    data = bytearray(src.read_bytes())
    with open(src, 'rb') as f:
        offset = make_reader(f).get_summary().chunk_indexes[0].chunk_start_offset
    # opcode, length, start, end, size, crc, compression string, data length, data
    pos = offset + 9 + 8 + 8 + 8 + 4
    (comp_len,) = struct.unpack_from('<I', data, pos)
    pos += 4 + comp_len + 8 + 20
    data[pos] ^= 0xFF
    dst.write_bytes(bytes(data))


@pytest.mark.parametrize('kind', ['empty', 'text', 'magic_only', 'garbage_after_magic',
                                  'truncated', 'corrupt_chunk', 'directory', 'missing',
                                  'sqlite'])
def test_bad_files_give_clear_errors_without_traceback(tmp_path, kind, capsys):
    good = tmp_path / 'good.mcap'
    write_sample_bag(good, n=8)
    bad = tmp_path / f'{kind}.mcap'
    if kind == 'empty':
        bad.write_bytes(b'')
    elif kind == 'text':
        bad.write_text('not a recording\n')
    elif kind == 'magic_only':
        bad.write_bytes(b'\x89MCAP0\r\n')
    elif kind == 'garbage_after_magic':
        bad.write_bytes(b'\x89MCAP0\r\n' + bytes(range(256)) * 4)
    elif kind == 'truncated':
        bad.write_bytes(good.read_bytes()[: good.stat().st_size * 2 // 3])
    elif kind == 'corrupt_chunk':
        _corrupt_chunk(good, bad)
    elif kind == 'directory':
        bad.mkdir()
    elif kind == 'sqlite':
        bad.write_bytes(b'SQLite format 3\x00' + bytes(100))
    before = bad.read_bytes() if bad.is_file() else None

    def read_all():
        with BagReader(bad) as bag:
            list(bag.decoded_messages())

    with pytest.raises(RecordingError) as info:
        read_all()
    assert str(bad) in str(info.value)
    for verb in (['info'], ['analyze', '--no-figures', '-o', str(tmp_path / 'an')]):
        capsys.readouterr()
        assert main(verb + [str(bad)]) == 2
        err = capsys.readouterr().err
        assert err.startswith('error: ') and 'Traceback' not in err
    if bad.is_file():
        assert bad.read_bytes() == before


def test_cli_info_json_matches_reader(tmp_path, capsys):
    import json
    path = tmp_path / 'info.mcap'
    written = write_sample_bag(path, n=6)
    capsys.readouterr()
    assert main(['info', '--json', str(path)]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data['messages'] == len(written)
    assert data['ros_distro'] == 'jazzy' and data['profile'] == 'ros2'
    assert {t['name']: t['count'] for t in data['topics']} == \
        {topic: sum(1 for w in written if w[0] == topic) for topic in {w[0] for w in written}}
    assert main(['info', str(path)]) == 0
    text = capsys.readouterr().out
    for topic in {w[0] for w in written}:
        assert topic in text


def test_cli_recover(tmp_path, capsys):
    src = tmp_path / 'killed.mcap'
    _written, flushed = _killed_file(src, n_rounds=20)
    dst = tmp_path / 'fixed.mcap'
    assert main(['recover', str(src), str(dst)]) == 0
    assert f'{flushed} messages' in capsys.readouterr().out
    assert main(['recover', str(src), str(dst)]) == 2
    assert 'already exists' in capsys.readouterr().err
    shutil.copy(dst, tmp_path / 'again.mcap')
    assert main(['info', str(tmp_path / 'again.mcap')]) == 0
