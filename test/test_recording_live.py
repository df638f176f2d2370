"""The live recorder and replay against real ROS processes, on loopback only.

Every ROS process gets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a domain id of its
own test; waits are on matching and on conditions, with generous timeouts.
"""
from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

import rclpy

from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.duration import Duration  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402
from std_msgs.msg import String  # noqa: E402

from gripper_sim.recording import qos  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.recording.recover import recover  # noqa: E402
from gripper_sim.recording.writer import BagWriter  # noqa: E402
from gripper_sim.ros.process import RosProcess, free_domain_id, ros_environment  # noqa: E402
from ros_client import ros_node  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TIMEOUT = 60.0  # s: generous, for a slow busy machine


def _domain() -> int:
    """A domain no process on this machine uses and no test of this session got before."""
    return free_domain_id(os.getpid())


def cli(domain: int, tmp_path: Path, *args: str, name: str = 'cli') -> RosProcess:
    return RosProcess('gripper_sim.cli.main', list(args), env=ros_environment(domain),
                      log_path=tmp_path / f'{name}.log')


def wait_for(condition, timeout: float = TIMEOUT, what: str = 'condition') -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.02)
    raise AssertionError(f'timed out after {timeout} s waiting for {what}')


def stop_cleanly(proc: RosProcess) -> None:
    code = proc.stop(timeout=TIMEOUT)
    assert code == 0, proc.log()


def same_payload(got: bytes, sent: bytes) -> bool:
    """Equal CDR payloads: DDS may pad a sample with up to 3 zero bytes (4-byte alignment)."""
    extra = got[len(sent):]
    return got[:len(sent)] == sent and len(extra) < 4 and not any(extra)


def make_cloud(i: int) -> PointCloud2:
    cloud = PointCloud2()
    cloud.header.frame_id = 'world'
    cloud.header.stamp.sec = i
    cloud.height, cloud.width = 1, 64
    cloud.fields = [PointField(name=n, offset=4 * k, datatype=PointField.FLOAT32, count=1)
                    for k, n in enumerate(('x', 'y', 'z', 'fx', 'fy', 'fz'))]
    cloud.point_step, cloud.row_step = 24, 24 * 64
    cloud.data = bytes((i + k) % 256 for k in range(24 * 64))
    return cloud


def test_recorded_messages_equal_what_was_published(tmp_path):
    domain = _domain()
    out = tmp_path / 'live.mcap'
    with ros_node(domain, 'talker') as (node, _):
        qos_profile = QoSProfile(depth=50, reliability=ReliabilityPolicy.RELIABLE)
        pubs = {
            '/chatter': node.create_publisher(String, '/chatter', qos_profile),
            '/sim/left_jaw/wrench': node.create_publisher(WrenchStamped,
                                                          '/sim/left_jaw/wrench', qos_profile),
            '/sim/fruit/nodes': node.create_publisher(PointCloud2, '/sim/fruit/nodes',
                                                      qos_profile),
        }
        recorder = cli(domain, tmp_path, 'record', '-o', str(out), *pubs, name='record')
        with recorder:
            wait_for(lambda: all(p.get_subscription_count() > 0 for p in pubs.values()),
                     what='the recorder to subscribe')
            sent: dict[str, list] = {t: [] for t in pubs}
            for i in range(150):
                msgs = {'/chatter': String(data=f'message {i}'),
                        '/sim/fruit/nodes': make_cloud(i)}
                wrench = WrenchStamped()
                wrench.header.stamp.nanosec = i
                wrench.wrench.force.x = -0.1 * i
                msgs['/sim/left_jaw/wrench'] = wrench
                for topic, msg in msgs.items():
                    pubs[topic].publish(msg)
                    sent[topic].append(msg)
                time.sleep(0.002)
            for pub in pubs.values():
                pub.wait_for_all_acked(Duration(seconds=TIMEOUT))
            wait_for(lambda: 'recording' in recorder.log(), what='recorder log')
            stop_cleanly(recorder)
    classes = {'/chatter': String, '/sim/left_jaw/wrench': WrenchStamped,
               '/sim/fruit/nodes': PointCloud2}
    with BagReader(out) as bag:
        assert set(bag.topics) == set(pubs)
        for topic, info in bag.topics.items():
            assert info.message_count == len(sent[topic])
            assert info.type_hash.startswith('RIHS01_')
            assert info.offered_qos_profiles[0]['reliability'] == 'reliable'
            raw = list(bag.messages([topic]))
            assert [deserialize_message(m.data, classes[topic]) for m in raw] == sent[topic]
            decoded = [d for _, d in bag.decoded_messages([topic])]
            if topic == '/chatter':
                assert [d.data for d in decoded] == [m.data for m in sent[topic]]
            if topic == '/sim/fruit/nodes':
                assert [bytes(d.data) for d in decoded] == [bytes(m.data) for m in sent[topic]]
            logs = [m.log_time for m in raw]
            assert logs == sorted(logs)
            assert all(m.publish_time <= m.log_time for m in raw)
        assert bag.bag_metadata()['message_count'] == sum(len(v) for v in sent.values())


