"""The node's state topics, published in step order, every ``publish_every`` steps.

Batches go out in step order: a state older than one already published (e.g. a step
that finished just before a reset) is dropped, never published after it. Messages are
built only for topics someone subscribes to (or when a publish observer listens).
"""
from __future__ import annotations

import threading
from typing import Callable

from rclpy.qos import QoSProfile

from gripper_sim.core.results import StepResult
from gripper_sim.ros import messages
from gripper_sim.ros.messages import MessageContext, build_messages

#: ``observer({suffix: msg}, stamp_ns)`` with every batch published
PublishObserver = Callable[[dict, int], None]


class OrderedPublisher:
    """Publishes ``messages.TOPICS`` for ``node``; one batch at a time, in step order.

    Args:
        node: the rclpy node to create the publishers on.
        qos: profile of every topic but ``/clock`` (keep-last 1).
        publish_clock: publish ``/clock`` too.

    Attributes:
        publish_every: publish the result of every n-th step (``set_rate``).
        publish_count: batches published so far.
    """

    def __init__(self, node, qos: QoSProfile, publish_clock: bool):
        self._publishers = {
            suffix: node.create_publisher(messages.MESSAGE_CLASSES[suffix], name,
                                          1 if suffix == 'clock' else qos)
            for suffix, (name, _) in messages.TOPICS.items()}
        self._lock = threading.Lock()
        self._published = -1        # sequence number of the last batch published
        self._observers: list[PublishObserver] = []
        self.publish_clock = publish_clock
        self.publish_every = 1
        self.publish_count = 0

    def add_observer(self, callback: PublishObserver) -> None:
        """Call ``callback({suffix: msg}, stamp_ns)`` with every batch published."""
        self._observers.append(callback)

    def remove_observer(self, callback: PublishObserver) -> None:
        """Stop calling ``callback`` (no error when it was not added)."""
        if callback in self._observers:
            self._observers.remove(callback)

    def set_rate(self, rate: float, dt: float) -> None:
        """Publish every ``1 / rate`` s of sim time (``rate`` Hz, ``dt`` s per step)."""
        self.publish_every = max(1, int(round(1.0 / (rate * dt))))

    def due(self, result: StepResult) -> bool:
        """Whether the result of this step is one to publish."""
        return result.step % self.publish_every == 0

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
            wanted = [suffix for suffix, pub in self._publishers.items()
                      if (suffix != 'clock' or self.publish_clock)
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
