"""The Foxglove live view end to end: the node's and replay's WebSocket, read by a plain
client (``view_client``) that decodes every channel with the schema it advertises."""
from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import websockets
from rclpy.serialization import deserialize_message
from rosgraph_msgs.msg import Clock

from gripper_sim.configuration import load_config
from gripper_sim.convert import messages
from gripper_sim.recording.offline import SimRecorder
from gripper_sim.recording.reader import BagReader
from gripper_sim.recording.recorder import import_message_class
from gripper_sim.recording.schemas import message_definition
from gripper_sim.ros.process import RosProcess, node_process, ros_environment
from gripper_sim.view import ViewError
from gripper_sim.view.foxglove import MESSAGE_BACKLOG, FoxgloveView, NodeFeed, node_topics
from gripper_sim.view.layout import layout_json
from gripper_sim.workflows.factory import make_simulation
from view_client import SUBPROTOCOLS, capture, protobuf_decoder, stall

pytestmark = [pytest.mark.ros]

NODE_TOPICS = {name for name, _ in node_topics('gripper_sim', '/').values()}
SCENE = '/gripper_sim/scene'


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def decode_all(seen) -> dict[str, list]:
    """Every message of every channel, decoded with the channel's advertised schema."""
    decoded = {}
    for channel in seen.channels.values():
        payloads = [payload for _, payload in seen.messages.get(channel['topic'], [])]
        if channel['encoding'] == 'cdr':
            assert channel['schemaEncoding'] == 'ros2msg'
            assert channel['schema'] == message_definition(channel['schemaName'])
            cls = import_message_class(channel['schemaName'])
            decoded[channel['topic']] = [deserialize_message(p, cls) for p in payloads]
        else:
            decode = protobuf_decoder(channel)
            decoded[channel['topic']] = [decode(p) for p in payloads]
    return decoded


def check_scene(scenes: list[dict]) -> None:
    ids = {entity['id'] for scene in scenes for entity in scene['entities']}
    assert {'fruit_outline/0', 'jaws/0', 'jaws/1', 'table/0', 'legend/pressure',
            'legend/state'} <= ids
    outline = next(e for s in scenes for e in s['entities'] if e['id'] == 'fruit_outline/0')
    line = outline['lines'][0]
    assert len(line['points']) > 10 and len(line['colors']) == len(line['points'])
    assert outline['frame_id'] == 'world'


@pytest.fixture(scope='module')
def node_view(tmp_path_factory, new_domain_id):
    port = free_port()
    log = tmp_path_factory.mktemp('view') / 'node.log'
    process = node_process({'real_time_factor': 0.0, 'foxglove_port': port},
                           env=ros_environment(new_domain_id()), log_path=log).start()
    try:
        assert process.wait_for_log('Foxglove live view on', timeout=120), process.log()
        yield process, port
    finally:
        code = process.stop()
        assert 'Traceback' not in process.log(), process.log()
        assert code == 0, process.log()


@pytest.mark.slow
def test_the_node_serves_every_topic_and_the_scene_decodable_by_schema(node_view):
    process, port = node_view
    seen = capture(f'ws://127.0.0.1:{port}', NODE_TOPICS | {SCENE}, per_topic=3)
    assert 'time' in seen.server_info['capabilities']
    # and the latched /tf_static and robot_description (test_recording_audit.py)
    assert {c['topic'] for c in seen.channels.values()} == \
        NODE_TOPICS | {SCENE} | {'/tf_static', '/robot_description'}
    decoded = decode_all(seen)
    states = decoded['/gripper_sim/fruit/state']
    assert all(s.dimension == 2 and s.node_count > 10 for s in states)
    # log time = the step's sim time = the header stamp
    stamps = [stamp for stamp, _ in seen.messages['/gripper_sim/fruit/state']]
    assert stamps == [s.header.stamp.sec * 10 ** 9 + s.header.stamp.nanosec for s in states]
    assert stamps == sorted(stamps)
    assert {m.ns for a in decoded['/gripper_sim/markers'] for m in a.markers} >= \
        {'fruit_outline', 'jaws', 'table'}
    assert decoded['/joint_states'][0].name == list(messages.JOINT_NAMES)
    check_scene(decoded[SCENE])
    assert process.running


