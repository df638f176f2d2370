"""What ``record`` writes after a stop (Ctrl-C, SIGTERM, the end of --duration): every
message published before the stop, however long a steadily publishing topic stalls,
while a silent or sparse topic holds the stop for no more than its short quiet time.

Most tests run the recorder against a fake graph with a fake clock (the recorder module's
``time``), so stalls of any length are exact and nothing depends on the machine's load;
one runs it on a real rclpy graph (loopback), the recorder held up as a busy machine
would.
"""
from __future__ import annotations

import os
import threading
import time
from types import SimpleNamespace

import pytest

import rclpy

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from gripper_sim.recording import recorder as recorder_mod  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.recording.recorder import (  # noqa: E402
    STEADY_QUIET, STOP_CEILING, STOP_QUIET, STOP_QUIET_MAX, Recorder, finish_after_stop)
from gripper_sim.recording.writer import BagWriter  # noqa: E402
from gripper_sim.ros.process import free_domain_id  # noqa: E402
from ros_client import isolated_context, spin_until  # noqa: E402

TIMEOUT = 60.0  # s: generous, for a slow busy machine
MS = 1_000_000  # ns
WALL = 1_700_000_000 * 10**9  # ns: the fake system clock at fake monotonic 0


# ---------------------------------------------------------------- a fake graph and clock
class FakeClock:
    """Monotonic and system time in step, in integer ns (exact, no float drift)."""

    def __init__(self):
        self.ns = 0

    def monotonic(self) -> float:
        return self.ns * 1e-9

    def time_ns(self) -> int:
        return WALL + self.ns


class FakeWriter:
    flush_interval = 1.0

    def __init__(self):
        self.written: list[tuple[str, bytes, int]] = []

    def flush_if_due(self) -> None:
        pass

    def add_topic(self, topic, type_name, **_kwargs) -> None:
        pass

    def write(self, topic, data, *, log_time, publish_time) -> None:
        self.written.append((topic, data, publish_time))

    def numbers(self, topic: str) -> list[int]:
        return [int(data) for t, data, _ in self.written if t == topic]


class FakeNode:
    """The graph: ``topics`` with one publisher each; subscriptions keep their callback."""

    def __init__(self, topics):
        self.topics = list(topics)
        self.callbacks = {}
        self.publishers = {topic: 1 for topic in self.topics}

    def create_timer(self, _period, _callback):
        return object()

    def destroy_timer(self, _timer):
        pass

    def get_topic_names_and_types(self):
        return [(topic, ['std_msgs/msg/Header']) for topic in self.topics]

    def get_publishers_info_by_topic(self, _topic):
        return [SimpleNamespace(topic_type='std_msgs/msg/Header', topic_type_hash='INVALID',
                                qos_profile=QoSProfile(
                                    depth=10, reliability=ReliabilityPolicy.RELIABLE))]

    def count_publishers(self, topic):
        return self.publishers[topic]

    def create_subscription(self, _msg_class, topic, callback, _qos, **_kwargs):
        self.callbacks[topic] = callback
        return SimpleNamespace()  # no handle: the recorder takes one message a callback

    def destroy_subscription(self, _sub):
        pass

    def get_logger(self):
        return SimpleNamespace(info=lambda *_: None, warning=lambda *_: None)


class FakeExecutor:
    """Each ``spin_once`` moves the clock on by its timeout, then delivers every message
    due by then (as the recorder's subscription callbacks do)."""

    def __init__(self, clock: FakeClock, node: FakeNode):
        self.clock = clock
        self.node = node
        self.due: list[tuple[int, int, str, int]] = []  # arrival ns, publish ns, topic, n
        self.counts: dict[str, int] = {}

    def publish(self, topic: str, published_ms: int, arrives_ms: int) -> int:
        """Message ``n`` (its payload) of ``topic``, published and arriving then (ms)."""
        number = self.counts.get(topic, 0)
        self.counts[topic] = number + 1
        self.due.append((arrives_ms * MS, published_ms * MS, topic, number))
        self.due.sort()
        return number

    def deliver_due(self) -> None:
        while self.due and self.due[0][0] <= self.clock.ns:
            arrival, published, topic, number = self.due.pop(0)
            self.node.callbacks[topic](str(number).encode(), {
                'source_timestamp': WALL + published, 'received_timestamp': WALL + arrival,
                'publication_sequence_number': number + 1})

    def run_until(self, ms: int) -> None:
        """Time passes while the recorder keeps up (1 ms steps)."""
        while self.clock.ns < ms * MS:
            self.clock.ns += MS
            self.deliver_due()

    def spin_once(self, timeout_sec: float) -> None:
        self.clock.ns += round(timeout_sec * 1e9)
        self.deliver_due()


