"""Fixes from the offline-tools audit (info, recover, analyze, replay, bag folders): each
test fails without its fix."""
from __future__ import annotations

import hashlib
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import String

from gripper_sim.cli.main import main
from gripper_sim.recording.writer import BagWriter


def chatter_file(path: Path, n: int = 5, step_ns: int = 10_000_000) -> Path:
    """A small closed MCAP file of ``n`` ``/chatter`` Strings, ``step_ns`` apart."""
    with BagWriter(path) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i in range(n):
            bag.write('/chatter', serialize_message(String(data=f'hi {i}')),
                      log_time=1_000_000_000 + i * step_ns)
    return path


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def one_line_error(capsys) -> str:
    """The stderr of a verb that failed: one ``error: ...`` line, no traceback."""
    err = capsys.readouterr().err
    assert err.startswith('error: ') and err.count('\n') == 1 and 'Traceback' not in err, err
    return err


# ------------------------------------------------------------------ recover
def test_recover_force_never_replaces_a_device_or_fifo(tmp_path, capsys):
    """``--force`` replaced whatever was at OUT with os.replace: ``recover x.mcap /dev/null
    --force`` turned /dev/null into a regular file. Only a regular file is replaced."""
    source = chatter_file(tmp_path / 'in.mcap')
    before = sha256(source)
    fifo = tmp_path / 'pipe.mcap'
    os.mkfifo(fifo)
    capsys.readouterr()
    assert main(['recover', str(source), str(fifo), '--force']) == 2
    assert 'not a regular file' in one_line_error(capsys)
    assert stat.S_ISFIFO(fifo.lstat().st_mode)
    assert sha256(source) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['in.mcap', 'pipe.mcap']
    # a regular file is still replaced with --force
    existing = tmp_path / 'old.mcap'
    existing.write_bytes(b'old')
    assert main(['recover', str(source), str(existing), '--force']) == 0
    assert existing.read_bytes() != b'old' and sha256(source) == before


# ------------------------------------------------------------------ analyze
@pytest.fixture(scope='module')
def dotted_bag(tmp_path_factory) -> Path:
    """A small squeeze recorded to the bag folder ``grasp.v2`` (a dot in its name)."""
    bag = tmp_path_factory.mktemp('dotted') / 'grasp.v2'
    assert main(['squeeze', '--to-force', '1', '--out', str(bag), '--set', 'fruit.nodes=16',
                 '--quiet']) == 0
    return bag


def _hashes(folder: Path) -> dict[str, str]:
    return {p.name: sha256(p) for p in sorted(folder.iterdir())}


@pytest.mark.parametrize('given', ['.', './', 'sub/..'])
def test_analyze_of_the_folder_one_stands_in_writes_beside_it(dotted_bag, given, tmp_path,
                                                            monkeypatch, capsys):
    """``analyze .`` inside a bag folder was a ValueError traceback (a path with an empty
    name), ``analyze bag/..`` wrote into the bag folder, and a bag folder with a dot in
    its name lost its tail (``grasp.v2`` -> ``grasp_analysis``). The default output is
    ``NAME_analysis`` beside the folder, the recording is left as it was."""
    bag = tmp_path / 'grasp.v2'
    bag.mkdir()
    for f in dotted_bag.iterdir():
        (bag / f.name).write_bytes(f.read_bytes())
    before = _hashes(bag)
    if given == 'sub/..':
        (bag / 'sub').mkdir()
        before['sub'] = None
    monkeypatch.chdir(bag)
    capsys.readouterr()
    assert main(['analyze', given, '--no-figures', '--no-html', '--quiet']) == 0
    assert (tmp_path / 'grasp.v2_analysis' / 'summary.json').is_file()
    after = {p.name: (None if p.is_dir() else sha256(p)) for p in sorted(bag.iterdir())}
    assert after == before


# ------------------------------------------------------------------ bag folders
def _killed_bag(folder: Path, *names: str) -> Path:
    """A bag folder as a killed recorder leaves it (no metadata.yaml), its files named."""
    folder.mkdir()
    for name in names:
        chatter_file(folder / name)
    return folder


