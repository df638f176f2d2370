"""The Foxglove live view: a WebSocket server (``foxglove-sdk``) on the node's topics.

``FoxgloveView`` serves, on ``host:port`` (127.0.0.1 by default):

- every topic of the node (``gripper_sim.convert.messages.TOPICS``) under its ROS name,
  message encoding ``cdr``, schema encoding ``ros2msg`` with the type's full message
  definition (``recording.schemas.message_definition``: the .msg text and every nested
  definition, as rosbag2 stores it), so Foxglove decodes them like a ROS 2 bag;
- the node's latched topics ``/tf_static`` and ``robot_description`` (the static frames,
  e.g. ``table``, and the URDF for Foxglove's 3D panel; ``recording.latched``): a
  latched channel keeps its last message and sends it to every client that subscribes
  (and again after a reset), as a transient-local publisher does;
- ``<node>/scene`` (e.g. ``/gripper_sim/scene``): a ``foxglove.SceneUpdate`` (protobuf)
  built from the node's markers (``view.scene``), for Foxglove's 3D panel without RViz
  or a URDF.

Messages carry the sim time of their step as log time, and the server announces it
(capability ``time``); when the time goes back (a reset) the session is cleared so
clients drop the old run. Work is done only for channels a client subscribed to.

A client that stops reading (busy, or on a slow link) loses data messages, the oldest
first, and once ``MESSAGE_BACKLOG`` control messages (time, session) wait for it the
server disconnects it; that is logged as one warning naming the client and the queue
(``_DropWatcher``), so that a user whose Foxglove froze can tell why.

The node starts its view with ``start_node_view(node)`` (parameters ``foxglove_port``,
0 = off, and ``foxglove_address``); ``replay`` with ``FoxgloveView.for_recording``.
"""
from __future__ import annotations

import logging
import threading
import time
import weakref
from typing import Any, Callable, Iterable, Mapping

import foxglove
from foxglove.channels import SceneUpdateChannel
from rclpy.serialization import deserialize_message, serialize_message

from gripper_sim.convert import messages
from gripper_sim.recording import qos
from gripper_sim.recording.analysis import read_config
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.latched import LATCHED_TOPICS, latched_messages, latched_topic
from gripper_sim.recording.recorder import import_message_class
from gripper_sim.recording.schemas import message_definition
from gripper_sim.view.errors import ViewError
from gripper_sim.view.scene import PressureLegend, scene_update

_LOG = logging.getLogger(__name__)
DEFAULT_PORT = 8765
DEFAULT_ADDRESS = '127.0.0.1'
MARKERS_TYPE = 'visualization_msgs/msg/MarkerArray'
STATE_TYPE = 'gripper_sim_interfaces/msg/FruitState'
SCENE_NAME = 'scene'
#: s of wall time, the shortest interval between two broadcasts of the data's time: each
#: is a control message that the server queues for every client and never drops, so one
#: per message of a fast replay filled a briefly busy client's queue (1024) within a
#: second or two and the server disconnected it
TIME_PERIOD = 0.02
#: messages of each kind (data, control) the server queues for a client; the oldest
#: data is dropped when more wait, and a client with this many control messages
#: waiting is disconnected (foxglove-sdk's ``message_backlog_size``, its default)
MESSAGE_BACKLOG = 1024


def scene_topic(markers_topic: str) -> str:
    """The scene's topic beside the markers topic: ``/gripper_sim/markers`` ->
    ``/gripper_sim/scene``."""
    parent = markers_topic.rsplit('/', 1)[0]
    return f'{parent}/{SCENE_NAME}'


def shown_address(host: str) -> str:
    """``host`` as an error message shows it: quoted when empty or holding spaces or
    control characters (a newline in ``foxglove_address`` split the message)."""
    plain = host and host.isprintable() and not any(c.isspace() for c in host)
    return host if plain else repr(host)


def _only_topic_of(topics: Mapping[str, str], type_name: str) -> str | None:
    found = [name for name, kind in topics.items() if kind == type_name]
    return found[0] if len(found) == 1 else None