def test_ctrl_c_right_after_a_burst_still_writes_every_message_of_it(tmp_path):
    """A stop writes what was published before it: queued and in-flight messages too."""
    domain = _domain()
    out = tmp_path / 'burst.mcap'
    count = 300  # below the recorder's keep-last depth (1000)
    with ros_node(domain, 'burst_talker') as (node, _):
        pub = node.create_publisher(
            String, '/burst', QoSProfile(depth=count, reliability=ReliabilityPolicy.RELIABLE))
        recorder = cli(domain, tmp_path, 'record', '-o', str(out), '/burst', name='record')
        with recorder:
            wait_for(lambda: pub.get_subscription_count() > 0, what='the recorder to subscribe')
            wait_for(lambda: "recording '/burst'" in recorder.log(), what='recorder log')
            for i in range(count):
                pub.publish(String(data=f'burst {i:04d} ' + 'x' * 100_000))
            stop_cleanly(recorder)  # at once: no wait for the recorder to take them
    with BagReader(out) as bag:
        got = [deserialize_message(m.data, String).data[:10] for m in bag.messages(['/burst'])]
    assert got == [f'burst {i:04d}' for i in range(count)]


def test_all_picks_up_topics_that_appear_later_and_duration_ends_it(tmp_path):
    domain = _domain()
    out = tmp_path / 'all.mcap'
    with ros_node(domain, 'late_talker') as (node, _):
        recorder = cli(domain, tmp_path, 'record', '--all', '--duration', '30', '-o',
                       str(out), name='record_all')
        with recorder:
            first = node.create_publisher(String, '/first', 10)
            wait_for(lambda: first.get_subscription_count() > 0, what='/first subscribed')
            for i in range(5):
                first.publish(String(data=f'a{i}'))
            second = node.create_publisher(WrenchStamped, '/later/second', 10)
            wait_for(lambda: second.get_subscription_count() > 0,
                     what='/later/second subscribed')
            for i in range(7):
                second.publish(WrenchStamped())
            for pub in (first, second):
                pub.wait_for_all_acked(Duration(seconds=TIMEOUT))
            stop_cleanly(recorder)
    with BagReader(out) as bag:
        assert bag.topics['/first'].message_count == 5
        assert bag.topics['/later/second'].message_count == 7
        assert bag.topics['/later/second'].type == 'geometry_msgs/msg/WrenchStamped'
    # --duration alone ends a recording, with a properly closed file
    short = tmp_path / 'short.mcap'
    proc = cli(domain, tmp_path, 'record', '--all', '--duration', '1', '-o', str(short),
               name='record_short').start()
    proc.process.wait(TIMEOUT)
    assert proc.process.returncode == 0, proc.log()
    with BagReader(short):
        pass


