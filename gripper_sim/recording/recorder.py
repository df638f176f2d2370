"""The live raw recorder: subscribe to topics of any node and write them to MCAP.

Types come from the ROS graph; every subscription is raw (CDR bytes are written as
received, never deserialized). The subscription QoS is adapted to what the publishers
offer, as rosbag2 does (reliable only if every publisher is, transient-local only if
every publisher is), and the offered profiles are stored in the channel metadata.

``log_time`` is the receive time and ``publish_time`` the source timestamp the
middleware reports, both integer ns of the system clock.

Lost messages are counted, never dropped silently (``LossTracker``): a gap in the
publication sequence numbers of a topic's one publisher (lost anywhere: overwritten in
the publisher's history before it was resent, or in this subscription's queue), and the
samples the middleware reports lost (``message_lost`` event; the only count on a topic
with several publishers, whose numbers interleave). Each loss is logged as a warning, and
the totals end up in the closing summary and in the recording's ``custom_data``
(``lost_messages``: JSON ``{topic: count}``).
"""
from __future__ import annotations

import importlib
import json
import os
import re
import signal
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable

from gripper_sim.recording import qos as qos_mod
from gripper_sim.recording import schemas
from gripper_sim.recording.bag_folder import open_bag_writer
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.writer import DEFAULT_FLUSH_INTERVAL

SUBSCRIPTION_DEPTH = 1000  # deep enough that bursts at full physics rate are not dropped
# On a stop (``Recorder.caught_up``): a topic publishing steadily is finished by a
# message published after the stop, or by STEADY_QUIET of silence; any other once it
# has been silent for its quiet time: STOP_QUIET_PERIODS of its typical gaps, within
# [STOP_QUIET, STOP_QUIET_MAX].
#: s: the shortest quiet time (and every topic's before it has STEADY_MESSAGES messages)
STOP_QUIET = 0.25
#: s: the longest quiet time; a topic whose typical gap is longer is never steady
STOP_QUIET_MAX = 1.0
#: a topic's quiet time in its typical gaps between messages
STOP_QUIET_PERIODS = 4
#: s: the silence that finishes a steady topic with no message published after the stop
#: (its publisher paused just before it, or the recorder or the machine stalled this long)
STEADY_QUIET = 2.0
#: messages a topic must have delivered before it can count as steady
STEADY_MESSAGES = 5
#: the gaps between publish times a topic's typical gap is the median of (the latest)
GAP_HISTORY = 31
#: s: the longest a stop waits for messages published before it to arrive
STOP_CEILING = 5.0
#: the recording's ``custom_data`` key of the lost-message counts (JSON ``{topic: n}``)
LOST_KEY = 'lost_messages'
#: s: the shortest time between two warnings of lost messages on one topic
LOSS_WARNING_PERIOD = 1.0