class _DropWatcher(logging.Filter):
    """Logs a warning when the server drops a client that fell behind.

    foxglove-sdk disconnects a client whose control queue is full without telling the
    program (``ServerListener`` has no reason, ``Client`` no address); its Rust log,
    forwarded to Python's logging (``pyo3-log``, logger = Rust module), says
    ``Connection closed by client <address>`` (INFO, ``POLLER``) when the client
    closed the connection and ``Unregistered client <address>`` (INFO, ``SERVER``)
    whenever a client is gone. A client gone without closing, while no view is
    stopping its server, was dropped for its full queue (the SDK's only other reason).
    The SDK lets a dropped connection go (and the warning comes) once it has sent the
    client its last status, i.e. when the client reads again (Foxglove, no longer
    busy, finds itself disconnected) or its connection breaks.

    ``install`` (before the first server starts: pyo3-log reads a logger's level on
    its first record) lowers those two loggers to INFO and filters them: records at
    the level they passed before (their own, else their parent's) go on, the INFO ones
    below it are only read here. With ``FOXGLOVE_LOG_LEVEL`` above info (or
    ``foxglove.set_log_level`` called first) the SDK never sends them and a drop is not
    logged.
    """

    SERVER = 'foxglove.websocket.server'
    POLLER = 'foxglove.websocket.connected_client.poller'
    CLOSED = 'Connection closed by client '
    GONE = 'Unregistered client '

    def __init__(self) -> None:
        super().__init__()
        self._lock = threading.Lock()
        self._installed = False
        self._own_levels: dict[str, int] = {}
        self._closed: set[str] = set()   # addresses that closed their connection
        self._stopping = 0               # views stopping their server now
        self._views: weakref.WeakSet[FoxgloveView] = weakref.WeakSet()

    def install(self) -> None:
        with self._lock:
            if self._installed:
                return
            self._installed = True
            for name in (self.SERVER, self.POLLER):
                logger = logging.getLogger(name)
                self._own_levels[name] = logger.level
                if logger.level == logging.NOTSET or logger.level > logging.INFO:
                    logger.setLevel(logging.INFO)
                logger.addFilter(self)

    def add(self, view: 'FoxgloveView') -> None:
        with self._lock:
            self._views.add(view)

    def stop(self, view: 'FoxgloveView') -> None:
        """Stop ``view``'s server: the clients it disconnects were not dropped."""
        with self._lock:
            self._stopping += 1
            self._views.discard(view)
        try:
            view.server.stop()
        finally:
            with self._lock:
                self._stopping -= 1

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if record.name == self.POLLER and message.startswith(self.CLOSED):
            with self._lock:
                self._closed.add(message.removeprefix(self.CLOSED))
        elif record.name == self.SERVER and message.startswith(self.GONE):
            address = message.removeprefix(self.GONE)
            with self._lock:
                closed = address in self._closed
                self._closed.discard(address)
                dropped = not closed and self._stopping == 0
                views = list(self._views)
            if dropped:
                where = f'live view on {views[0].url}' if len(views) == 1 else 'live view'
                _LOG.warning(
                    f'{where}: dropped Foxglove client {address}: it fell more than '
                    f'{MESSAGE_BACKLOG} messages behind (its queue of time and session '
                    'updates on the server was full: it stopped reading, busy or on a '
                    'slow link); it gets nothing more until it reconnects')
        own = self._own_levels.get(record.name, logging.NOTSET)
        if own == logging.NOTSET:
            parent = record.name.rpartition('.')[0]
            own = logging.getLogger(parent).getEffectiveLevel()
        return record.levelno >= own


_DROPS = _DropWatcher()


