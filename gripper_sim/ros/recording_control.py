"""Recording control of the node: the ``record_path`` parameter and ``~/record``.

In-node recording writes every physics step to MCAP (``NodeRecording``). Setting
``record_path`` starts the recording, ``''`` stops it; ``~/record`` (std_srvs/SetBool)
starts (to ``record_path`` or a timestamped file) and stops it, and keeps the parameter
saying what is being recorded. One recording at a time, however it was started: while
one runs, a start by either way is refused (``record_path`` set to another path too,
rather than switching recordings unasked); setting it to the path being recorded is
accepted and changes nothing.
"""
from __future__ import annotations

import threading
from pathlib import Path

from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import CallbackGroup
from rclpy.parameter import Parameter
from std_srvs.srv import SetBool

try:
    from gripper_sim.recording.node_recording import NodeRecording, default_path
    RECORDING_UNAVAILABLE = ''
except ImportError as _err:   # e.g. the mcap library is missing
    NodeRecording = None
    RECORDING_UNAVAILABLE = f'in-node recording is unavailable: {_err}'


class RecordingControl:
    """Starts and stops the in-node recording of ``node`` (a ``SimNode``).

    Register it after every other set-parameters callback: it starts or stops the
    recording, so every other check of the same change has already accepted it.

    Attributes:
        recording: the ``NodeRecording``, or None if recording is unavailable.
    """

    def __init__(self, node, group: CallbackGroup):
        self._node = node
        self._lock = threading.RLock()
        self._param_internal = False   # the node itself is updating record_path
        self.recording = NodeRecording(node) if NodeRecording is not None else None
        node.add_on_set_parameters_callback(self._check_record_path)
        node.create_service(SetBool, '~/record', self._on_record, callback_group=group)

    def start_at_startup(self) -> None:
        node = self._node
        path = str(node.params.get('record_path'))
        if not path:
            return
        ok, message = self._start(path)
        if ok:
            node.get_logger().info(message)
            return
        node.get_logger().error(f"record_path '{path}' refused: {message}; running "
                                'without recording')
        self._set_record_path('')

    @staticmethod
    def _target(path: str) -> Path:
        """The bag folder (or ``.mcap`` file) ``record_path`` = ``path`` names."""
        return NodeRecording.target(path)

    def _path_problem(self, path: str) -> str | None:
        """Why recording to ``path`` cannot start, or None (checked before switching)."""
        if self.recording is None:
            return RECORDING_UNAVAILABLE
        return self.recording.problem(path)

    def _start(self, path: str) -> tuple[bool, str]:
        """Start recording to ``path``; (ok, message)."""
        if self.recording is None:
            return False, RECORDING_UNAVAILABLE
        path = str(self._target(path))
        # Under the simulation lock: the file starts with the state of the last step
        # taken and then holds every following step, none twice.
        with self._node.lock:
            return self.recording.start(path)

    def _stop(self) -> tuple[bool, str]:
        if self.recording is None:
            return False, 'not recording'
        with self._node.lock:
            return self.recording.stop()

    def _set_record_path(self, value: str) -> None:
        """Make the ``record_path`` parameter say what is being recorded."""
        with self._lock:
            self._param_internal = True
            try:
                self._node.set_parameters([Parameter('record_path', value=value)])
            finally:
                self._param_internal = False

    def _check_record_path(self, parameters) -> SetParametersResult:
        """Start or stop the recording when ``record_path`` changes; another path while
        a recording runs is refused (``_busy_reason``)."""
        value = next((p.value for p in parameters if p.name == 'record_path'), None)
        if value is None:
            return SetParametersResult(successful=True)
        logger = self._node.get_logger()
        with self._lock:   # the node's own update holds it: others wait here
            if self._param_internal:
                return SetParametersResult(successful=True)
            recording = self.recording
            active = recording is not None and recording.active
            if not value:
                if active:
                    _, message = self._stop()
                    logger.info(f'recording stopped: {message}')
                return SetParametersResult(successful=True)
            if active and recording is not None and recording.path is not None and \
                    recording.path.resolve() == self._target(value).resolve():
                return SetParametersResult(successful=True)   # already recording there
            problem = self._busy_reason() if active else self._path_problem(value)
            if problem is None:
                ok, message = self._start(value)
                if ok:
                    logger.info(message)
                    return SetParametersResult(successful=True)
                problem = message
            reason = f"parameter 'record_path' = '{value}' refused: {problem}"
            logger.warning(f'parameter change rejected: {reason}')
            return SetParametersResult(successful=False, reason=reason)

    def _busy_reason(self) -> str:
        """Why a second recording cannot start: the one running, and how to stop it."""
        return (f'already recording to {self.recording.path}; stop it first (set '
                "record_path to '', call ~/record with false, or run gripper-sim "
                'record-node stop)')

    def _on_record(self, request, response):
        """``~/record``: true = start (to ``record_path`` or a timestamped file), false = stop."""
        node = self._node
        with self._lock:
            if request.data:
                if self.recording is None:
                    response.success, response.message = False, RECORDING_UNAVAILABLE
                elif self.recording.active:
                    response.success = False
                    response.message = self._busy_reason()
                else:
                    path = str(node.params.get('record_path')) or \
                        str(default_path(Path.cwd()))
                    response.success, response.message = self._start(path)
                    if response.success:
                        self._set_record_path(str(self.recording.path))
            else:
                response.success, response.message = self._stop()
                if response.success:
                    response.message = f'recording stopped: {response.message}'
                if node.params.get('record_path'):
                    self._set_record_path('')
        # (separate calls: an rclpy log call site must keep one severity)
        if response.success:
            node.get_logger().info(f'~/record: {response.message}')
        else:
            node.get_logger().warning(f'~/record: {response.message}')
        return response

    def finish(self) -> None:
        """Close the recording, if one is active (at shutdown)."""
        recording = self.recording
        if recording is not None and recording.active:
            ok, message = recording.stop()
            if ok:
                self._node.get_logger().info(f'recording stopped: {message}')
            else:
                self._node.get_logger().error(f'recording could not be finished: {message}')