def import_message_class(type_name: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (raises RecordingError if not installed)."""
    package, name = schemas.split_type_name(type_name)
    try:
        module = importlib.import_module(f'{package}.msg')
        return getattr(module, name)
    except (ImportError, AttributeError) as err:
        msg = (f"message type '{package}/msg/{name}' is not installed for Python "
               f'({err}); install its interface package')
        raise RecordingError(msg) from err


def compile_pattern(pattern: str | None, option: str) -> re.Pattern | None:
    """A topic pattern (matched against the whole topic name, as rosbag2 does), or None."""
    if pattern is None or pattern == '':
        return None
    try:
        return re.compile(pattern)
    except re.error as err:
        raise RecordingError(f"{option} '{pattern}' is not a valid regular expression: "
                             f'{err}') from None


@dataclass(frozen=True)
class TopicSelection:
    """Which topics to record, as ``ros2 bag record`` chooses them.

    A topic is recorded when it is named, or matches ``regex`` or ``all_topics`` is set
    (for these two hidden topics excepted, as rosbag2 does without
    --include-hidden-topics: an action's ``_action/*`` topics, a node's ``_instance``),
    and it does not match ``exclude``. Patterns match the whole topic name.
    """

    names: frozenset = frozenset()
    regex: re.Pattern | None = None
    exclude: re.Pattern | None = None
    all_topics: bool = False

    @classmethod
    def build(cls, topics: Iterable[str] = (), *, regex: str | None = None,
              exclude: str | None = None, all_topics: bool = False) -> TopicSelection:
        names = set()
        for topic in topics:
            topic = topic.strip()
            if not topic:
                raise RecordingError('empty topic name')
            names.add(topic if topic.startswith('/') else '/' + topic)
        selection = cls(frozenset(names), compile_pattern(regex, '--regex'),
                        compile_pattern(exclude, '--exclude'), all_topics)
        if not selection.names and selection.regex is None and not all_topics:
            raise RecordingError('give topics to record, --regex or --all')
        return selection

    def wants(self, topic: str) -> bool:
        if self.exclude is not None and self.exclude.fullmatch(topic):
            return False
        if topic in self.names:
            return True
        if is_hidden(topic):
            return False
        return self.all_topics or (self.regex is not None
                                   and self.regex.fullmatch(topic) is not None)


def is_hidden(topic: str) -> bool:
    """Hidden topics (a name component starting with '_'), skipped by --all and --regex
    like rosbag2."""
    return any(part.startswith('_') for part in topic.split('/') if part)


def counted(count: int, noun: str) -> str:
    """``count`` and ``noun``, the noun plural unless the count is one: '1 topic',
    '12 topics'."""
    return f'{count} {noun}' if count == 1 else f'{count} {noun}s'


@dataclass
class RecorderStats:
    """Counts kept while recording; ``lost``: messages known lost per topic."""

    messages: int = 0
    bytes: int = 0
    per_topic: dict = field(default_factory=dict)
    started: float = field(default_factory=time.monotonic)
    lost: dict = field(default_factory=dict)

    def elapsed(self) -> float:
        return time.monotonic() - self.started


class LossTracker:
    """Messages of one topic that never reached the recorder.

    ``sequence_gaps``: numbers skipped by the publication sequence number (one per
    sample the publisher wrote), counted while the topic has one publisher. A number
    lower than the last (a new publisher, or several interleaving) starts over without
    counting. ``reported``: the middleware's ``message_lost`` total. Both count a sample
    a publisher dropped before resending it, so ``lost`` is the larger, not the sum.
    """

    def __init__(self, publisher_count: Callable[[], int]):
        self.publisher_count = publisher_count
        self.sequence_gaps = 0
        self.reported = 0
        self._last: int | None = None

    @property
    def lost(self) -> int:
        return max(self.sequence_gaps, self.reported)

    def on_sequence(self, number: int | None) -> int:
        """Note a message's publication sequence number; the messages it shows lost."""
        if not number:
            return 0
        last, self._last = self._last, number
        if last is None or number <= last + 1:
            return 0
        if self.publisher_count() != 1:
            return 0  # several publishers: their numbers interleave, no gap to read
        self.sequence_gaps += number - last - 1
        return number - last - 1

    def on_reported(self, total: int) -> int:
        """Note the middleware's running total of lost samples; the increase."""
        increase = max(0, total - self.reported)
        self.reported = max(self.reported, total)
        return increase


class Recorder:
    """Records topics seen on the graph of ``node`` into ``writer``.

    Args:
        node: an rclpy node to create subscriptions on.
        writer: an open ``BagWriter`` or ``BagFolderWriter``.
        topics: topic names to record (subscribed as soon as a publisher appears).
        all_topics: record every (non-hidden) topic, including ones that appear later.
        regex: also record topics whose whole name matches this pattern.
        exclude: never record topics whose whole name matches this pattern.
        discovery_period: s between graph scans.
        on_message: optional callback ``(topic, log_time_ns)`` after each message.
    """

    def __init__(self, node: Any, writer: Any, *, topics: Iterable[str] = (),
                 all_topics: bool = False, regex: str | None = None,
                 exclude: str | None = None, discovery_period: float = 0.2,
                 on_message: Callable[[str, int], None] | None = None):
        self.node = node
        self.writer = writer
        self.selection = TopicSelection.build(topics, regex=regex, exclude=exclude,
                                              all_topics=all_topics)
        self.on_message = on_message
        self.stats = RecorderStats()
        #: per topic: the latest publish time written (ns), when the latest message
        #: arrived (monotonic s) and the gaps between the publish times of the last
        #: messages (ns; ``typical_gap``)
        self.latest_publish: dict[str, int] = {}
        self.latest_arrival: dict[str, float] = {}
        self.publish_gaps: dict[str, deque] = {}
        self._previous_publish: dict[str, int] = {}
        self._subscriptions: dict[str, Any] = {}
        self._losses: dict[str, LossTracker] = {}
        self._warned: dict[str, tuple[int, float]] = {}  # total warned of, when (monotonic s)
        self._skipped: set[str] = set()
        self._lock = threading.Lock()
        self._discovery_timer = node.create_timer(discovery_period, self.discover)
        self._flush_timer = node.create_timer(
            max(0.05, writer.flush_interval / 4), writer.flush_if_due)
        self.discover()

    @property
    def subscribed(self) -> list[str]:
        return sorted(self._subscriptions)

    def discover(self) -> None:
        """Subscribe to wanted topics that now have publishers."""
        for topic, types in self.node.get_topic_names_and_types():
            if topic in self._subscriptions or topic in self._skipped or not types:
                continue
            if not self.selection.wants(topic):
                continue
            if topic.endswith('/_service_event'):
                continue
            infos = self.node.get_publishers_info_by_topic(topic)
            if not infos:
                continue  # only subscribers so far: wait for a publisher to learn its QoS
            self._subscribe(topic, types, infos)

    def _subscribe(self, topic: str, types: list[str], infos: list[Any]) -> None:
        type_name = types[0]
        logger = self.node.get_logger()
        if len(types) > 1:
            logger.warning(f"topic '{topic}' has several types {types}; recording {type_name}")
        try:
            msg_class = import_message_class(type_name)
            definition = schemas.message_definition(type_name)
        except RecordingError as err:
            logger.warning(f"not recording '{topic}': {err}")
            self._skipped.add(topic)
            return
        profiles = [qos_mod.from_rclpy(info.qos_profile) for info in infos
                    if info.topic_type == type_name] or [qos_mod.default_profile()]
        hashes = {str(info.topic_type_hash) for info in infos if info.topic_type == type_name}
        hashes.discard('INVALID')
        type_hash = hashes.pop() if len(hashes) == 1 else schemas.type_hash(type_name)
        self.writer.add_topic(topic, type_name, offered_qos_profiles=profiles,
                              type_hash=type_hash or '', definition=definition)
        self._losses[topic] = LossTracker(lambda: self.node.count_publishers(topic))
        self._subscriptions[topic] = self.node.create_subscription(
            msg_class, topic, self._callback(topic), self._request_qos(profiles), raw=True,
            event_callbacks=self._event_callbacks(topic))
        logger.info(f"recording '{topic}' ({type_name})")

    def _event_callbacks(self, topic: str) -> Any:
        """The subscription's events: ``message_lost`` counted as lost on ``topic``."""
        from rclpy.event_handler import SubscriptionEventCallbacks

        def message_lost(status: Any) -> None:
            self._losses[topic].on_reported(status.total_count)
            self._note_lost(topic, 'the middleware reports them lost')
        return SubscriptionEventCallbacks(message_lost=message_lost)

    def _note_lost(self, topic: str, how: str) -> None:
        """Take ``topic``'s lost count from its tracker; warn if it grew (at most every
        ``LOSS_WARNING_PERIOD`` s a topic, with what was lost since the last warning)."""
        total = self._losses[topic].lost
        if total <= self.stats.lost.get(topic, 0):
            return
        self.stats.lost[topic] = total
        warned, warned_at = self._warned.get(topic, (0, -LOSS_WARNING_PERIOD))
        now = time.monotonic()
        if now - warned_at < LOSS_WARNING_PERIOD:
            return
        self._warned[topic] = (total, now)
        self.node.get_logger().warning(
            f"lost {counted(total - warned, 'message')} on '{topic}' ({how}; "
            f'{total} so far)')

    @property
    def lost(self) -> dict[str, int]:
        """Messages known lost, per topic (topics without losses left out)."""
        return {topic: n for topic, n in sorted(self.stats.lost.items()) if n}

    @staticmethod
    def _request_qos(profiles: list[dict]) -> Any:
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        reliable = all(p['reliability'] == 'reliable' for p in profiles)
        latched = all(p['durability'] == 'transient_local' for p in profiles)
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=SUBSCRIPTION_DEPTH,
            reliability=ReliabilityPolicy.RELIABLE if reliable else
            ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else
            DurabilityPolicy.VOLATILE)

    def _callback(self, topic: str) -> Callable[[bytes, Any], None]:
        def callback(data: bytes, info: Any) -> None:
            self._record(topic, data, info)
            # Drain what else is queued in one executor dispatch: far less overhead
            # per message than one dispatch each at full physics rate.
            sub = self._subscriptions.get(topic)
            if sub is None:
                return
            try:
                with sub.handle:
                    for _ in range(SUBSCRIPTION_DEPTH):
                        taken = sub.handle.take_message(sub.msg_type, True)
                        if taken is None:
                            break
                        self._record(topic, taken[0], taken[1])
            except Exception:  # noqa: BLE001 - an rclpy without handle access: no draining
                pass
        return callback

    def _record(self, topic: str, data: bytes, info: Any) -> None:
        received = 0
        sent = 0
        if isinstance(info, dict):
            received = int(info.get('received_timestamp') or 0)
            sent = int(info.get('source_timestamp') or 0)
        log_time = received if received > 0 else time.time_ns()
        publish_time = sent if sent > 0 else log_time
        if isinstance(info, dict):
            if self._losses[topic].on_sequence(info.get('publication_sequence_number')):
                self._note_lost(topic, 'a gap in the publication sequence numbers')
        self.writer.write(topic, data, log_time=log_time, publish_time=publish_time)
        self.stats.messages += 1
        self.stats.bytes += len(data)
        self.stats.per_topic[topic] = self.stats.per_topic.get(topic, 0) + 1
        previous = self._previous_publish.get(topic)
        if previous is not None:
            gaps = self.publish_gaps.get(topic)
            if gaps is None:
                gaps = self.publish_gaps[topic] = deque(maxlen=GAP_HISTORY)
            gaps.append(max(0, publish_time - previous))
        self._previous_publish[topic] = publish_time
        self.latest_publish[topic] = max(publish_time, self.latest_publish.get(topic, 0))
        self.latest_arrival[topic] = time.monotonic()
        if self.on_message is not None:
            self.on_message(topic, log_time)

    def typical_gap(self, topic: str) -> float | None:
        """s: the median gap between the publish times (source timestamps) of the
        topic's last messages; None before it delivered ``STEADY_MESSAGES``.

        Publish times, not arrival times: the recorder takes what queued up in bursts
        (and not at all while the machine is too busy), the publisher's rhythm shows
        in its timestamps.
        """
        gaps = self.publish_gaps.get(topic)
        if gaps is None or len(gaps) < STEADY_MESSAGES - 1:
            return None
        ordered = sorted(gaps)
        return ordered[len(ordered) // 2] * 1e-9

    def quiet_time(self, topic: str, quiet: float = STOP_QUIET) -> float:
        """s: how long a silence of ``topic`` means it has stopped publishing:
        ``STOP_QUIET_PERIODS`` of its typical gaps, at least ``quiet``, at most
        ``STOP_QUIET_MAX`` (``quiet`` while its gap is unknown)."""
        gap = self.typical_gap(topic)
        if gap is None:
            return quiet
        return min(max(quiet, STOP_QUIET_MAX), max(quiet, STOP_QUIET_PERIODS * gap))

    def steady(self, topic: str, stopped_at: float, quiet: float = STOP_QUIET) -> bool:
        """Whether ``topic`` was publishing steadily at a stop at ``stopped_at``
        (monotonic s): it delivered ``STEADY_MESSAGES`` messages at least, its typical
        gap is at most ``STOP_QUIET_MAX``, its latest message arrived less than its
        quiet time before the stop (or after it), and it still has a publisher (one
        that left the graph, e.g. stopped by the same Ctrl-C, publishes nothing more)."""
        gap = self.typical_gap(topic)
        if gap is None or gap > STOP_QUIET_MAX:
            return False
        arrival = self.latest_arrival.get(topic)
        if arrival is None or stopped_at - arrival >= self.quiet_time(topic, quiet):
            return False
        return self.node.count_publishers(topic) > 0

    def caught_up(self, stopped_at_ns: int, stopped_at: float,
                  quiet: float = STOP_QUIET) -> bool:
        """Whether every subscribed topic has delivered what was published before a stop.

        A topic has once it delivered a message published at or after ``stopped_at_ns``
        (system clock, ns). Short of that:

        * a topic publishing steadily at the stop (``steady``) has once it has been
          silent for ``STEADY_QUIET`` since the later of its last message and the stop:
          more of its messages published before the stop may be on their way while the
          recorder or the machine stalls (a publisher paused just before the stop sends
          nothing more, and is not waited for longer);
        * any other topic (latched, event-like, slow, few messages so far, or silent for
          its quiet time already at the stop) has once it has been silent for its
          ``quiet_time`` (at least ``quiet`` s, more on a topic with longer gaps) since
          the later of its last message and ``stopped_at`` (monotonic s).

        Judged afresh at each call: a topic that delivers a message after the stop
        (what queued while the recorder was held up) counts as steady from then on.
        """
        now = time.monotonic()
        for topic in self._subscriptions:
            if self.latest_publish.get(topic, 0) >= stopped_at_ns:
                continue
            since = max(self.latest_arrival.get(topic, stopped_at), stopped_at)
            limit = (STEADY_QUIET if self.steady(topic, stopped_at, quiet)
                     else self.quiet_time(topic, quiet))
            if now - since < limit:
                return False
        return True

    def destroy(self) -> None:
        for sub in self._subscriptions.values():
            self.node.destroy_subscription(sub)
        self._subscriptions.clear()
        self.node.destroy_timer(self._discovery_timer)
        self.node.destroy_timer(self._flush_timer)


def finish_after_stop(executor: Any, recorder: Recorder, *, quiet: float = STOP_QUIET,
                      ceiling: float = STOP_CEILING) -> None:
    """Keep recording until every topic has delivered what was published before now.

    Messages already acknowledged to the recorder but not yet taken, and those still on
    their way from a busy publisher, would otherwise be lost on Ctrl-C. A topic
    publishing steadily is waited for until it delivers a message published after the
    stop or has been silent for ``STEADY_QUIET``, a sparse or silent one until it has
    been quiet for its quiet time (``Recorder.caught_up``; ``quiet``: the shortest).
    Waits at most ``ceiling`` s (a warning on stderr if messages may still have been in
    flight: a topic still delivering what was published before the stop).
    """
    stopped_at_ns = time.time_ns()
    stopped_at = time.monotonic()
    while not recorder.caught_up(stopped_at_ns, stopped_at, quiet):
        if time.monotonic() - stopped_at >= ceiling:
            print(f'record: stopped after waiting {ceiling:g} s for messages published before '
                  'the stop; some may not have arrived', file=sys.stderr)
            return
        executor.spin_once(timeout_sec=min(0.05, quiet))


def run_record(output: str, *, topics: Iterable[str] = (), all_topics: bool = False,
               regex: str | None = None, exclude: str | None = None,
               duration: float | None = None, flush_interval: float = DEFAULT_FLUSH_INTERVAL,
               max_messages: int | None = None, max_bag_size: int = 0,
               max_bag_duration: float = 0.0, compression: str = 'zstd',
               node_name: str | None = None) -> str:
    """Record until Ctrl-C/SIGTERM, ``duration`` s or ``max_messages``; return a summary.

    ``output`` is a bag folder to create (split by ``max_bag_size`` bytes and/or
    ``max_bag_duration`` s) or, ending in ``.mcap``, one file. On a signal or at the end
    of ``duration``, messages published before the stop that are still queued or in
    flight are written too (``finish_after_stop``). The files are always
    closed properly (summary, statistics, rosbag2 metadata, ``metadata.yaml``), except
    after SIGKILL, where ``recover`` rebuilds them.
    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    topics = list(topics)
    TopicSelection.build(topics, regex=regex, exclude=exclude, all_topics=all_topics)
    writer = open_bag_writer(output, max_bag_size=max_bag_size,
                             max_bag_duration=max_bag_duration, compression=compression,
                             flush_interval=flush_interval)
    stop = threading.Event()

    def request_stop(_signum: int, _frame: Any) -> None:
        stop.set()

    # no command line: rcl would read this verb's own arguments (e.g. --remap
    # A:=B) as ROS remapping rules and warn that their syntax is deprecated
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    previous = {sig: signal.signal(sig, request_stop) for sig in (signal.SIGINT,
                                                                  signal.SIGTERM)}
    node = None
    recorder = None
    try:
        writer.open()
        node = rclpy.create_node(node_name or f'gripper_sim_recorder_{os.getpid()}')
        recorder = Recorder(node, writer, topics=topics, all_topics=all_topics, regex=regex,
                            exclude=exclude)
        executor = SingleThreadedExecutor()
        executor.add_node(node)
        deadline = None if duration is None else time.monotonic() + duration
        full = False
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.05)
            if deadline is not None and time.monotonic() >= deadline:
                break
            if max_messages is not None and recorder.stats.messages >= max_messages:
                full = True
                break
        if not full:
            finish_after_stop(executor, recorder)
        executor.remove_node(node)
    finally:
        if recorder is not None:
            recorder.destroy()
            if recorder.lost:
                writer.set_custom_data(LOST_KEY, json.dumps(recorder.lost))
        writer.close()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    stats = recorder.stats if recorder is not None else RecorderStats()
    missing = sorted({('/' + t.lstrip('/')) for t in topics} - set(stats.per_topic))
    files = getattr(writer, 'files', [writer.path])
    return record_summary(stats, output, files=len(files), missing=missing)


def record_summary(stats: RecorderStats, output: str, *, files: int = 1,
                   missing: Iterable[str] = ()) -> str:
    """The line ``gripper-sim record`` ends with: messages, topics, where (with the
    number of files when split), elapsed wall time (s), the named topics that sent
    nothing and the messages lost, per topic."""
    where = f'{output} ({files} files)' if files > 1 else str(output)
    text = (f"recorded {counted(stats.messages, 'message')} on "
            f"{counted(len(stats.per_topic), 'topic')} to {where} in {stats.elapsed():.1f} s")
    missing = list(missing)
    if missing:
        text += f" (no messages on: {', '.join(missing)})"
    lost = {topic: n for topic, n in sorted(stats.lost.items()) if n}
    if lost:
        text += (f"; LOST {counted(sum(lost.values()), 'message')}: "
                 + ', '.join(f'{n} on {topic}' for topic, n in lost.items()))
    return text
