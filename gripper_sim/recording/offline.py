"""Record a simulation's steps to MCAP as the node would publish them: offline and in-node.

``SimRecorder`` is a step observer (``on_step(result)``) that converts each
``StepResult`` with ``gripper_sim.convert.messages.build_messages`` (the node's own
conversion), serializes the messages and writes them under the node's topic names
(``/gripper_sim/fruit/state``, ...). Log and publish times are the sim time of the step
in integer ns, the same as the messages' header stamps and ``/clock`` (after a reset of
the simulation, shifted so that log times keep increasing). The
configuration used is stored as a Metadata record ``gripper_sim_config`` (key ``yaml``)
when the file is opened, so a run can be reproduced from its recording. With ``/tf``
the node's latched topics ``/tf_static`` and ``robot_description`` are recorded too,
once, at the start (``recording.latched``), so the TF tree of a replay is whole.

Offline (``squeeze``/``pick --out FILE.mcap``)::

    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        ...

In the node (``record_path`` parameter, start/stop): create it with the node's
``MessageContext`` and ``add_observer(rec.on_step)``; call ``close()`` to stop. Calls
to ``on_step`` after ``close()`` are ignored, so stopping from another thread is safe.
"""
from __future__ import annotations

import os
import threading
from typing import Any, Iterable, Mapping

from gripper_sim import __version__
from gripper_sim.configuration import to_yaml
from gripper_sim.convert import messages
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.lifecycle import OpenClose
from gripper_sim.recording.bag_folder import open_bag_writer
from gripper_sim.recording.cdr import CdrTrimmer
from gripper_sim.recording.latched import (LATCHED_PROFILE, LATCHED_TOPICS, latched_messages,
                                           latched_topic)
from gripper_sim.recording.writer import DEFAULT_FLUSH_INTERVAL

CONFIG_METADATA = 'gripper_sim_config'