def test_sigkill_loses_at_most_about_a_second(tmp_path):
    domain = _domain()
    out = tmp_path / 'killed.mcap'
    with ros_node(domain, 'steady_talker') as (node, _):
        pub = node.create_publisher(String, '/steady', QoSProfile(depth=100))
        recorder = cli(domain, tmp_path, 'record', '/steady', '--flush-interval', '0.5',
                       '-o', str(out), name='record_kill').start()
        try:
            wait_for(lambda: pub.get_subscription_count() > 0, what='recorder subscribed')
            sent_at = []
            start = time.monotonic()
            i = 0
            while time.monotonic() - start < 3.0:
                pub.publish(String(data=str(i)))
                sent_at.append(time.monotonic())
                i += 1
                time.sleep(0.005)
            killed_at = time.monotonic()
            recorder.process.send_signal(signal.SIGKILL)
            recorder.process.wait(TIMEOUT)
        finally:
            recorder.stop()
    fixed = tmp_path / 'fixed.mcap'
    report = recover(out, fixed)
    with BagReader(fixed) as bag:
        got = {int(deserialize_message(m.data, String).data) for m in bag.messages()}
    older = {k for k, t in enumerate(sent_at) if t < killed_at - 1.0}
    assert older, 'the test published nothing older than a second'
    assert older <= got, f'lost {len(older - got)} messages older than 1 s'
    assert report.messages == len(got)


def _synthetic_bag(path: Path) -> dict:
    """A 2 s recording: /a every 20 ms, /b every 50 ms, /latched once (transient local)."""
    latched = qos.default_profile(durability='transient_local', depth=1)
    best_effort = qos.default_profile(reliability='best_effort')
    t0 = 1_700_000_000_000_000_000
    written: dict[str, list] = {'/a': [], '/b': [], '/latched': []}
    with BagWriter(path) as bag:
        bag.add_topic('/a', 'std_msgs/msg/String')
        bag.add_topic('/b', 'geometry_msgs/msg/WrenchStamped',
                      offered_qos_profiles=[best_effort])
        bag.add_topic('/latched', 'std_msgs/msg/String', offered_qos_profiles=[latched])
        events = [(0, '/latched', String(data='config'))]
        events += [(k * 20_000_000, '/a', String(data=f'a{k}')) for k in range(100)]
        for k in range(40):
            w = WrenchStamped()
            w.wrench.force.z = float(k)
            events.append((k * 50_000_000 + 1, '/b', w))
        for t, topic, msg in sorted(events, key=lambda e: e[0]):
            data = serialize_message(msg)
            bag.write(topic, data, log_time=t0 + t)
            written[topic].append((t, data))
    return written