class FoxgloveView:
    """A Foxglove WebSocket server streaming ROS topics (CDR) and the 3D scene.

    Args:
        topics: ``{topic name: ROS type}`` (``'pkg/msg/Type'``) to serve.
        legend: the pressure colour bar of the scene (None = no legend).
        host, port: where to listen (port 0 = any free port; the node's parameter 0
            means off and never gets here).
        name: the server name clients show.
        on_watched: called with True when a client subscribes to the first channel and
            with False when the last subscription ends (from the server's thread): the
            node builds its messages for the view only while someone watches.
        latched: topics of ``topics`` served as latched (``latch``, or every message of
            ``log_cdr``, is kept and sent to each new subscriber).

    The scene is served when exactly one topic is a ``MarkerArray`` (its markers) and
    drawn with the ``FruitState`` of the same step when there is such a topic.

    Raises:
        ViewError: the server cannot listen there (port taken, bad address), or a
            type's message definition is not installed.
    """

    def __init__(self, topics: Mapping[str, str], *, legend: PressureLegend | None = None,
                 host: str = DEFAULT_ADDRESS, port: int = DEFAULT_PORT,
                 name: str = 'gripper_sim', on_watched: Callable[[bool], None] | None = None,
                 latched: Iterable[str] = ()):
        self.host = host
        self.legend = legend
        self._types = dict(topics)
        self._markers_topic = _only_topic_of(self._types, MARKERS_TYPE)
        self._state_topic = _only_topic_of(self._types, STATE_TYPE)
        self._classes: dict[str, Any] = {}
        self._last_state: Any = None
        self._last_time: int | None = None
        self._time_sent: float | None = None   # monotonic s of the last time broadcast
        self._latched_topics = set(latched) & set(self._types)
        self._latched: dict[str, bytes] = {}      # topic -> its last message (CDR)
        self.channels: dict[str, Any] = {}        # filled once the server listens
        # Kept: the server and the channels are bound to it only while it lives.
        self._context = context = foxglove.Context()
        try:
            schemas = {topic: foxglove.Schema(name=kind, encoding='ros2msg',
                                              data=message_definition(kind).encode())
                       for topic, kind in self._types.items()}
        except RecordingError as err:
            raise ViewError(f'cannot serve the live view: {err}') from err
        _DROPS.install()
        try:
            self.server = foxglove.start_server(
                name=name, host=host, port=int(port), context=context,
                capabilities=[foxglove.Capability.Time],
                server_listener=_SubscriptionCounter(on_watched, self._on_subscribe),
                message_backlog_size=MESSAGE_BACKLOG)
        except RuntimeError as err:   # foxglove-sdk's FoxgloveError, e.g. port taken
            reason = str(err).removeprefix('FoxgloveError: ')
            msg = (f'cannot serve the Foxglove live view on {shown_address(host)}:{port}: '
                   f'{reason}; choose '
                   'a free port or an address of this machine')
            raise ViewError(msg) from err
        _DROPS.add(self)
        self.channels.update({topic: foxglove.Channel(topic, schema=schema,
                                                      message_encoding='cdr',
                                                      context=context)
                              for topic, schema in schemas.items()})
        self.scene_topic = (scene_topic(self._markers_topic)
                            if self._markers_topic is not None else None)
        self.scene_channel = (SceneUpdateChannel(self.scene_topic, context=context)
                              if self.scene_topic is not None else None)
        self.scenes = 0
        self.undecodable = 0   # recorded messages the scene could not read (log_cdr)
        self._undecodable_topics: set[str] = set()

    @property
    def port(self) -> int:
        """The port the server listens on."""
        return int(self.server.port)

    @property
    def url(self) -> str:
        host = f'[{self.host}]' if ':' in self.host else self.host   # IPv6
        return f'ws://{host}:{self.port}'

    def _advance_time(self, stamp_ns: int) -> None:
        """Tell the clients the data's time ``stamp_ns``: a reset (time going back) at
        once, a later time at most every ``TIME_PERIOD`` s of wall time."""
        now = time.monotonic()
        if self._last_time is not None and stamp_ns < self._last_time:
            self.server.clear_session()   # a reset: clients drop the old run
            self._last_state = None
            self._time_sent = None
            self._last_time = stamp_ns
            for topic in self._latched:   # ... and get the latched messages again
                self._send_latched(topic)
        self._last_time = stamp_ns
        if self._time_sent is None or now - self._time_sent >= TIME_PERIOD:
            self.server.broadcast_time(stamp_ns)
            self._time_sent = now

    def latch(self, topic: str, data: bytes) -> None:
        """Serve ``data`` (CDR) as the latched message of ``topic``: now to its
        subscribers, later to each client that subscribes."""
        if topic in self._latched_topics:
            self._latched[topic] = data
            self._send_latched(topic)

    def _send_latched(self, topic: str) -> None:
        channel = self.channels.get(topic)
        data = self._latched.get(topic)
        if channel is not None and data is not None and channel.has_sinks():
            channel.log(data, log_time=self._last_time or 0)

    def _on_subscribe(self, topic: str) -> None:
        """A client subscribed to ``topic`` (server thread): a latched one gets its
        message (every subscriber of the channel does; a latched message is the same
        whenever it arrives)."""
        if topic in self._latched_topics:
            self._send_latched(topic)

    def _scene_wanted(self) -> bool:
        return self.scene_channel is not None and self.scene_channel.has_sinks()

    def _log_scene(self, markers: Any, state: Any, stamp_ns: int) -> None:
        assert self.scene_channel is not None
        update = scene_update(markers.markers, legend=self.legend, fruit_state=state,
                              stamp_ns=stamp_ns)
        self.scene_channel.log(update, log_time=stamp_ns)
        self.scenes += 1

    def log_messages(self, batch: Mapping[str, Any], stamp_ns: int) -> None:
        """Serve one step's messages ``{topic: ROS message}`` (live, from the node)."""
        self._advance_time(stamp_ns)
        for topic, msg in batch.items():
            channel = self.channels.get(topic)
            if channel is not None and channel.has_sinks():
                channel.log(serialize_message(msg), log_time=stamp_ns)
        if self._scene_wanted() and self._markers_topic in batch:
            self._log_scene(batch[self._markers_topic], batch.get(self._state_topic),
                            stamp_ns)

    def _decode(self, topic: str, data: bytes, stamp_ns: int) -> Any:
        """The message of ``data`` (CDR), or None if it is not one of ``topic``'s type (a
        damaged recording): that is logged once per topic and the scene goes without
        it, while the bytes are still served as recorded (``replay`` publishes them)."""
        cls = self._classes.get(topic)
        if cls is None:
            cls = self._classes[topic] = import_message_class(self._types[topic])
        try:
            return deserialize_message(data, cls)
        except Exception as err:  # noqa: BLE001 - rclpy raises its RMWError, not exported
            self.undecodable += 1
            if topic not in self._undecodable_topics:
                self._undecodable_topics.add(topic)
                _LOG.warning(f'live view: a {topic} message at {stamp_ns / 1e9:.3f} s is not '
                             f'a {self._types[topic]} ({err}); the scene goes without it '
                             '(and without any later one that cannot be read)')
            return None

    def log_cdr(self, topic: str, data: bytes, stamp_ns: int) -> None:
        """Serve one recorded message (CDR bytes) of ``topic`` (replay); the scene is
        drawn from each markers message with the latest fruit state before it."""
        channel = self.channels.get(topic)
        if channel is None:
            return
        self._advance_time(stamp_ns)
        if topic in self._latched_topics:
            self._latched[topic] = data
        if channel.has_sinks():
            channel.log(data, log_time=stamp_ns)
        if not self._scene_wanted():
            return
        if topic not in (self._state_topic, self._markers_topic):
            return
        message = self._decode(topic, data, stamp_ns)
        if message is None:
            return
        if topic == self._state_topic:
            self._last_state = message
        else:
            self._log_scene(message, self._last_state, stamp_ns)

    def close(self) -> None:
        """Stop the server (clients are disconnected)."""
        for channel in self.channels.values():
            channel.close()
        if self.scene_channel is not None:
            self.scene_channel.close()
        _DROPS.stop(self)