def test_a_folder_of_several_recordings_is_not_merged(tmp_path, capsys):
    """Without metadata.yaml every .mcap file of the folder was read as one bag: a copy
    or another recording beside the files doubled the messages that info counted and
    analyze analysed. Only one file or one split series NAME_0, NAME_1, ... is a bag."""
    mixed = _killed_bag(tmp_path / 'mixed', 'run_0.mcap', 'copy.mcap')
    before = _hashes(mixed)
    capsys.readouterr()
    for verb in (['info'], ['analyze', '--quiet'], ['replay']):
        assert main([*verb, str(mixed)]) == 2
        assert 'more than one recording (copy.mcap, run_0.mcap)' in one_line_error(capsys)
    assert main(['recover', str(mixed), str(tmp_path / 'fixed')]) == 2
    one_line_error(capsys)
    assert not (tmp_path / 'fixed').exists() and _hashes(mixed) == before
    two_runs = _killed_bag(tmp_path / 'two_runs', 'a_0.mcap', 'b_0.mcap')
    assert main(['info', str(two_runs)]) == 2
    one_line_error(capsys)
    # one split series, also in a renamed folder, and a lone file are bags
    for folder in (_killed_bag(tmp_path / 'renamed', 'run_0.mcap', 'run_1.mcap'),
                   _killed_bag(tmp_path / 'lone', 'whatever.mcap')):
        assert main(['info', '--json', str(folder)]) == 0
        assert f'"messages": {5 * len(list(folder.iterdir()))}' in capsys.readouterr().out


def test_a_file_listed_twice_in_metadata_yaml_is_refused(tmp_path, capsys):
    """relative_file_paths naming a file twice had its messages read twice."""
    folder = _killed_bag(tmp_path / 'bag', 'bag_0.mcap')
    (folder / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
        '  relative_file_paths:\n    - bag_0.mcap\n    - bag_0.mcap\n')
    capsys.readouterr()
    assert main(['info', str(folder)]) == 2
    assert 'lists bag_0.mcap more than once' in one_line_error(capsys)


