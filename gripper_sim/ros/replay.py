"""Replay: republish the raw messages of a recording with their original timing and QoS.

Messages go out in log-time order, the n-th at ``start + (log_time - t0) / rate`` of
the wall clock, as the CDR bytes that were recorded (no deserialization). Each topic's
publisher offers the QoS its recorded publishers offered (see ``qos.adapt_for_replay``).
With ``clock_hz``, ``/clock`` carries the recording's time so that nodes running with
``use_sim_time`` follow the replay (a recorded ``/clock`` topic is then not replayed).
"""
from __future__ import annotations

import os
import signal
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping

import rclpy
from rclpy.duration import Duration
from rclpy.exceptions import NameValidationException
from rclpy.qos import QoSProfile
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock

from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.reader import BagReader
from gripper_sim.recording.recorder import counted, import_message_class
from gripper_sim.view.foxglove import recording_view

CLOCK_TOPIC = '/clock'
PUBLISHER_DEPTH = 100


@dataclass
class ReplayStats:
    messages: int = 0
    loops: int = 0
    per_topic: dict = field(default_factory=dict)
    clock_messages: int = 0
    wall_time: float = 0.0
    max_lateness: float = 0.0  # s, worst delay of a publish behind its schedule


class Player:
    """Publishes a recording on ``node``.

    Args:
        node: an rclpy node to create the publishers on.
        bag: an open ``BagReader``.
        rate: speed factor (2 = twice as fast).
        topics: topics to replay (None = all that can be).
        start: s of the recording to skip.
        clock_hz: publish ``/clock`` at this rate (None = not).
        remaps: ``{recorded topic: published topic}``.
        view: a ``FoxgloveView`` that also gets every replayed message (None = none).
    """

    def __init__(self, node: Any, bag: BagReader, *, rate: float = 1.0,
                 topics: Iterable[str] | None = None, start: float = 0.0,
                 clock_hz: float | None = None, remaps: Mapping[str, str] | None = None,
                 view: Any = None):
        if not rate > 0:
            raise RecordingError(f'rate must be positive, got {rate}')
        if start < 0:
            raise RecordingError(f'start must not be negative, got {start}')
        if clock_hz is not None and not clock_hz > 0:
            raise RecordingError(f'clock rate must be positive, got {clock_hz}')
        self.node = node
        self.bag = bag
        self.rate = float(rate)
        self.clock_hz = clock_hz
        self.stats = ReplayStats()
        self.stop = threading.Event()
        self.view = view
        remaps = dict(remaps or {})
        explicit = topics is not None
        selected = bag.check_topics(topics) or list(bag.topics)
        unknown_remaps = set(remaps) - set(bag.topics)
        if unknown_remaps:
            raise RecordingError(f"--remap of topics not in {bag.path}: "
                                 f"{', '.join(sorted(unknown_remaps))}")
        if clock_hz is not None and CLOCK_TOPIC in selected and \
                remaps.get(CLOCK_TOPIC, CLOCK_TOPIC) == CLOCK_TOPIC:
            selected.remove(CLOCK_TOPIC)  # the replay's own clock replaces it
        self.publishers: dict[str, Any] = {}
        self.skipped: list[str] = []
        for topic in selected:
            info = bag.topics[topic]
            if info.message_encoding != 'cdr':
                if explicit:
                    raise RecordingError(f"topic '{topic}' is not CDR-encoded and cannot be "
                                         'replayed on ROS 2')
                self.skipped.append(topic)
                continue
            try:
                msg_class = import_message_class(info.type)
            except RecordingError as err:
                if explicit:
                    raise RecordingError(f"cannot replay '{topic}': {err}") from err
                node.get_logger().warning(f"skipping '{topic}': {err}")
                self.skipped.append(topic)
                continue
            offer = qos_mod.adapt_for_replay(info.offered_qos_profiles)
            if offer['durability'] != 'transient_local':
                offer['depth'] = max(offer['depth'], PUBLISHER_DEPTH)  # no loss in bursts
            profile = qos_mod.to_rclpy(offer)
            name = remaps.get(topic, topic)
            try:
                self.publishers[topic] = node.create_publisher(msg_class, name, profile)
            except (NameValidationException, ValueError) as err:
                reason = str(err).splitlines()[0].rstrip(':')
                if explicit or topic in remaps:
                    raise RecordingError(f"cannot replay '{topic}' as '{name}': "
                                         f'{reason}') from None
                node.get_logger().warning(f"skipping '{topic}': {reason}")
                self.skipped.append(topic)
        if not self.publishers:
            raise RecordingError(f'{bag.path}: nothing to replay')
        self.clock_publisher = None
        if clock_hz is not None:
            self._clock_class = Clock
            self.clock_publisher = node.create_publisher(Clock, CLOCK_TOPIC,
                                                         QoSProfile(depth=10))
        self._next_clock = 0.0
        self.t0 = bag.start_time + int(round(start * 1e9))
        if bag.message_count and self.t0 > bag.end_time:
            raise RecordingError(f'--start {start} s is past the end of {bag.path} '
                                 f'({bag.duration_ns / 1e9:.3f} s long)')
        if not self._has_messages():
            after = f' from --start {start} s on' if start else ''
            raise RecordingError(f'{bag.path}: nothing to replay (no message on '
                                 f"{', '.join(self.publishers)}{after})")

    def _has_messages(self) -> bool:
        """Whether a message of a replayed topic is logged at or after ``t0`` (a play of
        none would end at once, and a --loop of it spin without end)."""
        stream = self.bag.messages(list(self.publishers), start=self.t0)
        try:
            return next(stream, None) is not None
        finally:
            stream.close()

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait (up to ``timeout`` s) until every publisher has a subscriber."""
        deadline = time.monotonic() + timeout
        while not self.stop.is_set():
            if all(p.get_subscription_count() > 0 for p in self.publishers.values()):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.02)
        return False

    def _publish_clock(self, bag_ns: int) -> None:
        assert self.clock_publisher is not None
        msg = self._clock_class()
        msg.clock.sec, msg.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.clock_publisher.publish(msg)
        self.stats.clock_messages += 1

    def _clock_time(self, now: float, wall0: float) -> int:
        """The recording's time (ns) at the wall time ``now`` (monotonic s) of a play that
        began at ``wall0``: never past the recording's end, however large the rate."""
        elapsed_ns = (now - wall0) * self.rate * 1e9
        return self.t0 + int(min(elapsed_ns, max(self.bag.end_time - self.t0, 0)))

    def _wait_until(self, wall_target: float, wall0: float) -> None:
        """Sleep until ``wall_target`` (monotonic s), publishing /clock ticks meanwhile
        (at most one a turn: a clock rate faster than publishing never holds messages)."""
        while not self.stop.is_set():
            now = time.monotonic()
            if self.clock_publisher is not None and self.clock_hz is not None:
                due = self._next_clock
                if due <= now:
                    self._publish_clock(self._clock_time(now, wall0))
                    self._next_clock = max(due + 1.0 / self.clock_hz, now)
            if now >= wall_target:
                return
            wake = wall_target
            if self.clock_publisher is not None:
                wake = min(wake, self._next_clock)
            time.sleep(min(max(wake - now, 0.0), 0.05))

    def play_once(self) -> None:
        """Play the recording (from ``start``) once."""
        wall0 = time.monotonic()
        self._next_clock = wall0
        topics = list(self.publishers)
        for msg in self.bag.messages(topics, start=self.t0):
            target = wall0 + (msg.log_time - self.t0) / 1e9 / self.rate
            self._wait_until(target, wall0)
            if self.stop.is_set():
                return
            self.stats.max_lateness = max(self.stats.max_lateness, time.monotonic() - target)
            self.publishers[msg.topic].publish(msg.data)
            if self.view is not None:
                self.view.log_cdr(msg.topic, msg.data, msg.log_time)
            self.stats.messages += 1
            self.stats.per_topic[msg.topic] = self.stats.per_topic.get(msg.topic, 0) + 1
        self.stats.loops += 1

    def play(self, *, loop: bool = False) -> ReplayStats:
        started = time.monotonic()
        while not self.stop.is_set():
            self.play_once()
            if not loop:
                break
        self.stats.wall_time = time.monotonic() - started
        return self.stats

    def drain(self, timeout: float = 2.0) -> None:
        """Give reliable subscribers time to receive the last messages."""
        for pub in self.publishers.values():
            try:
                pub.wait_for_all_acked(Duration(seconds=timeout))
            except Exception:  # noqa: BLE001 - best effort; not all rmw support it
                pass


