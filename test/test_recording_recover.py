"""``recover`` keeps a file as it was: a foreign profile, empty channels, an honest state."""
from __future__ import annotations

import json

from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from gripper_sim.cli.main import main
from gripper_sim.recording.bag_folder import BagFolderWriter
from gripper_sim.recording.reader import BagReader
from gripper_sim.recording.recover import recover
from gripper_sim.recording.writer import BagWriter


def _write_foreign(path) -> list[tuple[str, int, bytes]]:
    """A non-ROS MCAP file: its own profile, a JSON channel, a schemaless channel and a
    channel that never got a message."""
    written = []
    with open(path, 'wb') as stream:
        writer = Writer(stream, compression=CompressionType.ZSTD)
        writer.start(profile='x-robot-logs', library='acme-logger 2.1')
        schema = writer.register_schema('acme.Pose', 'jsonschema',
                                        json.dumps({'type': 'object'}).encode())
        pose = writer.register_channel('pose', 'json', schema, {'unit': 'm'})
        raw = writer.register_channel('raw/bytes', 'application/octet-stream', 0, {})
        writer.register_channel('silent', 'json', schema, {'note': 'no messages'})
        for i in range(5):
            data = json.dumps({'x': i}).encode()
            writer.add_message(pose, log_time=100 + i, data=data, publish_time=100 + i)
            written.append(('pose', 100 + i, data))
            writer.add_message(raw, log_time=200 + i, data=bytes([i]), publish_time=200 + i)
            written.append(('raw/bytes', 200 + i, bytes([i])))
        writer.finish()
    return written


def _channels(path) -> dict[str, tuple]:
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    out = {}
    for channel in summary.channels.values():
        schema = summary.schemas.get(channel.schema_id)
        out[channel.topic] = (channel.message_encoding, dict(channel.metadata),
                              (schema.name, schema.encoding, schema.data) if schema else None)
    return out


def test_recover_keeps_a_foreign_file_as_it_was(tmp_path):
    src, dst = tmp_path / 'foreign.mcap', tmp_path / 'fixed.mcap'
    written = _write_foreign(src)
    report = recover(src, dst)
    assert report.messages == len(written) and report.complete
    with open(dst, 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        assert (header.profile, header.library) == ('x-robot-logs', 'acme-logger 2.1')
        assert [m.name for m in reader.iter_metadata()] == []   # no rosbag2 record stamped
        got = sorted((c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages())
    assert got == sorted(written)
    assert _channels(dst) == _channels(src)


def test_recover_keeps_channels_without_messages(tmp_path):
    src, dst = tmp_path / 'ros.mcap', tmp_path / 'fixed.mcap'
    with BagWriter(src) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.add_topic('/quiet', 'std_msgs/msg/String')
        for i in range(3):
            bag.write('/chatter', serialize_message(String(data=str(i))), log_time=10 + i)
    recover(src, dst)
    with BagReader(dst) as bag:
        assert {t: i.message_count for t, i in bag.topics.items()} == \
            {'/chatter': 3, '/quiet': 0}
        listed = {t['topic_metadata']['name']: t['message_count']
                  for t in bag.bag_metadata()['topics_with_message_count']}
    assert listed == {'/chatter': 3, '/quiet': 0}


def test_a_file_with_a_cut_tail_is_recovered_not_complete(tmp_path, capsys):
    src = tmp_path / 'whole.mcap'
    with BagWriter(src) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i in range(20):
            bag.write('/chatter', serialize_message(String(data=str(i))), log_time=10 + i)
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(src.read_bytes()[:-20])   # the footer and closing magic are gone
    report = recover(cut, tmp_path / 'fixed.mcap')
    assert report.messages == 20
    assert not report.complete
    assert main(['recover', str(cut), str(tmp_path / 'again.mcap')]) == 0
    out = capsys.readouterr().out
    assert 'cut short' in out and 'complete' not in out.split('\n')[0]


def test_recovering_a_bag_folder_names_the_metadata_file_it_wrote(tmp_path, capsys):
    src = tmp_path / 'killed'
    with BagFolderWriter(src) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i in range(5):
            bag.write('/chatter', serialize_message(String(data=str(i))), log_time=10 + i)
    (src / 'metadata.yaml').unlink()   # as after a SIGKILL
    assert main(['recover', str(src), str(tmp_path / 'fixed')]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == f"wrote:  {tmp_path / 'fixed' / 'metadata.yaml'}"
