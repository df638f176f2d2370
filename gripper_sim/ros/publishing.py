"""The node's state topics, published in step order: ``/clock`` every ``clock_rate``,
``~/markers`` every ``marker_rate``, every other topic every ``publish_rate`` (each a
whole number of physics steps; a reset state goes out on every topic).

Every topic but ``/clock`` and ``/tf`` keeps the last ``STATE_DEPTH`` messages
(``~/markers`` its own ``HISTORY_DEPTHS``), reliable: a subscriber held up for a while
(its process not scheduled on a loaded machine) while the node publishes at full physics
rate still gets every message, resent, as long as it misses no more than that (and its
own history is deep enough to keep them until it takes them).

Batches go out in step order: a state older than one already published (e.g. a step
that finished just before a reset) is dropped, never published after it. Messages are
built only for topics someone subscribes to (or when a publish observer listens).
"""
from __future__ import annotations

import threading
from typing import Callable

from rclpy.qos import QoSProfile

from gripper_sim.convert import messages
from gripper_sim.convert.messages import MessageContext, build_messages
from gripper_sim.core.results import StepResult

#: keep-last depths of their own: /clock 1, /tf 100 (tf2's broadcaster)
QOS_DEPTHS = {'clock': 1, 'tf': 100}
#: keep-last depth (messages) of every other topic, at least. DDS resends a sample a
#: held-up subscriber missed only while the publisher still holds it. At rtf 0 and
#: publish_rate 200 Hz the 2D node publishes about 260 states a wall second, so this
#: covers about 4 s (with depth 10 a recorder held up 2.5 s lost 750 states, one on a
#: loaded CI machine about 20).
#: Acknowledged samples are released: the memory is taken only while a subscriber lags.
STATE_DEPTH = 1000
#: own depths: a 3D MarkerArray is about 160 kB; it goes out at ``marker_rate``, by
#: default 10 times less often than the states, so 100 cover as long as the states' 1000
HISTORY_DEPTHS = {'markers': 100}

#: topics published at their own rate; every other suffix is in group 'state'
GROUP_OF = {'clock': 'clock', 'markers': 'markers'}
GROUPS = ('state', 'clock', 'markers')

#: ``observer({suffix: msg}, stamp_ns)`` with every batch published
PublishObserver = Callable[[dict, int], None]


def topic_qos(suffix: str, qos: QoSProfile) -> QoSProfile | int:
    """The publisher profile of topic ``suffix``: a depth of its own (``QOS_DEPTHS``), or
    ``qos`` keeping at least ``HISTORY_DEPTHS`` or ``STATE_DEPTH`` messages."""
    if suffix in QOS_DEPTHS:
        return QOS_DEPTHS[suffix]
    depth = max(qos.depth, HISTORY_DEPTHS.get(suffix, STATE_DEPTH))
    return QoSProfile(history=qos.history, depth=depth,
                      reliability=qos.reliability, durability=qos.durability,
                      deadline=qos.deadline, lifespan=qos.lifespan,
                      liveliness=qos.liveliness,
                      liveliness_lease_duration=qos.liveliness_lease_duration)


class OrderedPublisher:
    """Publishes ``messages.TOPICS`` for ``node``; one batch at a time, in step order.

    Args:
        node: the rclpy node to create the publishers on.
        qos: profile of every topic but ``/clock`` and ``/tf`` (``QOS_DEPTHS``), its
            depth raised to ``STATE_DEPTH`` (``topic_qos``).
        publish_clock: publish ``/clock`` too.

    Attributes:
        publish_every: publish the result of every n-th step (``set_rate``).
        publish_count: batches published so far.
    """

    def __init__(self, node, qos: QoSProfile, publish_clock: bool):
        self._publishers = {
            suffix: node.create_publisher(messages.MESSAGE_CLASSES[suffix], name,
                                          topic_qos(suffix, qos))
            for suffix, (name, _) in messages.TOPICS.items()}
        self._lock = threading.Lock()
        self._published = -1        # sequence number of the last batch published
        self._observers: list[PublishObserver] = []
        self.publish_clock = publish_clock
        self.every = {group: 1 for group in GROUPS}
        self.publish_count = 0

    @property
    def publish_every(self) -> int:
        """Steps between two state batches (``publish_rate``)."""
        return self.every['state']

    def add_observer(self, callback: PublishObserver) -> None:
        """Call ``callback({suffix: msg}, stamp_ns)`` with every batch published."""
        self._observers.append(callback)

    def remove_observer(self, callback: PublishObserver) -> None:
        """Stop calling ``callback`` (no error when it was not added)."""
        if callback in self._observers:
            self._observers.remove(callback)

    def set_rate(self, rate: float, dt: float, group: str = 'state') -> None:
        """Publish ``group`` (``GROUPS``) every ``1 / rate`` s of sim time, at most every
        step (``rate`` Hz, ``dt`` s per step)."""
        self.every[group] = max(1, int(round(1.0 / (rate * dt))))

    def _due_groups(self, step: int) -> set[str]:
        due = {group for group, every in self.every.items() if step % every == 0}
        if not self.publish_clock:
            due.discard('clock')
        return due

    def due(self, result: StepResult) -> bool:
        """Whether the result of this step has a topic to publish."""
        return bool(self._due_groups(result.step))

    def publish(self, result: StepResult, context: MessageContext, sequence: int) -> None:
        """Publish the batch of step ``sequence``, unless a later one is already out.

        Called outside the simulation lock, from the physics thread, ``~/step`` and
        ``~/reset``: without the check a step that finished just before a reset could
        go out after the reset state (and a client would never see t = 0).
        """
        with self._lock:
            if sequence <= self._published:
                return
            self._published = sequence
            stamp = messages.time_msg(result.time)
            due = self._due_groups(result.step)
            wanted = [suffix for suffix, pub in self._publishers.items()
                      if GROUP_OF.get(suffix, 'state') in due
                      and (self._observers or pub.get_subscription_count() > 0)]
            if not wanted:
                return
            batch = build_messages(result, context, stamp, topics=wanted)
            for suffix, msg in batch.items():
                self._publishers[suffix].publish(msg)
            self.publish_count += 1
            if self._observers:
                ns = stamp.sec * 1_000_000_000 + stamp.nanosec
                for observer in self._observers:
                    observer(batch, ns)