def _foreign_file(path: Path, *, rosbag2_yaml: str | None = None,
                  qos_yaml: str | None = None) -> Path:
    """One /chatter message in a file written by the plain mcap writer, with the given
    rosbag2 metadata record and channel QoS text."""
    from mcap.writer import Writer
    with open(path, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data\n')
        metadata = {} if qos_yaml is None else {'offered_qos_profiles': qos_yaml}
        channel = writer.register_channel('/chatter', 'cdr', schema, metadata)
        writer.add_message(channel, log_time=1, publish_time=1,
                           data=serialize_message(String(data='hi')))
        if rosbag2_yaml is not None:
            writer.add_metadata('rosbag2', {'serialized_metadata': rosbag2_yaml})
        writer.finish()
    return path


def test_broken_yaml_is_a_one_line_error(tmp_path, capsys):
    """A metadata.yaml that is not YAML printed PyYAML's five-line report; one nested too
    deeply (a metadata.yaml, a rosbag2 record, a channel's QoS) was a RecursionError
    traceback."""
    bag = _killed_bag(tmp_path / 'bag', 'bag_0.mcap')
    meta = bag / 'metadata.yaml'
    capsys.readouterr()
    meta.write_text('rosbag2_bagfile_information: [unclosed\n  : : :\n')
    assert main(['info', str(bag)]) == 2
    assert 'is not valid YAML: line 2, column 3: ' in one_line_error(capsys)
    meta.write_text('rosbag2_bagfile_information: ' + '[' * 5000 + ']' * 5000 + '\n')
    assert main(['info', str(bag)]) == 2
    assert 'nests too deeply' in one_line_error(capsys)
    deep = _foreign_file(tmp_path / 'deep.mcap', rosbag2_yaml='[' * 5000)
    assert main(['info', str(deep)]) == 2
    assert "deep.mcap's rosbag2 metadata is not valid YAML" in one_line_error(capsys)
    # a channel's unreadable QoS is no QoS (as an absent one), not a failure
    deep_qos = _foreign_file(tmp_path / 'qos.mcap', qos_yaml='[' * 5000)
    assert main(['info', '--json', str(deep_qos)]) == 0
    assert '"qos": []' in capsys.readouterr().out


@pytest.mark.parametrize('version, problem', [
    (None, 'has no version'), ("'nine'", "version 'nine' is not a BagMetadata version"),
    ('0', 'version 0 is not'), ('true', 'version True is not')])
def test_metadata_yaml_without_a_whole_number_version_is_refused(tmp_path, version,
                                                                 problem, capsys):
    """A metadata.yaml without a version, or with one that is not a whole number, was
    read as if it were rosbag2's (rosbag2 and rosbags refuse it); older and newer whole
    numbers are read, as rosbag2 reads them."""
    bag = _killed_bag(tmp_path / 'bag', 'bag_0.mcap')
    line = '' if version is None else f'  version: {version}\n'
    (bag / 'metadata.yaml').write_text(
        f'rosbag2_bagfile_information:\n{line}  storage_identifier: mcap\n'
        '  relative_file_paths:\n    - bag_0.mcap\n')
    capsys.readouterr()
    assert main(['info', str(bag)]) == 2
    assert problem in one_line_error(capsys)


@pytest.mark.parametrize('version', [5, 9, 10])
def test_metadata_yaml_of_another_rosbag2_version_is_read(tmp_path, version, capsys):
    bag = _killed_bag(tmp_path / 'bag', 'bag_0.mcap')
    (bag / 'metadata.yaml').write_text(
        f'rosbag2_bagfile_information:\n  version: {version}\n  storage_identifier: mcap\n'
        '  relative_file_paths:\n    - bag/bag_0.mcap\n')
    assert main(['info', '--json', str(bag)]) == 0
    assert '"messages": 5' in capsys.readouterr().out


# ------------------------------------------------------------------ replay
class Sink:
    """A publisher stand-in that keeps what it is given; with ``stop_after`` it stops
    the player after that many messages (so a replay that would never end does)."""

    def __init__(self):
        self.sent: list = []
        self.player = None
        self.limit = 0

    def stop_after(self, player, limit: int) -> None:
        self.player, self.limit = player, limit

    def publish(self, msg) -> None:
        self.sent.append(msg)
        if self.limit and len(self.sent) >= self.limit:
            self.player.stop.set()

    def get_subscription_count(self) -> int:
        return 1


class FakeNode:
    """The part of an rclpy node ``Player`` uses; its publishers are ``Sink``s."""

    def __init__(self):
        self.created: dict[str, Sink] = {}

    def create_publisher(self, _msg_class, topic: str, _qos) -> Sink:
        self.created[topic] = Sink()
        return self.created[topic]

    def get_logger(self):
        import logging
        return logging.getLogger('fake_replay_node')


def _stamps_ns(sink: Sink) -> list[int]:
    return [m.clock.sec * 1_000_000_000 + m.clock.nanosec for m in sink.sent]


@pytest.mark.parametrize('rate', [1e12, 1e300])
def test_the_replay_clock_never_passes_the_recordings_end(tmp_path, rate):
    """``replay --clock`` at a large rate published the wall time scaled by the rate:
    at 1e12 /clock wrapped round int32 seconds (negative times), at 1e300 it was an
    OverflowError traceback. The clock stops at the recording's last message."""
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.ros.replay import Player
    with BagReader(chatter_file(tmp_path / 'c.mcap', n=50)) as bag:
        node = FakeNode()
        player = Player(node, bag, rate=rate, clock_hz=1000.0)
        player.play_once()
        stamps = _stamps_ns(node.created['/clock'])
        assert stamps and all(bag.start_time <= t <= bag.end_time for t in stamps)
        assert len(node.created['/chatter'].sent) == 50


def test_a_clock_faster_than_publishing_does_not_hold_the_messages(tmp_path):
    """A /clock tick that came due while the last one was published was published
    before the message waiting: at ``--clock 1e9`` (or any rate a loaded machine cannot
    publish at) the replay sent /clock only, forever."""
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.ros.replay import Player
    with BagReader(chatter_file(tmp_path / 'c.mcap', n=20)) as bag:
        node = FakeNode()
        player = Player(node, bag, rate=1000.0, clock_hz=1e9)
        node.created['/clock'].stop_after(player, 100_000)
        player.play_once()
        assert len(node.created['/chatter'].sent) == 20
        stamps = _stamps_ns(node.created['/clock'])
        assert stamps == sorted(stamps) and stamps[-1] <= bag.end_time


def test_replay_refuses_an_invalid_topic_name_in_one_line(tmp_path, capsys):
    """``--remap /chatter:=bad//name`` was rclpy's InvalidTopicNameException traceback
    (exit 1); a recorded topic whose name ROS 2 does not allow (a foreign MCAP file) is
    skipped like a topic of an unknown type, unless asked for."""
    source = chatter_file(tmp_path / 'in.mcap')
    capsys.readouterr()
    assert main(['replay', str(source), '--remap', '/chatter:=bad//name']) == 2
    assert "cannot replay '/chatter' as 'bad//name': Invalid topic name: topic name must " \
        "not contain repeated '/'" in one_line_error(capsys)
    foreign = tmp_path / 'foreign.mcap'
    from mcap.writer import Writer
    with open(foreign, 'wb') as stream:
        writer = Writer(stream)
        writer.start(profile='ros2', library='test')
        schema = writer.register_schema('std_msgs/msg/String', 'ros2msg', b'string data\n')
        for topic in ('/chatter', 'my topic'):
            channel = writer.register_channel(topic, 'cdr', schema, {})
            writer.add_message(channel, log_time=1, publish_time=1,
                               data=serialize_message(String(data='hi')))
        writer.finish()
    assert main(['replay', str(foreign), '--topics', 'my topic']) == 2
    assert "cannot replay 'my topic' as 'my topic'" in one_line_error(capsys)
    assert main(['replay', str(foreign)]) == 0
    assert 'replayed 1 message on 1 topic' in capsys.readouterr().err


def test_replay_with_nothing_to_replay_is_refused(tmp_path):
    """A recording without messages on the replayed topics (from ``--start`` on) played
    nothing and, with ``--loop``, spun at full CPU without end (39,000 empty loops in
    15 s). It is 'nothing to replay' instead."""
    from gripper_sim.recording.errors import RecordingError
    from gripper_sim.recording.reader import BagReader
    from gripper_sim.ros.replay import Player
    empty = tmp_path / 'empty.mcap'
    with BagWriter(empty) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
    mixed = tmp_path / 'mixed.mcap'
    with BagWriter(mixed) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        bag.add_topic('/late', 'std_msgs/msg/String')
        bag.write('/chatter', serialize_message(String(data='early')), log_time=0)
        bag.write('/late', serialize_message(String(data='late')), log_time=2_000_000_000)
    for path, options in ((empty, {}), (mixed, {'topics': ['/chatter'], 'start': 1.0})):
        with BagReader(path) as bag:
            with pytest.raises(RecordingError, match='nothing to replay'):
                Player(FakeNode(), bag, **options)
    with BagReader(mixed) as bag:
        node = FakeNode()
        Player(node, bag, start=1.0).play_once()
        assert node.created['/late'].sent and not node.created['/chatter'].sent


def test_a_topic_remapped_twice_is_refused(tmp_path, capsys):
    """``--remap /chatter:=/x --remap /chatter:=/y`` published on /y only, silently."""
    source = chatter_file(tmp_path / 'in.mcap')
    capsys.readouterr()
    assert main(['replay', str(source), '--remap', '/chatter:=/x',
                 '--remap', '/chatter:=/y']) == 2
    assert '--remap gives /chatter two names (/x and /y)' in one_line_error(capsys)


def test_a_file_being_recorded_is_refused_and_left_alone(tmp_path, capsys):
    """A file still being written has no footer yet: info, analyze and replay refuse it
    with a line that says it may still be recorded (it said 'the recorder was probably
    killed') and how to read what it holds; recover reads it without touching it."""
    path = tmp_path / 'live.mcap'
    with BagWriter(path) as bag:
        bag.add_topic('/chatter', 'std_msgs/msg/String')
        for i in range(3):
            bag.write('/chatter', serialize_message(String(data=f'hi {i}')), log_time=i)
        bag.flush()
        before = sha256(path)
        capsys.readouterr()
        for verb in (['info'], ['analyze', '--quiet'], ['replay']):
            assert main([*verb, str(path)]) == 2
            err = one_line_error(capsys)
            assert 'still being recorded, or its recorder was killed' in err
            assert f'gripper-sim recover {path} FIXED.mcap' in err
        assert main(['recover', str(path), str(tmp_path / 'so_far.mcap')]) == 0
        assert 'so_far.mcap: 3 messages' in capsys.readouterr().out
        assert sha256(path) == before


def _run_without_root_rights(*argv: str) -> subprocess.CompletedProcess:
    """``gripper-sim ARGV`` in a process that file permissions apply to: as root, one
    without the capabilities that override them."""
    command = [sys.executable, '-c', 'import sys; from gripper_sim.cli.main import main; '
               'sys.exit(main(sys.argv[1:]))', *argv]
    if os.geteuid() == 0:
        if shutil.which('setpriv') is None:
            pytest.skip('running as root without setpriv: permissions cannot be tested')
        command = ['setpriv', '--bounding-set=-dac_override,-dac_read_search', *command]
    return subprocess.run(command, capture_output=True, text=True, timeout=300,
                          check=False)


@pytest.mark.parametrize('verb', [['info'], ['analyze', '--quiet'], ['recover']])
def test_a_bag_folder_that_cannot_be_read_is_a_one_line_error(tmp_path, verb):
    """A bag folder without read or search permission was a PermissionError traceback
    (exit 1) from looking for its metadata.yaml; a file in it that cannot be read no
    longer suggests 'recover', which cannot read it either."""
    bag = _killed_bag(tmp_path / 'bag', 'bag_0.mcap')
    extra = [str(tmp_path / 'fixed')] if verb == ['recover'] else []
    bag.chmod(0o444)
    try:
        done = _run_without_root_rights(*verb, str(bag), *extra)
    finally:
        bag.chmod(0o755)
    assert done.returncode == 2, done.stderr
    assert done.stderr == f'error: cannot read {bag}/metadata.yaml: Permission denied\n'
    (bag / 'bag_0.mcap').chmod(0)
    done = _run_without_root_rights(*verb, str(bag), *extra)
    assert done.returncode == 2, done.stderr
    assert done.stderr == f'error: cannot read {bag}/bag_0.mcap: Permission denied\n'
    assert not (tmp_path / 'fixed').exists()


def test_recover_never_writes_into_the_bag_folder_it_reads(tmp_path, capsys):
    """``recover bag bag/fixed`` created its output folder inside the input bag folder."""
    bag = _killed_bag(tmp_path / 'bag', 'bag_0.mcap', 'bag_1.mcap')
    before = _hashes(bag)
    capsys.readouterr()
    for inside in (bag / 'fixed', bag / 'sub' / '..' / 'fixed'):
        if inside.parent != bag:
            (bag / 'sub').mkdir()
            before['sub'] = _hashes(bag / 'sub')
        assert main(['recover', str(bag), str(inside)]) == 2
        assert 'is inside the bag folder' in one_line_error(capsys)
        assert {p.name: (_hashes(p) if p.is_dir() else sha256(p))
                for p in bag.iterdir()} == before
    assert main(['recover', str(bag), str(tmp_path / 'fixed')]) == 0


def test_a_listed_storage_file_that_is_a_folder_is_named_as_such(tmp_path, capsys):
    """A folder where metadata.yaml lists a storage file was 'is a directory; give the
    .mcap file inside it (for the whole bag: gripper-sim recover ...)', advice that
    cannot work (recover fails the same way)."""
    bag = _killed_bag(tmp_path / 'bag')
    (bag / 'bag_0.mcap').mkdir()
    (bag / 'metadata.yaml').write_text(
        'rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n'
        '  relative_file_paths:\n    - bag_0.mcap\n')
    capsys.readouterr()
    assert main(['info', str(bag)]) == 2
    err = one_line_error(capsys)
    assert 'bag_0.mcap, listed in metadata.yaml, is not a file' in err and 'recover' not in err


def test_recover_counts_in_english(tmp_path, capsys):
    """recover said '1 messages from 1 chunks, 1 damaged chunks skipped'."""
    source = chatter_file(tmp_path / 'one.mcap', n=1)
    capsys.readouterr()
    assert main(['recover', str(source), str(tmp_path / 'fixed.mcap')]) == 0
    assert 'fixed.mcap: 1 message from 1 chunk\n' in capsys.readouterr().out