@pytest.mark.slow
def test_a_port_in_use_is_a_warning_and_the_node_runs_on(tmp_path, new_domain_id):
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        process = node_process({'real_time_factor': 0.0, 'foxglove_port': port},
                               env=ros_environment(new_domain_id()),
                               log_path=tmp_path / 'node.log').start()
        try:
            assert process.wait_for_log('running without the live view', timeout=120), \
                process.log()
            assert process.wait_for_log('ready:', timeout=60), process.log()
            text = process.log()
            assert f'cannot serve the Foxglove live view on 127.0.0.1:{port}' in text
            assert 'Address already in use' in text and 'foxglove_port, 0 = off' in text
            assert process.running
        finally:
            code = process.stop()
    assert code == 0 and 'Traceback' not in process.log(), process.log()


def test_a_view_on_a_taken_port_or_a_foreign_address_raises_a_view_error():
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(ViewError, match=f'127.0.0.1:{port}: .*in use.*a free port'):
            FoxgloveView({'/clock': 'rosgraph_msgs/msg/Clock'}, port=port)
    # 192.0.2.1: TEST-NET-1 (RFC 5737), never an address of this machine
    with pytest.raises(ViewError, match='on 192.0.2.1:0: .*an address of this machine'):
        FoxgloveView({'/clock': 'rosgraph_msgs/msg/Clock'}, host='192.0.2.1', port=0)


@pytest.fixture(scope='module')
def recording(tmp_path_factory):
    """A short 2D squeeze recorded offline, every step."""
    path = tmp_path_factory.mktemp('rec') / 'squeeze.mcap'
    config = load_config(overrides=['fruit.nodes=32'])
    sim = make_simulation(config)
    with SimRecorder(path, config, initial=sim.last) as recorder:
        sim.add_observer(recorder.on_step)
        sim.command_force(3.0)
        for _ in range(300):
            sim.step()
    return path


@contextlib.contextmanager
def looped_replay(recording, domain_id: int, tmp_path):
    """A ``gripper-sim replay`` of ``recording`` at rate 5, looping, served to Foxglove;
    yields its view's URL, then stops it and checks it ended cleanly."""
    port = free_port()
    replay = RosProcess('gripper_sim.cli.main',
                        ['replay', str(recording), '--loop', '--rate', '5',
                         '--foxglove', str(port)],
                        env=ros_environment(domain_id), log_path=tmp_path / 'replay.log')
    replay.start()
    try:
        assert replay.wait_for_log('Foxglove view of the replay on', timeout=120), replay.log()
        yield f'ws://127.0.0.1:{port}'
    finally:
        code = replay.stop()   # SIGINT: the replay ends its loop and exits cleanly
    assert code == 0 and 'Traceback' not in replay.log(), replay.log()


@pytest.mark.slow
def test_replay_serves_the_recording_and_its_scene(recording, new_domain_id, tmp_path):
    with BagReader(recording) as bag:
        recorded = {name: [m.data for m in bag.messages([name])] for name in bag.topics}
    with looped_replay(recording, new_domain_id(), tmp_path) as url:
        seen = capture(url, set(recorded) | {SCENE}, per_topic=3)
    assert {c['topic'] for c in seen.channels.values()} == set(recorded) | {SCENE}
    for topic, payloads in seen.messages.items():
        if topic != SCENE:   # the recorded bytes, as they are
            assert all(payload in recorded[topic] for _, payload in payloads), topic
    decoded = decode_all(seen)
    check_scene(decoded[SCENE])
    labels = [t['text'] for s in decoded[SCENE] for e in s['entities'] for t in e['texts']]
    assert '>= 260 kPa (bruise)' in labels   # the apple's, from the stored configuration