def run_replay(path: str, *, rate: float = 1.0, loop: bool = False,
               topics: Iterable[str] | None = None, start: float = 0.0,
               clock_hz: float | None = None, remaps: Mapping[str, str] | None = None,
               wait_for_subscribers: float = 0.0, foxglove_port: int | None = None,
               foxglove_address: str = '127.0.0.1') -> str:
    """Replay ``path`` until done (or Ctrl-C/SIGTERM with ``loop``); return a summary.

    With ``foxglove_port`` the same messages and the 3D scene are also served to
    Foxglove (``gripper_sim.view.foxglove.recording_view``; ViewError if it cannot).
    """
    with BagReader(path) as bag:
        # no command line: rcl would read this verb's own arguments (e.g. --remap
        # A:=B) as ROS remapping rules and warn that their syntax is deprecated
        rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
        node = None
        player = None
        view = None

        def request_stop(_signum: int, _frame: Any) -> None:
            if player is not None:
                player.stop.set()

        previous = {sig: signal.signal(sig, request_stop)
                    for sig in (signal.SIGINT, signal.SIGTERM)}
        try:
            node = rclpy.create_node(f'gripper_sim_replay_{os.getpid()}')
            player = Player(node, bag, rate=rate, topics=topics, start=start,
                            clock_hz=clock_hz, remaps=remaps)
            if foxglove_port is not None:
                view = player.view = recording_view(bag, host=foxglove_address,
                                                    port=foxglove_port,
                                                    topics=list(player.publishers))
                node.get_logger().info(f'Foxglove view of the replay on {view.url}')
            if wait_for_subscribers > 0 and not player.wait_for_subscribers(
                    wait_for_subscribers):
                lonely = [t for t, p in player.publishers.items()
                          if p.get_subscription_count() == 0]
                node.get_logger().warning(
                    f"no subscriber after {wait_for_subscribers} s on: {', '.join(lonely)}")
            stats = player.play(loop=loop)
            player.drain()
        finally:
            if view is not None:
                view.close()
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return replay_summary(stats, loop=loop,
                          skipped=player.skipped if player is not None else ())


def replay_summary(stats: ReplayStats, *, loop: bool, skipped: Iterable[str] = ()) -> str:
    """The line ``gripper-sim replay`` ends with: messages, topics, wall time (s), the
    loops when looping and the topics it skipped."""
    text = (f"replayed {counted(stats.messages, 'message')} on "
            f"{counted(len(stats.per_topic), 'topic')} in {stats.wall_time:.2f} s")
    if loop:
        text += f" ({counted(stats.loops, 'loop')})"
    skipped = list(skipped)
    if skipped:
        text += f" (skipped: {', '.join(skipped)})"
    return text