class _SubscriptionCounter:
    """A ``foxglove.websocket.ServerListener`` that counts subscriptions (all clients)
    and reports when the count leaves or returns to zero."""

    def __init__(self, on_watched: Callable[[bool], None] | None,
                 on_channel: Callable[[str], None] | None = None):
        self._on_watched = on_watched
        self._on_channel = on_channel
        self._lock = threading.Lock()
        self.count = 0

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.count += 1
            first = self.count == 1
        if first and self._on_watched is not None:
            self._on_watched(True)
        if self._on_channel is not None:
            self._on_channel(channel.topic)

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        with self._lock:
            self.count = max(self.count - 1, 0)
            last = self.count == 0
        if last and self._on_watched is not None:
            self._on_watched(False)


def node_topics(node_name: str, namespace: str) -> dict[str, tuple[str, str]]:
    """``{topic suffix: (topic name, ROS type)}`` of a node named so: the topics it
    publishes with every state batch."""
    return {suffix: (messages.resolved_topic(suffix, node_name, namespace), kind)
            for suffix, (_, kind) in messages.TOPICS.items()}


def node_latched_topics(namespace: str) -> dict[str, str]:
    """``{topic name: ROS type}`` of the latched topics of a node in ``namespace``."""
    return {latched_topic(suffix, namespace): kind
            for suffix, (_, kind) in LATCHED_TOPICS.items()}