@pytest.mark.slow
def test_a_client_busy_for_seconds_stays_connected_to_a_fast_replay(recording, new_domain_id,
                                                                    tmp_path):
    """A fast replay (rate 5, looping: thousands of messages a second) and a client that
    reads nothing for 4 s after subscribing (a busy viewer): the server drops old data
    for it but keeps it connected. With the data's time broadcast once per message its
    never-dropped control queue filled and the server closed the connection."""
    with looped_replay(recording, new_domain_id(), tmp_path) as url:
        # past what the socket's buffers held during the stall (~8000 frames)
        seen = capture(url, {'/gripper_sim/fruit/state'}, per_topic=5000, stall=4.0)
    assert len(seen.messages['/gripper_sim/fruit/state']) >= 5000


@pytest.mark.slow
def test_replay_on_a_taken_port_is_an_error(recording, new_domain_id):
    with socket.socket() as taken:
        taken.bind(('127.0.0.1', 0))
        taken.listen()
        port = taken.getsockname()[1]
        run = subprocess.run([sys.executable, '-m', 'gripper_sim.cli.main', 'replay',
                              str(recording), '--foxglove', str(port)],
                             env=ros_environment(new_domain_id()), capture_output=True,
                             text=True, timeout=300)
    assert run.returncode == 2, run.stderr
    assert run.stderr.startswith(
        f'error: cannot serve the Foxglove live view on 127.0.0.1:{port}: '), run.stderr
    assert 'Traceback' not in run.stderr


def test_the_shipped_layout_is_the_built_one_and_names_our_topics():
    shipped = Path(__file__).resolve().parent.parent / 'config/foxglove/gripper_sim_layout.json'
    assert shipped.read_text() == layout_json()
    text = json.dumps(json.loads(shipped.read_text()))
    for path in (SCENE, '/gripper_sim/fruit/state.grip_force',
                 '/gripper_sim/fruit/state.compression',
                 '/gripper_sim/fruit/state.slip_distance'):
        assert f'"{path}"' in text
    panels = {p for p in ('ThreeDee', 'Plot', 'RawMessages') if f'"panelType": "{p}"' in text}
    assert panels == {'ThreeDee', 'Plot', 'RawMessages'}


class PublishingNode:
    """Stands in for the node: publishes one batch to its publish observers on demand."""

    def __init__(self, batch):
        self.batch = batch
        self.observers = []

    def add_publish_observer(self, callback):
        self.observers.append(callback)

    def remove_publish_observer(self, callback):
        self.observers.remove(callback)

    def publish(self, stamp_ns):
        for observer in list(self.observers):
            observer(self.batch, stamp_ns)


def test_the_node_is_observed_only_while_a_client_subscribes():
    config = load_config(overrides=['fruit.nodes=32'])
    sim = make_simulation(config)
    batch = messages.build_messages(sim.last, config)
    node = PublishingNode(batch)
    topics = node_topics('gripper_sim', '/')
    feed = NodeFeed(node, {suffix: name for suffix, (name, _) in topics.items()})
    feed.view = FoxgloveView({name: kind for name, kind in topics.values()}, port=0,
                             on_watched=feed.watched)
    stop = threading.Event()

    def publish():
        stamp = 0
        while not stop.wait(0.01):
            stamp += 10 ** 7
            node.publish(stamp)
    publisher = threading.Thread(target=publish)
    try:
        assert node.observers == []   # nobody watches: the node builds nothing for it
        publisher.start()
        seen = capture(feed.view.url, {'/gripper_sim/fruit/state'}, per_topic=2)
        assert len(seen.messages['/gripper_sim/fruit/state']) >= 2
        # the client has gone: the observer is removed again
        deadline = time.monotonic() + 60.0
        while node.observers and time.monotonic() < deadline:
            time.sleep(0.01)
        assert node.observers == []
    finally:
        stop.set()
        publisher.join()
        feed.view.close()


