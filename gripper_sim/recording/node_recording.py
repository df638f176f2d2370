"""In-node recording: the ``gripper_sim`` node writes its own bag at full physics rate.

``record_path`` names the recording: a bag folder to create (``NAME/NAME_0.mcap`` and
``NAME/metadata.yaml``, as ``ros2 bag record -o NAME`` writes), or one MCAP file when
it ends in ``.mcap``. Nothing is appended to it, so the parameter always names what is
being written; an existing file or folder, or a missing or read-only parent, is
refused with the reason (``NodeRecording.problem``).

``NodeRecording`` hooks one step observer into the node (``node.add_observer``) and
forwards every physics step to the active ``SimRecorder``, if any, so recording can
start and stop any number of times. It writes every step (not only what is
published), with the node's topic names, its ``MessageContext`` (so bruising history
matches what the node publishes) and the configuration as a Metadata record.

What the node needs (``gripper_sim/ros/node.py``)::

    from gripper_sim.recording.node_recording import NodeRecording
    self.recording = NodeRecording(self)            # after message_context exists
    path = self.get_parameter('record_path').value  # '' = not recording
    if path:
        self.recording.start(path)
    # ~/record (std_srvs/SetBool): data=True starts (to record_path, or a new
    # timestamped bag folder when it is empty), data=False stops:
    ok, message = self.recording.start() / self.recording.stop()
    # in destroy_node: self.recording.stop()
    # (resets are followed through the node's add_reset_listener hook)

The node object must offer ``add_observer``, ``message_context``, ``params.config``
(or ``sim.config``), ``get_name()`` and ``get_namespace()``.
"""
from __future__ import annotations

import os
import threading
import time
from pathlib import Path
from typing import Any

from gripper_sim.recording.bag_folder import check_new_bag_path
from gripper_sim.recording.errors import RecordingError
from gripper_sim.recording.offline import SimRecorder


def default_path(directory: str | os.PathLike = '.') -> Path:
    """A new bag folder name ``gripper_sim_YYYYmmdd_HHMMSS`` in ``directory``."""
    stamp = time.strftime('%Y%m%d_%H%M%S')
    path = Path(directory) / f'gripper_sim_{stamp}'
    k = 1
    while path.exists():
        path = Path(directory) / f'gripper_sim_{stamp}_{k}'
        k += 1
    return path


class NodeRecording:
    """Start/stop recording of a sim node's every step.

    Args:
        node: the ``SimNode``.
        every: record every n-th physics step (1 = full physics rate).
    """

    def __init__(self, node: Any, *, every: int = 1):
        self.node = node
        self.every = every
        self._lock = threading.Lock()
        self._recorder: SimRecorder | None = None
        self.last_path: Path | None = None
        node.add_observer(self._on_step)
        if hasattr(node, 'add_reset_listener'):
            node.add_reset_listener(self._on_reset)

    @property
    def active(self) -> bool:
        rec = self._recorder
        return rec is not None and rec.is_open

    @property
    def path(self) -> Path | None:
        rec = self._recorder
        return rec.path if rec is not None else None

    @staticmethod
    def target(path: str | os.PathLike) -> Path:
        """The absolute bag folder (or ``.mcap`` file) that ``record_path`` = ``path`` names."""
        return Path(path).expanduser().absolute()

    @staticmethod
    def problem(path: str | os.PathLike) -> str | None:
        """Why recording to ``path`` cannot start, or None."""
        try:
            check_new_bag_path(path)
        except RecordingError as err:
            return str(err)
        return None

    def _config(self) -> dict:
        params = getattr(self.node, 'params', None)
        config = getattr(params, 'config', None)
        if config is None:
            config = getattr(getattr(self.node, 'sim', None), 'config', {})
        return dict(config)

    def start(self, path: str | os.PathLike | None = None) -> tuple[bool, str]:
        """Start recording to ``path`` (default: a new timestamped bag folder); (ok, message).

        The message names the absolute path being written.
        """
        with self._lock:
            if self._recorder is not None and self._recorder.is_open:
                return False, f'already recording to {self._recorder.path}'
            target = self.target(path if path else default_path())
            problem = self.problem(target)
            if problem is not None:
                return False, problem
            initial = None
            sim = getattr(self.node, 'sim', None)
            if sim is not None:
                initial = getattr(sim, 'last', None)
            try:
                rec = SimRecorder(
                    target, self._config(), initial=initial,
                    context=getattr(self.node, 'message_context', None),
                    node_name=self.node.get_name(), namespace=self.node.get_namespace(),
                    every=self.every, source='node')
                rec.open()
            except RecordingError as err:
                return False, str(err)
            self._recorder = rec
            self.last_path = rec.path
            return True, f'recording every step to {rec.path}'

    def stop(self) -> tuple[bool, str]:
        """Stop and finish the file; (ok, message)."""
        with self._lock:
            rec = self._recorder
            if rec is None or not rec.is_open:
                return False, 'not recording'
            self._recorder = None
        try:
            rec.close()
        except RecordingError as err:
            return False, str(err)
        return True, rec.describe()

    def on_reset(self) -> None:
        """The node reset its simulation: keep recording, with log times still increasing."""
        rec = self._recorder
        if rec is not None:
            rec.reset()

    def _on_reset(self, initial: Any) -> None:
        """Reset listener: the history restarts and the initial state is written."""
        rec = self._recorder
        if rec is None:
            return
        rec.reset()
        try:
            rec.write_result(initial)
        except RecordingError:
            pass

    def _on_step(self, result: Any) -> None:
        rec = self._recorder
        if rec is None:
            return
        try:
            rec.on_step(result)
        except RecordingError as err:
            self._recorder = None
            logger = getattr(self.node, 'get_logger', None)
            if logger is not None:
                logger().error(f'in-node recording stopped: {err}')
            try:
                rec.close()
            except RecordingError:
                pass
