"""The live recorder never loses messages silently: every loss is counted, warned about,
named in ``record``'s closing line and stored in the recording's ``custom_data``.

Two ways a message goes missing, each forced here rather than waited for: the
recorder's own queue overflows while it cannot take messages (a gap in the publisher's
sequence numbers; the middleware does not report it), and a publisher with a short
history drops a sample before it could resend it to a recorder that was held up (the
middleware's ``message_lost``). The recorder is held up with SIGSTOP, as a loaded
machine would.
"""
from __future__ import annotations

import json
import os
import signal
import time
from types import SimpleNamespace

import pytest

import rclpy

from rclpy.duration import Duration  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_msgs.msg import Header  # noqa: E402

from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.recording.recorder import (  # noqa: E402
    LOST_KEY, SUBSCRIPTION_DEPTH, LossTracker, Recorder, RecorderStats, record_summary)
from gripper_sim.recording.writer import BagWriter  # noqa: E402
from gripper_sim.ros.process import RosProcess, free_domain_id, ros_environment  # noqa: E402
from ros_client import isolated_context, spin_until  # noqa: E402

TIMEOUT = 60.0  # s: generous, for a slow busy machine
TOPIC = '/loss_test'
# ---------------------------------------------------------------- counting, no ROS graph
def test_a_gap_in_the_sequence_numbers_of_one_publisher_counts_the_numbers_skipped():
    tracker = LossTracker(lambda: 1)
    assert [tracker.on_sequence(n) for n in (5, 6, 7, 10, 11, 20)] == [0, 0, 0, 2, 0, 8]
    assert tracker.lost == 10


def test_a_new_publisher_or_several_publishers_are_no_gap():
    restarted = LossTracker(lambda: 1)
    assert [restarted.on_sequence(n) for n in (40, 41, 1, 2, 3)] == [0] * 5
    assert restarted.lost == 0
    interleaved = LossTracker(lambda: 2)
    assert [interleaved.on_sequence(n) for n in (500, 3, 501, 4, 502)] == [0] * 5
    assert interleaved.lost == 0
    unknown = LossTracker(lambda: 1)
    assert [unknown.on_sequence(n) for n in (None, 0, None)] == [0, 0, 0]


def test_the_middlewares_count_and_the_gaps_count_one_loss_once():
    tracker = LossTracker(lambda: 1)
    tracker.on_sequence(1)
    assert tracker.on_reported(3) == 3
    tracker.on_sequence(5)  # the same three, seen as a gap
    assert tracker.lost == 3
    assert tracker.on_reported(3) == 0 and tracker.on_reported(7) == 4
    assert tracker.lost == 7


def test_the_closing_line_names_the_lost_messages_per_topic():
    stats = RecorderStats(messages=10, per_topic={'/a': 4, '/b': 6}, lost={'/b': 3, '/a': 0})
    text = record_summary(stats, 'grasp', missing=['/c'])
    assert text.endswith(' s (no messages on: /c); LOST 3 messages: 3 on /b')
    stats.lost['/a'] = 1
    assert record_summary(stats, 'grasp').endswith('; LOST 4 messages: 1 on /a, 3 on /b')
    assert 'LOST' not in record_summary(RecorderStats(messages=1, per_topic={'/a': 1}), 'g')


# ---------------------------------------------------------------- ROS
def header(number: int, size: int = 0) -> Header:
    """Message ``number`` (its stamp's seconds), ``size`` bytes of frame id."""
    msg = Header()
    msg.stamp.sec = number
    msg.frame_id = 'x' * size
    return msg


@pytest.mark.ros
def test_an_overflowing_subscription_queue_is_counted_from_the_sequence_numbers(tmp_path):
    behind = 500
    with isolated_context(free_domain_id(os.getpid())) as context:
        node = rclpy.create_node('loss_recorder', context=context)
        talker = rclpy.create_node('loss_talker', context=context)
        pub = talker.create_publisher(
            Header, TOPIC, QoSProfile(depth=4 * SUBSCRIPTION_DEPTH,
                                      reliability=ReliabilityPolicy.RELIABLE))
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        writer = BagWriter(tmp_path / 'overflow.mcap')
        writer.open()
        recorder = Recorder(node, writer, topics=[TOPIC])
        try:
            spin_until(executor, lambda: recorder.subscribed == [TOPIC]
                       and pub.get_subscription_count() == 1, what='the recorder to subscribe')
            pub.publish(header(0))
            spin_until(executor, lambda: recorder.stats.messages == 1, what='the first message')
            # the recorder takes nothing meanwhile: its queue keeps the newest DEPTH
            for number in range(1, SUBSCRIPTION_DEPTH + behind + 1):
                pub.publish(header(number))
            assert pub.wait_for_all_acked(Duration(seconds=TIMEOUT))
            spin_until(executor, lambda: recorder.stats.messages == SUBSCRIPTION_DEPTH + 1,
                       what='the queued messages')
            assert recorder.lost == {TOPIC: behind}
            assert recorder.stats.lost == {TOPIC: behind}
        finally:
            recorder.destroy()
            writer.close()
            executor.shutdown()
            talker.destroy_node()
            node.destroy_node()
    with BagReader(tmp_path / 'overflow.mcap') as bag:
        numbers = [deserialize_message(m.data, Header).stamp.sec
                   for m in bag.messages([TOPIC])]
    assert numbers == [0, *range(behind + 1, SUBSCRIPTION_DEPTH + behind + 1)]