def events(frames: list) -> list:
    """'serverInfo' for each serverInfo and the time of each Message Data frame."""
    out = []
    for frame in frames:
        if isinstance(frame, str) and json.loads(frame)['op'] == 'serverInfo':
            out.append('serverInfo')
        elif isinstance(frame, bytes) and frame[0] == 1:
            out.append(struct.unpack_from('<Q', frame, 5)[0])
    return out


def test_time_going_back_starts_a_new_session():
    """A reset (sim time back to 0): clients are told to drop the old run (a new
    serverInfo with a new session id; it travels apart from the data, so it may
    arrive just after the first message of the new run)."""
    view = FoxgloveView({'/clock': 'rosgraph_msgs/msg/Clock'}, port=0)

    async def run() -> list:
        async with websockets.connect(view.url, subprotocols=SUBPROTOCOLS,
                                      proxy=None) as socket:
            frames = [await socket.recv(), await socket.recv()]   # serverInfo, advertise
            channel = json.loads(frames[1])['channels'][0]['id']
            await socket.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 0, 'channelId': channel}]}))
            while not view.channels['/clock'].has_sinks():
                await asyncio.sleep(0.01)
            for stamp in (10, 20, 5):
                view.log_messages({'/clock': Clock()}, stamp)
            while events(frames).count('serverInfo') < 2 or 5 not in events(frames):
                frames.append(await socket.recv())
            return frames

    try:
        frames = asyncio.run(asyncio.wait_for(run(), 120))
    finally:
        view.close()
    assert [e for e in events(frames) if e != 'serverInfo'] == [10, 20, 5]
    sessions = [json.loads(f)['sessionId'] for f in frames
                if isinstance(f, str) and json.loads(f)['op'] == 'serverInfo']
    assert len(sessions) == 2 and sessions[0] != sessions[1]


def test_a_failing_view_stops_feeding_and_never_raises_into_the_physics():
    class Logger:
        def __init__(self):
            self.errors = []

        def error(self, text):
            self.errors.append(text)

    class Node(PublishingNode):
        logger = Logger()

        def get_logger(self):
            return self.logger

    class BrokenView:
        def log_messages(self, batch, stamp_ns):
            raise RuntimeError('the server went away')

    node = Node({'fruit/state': None})
    feed = NodeFeed(node, {'fruit/state': '/gripper_sim/fruit/state'})
    feed.view = BrokenView()
    feed.watched(True)
    node.publish(1)   # must not raise
    node.publish(2)
    assert node.observers == [] and feed.view is None
    assert node.logger.errors == ['Foxglove live view stopped: RuntimeError: the server '
                                  'went away']


def test_a_damaged_recorded_message_leaves_the_scene_and_the_replay_running(caplog):
    """``replay --foxglove`` hands every recorded message to the view; one whose bytes
    are not its type (a damaged recording) raised rclpy's RMWError out of the replay
    (a traceback, the replay ended) while a client watched the scene."""
    from visualization_msgs.msg import MarkerArray
    from rclpy.serialization import serialize_message

    markers, state = '/gripper_sim/markers', '/gripper_sim/fruit/state'
    view = FoxgloveView({markers: 'visualization_msgs/msg/MarkerArray',
                         state: 'gripper_sim_interfaces/msg/FruitState'}, port=0)

    async def watch_the_scene() -> None:
        async with websockets.connect(view.url, subprotocols=SUBPROTOCOLS,
                                      proxy=None) as socket:
            channels = []
            while view.scene_topic not in [c['topic'] for c in channels]:
                message = json.loads(await socket.recv())
                channels += message.get('channels', [])
            scene = next(c['id'] for c in channels if c['topic'] == view.scene_topic)
            await socket.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': 0, 'channelId': scene}]}))
            while not view.scene_channel.has_sinks():
                await asyncio.sleep(0.01)
            damaged = b'\x00\x01\x00\x00\xff\xff\xff\x7f'
            view.log_cdr(state, damaged, 10)
            view.log_cdr(markers, damaged, 20)
            view.log_cdr(markers, damaged, 30)
            view.log_cdr(markers, serialize_message(MarkerArray()), 40)

    try:
        with caplog.at_level('WARNING', logger='gripper_sim.view.foxglove'):
            asyncio.run(asyncio.wait_for(watch_the_scene(), 120))
    finally:
        view.close()
    assert view.undecodable == 3 and view.scenes == 1
    warnings = [r.getMessage() for r in caplog.records]
    assert len(warnings) == 2   # once per topic
    assert warnings[1].startswith(f'live view: a {markers} message at 0.000 s is not a '
                                  'visualization_msgs/msg/MarkerArray (')