@pytest.fixture
def world(monkeypatch):
    """``build(*topics)``: (clock, node, executor, recorder, writer) on those topics, a
    new clock at 0 each time."""
    def build(*topics: str):
        clock = FakeClock()
        monkeypatch.setattr(recorder_mod, 'time', SimpleNamespace(
            monotonic=clock.monotonic, time_ns=clock.time_ns))
        node = FakeNode(topics)
        writer = FakeWriter()
        rec = Recorder(node, writer, topics=topics)
        assert rec.subscribed == sorted(topics)
        return clock, node, FakeExecutor(clock, node), rec, writer
    return build


def steady(executor: FakeExecutor, topic: str, start_ms: int, end_ms: int, *,
           period_ms: int = 10, latency_ms: int = 2, stall=None) -> list[int]:
    """``topic`` published every ``period_ms`` in [start, end); each arrives
    ``latency_ms`` later, or at ``stall(published_ms)`` if that gives a time (ms).
    Returns their numbers."""
    numbers = []
    for published in range(start_ms, end_ms, period_ms):
        arrives = published + latency_ms
        if stall is not None and stall(published) is not None:
            arrives = stall(published)
        numbers.append(executor.publish(topic, published, arrives))
    return numbers


def finish(clock, executor, rec) -> float:
    """Run ``finish_after_stop`` now; the (fake) seconds it took."""
    start = clock.ns
    finish_after_stop(executor, rec)
    return (clock.ns - start) * 1e-9


# ---------------------------------------------------------------- the rule
def test_quiet_time_scales_with_a_topics_gaps_within_its_bounds(world):
    clock, _node, executor, rec, _writer = world('/fast', '/five_hz', '/slow', '/latched')
    steady(executor, '/fast', 0, 3000, period_ms=10)
    steady(executor, '/five_hz', 0, 3000, period_ms=200)
    steady(executor, '/slow', 0, 3000, period_ms=500)
    executor.publish('/latched', 5, 6)
    executor.run_until(3000)
    assert rec.quiet_time('/fast') == STOP_QUIET          # 4 x 10 ms, raised to the floor
    assert rec.quiet_time('/five_hz') == pytest.approx(0.8)  # 4 x 200 ms
    assert rec.quiet_time('/slow') == STOP_QUIET_MAX      # 4 x 500 ms, capped
    assert rec.quiet_time('/latched') == STOP_QUIET       # one message: no gap known
    stop = clock.monotonic()
    assert rec.steady('/fast', stop) and rec.steady('/five_hz', stop)
    assert not rec.steady('/latched', stop)
    # the same topics long after they fell silent: no longer steady
    assert not rec.steady('/fast', stop + 10) and not rec.steady('/five_hz', stop + 10)


def test_a_steady_topic_stalled_after_the_stop_still_delivers_what_was_published_before(
        world, capsys):
    # /joint_states at 100 Hz; from 970 ms on its messages are held up until 1.6 s
    # (0.6 s after the stop at 1 s), those published before the stop among them
    clock, _node, executor, rec, writer = world('/joint_states')
    held = steady(executor, '/joint_states', 0, 1000,
                  stall=lambda published: 1600 if published >= 970 else None)
    steady(executor, '/joint_states', 1000, 2000, stall=lambda published: max(1600, published + 2))
    executor.run_until(1000)
    assert writer.numbers('/joint_states') == held[:-3]  # the last three still on the way
    took = finish(clock, executor, rec)
    assert writer.numbers('/joint_states')[:len(held)] == held
    assert 0.6 <= took < 1.0
    assert 'some may not have arrived' not in capsys.readouterr().err


def test_a_topic_silent_long_before_the_stop_holds_it_only_its_short_quiet_time(world, capsys):
    clock, _node, executor, rec, writer = world('/fruit_state', '/latched', '/five_hz')
    steady(executor, '/fruit_state', 0, 1000)                   # paused at 1 s
    steady(executor, '/five_hz', 0, 1000, period_ms=200)        # ended at 1 s
    executor.publish('/latched', 0, 1)
    executor.run_until(11_000)                                  # the stop 10 s later
    took = finish(clock, executor, rec)
    # the longest quiet time here is /five_hz's 0.8 s; one 50 ms spin of slack
    assert took <= rec.quiet_time('/five_hz') + 0.05 + 1e-9
    assert took <= STOP_QUIET_MAX + 0.05
    assert 'some may not have arrived' not in capsys.readouterr().err
    # and a fast one alone: the floor
    clock, _node, executor, rec, writer = world('/fast_only')
    steady(executor, '/fast_only', 0, 1000)
    executor.run_until(11_000)
    assert finish(clock, executor, rec) <= STOP_QUIET + 0.05 + 1e-9