def test_replay_while_recording_reproduces_topics_counts_payloads_and_timing(tmp_path):
    domain = _domain()
    src = tmp_path / 'original.mcap'
    written = _synthetic_bag(src)
    out = tmp_path / 'replayed.mcap'
    recorder = cli(domain, tmp_path, 'record', '/a', '/b', '/latched', '-o', str(out),
                   name='record_replay')
    with recorder:
        replay = cli(domain, tmp_path, 'replay', str(src), '--wait-for-subscribers', '30',
                     name='replay')
        with replay:
            wait_for(lambda: recorder.log().count("recording '") == 3,
                     what='the recorder to subscribe to the replayed topics')
            replay.process.wait(TIMEOUT)
            assert replay.process.returncode == 0, replay.log()
        wait_for(lambda: out.exists(), what='the recording file')
        stop_cleanly(recorder)
    with BagReader(out) as bag:
        assert set(bag.topics) == set(written)
        for topic, items in written.items():
            got = list(bag.messages([topic]))
            assert len(got) == len(items), topic
            assert all(same_payload(m.data, d) for m, (_, d) in zip(got, items)), topic
        assert bag.topics['/b'].offered_qos_profiles[0]['reliability'] == 'best_effort'
        assert bag.topics['/latched'].offered_qos_profiles[0]['durability'] == \
            'transient_local'
        a_times = [m.log_time for m in bag.messages(['/a'])]
    span = (a_times[-1] - a_times[0]) / 1e9
    original = (written['/a'][-1][0] - written['/a'][0][0]) / 1e9
    assert abs(span - original) <= 0.1 * original, (span, original)
    gaps = sorted((b - a) / 1e9 for a, b in zip(a_times, a_times[1:]))
    assert abs(gaps[len(gaps) // 2] - 0.020) <= 0.002  # the median gap


def test_replay_options_rate_start_topics_remap_clock(tmp_path):
    domain = _domain()
    src = tmp_path / 'original.mcap'
    written = _synthetic_bag(src)
    out = tmp_path / 'fast.mcap'
    recorder = cli(domain, tmp_path, 'record', '/renamed', '/clock', '/b', '-o', str(out),
                   name='record_opts')
    with recorder:
        replay = cli(domain, tmp_path, 'replay', str(src), '--rate', '2', '--start', '1.0',
                     '--topics', '/a', '--remap', '/a:=/renamed', '--clock', '50',
                     '--wait-for-subscribers', '30', name='replay_opts')
        with replay:
            wait_for(lambda: recorder.log().count("recording '") == 2,
                     what='the recorder to subscribe')
            replay.process.wait(TIMEOUT)
            assert replay.process.returncode == 0, replay.log()
        stop_cleanly(recorder)
    with BagReader(out) as bag:
        assert '/b' not in bag.topics  # not selected with --topics
        expected = [d for t, d in written['/a'] if t >= 1_000_000_000]
        got = list(bag.messages(['/renamed']))
        assert len(got) == len(expected)
        assert all(same_payload(m.data, d) for m, d in zip(got, expected))
        span = (got[-1].log_time - got[0].log_time) / 1e9
        original = (written['/a'][-1][0] - 1_000_000_000) / 1e9 / 2.0
        assert abs(span - original) <= 0.1 * original + 0.02, (span, original)
        clocks = [deserialize_message(m.data, __import__('rosgraph_msgs.msg',
                  fromlist=['Clock']).Clock).clock for m in bag.messages(['/clock'])]
    stamps = [c.sec * 1_000_000_000 + c.nanosec for c in clocks]
    assert len(stamps) >= 10
    assert stamps == sorted(stamps)
    t0 = 1_700_000_000_000_000_000
    assert t0 + 1_000_000_000 <= stamps[0] and stamps[-1] <= t0 + 2_100_000_000


def test_replay_and_record_reject_bad_input(tmp_path):
    domain = _domain()
    bad = tmp_path / 'bad.mcap'
    bad.write_text('hello')
    good = tmp_path / 'good.mcap'
    _synthetic_bag(good)
    cases = [
        (['replay', str(bad)], 'not an MCAP file'),
        (['replay', str(good), '--topics', '/nope'], "no topic '/nope'"),
        (['replay', str(good), '--start', '99'], 'past the end'),
        (['record', '-o', str(good), '/a'], 'already exists'),
        (['record', '-o', str(tmp_path / 'x.mcap')], 'give topics'),
    ]
    for k, (args, text) in enumerate(cases):
        proc = cli(domain, tmp_path, *args, name=f'bad{k}').start()
        proc.process.wait(TIMEOUT)
        log = proc.log()
        assert proc.process.returncode == 2, log
        assert 'error: ' in log and text in log and 'Traceback' not in log, log


def test_replay_loop_repeats_until_interrupted(tmp_path):
    domain = _domain()
    src = tmp_path / 'short.mcap'
    with BagWriter(src) as bag:
        bag.add_topic('/tick', 'std_msgs/msg/String')
        for k in range(5):
            bag.write('/tick', serialize_message(String(data=f't{k}')),
                      log_time=1_000_000_000 + k * 20_000_000)
    with ros_node(domain, 'loop_listener') as (node, _):
        got: list[str] = []
        node.create_subscription(String, '/tick', lambda m: got.append(m.data), 100)
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        replay = cli(domain, tmp_path, 'replay', str(src), '--loop',
                     '--wait-for-subscribers', '30', name='replay_loop')
        with replay:
            deadline = time.monotonic() + TIMEOUT
            while len(got) < 12 and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            assert len(got) >= 12, replay.log()
            assert replay.running  # still looping
            stop_cleanly(replay)
        assert 'loops' in replay.log()
        executor.shutdown()
    assert got[:10] == [f't{k}' for k in range(5)] * 2


def test_replay_clock_drives_a_use_sim_time_node(tmp_path):
    domain = _domain()
    src = tmp_path / 'original.mcap'
    _synthetic_bag(src)
    t0 = 1_700_000_000_000_000_000
    with ros_node(domain, 'sim_time_listener') as (node, _):
        node.set_parameters([rclpy.parameter.Parameter('use_sim_time', value=True)])
        executor = SingleThreadedExecutor(context=node.context)
        executor.add_node(node)
        seen: list[int] = []
        replay = cli(domain, tmp_path, 'replay', str(src), '--clock', '100', '--topics', '/a',
                     name='replay_clock')
        with replay:
            deadline = time.monotonic() + TIMEOUT
            while replay.running and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.02)
                seen.append(node.get_clock().now().nanoseconds)
            assert replay.process.wait(TIMEOUT) == 0, replay.log()
        executor.shutdown()
    followed = [t for t in seen if t >= t0]
    assert len(followed) > 10, 'the node never followed the replayed /clock'
    assert followed == sorted(followed)
    assert followed[-1] - followed[0] >= 1_000_000_000  # most of the 2 s recording
    assert followed[-1] <= t0 + 2_100_000_000


def test_record_a_split_bag_folder_by_pattern_and_replay_it(tmp_path):
    from rosbags.rosbag2 import Reader as RosbagsReader

    domain = _domain()
    out = tmp_path / 'patterns'
    with ros_node(domain, 'pattern_talker') as (node, _):
        qos_profile = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
        pubs = {t: node.create_publisher(String, t, qos_profile)
                for t in ('/sim/a', '/sim/b', '/other')}
        recorder = cli(domain, tmp_path, 'record', '-o', str(out), '-e', '/sim/.*',
                       '-x', '.*/b', '--max-bag-duration', '0.2', name='record_patterns')
        with recorder:
            wait_for(lambda: pubs['/sim/a'].get_subscription_count() > 0,
                     what='/sim/a subscribed')
            for i in range(60):
                for topic, pub in pubs.items():
                    pub.publish(String(data=f'{topic} {i}'))
                time.sleep(0.02)
            for pub in pubs.values():
                pub.wait_for_all_acked(Duration(seconds=TIMEOUT))
            wait_for(lambda: "recording '/sim/a'" in recorder.log(), what='recorder log')
            stop_cleanly(recorder)
    log = recorder.log()
    assert "recording '/sim/b'" not in log and "recording '/other'" not in log, log
    files = sorted(p.name for p in out.glob('*.mcap'))
    assert (out / 'metadata.yaml').is_file()
    with BagReader(out) as bag:
        assert set(bag.topics) == {'/sim/a'} and bag.message_count == 60
        sent = [m.data for m in bag.messages()]
    with RosbagsReader(out) as reader:
        stamped = [(log_time, bytes(raw)) for _, log_time, raw in reader.messages()]
    assert [raw for _, raw in stamped] == sent
    # a new file once a message is logged more than 0.2 s after its file's first (the
    # recorder's receive times: a loaded machine may deliver the 1.2 s of sending in
    # bursts, so the count is the one these times call for)
    expected, start = 1, stamped[0][0]
    for log_time, _ in stamped:
        if log_time - start > 200_000_000:
            expected, start = expected + 1, log_time
    assert len(files) == expected >= 2, files

    # the folder replays like a file: every message, in order
    copy = tmp_path / 'copy'
    domain = _domain()
    recorder = cli(domain, tmp_path, 'record', '/sim/a', '-o', str(copy), name='record_copy')
    with recorder:
        replay = cli(domain, tmp_path, 'replay', str(out), '--wait-for-subscribers', '30',
                     name='replay_folder')
        with replay:
            replay.process.wait(TIMEOUT)
            assert replay.process.returncode == 0, replay.log()
        wait_for(lambda: copy.exists(), what='the copy')
        stop_cleanly(recorder)
    with BagReader(copy) as bag:
        got = [m.data for m in bag.messages()]
    assert len(got) == len(sent) and all(same_payload(g, s) for g, s in zip(got, sent))
