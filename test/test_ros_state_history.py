"""The node's state topics keep a deep history: a subscriber held up while the node
publishes at full physics rate still gets every state, resent, once it runs again.

The held-up subscriber is ``gripper-sim record`` stopped with SIGSTOP (what a loaded
machine does to a process for a moment, made long and certain) while the paused node
takes an exact number of steps: more states than the shared-memory transport queues for
a stopped process, fewer than the node's history keeps.
"""
from __future__ import annotations

import os
import signal
import time

import pytest


from gripper_sim_interfaces.msg import FruitState  # noqa: E402
from gripper_sim_interfaces.srv import Step  # noqa: E402
from rclpy.qos import QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.recording.recover import scan  # noqa: E402
from gripper_sim.ros.process import (  # noqa: E402
    RosProcess, free_domain_id, node_process, ros_environment)
from gripper_sim.ros.publishing import (  # noqa: E402
    HISTORY_DEPTHS, QOS_DEPTHS, STATE_DEPTH, topic_qos)
from ros_client import ros_node  # noqa: E402

TIMEOUT = 120.0  # s: generous, for a slow busy machine
STATE = '/gripper_sim/fruit/state'
EVERY = 5        # steps a state: publish_rate 200 Hz at the default dt of 1 ms
HELD = 600       # states published while the recorder is stopped
def test_state_topics_keep_a_deep_history_clock_and_tf_their_own():
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    for suffix in ('fruit/state', 'fruit/nodes', 'left_jaw/wrench', 'joint_states'):
        profile = topic_qos(suffix, qos)
        assert profile.depth == STATE_DEPTH >= 1000
        assert profile.reliability == ReliabilityPolicy.RELIABLE
    assert topic_qos('markers', qos).depth == HISTORY_DEPTHS['markers'] == 100
    assert topic_qos('clock', qos) == QOS_DEPTHS['clock'] == 1
    assert topic_qos('tf', qos) == QOS_DEPTHS['tf'] == 100
    assert topic_qos('fruit/state', QoSProfile(depth=5000)).depth == 5000


def call(executor, client, request):
    """The response of a service call (AssertionError after TIMEOUT)."""
    assert client.wait_for_service(timeout_sec=TIMEOUT), client.srv_name
    future = client.call_async(request)
    executor.spin_until_future_complete(future, timeout_sec=TIMEOUT)
    assert future.done(), f'{client.srv_name} did not answer in {TIMEOUT} s'
    return future.result()


def stamps_so_far(path) -> list[int]:
    """ns, the header stamps of the states already in the chunks of a recording still
    being written."""
    if not path.exists() or path.stat().st_size == 0:
        return []
    return [stamp(deserialize_message(record.data, FruitState))
            for record in scan(path).records if type(record).__name__ == 'Message']


def spacing_ns() -> int:
    """ns of sim time between two states: EVERY steps of 1 ms."""
    return EVERY * 1_000_000


def stamp(message) -> int:
    """ns, a message's header stamp."""
    return message.header.stamp.sec * 10**9 + message.header.stamp.nanosec


@pytest.mark.ros
@pytest.mark.slow
def test_a_recorder_held_up_while_the_node_publishes_600_states_records_every_one(tmp_path):
    assert HELD < STATE_DEPTH
    domain = free_domain_id(os.getpid())
    env = ros_environment(domain)
    out = tmp_path / 'held_up.mcap'
    node_proc = node_process({'real_time_factor': 0.0, 'publish_rate': 200.0}, env=env,
                             log_path=tmp_path / 'node.log')
    with node_proc, ros_node(domain, 'history_test') as (node, executor):
        assert node_proc.wait_for_log('ready', timeout=TIMEOUT), node_proc.log()
        assert f'publishing every {EVERY} steps' in node_proc.log()
        pause = node.create_client(SetBool, '/gripper_sim/pause')
        step = node.create_client(Step, '/gripper_sim/step')
        assert call(executor, pause, SetBool.Request(data=True)).success
        recorder = RosProcess('gripper_sim.cli.main',
                              ['record', '-o', str(out), '--flush-interval', '0.05', STATE],
                              env=env, log_path=tmp_path / 'record.log')
        with recorder:
            deadline = time.monotonic() + TIMEOUT
            while not stamps_so_far(out):  # one state a call, until one is on disk
                assert time.monotonic() < deadline, recorder.log()
                assert call(executor, step, Step.Request(steps=EVERY)).success
            os.kill(recorder.process.pid, signal.SIGSTOP)
            try:
                assert call(executor, step, Step.Request(steps=EVERY * HELD)).success
            finally:
                os.kill(recorder.process.pid, signal.SIGCONT)
            # one state more; reliable delivery hands it over after every earlier one
            # (resent ones included), or the recorder finds the gap and warns
            newest = call(executor, step, Step.Request(steps=EVERY)).sim_time
            newest_ns = round(newest * 1e9) - spacing_ns() + 1
            deadline = time.monotonic() + TIMEOUT
            while not (max(stamps_so_far(out)) >= newest_ns or 'lost' in recorder.log()):
                assert time.monotonic() < deadline, recorder.log()
                time.sleep(0.05)
            assert recorder.stop(timeout=TIMEOUT) == 0, recorder.log()
    log = recorder.log()
    assert 'LOST' not in log and 'lost' not in log and 'may not have arrived' not in log, log
    with BagReader(out) as bag:
        stamps = [stamp(deserialize_message(m.data, FruitState)) for m in bag.messages([STATE])]
    assert len(stamps) > HELD + 1
    gaps = [(a, b) for a, b in zip(stamps, stamps[1:]) if b - a != spacing_ns()]
    assert not gaps, f'{len(gaps)} gaps in the recorded states, first {gaps[:3]}'
