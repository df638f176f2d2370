"""Recording the real ``gripper_sim`` node: ``analyze`` reproduces what the node reported.

A node process grips the fruit; this test subscribes to the node's FruitState topic
live while a ``gripper-sim record`` process records it. The peak grip force and
compression that ``analyze`` finds in the file equal those seen live over the same
span of sim time, exactly (the same float64 values travel both ways).

At real_time_factor 0 the node publishes hundreds of states a wall second; on a loaded
machine the recorder's process is sometimes held up meanwhile. The node's state topics
keep the last 1000 (``publishing.STATE_DEPTH``), so they are resent to it; a state lost
all the same would be in record's closing line (``LOST``), which is checked first.
"""
from __future__ import annotations

import os

import pytest

import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim_interfaces.msg import FruitState  # noqa: E402
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_msgs.msg import Float64  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from gripper_sim.recording.analysis import analyze  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.ros.process import (  # noqa: E402
    RosProcess, free_domain_id, node_process, ros_environment)
from ros_client import ros_node, spin_until  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TIMEOUT = 120.0
STATE = '/gripper_sim/fruit/state'
def stamp(message) -> int:
    """ns, a message's header stamp."""
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


def test_analyze_reproduces_the_peaks_the_node_reported_live(tmp_path):
    domain = free_domain_id(os.getpid())
    env = ros_environment(domain)
    out = tmp_path / 'grasp.mcap'
    node_proc = node_process({'real_time_factor': 0.0, 'publish_rate': 200.0}, env=env,
                             log_path=tmp_path / 'node.log')
    with node_proc, ros_node(domain, 'live_observer') as (node, executor):
        assert node_proc.wait_for_log('ready', timeout=TIMEOUT), node_proc.log()
        live: list[FruitState] = []
        # keep all: behind on a busy machine, it must still see every state the recorder does
        node.create_subscription(FruitState, STATE, live.append,
                                 QoSProfile(history=HistoryPolicy.KEEP_ALL,
                                            reliability=ReliabilityPolicy.RELIABLE))
        force = node.create_publisher(Float64, '/gripper_sim/jaw/force_command', 10)
        recorder = RosProcess('gripper_sim.cli.main',
                              ['record', '-o', str(out), STATE, '/gripper_sim/left_jaw/wrench',
                               '/gripper_sim/right_jaw/wrench', '/gripper_sim/markers'],
                              env=env, log_path=tmp_path / 'record.log')
        with recorder:
            spin_until(executor, lambda: node.count_subscribers(STATE) >= 2 and live,
                       what='the recorder and this test to receive the state')
            spin_until(executor, lambda: recorder.log().count("recording '") == 4,
                       what='the recorder to subscribe to all four topics')
            spin_until(executor, lambda: force.get_subscription_count() > 0,
                       what='the node to subscribe to force commands')
            force.publish(Float64(data=4.0))
            spin_until(executor, lambda: max(m.grip_force for m in live) >= 3.0,
                       what='a grip of 3 N')
            grip_at = stamp(live[-1])
            spin_until(executor, lambda: stamp(live[-1]) >= grip_at + 100_000_000,
                       what='0.1 s of sim time holding the grip')
            assert recorder.stop(timeout=TIMEOUT) == 0, recorder.log()
        assert 'LOST' not in recorder.log(), recorder.log()
        # the recorder wrote what was in flight when it stopped (and a little after): the
        # live subscriber, behind on a busy machine, catches up to its last message
        with BagReader(out) as bag:
            last_recorded = stamp(deserialize_message(list(bag.messages([STATE]))[-1].data,
                                                      FruitState))
        spin_until(executor, lambda: stamp(live[-1]) >= last_recorded,
                   what='the live subscriber to reach the last recorded state')

    result = analyze(out, tmp_path / 'analysis')
    classes = {STATE: FruitState, '/gripper_sim/left_jaw/wrench': WrenchStamped,
               '/gripper_sim/right_jaw/wrench': WrenchStamped,
               '/gripper_sim/markers': MarkerArray}
    with BagReader(out) as bag:
        assert set(bag.topics) == set(classes)
        for topic, cls in classes.items():
            raw = list(bag.messages([topic]))
            assert raw, topic
            decoded = [d for _, d in bag.decoded_messages([topic])]  # mcap-ros2-support
            by_rclpy = [deserialize_message(m.data, cls) for m in raw]
            assert len(decoded) == len(by_rclpy) == bag.topics[topic].message_count
            log_times = [m.log_time for m in raw]
            assert log_times == sorted(log_times)
            if cls is MarkerArray:
                by_rclpy = [m.markers[0] for m in by_rclpy]
                decoded = [d.markers[0] for d in decoded]
            stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in by_rclpy]
            assert stamps == sorted(stamps)
            assert stamps == [(d.header.stamp.sec, d.header.stamp.nanosec) for d in decoded]
        recorded = [deserialize_message(m.data, FruitState) for m in bag.messages([STATE])]
        decoded_states = [d for _, d in bag.decoded_messages([STATE])]
    first, last = stamp(recorded[0]), stamp(recorded[-1])
    window = [m for m in live if first <= stamp(m) <= last]
    missing = sorted({stamp(m) for m in window} - {stamp(m) for m in recorded})
    assert not missing, (f'{len(missing)} states published live are not in the recording '
                         f'(the first at {missing[:3]} ns of sim time); record said: '
                         f'{recorder.log().splitlines()[-1]}')
    assert window == recorded  # every message equals what the node published
    assert [d.grip_force for d in decoded_states] == [m.grip_force for m in window]
    assert [d.compression for d in decoded_states] == [m.compression for m in window]
    s = result.summary
    assert s['samples'] == len(window)
    assert s['peak_grip_force_n'] == max(m.grip_force for m in window)
    assert s['peak_compression_m'] == max(m.compression for m in window)
    assert s['peak_grip_force_n'] >= 3.0
    assert s['peak_left_force_n'] is not None and s['peak_right_force_n'] is not None
    assert (tmp_path / 'analysis' / 'outline_snapshots.png').is_file()