@pytest.mark.parametrize('host, shown', [('127.0.0.1\n', "'127.0.0.1\\n'"), ('', "''"),
                                         ('a b', "'a b'")])
def test_a_bad_address_is_named_in_one_line(host, shown):
    """``foxglove_address`` with a newline gave a two-line warning; an empty one read
    'on :8765'."""
    with pytest.raises(ViewError) as caught:
        FoxgloveView({'/clock': 'rosgraph_msgs/msg/Clock'}, host=host, port=0)
    message = str(caught.value)
    assert '\n' not in message
    assert message.startswith(f'cannot serve the Foxglove live view on {shown}:0: ')


def drop_warnings(caplog) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.name == 'gripper_sim.view.foxglove' and 'dropped Foxglove client' in
            r.getMessage()]


def test_a_client_that_stops_reading_is_dropped_with_one_warning_naming_it(caplog):
    """The server disconnects a client that stopped reading once its queue of control
    messages (time, session) is full; that used to leave no trace in the log, so a
    user whose Foxglove froze could not tell why. One warning names the client and the
    queue; a client that closes, or one still there when the view stops, is no drop."""
    view = FoxgloveView({'/big': 'std_msgs/msg/String'}, host='127.0.0.1', port=0)
    url = view.url
    subscribed, release = threading.Event(), threading.Event()
    seen = {}
    closing = False
    client = threading.Thread(target=lambda: seen.update(
        stalled=stall(view.url, '/big', subscribed, release)))
    try:
        with caplog.at_level('WARNING', logger='gripper_sim.view.foxglove'):
            client.start()
            assert subscribed.wait(120)
            while not view.channels['/big'].has_sinks():
                time.sleep(0.01)
            # fill the socket's buffers with data (32 MB; queued data is dropped, the
            # oldest first), then its queue of time messages, 8 times over
            payload = bytes(32_000)
            for stamp in range(1, 8 * MESSAGE_BACKLOG + 1):
                view.log_cdr('/big', payload, stamp)
                view.server.broadcast_time(stamp)
            # the server lets the connection go once the client reads again (it
            # finds itself disconnected) or the connection breaks
            release.set()
            client.join(120)
            deadline = time.monotonic() + 60.0
            while not drop_warnings(caplog) and time.monotonic() < deadline:
                time.sleep(0.01)
            # a client that closes its connection, and one still there at close()
            capture(view.url, {'/big'}, per_topic=0)
            there, go_on = threading.Event(), threading.Event()
            kept = threading.Thread(target=lambda: seen.update(
                kept=stall(view.url, '/big', there, go_on)))
            kept.start()
            assert there.wait(120)
            closing = True
            view.close()
            go_on.set()
            kept.join(120)
    finally:
        release.set()
        if not closing:
            view.close()
    assert seen['kept'].closed
    stalled = seen['stalled']
    assert stalled.closed
    assert any('message backlog on the server is full' in text for text in stalled.texts)
    warnings = drop_warnings(caplog)
    assert len(warnings) == 1, warnings
    assert warnings[0].startswith(f'live view on {url}: dropped Foxglove client '
                                  f'{stalled.address}: it fell more than '
                                  f'{MESSAGE_BACKLOG} messages behind (')
    assert '\n' not in warnings[0]