class SimRecorder(OpenClose):
    """Writes every ``every``-th step of a run to a rosbag2 bag folder or MCAP file.

    Args:
        path: the bag folder to create, or one file when it ends in ``.mcap`` (never
            overwritten unless ``overwrite``, which only a single file allows).
        config: the flat configuration of the run (stored in the file).
        initial: the result of the initial state (``Simulation.last`` before any step):
            written as the first sample and used for the jaw joint origin.
        context: a ``MessageContext`` to share (the node's); default: a new one.
        node_name, namespace: give the topic names, as the node's would be.
        topics: topic suffixes to write (``messages.TOPICS`` keys); None = all. With
            'tf', the latched ``/tf_static`` and ``robot_description`` are written
            once, before the first sample.
        every: write every n-th step (1 = every step, full physics rate).
        source: 'offline' or 'node', stored with the configuration.
        overwrite, flush_interval: passed to ``BagWriter``.

    Raises:
        RecordingError: the file cannot be created; bad ``every`` or topic suffix.
    """

    def __init__(self, path: str | os.PathLike, config: Mapping[str, Any], *,
                 initial: Any = None, context: Any = None, node_name: str = 'gripper_sim',
                 namespace: str = '/', topics: Iterable[str] | None = None, every: int = 1,
                 source: str = 'offline', overwrite: bool = False,
                 flush_interval: float = DEFAULT_FLUSH_INTERVAL):
        self._messages = messages
        if int(every) < 1:
            raise RecordingError(f'every must be a positive whole number of steps, got {every}')
        self.every = int(every)
        self.suffixes = list(messages.TOPICS) if topics is None else list(topics)
        unknown = set(self.suffixes) - set(messages.TOPICS)
        if unknown:
            raise RecordingError(f"unknown topic suffix(es) {', '.join(sorted(unknown))}; "
                                 f"known: {', '.join(messages.TOPICS)}")
        self.config = dict(config)
        self.context = context if context is not None else \
            messages.MessageContext.from_config(self.config, initial=initial)
        self.topic_names = {s: messages.resolved_topic(s, node_name, namespace)
                            for s in self.suffixes}
        self.latched_names = {s: latched_topic(s, namespace) for s in LATCHED_TOPICS} \
            if 'tf' in self.suffixes else {}
        self._latched_due = bool(self.latched_names)
        self.initial = initial
        self.source = source
        self._trimmer = CdrTrimmer()
        self.writer = open_bag_writer(path, overwrite=overwrite, flush_interval=flush_interval)
        self.steps_seen = 0
        self.samples = 0
        self.failures = 0
        self._lock = threading.Lock()
        self._last_time_ns: int | None = None
        self._offset = 0
        self.last_error: str = ''

    @property
    def path(self):
        return self.writer.path

    # ------------------------------------------------------------------ lifecycle
    @property
    def is_open(self) -> bool:
        return self.writer.is_open

    def open(self) -> None:
        """Create the file, register the topics, store the configuration."""
        with self._lock:
            self.writer.open()
            try:
                for suffix in self.suffixes:
                    self.writer.add_topic(self.topic_names[suffix],
                                          self._messages.TOPICS[suffix][1])
                for suffix, name in self.latched_names.items():
                    self.writer.add_topic(name, LATCHED_TOPICS[suffix][1],
                                          offered_qos_profiles=[LATCHED_PROFILE])
                try:
                    text = to_yaml(self.config)
                except Exception as err:  # noqa: BLE001 - keep recording without it
                    text = f'# configuration could not be serialized: {err}\n'
                self.writer.add_metadata(CONFIG_METADATA, {
                    'yaml': text, 'source': self.source,
                    'gripper_sim_version': __version__})
            except BaseException:
                self.writer.close()
                raise
        if self.initial is not None:
            self.write_result(self.initial)

    def close(self) -> None:
        """Finish the file (idempotent)."""
        with self._lock:
            self.writer.close()

    # ------------------------------------------------------------------ observing
    def on_step(self, result: Any) -> None:
        """Observer: write ``result`` (every ``every``-th step). Ignored when closed."""
        self.steps_seen += 1
        if (self.steps_seen - 1) % self.every:
            return
        self.write_result(result)

    __call__ = on_step

    def reset(self) -> None:
        """The simulation was reset (its time restarts at 0); the history is cleared.

        Log times stay increasing across resets: samples after a reset are logged
        1 ms after the last one (their header stamps keep the sim time).
        """
        self.context.reset()

    def write_result(self, result: Any) -> None:
        """Write one result now, whatever ``every`` (e.g. the state after a reset)."""
        messages = self._messages
        if not messages.result_is_finite(result):
            self.failures += 1
            return
        stamp = messages.time_msg(result.time)
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        batch = messages.build_messages(result, self.context, stamp, topics=self.suffixes)
        self.write_batch(batch, ns)

    def write_batch(self, batch: Mapping[str, Any], stamp_ns: int) -> None:
        """Write already-built messages ``{suffix: msg}`` stamped ``stamp_ns`` (sim time)."""
        with self._lock:
            if not self.writer.is_open:
                return
            stamp_ns = int(stamp_ns)
            if self._last_time_ns is not None and stamp_ns + self._offset < self._last_time_ns:
                # time went back (a reset): keep the log in order, 1 ms after the last sample
                self._offset = self._last_time_ns + 1_000_000 - stamp_ns
            log_time = stamp_ns + self._offset
            if self._latched_due:
                self._write_latched(log_time)
            for suffix, msg in batch.items():
                topic = self.topic_names.get(suffix)
                if topic is None:
                    continue
                self._write(topic, self._messages.TOPICS[suffix][1], msg, log_time)
            self.samples += 1
            self._last_time_ns = log_time
            self.writer.flush_if_due()

    def _write(self, topic: str, type_name: str, msg: Any, log_time: int) -> None:
        """Serialize ``msg`` to exact CDR and write it (the lock held)."""
        from rclpy.serialization import serialize_message

        data = self._trimmer.trim(type_name, serialize_message(msg))
        self.writer.write(topic, data, log_time=log_time, publish_time=log_time)

    def _write_latched(self, log_time: int) -> None:
        """The latched topics' one message each, as the node published them (the lock
        held; before the first sample, at its log time)."""
        for suffix, msg in latched_messages(self.context.frames).items():
            self._write(self.latched_names[suffix], LATCHED_TOPICS[suffix][1], msg,
                        log_time)
        self._latched_due = False

    def describe(self) -> str:
        return (f'wrote {self.samples} samples ({self.writer.message_count} messages) to '
                f'{self.path}')


#: The name the offline CLI (``squeeze``/``pick --out``) uses.
OfflineRecorder = SimRecorder