def latch_node_description(view: FoxgloveView, frames: Any, namespace: str) -> None:
    """Serve the node's ``/tf_static`` and ``robot_description`` of ``frames``
    (``GripperFrames``) on ``view``, latched: the messages the node publishes."""
    for suffix, msg in latched_messages(frames).items():
        view.latch(latched_topic(suffix, namespace), serialize_message(msg))


def start_node_view(node: Any) -> FoxgloveView | None:
    """Serve the live view of a ``SimNode`` (None if ``foxglove_port`` is 0 or it fails).

    Reads the node's parameters ``foxglove_port`` and ``foxglove_address`` and its
    ``message_context`` (the legend). While a client subscribes to anything, it
    observes every batch the node publishes (``add_publish_observer``; removed again
    when the last subscription ends: an observer makes the node build every message).
    A port already in use is a warning: the node runs on without the view.
    """
    port = int(node.params.get('foxglove_port'))
    host = str(node.params.get('foxglove_address'))
    logger = node.get_logger()
    if port == 0:
        return None
    namespace = node.get_namespace()
    topics = node_topics(node.get_name(), namespace)
    latched = node_latched_topics(namespace)
    feed = NodeFeed(node, {suffix: name for suffix, (name, _) in topics.items()})
    try:
        feed.view = FoxgloveView({**{name: kind for name, kind in topics.values()},
                                  **latched},
                                 legend=PressureLegend.beside(node.message_context),
                                 host=host, port=port, name=node.get_fully_qualified_name(),
                                 on_watched=feed.watched, latched=latched)
    except ViewError as err:
        logger.warning(f'{err} (parameters foxglove_port, 0 = off, and foxglove_address); '
                       'running without the live view')
        return None
    view = feed.view
    latch_node_description(view, node.message_context.frames, namespace)
    logger.info(f'Foxglove live view on {view.url} (in Foxglove: Open connection > '
                'Foxglove WebSocket; layout config/foxglove/gripper_sim_layout.json)')
    return view


class NodeFeed:
    """Feeds the batches a node publishes to its view while a client watches.

    Args:
        node: has ``add_publish_observer`` / ``remove_publish_observer``.
        names: ``{topic suffix: topic name}`` of the node.
    """

    def __init__(self, node: Any, names: Mapping[str, str]):
        self.node = node
        self.names = dict(names)
        self.view: FoxgloveView | None = None

    def watched(self, yes: bool) -> None:
        """``FoxgloveView``'s ``on_watched``: observe the node only while watched."""
        if yes:
            self.node.add_publish_observer(self.observe)
        else:
            self.node.remove_publish_observer(self.observe)

    def observe(self, batch: Mapping[str, Any], stamp_ns: int) -> None:
        """A publish observer: ``batch`` is ``{topic suffix: message}``.

        It runs in the node's physics thread, which resets the simulation on any
        exception: a failing view logs the error and stops feeding instead.
        """
        if self.view is None:
            return
        try:
            self.view.log_messages({self.names[s]: msg for s, msg in batch.items()}, stamp_ns)
        except Exception as err:  # noqa: BLE001 - never let the view reset the physics
            self.view = None
            self.node.remove_publish_observer(self.observe)
            self.node.get_logger().error(
                f'Foxglove live view stopped: {type(err).__name__}: {err}')


def recording_view(bag: Any, *, host: str = DEFAULT_ADDRESS, port: int = DEFAULT_PORT,
                   topics: list[str] | None = None) -> FoxgloveView:
    """The view of an open ``BagReader`` for ``replay``: its CDR topics (``topics`` =
    only these; latched those whose recorded publishers offered transient local, as
    ``replay`` publishes them), the legend from the configuration stored in it (if
    any)."""
    wanted = set(topics) if topics is not None else None
    served = {name: info.type for name, info in bag.topics.items()
              if info.message_encoding == 'cdr' and (wanted is None or name in wanted)}
    latched = [name for name in served if qos.adapt_for_replay(
        bag.topics[name].offered_qos_profiles)['durability'] == 'transient_local']
    legend = PressureLegend.beside(messages.MessageContext.from_config(read_config(bag)))
    return FoxgloveView(served, legend=legend, host=host, port=port,
                        name=f'gripper_sim replay {bag.path}', latched=latched)