def test_the_middlewares_lost_report_reaches_the_count_and_a_warning():
    """The ``message_lost`` event callback the recorder registers feeds the count (a
    recorder without its ROS node: its logger only collects the warnings)."""
    warnings: list[str] = []
    recorder = Recorder.__new__(Recorder)
    recorder.stats = RecorderStats()
    recorder._losses = {TOPIC: LossTracker(lambda: 1)}
    recorder._warned = {}
    recorder.node = SimpleNamespace(get_logger=lambda: SimpleNamespace(
        warning=warnings.append))
    callbacks = recorder._event_callbacks(TOPIC)
    callbacks.message_lost(SimpleNamespace(total_count=7, total_count_change=7))
    assert recorder.lost == {TOPIC: 7}
    assert warnings == [f"lost 7 messages on '{TOPIC}' (the middleware reports them lost; "
                        '7 so far)']
    callbacks.message_lost(SimpleNamespace(total_count=9, total_count_change=2))
    assert recorder.lost == {TOPIC: 9} and len(warnings) == 1  # the next within a second


@pytest.mark.ros
@pytest.mark.slow
def test_record_names_messages_a_held_up_recorder_lost_in_its_summary_and_metadata(tmp_path):
    """``gripper-sim record`` stopped (SIGSTOP) while a depth-1 publisher sends 30 MB,
    far more than the shared-memory transport holds: the publisher can resend only its
    last sample, the others are lost, and record says how many. Every message is
    either in the recording or counted lost."""
    flood, size = 300, 100_000
    domain = free_domain_id(os.getpid())
    out = tmp_path / 'held_up'
    with isolated_context(domain) as context:
        node = rclpy.create_node('loss_publisher', context=context)
        pub = node.create_publisher(
            Header, TOPIC, QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
        recorder = RosProcess('gripper_sim.cli.main', ['record', '-o', str(out), TOPIC],
                              env=ros_environment(domain), log_path=tmp_path / 'record.log')
        with recorder:
            deadline = time.monotonic() + TIMEOUT
            while pub.get_subscription_count() < 1:
                assert time.monotonic() < deadline, recorder.log()
                time.sleep(0.05)
            pub.publish(header(0))
            assert pub.wait_for_all_acked(Duration(seconds=TIMEOUT)), recorder.log()
            os.kill(recorder.process.pid, signal.SIGSTOP)
            try:
                for number in range(1, flood + 1):
                    pub.publish(header(number, size))
            finally:
                os.kill(recorder.process.pid, signal.SIGCONT)
            pub.publish(header(flood + 1))
            assert pub.wait_for_all_acked(Duration(seconds=TIMEOUT)), recorder.log()
            assert recorder.stop(timeout=TIMEOUT) == 0, recorder.log()
        node.destroy_node()
    with BagReader(out) as bag:
        numbers = [deserialize_message(m.data, Header).stamp.sec
                   for m in bag.messages([TOPIC])]
        custom = bag.bag_metadata()['custom_data']
    lost = flood + 2 - len(numbers)
    assert numbers[0] == 0 and numbers[-1] == flood + 1 and numbers == sorted(numbers)
    assert lost > 0, 'nothing was lost: the flood did not overflow the transport'
    summary = recorder.log().strip().splitlines()[-1]
    assert summary.endswith(f'; LOST {lost} messages: {lost} on {TOPIC}'), recorder.log()
    assert f"on '{TOPIC}'" in recorder.log() and '[WARN]' in recorder.log()
    assert json.loads(custom[LOST_KEY]) == {TOPIC: lost}