def test_a_steady_topic_whose_publisher_paused_at_the_stop_holds_it_its_steady_quiet(
        world, capsys):
    # e.g. the node paused just before the recorder is stopped: nothing more comes, and
    # nothing was lost, so no warning
    clock, _node, executor, rec, writer = world('/joint_states')
    sent = steady(executor, '/joint_states', 0, 1000)           # the last at 990 ms
    executor.run_until(1000)
    took = finish(clock, executor, rec)
    assert writer.numbers('/joint_states') == sent
    assert STEADY_QUIET <= took < STEADY_QUIET + 0.2
    assert 'some may not have arrived' not in capsys.readouterr().err


def test_a_topic_still_delivering_old_messages_at_the_ceiling_is_warned_of(world, capsys):
    # messages published before the stop keep arriving, late, for longer than the ceiling
    clock, _node, executor, rec, writer = world('/joint_states')
    steady(executor, '/joint_states', 0, 1000,
           stall=lambda published: None if published < 900 else 1000 + 60 * (published - 900))
    executor.run_until(1000)
    took = finish(clock, executor, rec)
    assert STOP_CEILING <= took < STOP_CEILING + 0.2
    assert 'some may not have arrived' in capsys.readouterr().err


def test_a_steady_topic_whose_publisher_left_the_graph_holds_the_stop_its_quiet_time(
        world, capsys):
    # e.g. the node stopped by the same Ctrl-C as the recorder
    clock, node, executor, rec, writer = world('/joint_states')
    sent = steady(executor, '/joint_states', 0, 1000)
    executor.run_until(1000)
    node.publishers['/joint_states'] = 0
    took = finish(clock, executor, rec)
    assert writer.numbers('/joint_states') == sent
    assert took <= STOP_QUIET + 0.05 + 1e-9
    assert 'some may not have arrived' not in capsys.readouterr().err


def test_a_message_delivered_after_the_stop_makes_a_held_up_topic_steady(world):
    # the recorder itself was held up 0.5 s before it saw the stop: its topics look
    # silent at the stop, until what queued meanwhile arrives; then it waits for the rest
    clock, _node, executor, rec, writer = world('/joint_states')
    held = steady(executor, '/joint_states', 0, 1500, stall=lambda published: (
        1520 if 1000 <= published < 1200 else 2200 if published >= 1200 else None))
    steady(executor, '/joint_states', 1500, 2500, stall=lambda published: 2200)
    executor.run_until(1500)
    finish(clock, executor, rec)
    assert writer.numbers('/joint_states')[:len(held)] == held


# ---------------------------------------------------------------- ROS
class HeldUpExecutor:
    """A real executor that takes nothing for ``hold`` s after its first ``spin_once``
    (the recorder starved on a busy machine while its messages wait in the queue)."""

    def __init__(self, executor, hold: float):
        self.executor = executor
        self.hold = hold
        self.started: float | None = None

    def spin_once(self, timeout_sec: float) -> None:
        if self.started is None:
            self.started = time.monotonic()
        if time.monotonic() - self.started < self.hold:
            time.sleep(timeout_sec)
            return
        self.executor.spin_once(timeout_sec=timeout_sec)


@pytest.mark.ros
def test_a_steady_ros_topic_held_up_across_the_stop_is_recorded_whole(tmp_path):
    topic = '/stop_test'
    with isolated_context(free_domain_id(os.getpid())) as context:
        node = rclpy.create_node('stop_recorder', context=context)
        talker = rclpy.create_node('stop_talker', context=context)
        pub = talker.create_publisher(Header, topic, QoSProfile(
            depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        writer = BagWriter(tmp_path / 'stop.mcap')
        writer.open()
        rec = Recorder(node, writer, topics=[topic])
        published = [0]
        running = threading.Event()
        running.set()

        def talk() -> None:  # 100 Hz until told to stop
            while running.is_set():
                msg = Header()
                msg.stamp.sec = published[0]
                pub.publish(msg)
                published[0] += 1
                time.sleep(0.01)
        thread = threading.Thread(target=talk, daemon=True)
        try:
            spin_until(executor, lambda: rec.subscribed == [topic]
                       and pub.get_subscription_count() == 1, timeout=TIMEOUT,
                       what='the recorder to subscribe')
            thread.start()
            spin_until(executor, lambda: rec.stats.messages >= 50, timeout=TIMEOUT,
                       what='50 messages')
            time.sleep(0.1)  # some published but not yet taken
            before = published[0]  # all of these were published before the stop
            finish_after_stop(HeldUpExecutor(executor, hold=0.6), rec)
        finally:
            running.clear()
            if thread.is_alive():
                thread.join(TIMEOUT)
            rec.destroy()
            writer.close()
            executor.shutdown()
            talker.destroy_node()
            node.destroy_node()
    with BagReader(tmp_path / 'stop.mcap') as bag:
        numbers = [deserialize_message(m.data, Header).stamp.sec
                   for m in bag.messages([topic])]
    assert numbers[:before] == list(range(before))
