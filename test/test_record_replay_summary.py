"""The last line of `gripper-sim record` and `gripper-sim replay` counts in English:
'1 topic', '1 loop', not '1 topics', '1 loops'."""
from gripper_sim.recording.recorder import RecorderStats, record_summary
from gripper_sim.ros.replay import ReplayStats, replay_summary


def test_a_replay_of_one_topic_once_says_topic_and_loop_in_the_singular():
    stats = ReplayStats(messages=698, loops=1, per_topic={'/gripper_sim/fruit/state': 698},
                        wall_time=5.1)
    assert replay_summary(stats, loop=True) == \
        'replayed 698 messages on 1 topic in 5.10 s (1 loop)'


def test_a_replay_of_several_topics_and_loops_says_them_in_the_plural():
    stats = ReplayStats(messages=1, loops=3, per_topic={'/a': 1, '/b': 0}, wall_time=0.5)
    assert replay_summary(stats, loop=True, skipped=['/c']) == \
        'replayed 1 message on 2 topics in 0.50 s (3 loops) (skipped: /c)'
    assert '(' not in replay_summary(stats, loop=False)


def test_a_recording_of_one_topic_says_topic():
    stats = RecorderStats(messages=1, per_topic={'/gripper_sim/fruit/state': 1})
    text = record_summary(stats, 'grasp', missing=['/tf_static'])
    assert text.startswith('recorded 1 message on 1 topic to grasp in ')
    assert text.endswith(' s (no messages on: /tf_static)')
    split = record_summary(RecorderStats(messages=12, per_topic={'/a': 5, '/b': 7}), 'long',
                           files=3)
    assert split.startswith('recorded 12 messages on 2 topics to long (3 files) in ')
