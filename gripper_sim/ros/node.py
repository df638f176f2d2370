"""The ``gripper_sim`` node: a thin ROS 2 adapter around the physics core (``Simulation``, or
``Simulation3D`` with the physics parameter ``dimension`` 3: ``core.make_simulation``).

Physics runs in its own thread at the configured dt, paced to ``real_time_factor``
(0 = as fast as possible), and publishes every ``1 / publish_rate`` s of sim time.
Callbacks only validate and enqueue: a command takes effect on the next physics step.
One lock guards the simulation (``SimLock``: the physics thread lets a waiting callback
have it before its next step); action servers hook in as step listeners. Published
batches go out in step order: a state older than one already published (e.g. a step
that finished just before a reset) is dropped, never published after it.

See the README section "ROS interface" for every topic, service, action and parameter.
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any, Callable

import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args
from std_msgs.msg import Float64, String
from std_srvs.srv import SetBool, Trigger

from gripper_sim_interfaces.srv import Step

from gripper_sim.core.results import StepResult
from gripper_sim.core import make_simulation
from gripper_sim.errors import CommandError, ConfigError, ConvergenceError
from gripper_sim.ros import messages
from gripper_sim.ros.messages import MessageContext, build_messages
from gripper_sim.ros.params import PHYSICS_PREFIX, SimParameters, physics_changes

NODE_NAME = 'gripper_sim'
MAX_STEPS_PER_REQUEST = 1_000_000
# Falling further behind real time than this re-anchors the pacing instead of racing.
MAX_LAG = 0.25   # s of wall time
SPEED_WINDOW = 5.0   # s of wall time over which the achieved real-time factor is measured
# The physics thread waits at most this long for callbacks waiting for the lock.
LOCK_YIELD_TIMEOUT = 0.5   # s
# GIL switch interval of the node process (Python's default: 5 ms). The physics thread
# computes without pause at real_time_factor 0; every other thread (executor, service
# and action callbacks) that gives up the GIL for a moment waits up to this long to get
# it back, many times per callback. At 5 ms a ~/reset or ~/pause took up to 1 s on a
# busy 2-core machine, at 1 ms under 0.2 s.
GIL_SWITCH_INTERVAL = 0.001   # s


def command_problem(value: float, what: str, unit: str, allow_negative: bool = False
                    ) -> str | None:
    """Why a commanded value is unusable, or None (finite, and >= 0 unless allowed)."""
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return f'{what} must be a finite number of {unit}, got {value}'
    if value < 0 and not allow_negative:
        return f'{what} must not be negative, got {value} {unit}'
    return None


class SimLock:
    """The simulation lock: re-entrant, and fair to the threads that wait for it.

    The physics thread steps back to back at ``real_time_factor`` 0 (or whenever it
    cannot keep up), releasing the lock only for a moment between steps. A plain lock
    then nearly always goes straight back to it: a callback waiting for the lock
    (``~/reset``, ``~/pause``, an action, a recording switch) could wait for seconds or
    for ever. The physics thread calls ``yield_to_waiters`` before each step, so a
    thread already waiting gets the lock first. Use it like ``threading.RLock``.
    """

    def __init__(self) -> None:
        self._lock = threading.RLock()
        self._state = threading.Condition(threading.Lock())
        self._waiting = 0

    def acquire(self, blocking: bool = True, timeout: float = -1) -> bool:
        if self._lock.acquire(False):   # free, or held by this thread
            return True
        if not blocking:
            return False
        with self._state:
            self._waiting += 1
        try:
            return self._lock.acquire(True, timeout)
        finally:
            with self._state:
                self._waiting -= 1
                if not self._waiting:
                    self._state.notify_all()

    def release(self) -> None:
        self._lock.release()

    def __enter__(self) -> 'SimLock':
        self.acquire()
        return self

    def __exit__(self, *exc) -> None:
        self.release()

    @property
    def waiting(self) -> int:
        """How many threads are blocked waiting for the lock."""
        return self._waiting

    def yield_to_waiters(self, timeout: float) -> None:
        """Until every thread waiting for the lock got it (at most ``timeout`` s).

        Call it without holding the lock (it would be a deadlock otherwise, bounded by
        ``timeout``).
        """
        with self._state:
            if self._waiting:
                self._state.wait_for(lambda: not self._waiting, timeout)


class JawOwner:
    """What an action that drives the jaws implements so the node can stop it."""

    kind = 'action'

    def abort(self, reason: str) -> None:  # pragma: no cover - interface
        raise NotImplementedError


class SimNode(Node):
    """The simulator node.

    Args:
        fruit, config_file: take precedence over the parameters of the same name.
        simulation_factory: builds the simulation from the flat configuration.
        start: start the physics thread (tests may drive ``advance`` by hand).
        **kwargs: passed to ``rclpy.node.Node`` (e.g. ``parameter_overrides``).

    Raises:
        ConfigError: a parameter or the configuration is invalid.
    """

    def __init__(self, *, fruit: str | None = None, config_file: str | None = None,
                 simulation_factory: Callable[[dict], Any] = make_simulation, start: bool = True,
                 **kwargs):
        super().__init__(NODE_NAME, **kwargs)
        self.params = SimParameters(self, fruit=fruit, config_file=config_file)
        self.lock = SimLock()
        # Publishing: one batch at a time, in step order (see _publish).
        self._publish_lock = threading.Lock()
        self._sequence = 0          # +1 per step and per reset, under ``lock``
        self._published = -1        # sequence number of the last batch published
        self.sim = simulation_factory(dict(self.params.config))
        self.message_context = MessageContext.from_config(self.params.config,
                                                          initial=self.sim.last)
        self._commands: deque[tuple[str, Callable[[], None], Any]] = deque()
        self._step_listeners: list[Callable[[StepResult], None]] = []
        self._observers: list[Callable[[StepResult], None]] = []
        self._publish_observers: list[Callable[[dict, int], None]] = []
        self._reset_listeners: list[Callable[[StepResult], None]] = []
        self._jaw_owner: JawOwner | None = None
        self._owner_guard = threading.Lock()
        self._owner_changed = threading.Condition(self._owner_guard)
        self._paused = False
        self._stop = threading.Event()
        self._wake = threading.Event()
        self._rtf = float(self.params.get('real_time_factor'))
        self._publish_clock = bool(self.params.get('publish_clock'))
        self._publish_every = 1
        self._set_publish_rate(float(self.params.get('publish_rate')))
        self._anchor = (time.monotonic(), self.sim.time)
        self._speed_window = self._anchor
        self._speed_warned = -math.inf
        self.achieved_rtf = math.nan
        self.failures = 0
        self.steps_taken = 0
        self.publish_count = 0
        self.params.on_change(self._on_parameters_changed)
        self.add_on_set_parameters_callback(self._check_runtime_physics)
        self._init_recording()

        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._topic_publishers = {
            suffix: self.create_publisher(messages.MESSAGE_CLASSES[suffix], name,
                                          1 if suffix == 'clock' else qos)
            for suffix, (name, _) in messages.TOPICS.items()}
        # One String per jaw/lift topic command: 'accepted: <command>' once applied,
        # 'rejected: <command>: <reason>' (what `gripper-sim jaw` waits for).
        self._command_status = self.create_publisher(String, '~/jaw/command_status', qos)

        commands = MutuallyExclusiveCallbackGroup()
        self.create_subscription(Float64, '~/jaw/gap_command', self._on_gap, qos,
                                 callback_group=commands)
        self.create_subscription(Float64, '~/jaw/force_command', self._on_force, qos,
                                 callback_group=commands)
        self.create_subscription(Float64, '~/lift/command', self._on_lift, qos,
                                 callback_group=commands)
        services = MutuallyExclusiveCallbackGroup()
        self.create_service(Trigger, '~/reset', self._on_reset, callback_group=services)
        self.create_service(SetBool, '~/pause', self._on_pause, callback_group=services)
        self.create_service(Step, '~/step', self._on_step, callback_group=services)
        self.create_service(Trigger, '~/jaw/open', self._on_open, callback_group=services)
        self.create_service(SetBool, '~/record', self._on_record, callback_group=services)

        # Imported here: the servers import this module for JawOwner.
        from gripper_sim.ros.grasp_server import GraspServer
        from gripper_sim.ros.gripper_command_server import GripperCommandServer
        self.grasp_server = GraspServer(self)
        self.gripper_command_server = GripperCommandServer(self)

        config = self.params.config
        self.get_logger().info(
            f"ready: fruit '{config['fruit.name']}' ({config['fruit.model']} model, "
            f"{getattr(self.sim, 'dimension', 2)}D, {len(self.sim.last.positions)} nodes), "
            f'dt {self.sim.dt:g} s, publishing every '
            f'{self._publish_every} steps ({1.0 / (self._publish_every * self.sim.dt):g} Hz '
            f'sim time), real-time factor {self._rtf:g}')
        self._publish(self.sim.last, self.message_context.snapshot(), self._sequence)
        self._start_recording_at_startup()
        self._thread = threading.Thread(target=self._run, name='physics', daemon=True)
        if start:
            self._thread.start()

    # ------------------------------------------------------------------ hooks
    def add_observer(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(result)`` after every physics step (physics thread, under ``lock``).

        The hook for in-node recording; keep it fast, it runs in the physics loop.
        """
        self._observers.append(callback)

    def add_publish_observer(self, callback: Callable[[dict, int], None]) -> None:
        """Call ``callback({suffix: msg}, stamp_ns)`` with every batch the node publishes."""
        self._publish_observers.append(callback)

    def add_reset_listener(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(initial_result)`` after every reset (``~/reset`` or recovery).

        Called under ``lock``, before the next step."""
        self._reset_listeners.append(callback)

    def add_step_listener(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(result)`` after every step, under ``lock`` (actions)."""
        with self.lock:
            self._step_listeners.append(callback)

    def remove_step_listener(self, callback: Callable[[StepResult], None]) -> None:
        with self.lock:
            if callback in self._step_listeners:
                self._step_listeners.remove(callback)

    def claim_jaws(self, owner: JawOwner, preempt_kind: str | None = None) -> str | None:
        """Make ``owner`` the only driver of the jaws; the reason it cannot, or None.

        An active owner of kind ``preempt_kind`` is aborted (preempted) instead.
        """
        with self._owner_guard:
            if self._stop.is_set():   # nothing would ever finish it (stop() has run)
                return 'the simulator is shutting down'
            current = self._jaw_owner
            if current is not None:
                if preempt_kind is None or current.kind != preempt_kind:
                    return f'a {current.kind} goal is already driving the jaws'
                current.abort(f'preempted by a new {owner.kind} goal')
            self._jaw_owner = owner
            return None

    def release_jaws(self, owner: JawOwner) -> None:
        with self._owner_changed:
            if self._jaw_owner is owner:
                self._jaw_owner = None
                self._owner_changed.notify_all()

    @property
    def jaw_owner(self) -> JawOwner | None:
        return self._jaw_owner

    @property
    def paused(self) -> bool:
        return self._paused

    def hold_jaws(self) -> None:
        """Stop the jaws and the lift where they are (call with ``lock`` held)."""
        last = self.sim.last
        try:
            if hasattr(self.sim, 'hold'):
                self.sim.hold()
            else:
                self.sim.command_gap(float(last.gap))
            self.sim.command_lift(float(last.lift))
        except CommandError as err:
            self.get_logger().warning(f'could not hold the jaws in place: {err}')

    def enqueue(self, description: str, command: Callable[[], None],
                on_done: Callable[[str | None], None] | None = None) -> None:
        """Run ``command()`` in the physics thread before the next step (at once while
        paused); then ``on_done(None)``, or ``on_done(reason)`` if the core refused it."""
        self._commands.append((description, command, on_done))
        self._wake.set()

    # --------------------------------------------------------------- physics
    def _run(self) -> None:
        while not self._stop.is_set():
            if self._paused:
                if self._commands:   # validated and set now; they act at the next step
                    with self.lock:
                        self._apply_commands()
                self._wake.wait(0.5)
                self._wake.clear()
                continue
            # A callback waiting for the lock (reset, pause, an action) goes first.
            self.lock.yield_to_waiters(LOCK_YIELD_TIMEOUT)
            try:
                self.advance(unless_paused=True)
            except Exception as err:   # never let the physics thread die silently
                self.get_logger().error(f'physics step raised {type(err).__name__}: {err}; '
                                        'resetting the simulation')
                self._recover(f'{type(err).__name__}: {err}')
                continue
            rtf = self._rtf
            self._watch_speed(rtf)
            if rtf <= 0.0:
                continue
            wall0, sim0 = self._anchor
            delay = wall0 + (self.sim.time - sim0) / rtf - time.monotonic()
            if delay > 0.002:
                self._wake.wait(delay)
                self._wake.clear()
            elif delay < -MAX_LAG:
                self._anchor = (time.monotonic(), self.sim.time)

    def _watch_speed(self, rtf: float) -> None:
        """Measure the achieved real-time factor; warn when it misses the target."""
        now, sim_now = time.monotonic(), self.sim.time
        wall0, sim0 = self._speed_window
        if now - wall0 < SPEED_WINDOW:
            return
        self._speed_window = (now, sim_now)
        if sim_now < sim0:   # reset in between
            return
        self.achieved_rtf = (sim_now - sim0) / (now - wall0)
        if 0.0 < rtf and self.achieved_rtf < 0.9 * rtf and now - self._speed_warned > 60.0:
            self._speed_warned = now
            self.get_logger().warning(
                f'running at {self.achieved_rtf:.2f}x real time, below real_time_factor '
                f'{rtf:g}: the physics cannot keep up (fewer nodes or a larger '
                'physics.sim.dt would)')

    def advance(self, *, unless_paused: bool = False) -> StepResult | None:
        """Apply queued commands and take one physics step; None if the step failed.

        Args:
            unless_paused: take no step (None) if the node is paused, checked under the
                lock (the physics thread: no step starts after ``~/pause`` answered).
        """
        batch = None
        with self.lock:
            if unless_paused and self._paused:
                return None
            self._apply_commands()
            try:
                result = self.sim.step()
            except ConvergenceError as err:
                self._recover(f'solver did not converge at t = {self.sim.time:.4f} s: {err}')
                return None
            if not messages.result_is_finite(result):
                self._recover(f'step produced non-finite values at t = {result.time:.4f} s')
                return None
            self.steps_taken += 1
            self._sequence += 1
            self.message_context.observe(result)
            for listener in list(self._step_listeners):
                listener(result)
            if result.step % self._publish_every == 0:
                # built outside the lock from a copy of the run history as of this step
                batch = (result, self.message_context.snapshot(), self._sequence)
            # Under the lock, so a recording started or stopped (also under the lock)
            # holds exactly the steps taken in between, none twice.
            for observer in self._observers:
                observer(result)
        if batch is not None:
            self._publish(*batch)
        return result

    def _apply_commands(self) -> None:
        while self._commands:
            description, command, on_done = self._commands.popleft()
            try:
                command()
            except (CommandError, ConfigError) as err:
                self.get_logger().warning(f'{description} rejected: {err}')
                if on_done is not None:
                    on_done(str(err))
            else:
                if on_done is not None:
                    on_done(None)

    def _recover(self, reason: str) -> None:
        """Log a failed step, abort the goals, reset: nothing non-finite is published."""
        self.failures += 1
        self.get_logger().error(f'{reason}; nothing was published for this step. '
                                'Recovering: resetting the simulation to t = 0 and '
                                'aborting the active goal')
        self._reset(f'the simulation was reset after a failed step ({reason})')

    def _reset(self, reason: str) -> None:
        with self._owner_guard:
            owner = self._jaw_owner
        if owner is not None:
            owner.abort(reason)
        with self.lock:
            self._commands.clear()
            self.sim.reset()
            self.message_context.reset()
            self._anchor = (time.monotonic(), self.sim.time)
            self._sequence += 1
            initial = self.sim.last
            batch = (initial, self.message_context.snapshot(), self._sequence)
            for listener in self._reset_listeners:
                listener(initial)
        self._publish(*batch)

    def _publish(self, result: StepResult, context: MessageContext, sequence: int) -> None:
        """Publish the batch of step ``sequence``, unless a later one is already out.

        Called outside the simulation lock, from the physics thread, ``~/step`` and
        ``~/reset``: without the check a step that finished just before a reset could
        go out after the reset state (and a client would never see t = 0).
        """
        with self._publish_lock:
            if sequence <= self._published:
                return
            self._published = sequence
            stamp = messages.time_msg(result.time)
            wanted = [suffix for suffix, pub in self._topic_publishers.items()
                      if (suffix != 'clock' or self._publish_clock)
                      and (self._publish_observers or pub.get_subscription_count() > 0)]
            if not wanted:
                return
            batch = build_messages(result, context, stamp, topics=wanted)
            for suffix, msg in batch.items():
                self._topic_publishers[suffix].publish(msg)
            self.publish_count += 1
            if self._publish_observers:
                ns = stamp.sec * 1_000_000_000 + stamp.nanosec
                for observer in self._publish_observers:
                    observer(batch, ns)

    # ------------------------------------------------------------ parameters
    def _set_publish_rate(self, rate: float) -> None:
        self._publish_every = max(1, int(round(1.0 / (rate * self.sim.dt))))

    def _check_runtime_physics(self, parameters):
        changes = physics_changes({p.name: p.value for p in parameters})
        if changes and not hasattr(self.sim, 'set_parameter'):
            reason = (f"this simulation core cannot change {', '.join(sorted(changes))} "
                      'while running; set it at start-up')
            self.get_logger().warning(f'parameter change rejected: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_parameters_changed(self, changes: dict[str, Any]) -> None:
        if 'publish_rate' in changes:
            self._set_publish_rate(float(changes['publish_rate']))
        if 'real_time_factor' in changes:
            self._rtf = float(changes['real_time_factor'])
            self._anchor = (time.monotonic(), self.sim.time)
            self._wake.set()
        if 'publish_clock' in changes:
            self._publish_clock = bool(changes['publish_clock'])
        physics = physics_changes(changes)
        for key, value in physics.items():
            self.enqueue(f'parameter change {PHYSICS_PREFIX}{key} = {value}',
                         lambda key=key, value=value: self.sim.set_parameter(key, value))
        self.get_logger().info(f'parameters changed: {changes}')

    def set_parameters(self, parameter_list):
        results = super().set_parameters(parameter_list)
        self._log_rejections(parameter_list, results)
        return results

    def set_parameters_atomically(self, parameter_list):
        result = super().set_parameters_atomically(parameter_list)
        self._log_rejections(parameter_list, [result] * len(parameter_list))
        return result

    def _log_rejections(self, parameter_list, results) -> None:
        logged = set()
        for parameter, result in zip(parameter_list, results):
            if not result.successful and result.reason not in logged:
                logged.add(result.reason)
                if not result.reason.startswith(('parameter ', 'this simulation core')):
                    # rclpy's own checks (range, type, read-only) are not logged by it
                    self.get_logger().warning(
                        f"parameter change of '{parameter.name}' rejected: {result.reason}")

    # ------------------------------------------------------------- recording
    def _init_recording(self) -> None:
        """In-node recording (``record_path``, ``~/record``): every physics step to MCAP."""
        self._record_lock = threading.RLock()
        self._record_param_internal = False   # the node itself is updating record_path
        self.recording = None
        self._recording_unavailable = ''
        try:
            from gripper_sim.recording.node_recording import NodeRecording
            self.recording = NodeRecording(self)
        except ImportError as err:   # e.g. the mcap library is missing
            self._recording_unavailable = f'in-node recording is unavailable: {err}'
        # Registered last: it starts or stops the recording, so every other check of
        # the same change has already accepted it.
        self.add_on_set_parameters_callback(self._check_record_path)

    def _start_recording_at_startup(self) -> None:
        path = str(self.params.get('record_path'))
        if not path:
            return
        ok, message = self._start_recording(path)
        if ok:
            self.get_logger().info(message)
            return
        self.get_logger().error(f"record_path '{path}' refused: {message}; running "
                                'without recording')
        self._set_record_path('')

    def _recording_target(self, path: str) -> Path:
        """The bag folder (or ``.mcap`` file) ``record_path`` = ``path`` names."""
        return self.recording.target(path)

    def _record_path_problem(self, path: str) -> str | None:
        """Why recording to ``path`` cannot start, or None (checked before switching)."""
        if self.recording is None:
            return self._recording_unavailable
        return self.recording.problem(path)

    def _start_recording(self, path: str) -> tuple[bool, str]:
        """Start recording to ``path``; (ok, message)."""
        if self.recording is None:
            return False, self._recording_unavailable
        path = str(self._recording_target(path))
        # Under the simulation lock: the file starts with the state of the last step
        # taken and then holds every following step, none twice.
        with self.lock:
            return self.recording.start(path)

    def _stop_recording(self) -> tuple[bool, str]:
        if self.recording is None:
            return False, 'not recording'
        with self.lock:
            return self.recording.stop()

    def _set_record_path(self, value: str) -> None:
        """Make the ``record_path`` parameter say what is being recorded."""
        with self._record_lock:
            self._record_param_internal = True
            try:
                self.set_parameters([Parameter('record_path', value=value)])
            finally:
                self._record_param_internal = False

    def _check_record_path(self, parameters) -> SetParametersResult:
        """Start, switch or stop the recording when ``record_path`` changes."""
        value = next((p.value for p in parameters if p.name == 'record_path'), None)
        if value is None:
            return SetParametersResult(successful=True)
        with self._record_lock:   # the node's own update holds it: others wait here
            if self._record_param_internal:
                return SetParametersResult(successful=True)
            recording = self.recording
            active = recording is not None and recording.active
            if not value:
                if active:
                    _, message = self._stop_recording()
                    self.get_logger().info(f'recording stopped: {message}')
                return SetParametersResult(successful=True)
            if active and recording is not None and recording.path is not None and \
                    recording.path.resolve() == self._recording_target(value).resolve():
                return SetParametersResult(successful=True)   # already recording there
            problem = self._record_path_problem(value)
            if problem is None:
                if active:
                    _, message = self._stop_recording()
                    self.get_logger().info(f'recording stopped: {message}')
                ok, message = self._start_recording(value)
                if ok:
                    self.get_logger().info(message)
                    return SetParametersResult(successful=True)
                problem = message
            reason = f"parameter 'record_path' = '{value}' refused: {problem}"
            self.get_logger().warning(f'parameter change rejected: {reason}')
            return SetParametersResult(successful=False, reason=reason)

    def _on_record(self, request, response):
        """``~/record``: true = start (to ``record_path`` or a timestamped file), false = stop."""
        with self._record_lock:
            if request.data:
                if self.recording is None:
                    response.success, response.message = False, self._recording_unavailable
                elif self.recording.active:
                    response.success = False
                    response.message = (f'already recording to {self.recording.path}; '
                                        'stop it first')
                else:
                    from gripper_sim.recording.node_recording import default_path
                    path = str(self.params.get('record_path')) or \
                        str(default_path(Path.cwd()))
                    response.success, response.message = self._start_recording(path)
                    if response.success:
                        self._set_record_path(str(self.recording.path))
            else:
                response.success, response.message = self._stop_recording()
                if response.success:
                    response.message = f'recording stopped: {response.message}'
                if self.params.get('record_path'):
                    self._set_record_path('')
        # (separate calls: an rclpy log call site must keep one severity)
        if response.success:
            self.get_logger().info(f'~/record: {response.message}')
        else:
            self.get_logger().warning(f'~/record: {response.message}')
        return response

    def _finish_recording(self) -> None:
        recording = getattr(self, 'recording', None)
        if recording is not None and recording.active:
            ok, message = recording.stop()
            if ok:
                self.get_logger().info(f'recording stopped: {message}')
            else:
                self.get_logger().error(f'recording could not be finished: {message}')

    # ---------------------------------------------------------------- topics
    def _jaw_command(self, description: str, value: float, unit: str,
                     command: Callable[[float], None], allow_negative: bool = False) -> None:
        problem = command_problem(value, description, unit, allow_negative)
        if problem is None and self._jaw_owner is not None:
            problem = (f'{description} ignored: a {self._jaw_owner.kind} goal is driving the '
                       'jaws (cancel it first)')
        what = f'{description} {value:g} {unit}'
        if problem is not None:
            self.get_logger().warning(f'rejected: {problem}')
            self._command_status.publish(String(data=f'rejected: {what}: {problem}'))
            return

        def report(reason: str | None) -> None:
            text = f'accepted: {what}' if reason is None else f'rejected: {what}: {reason}'
            self._command_status.publish(String(data=text))
        self.enqueue(what, lambda: command(value), report)

    def _on_gap(self, msg: Float64) -> None:
        self._jaw_command('gap command', msg.data, 'm', self.sim.command_gap)

    def _on_force(self, msg: Float64) -> None:
        self._jaw_command('force command', msg.data, 'N', self.sim.command_force)

    def _on_lift(self, msg: Float64) -> None:
        self._jaw_command('lift command', msg.data, 'm', self.sim.command_lift,
                          allow_negative=True)

    # -------------------------------------------------------------- services
    def _on_reset(self, request, response):
        self._reset('the simulation was reset (~/reset)')
        response.success = True
        response.message = 'simulation reset to t = 0'
        self.get_logger().info(response.message)
        return response

    def _on_pause(self, request, response):
        # Under the lock: once this answers "paused", the physics thread takes no step.
        with self.lock:
            self._paused = bool(request.data)
            if not self._paused:
                self._anchor = (time.monotonic(), self.sim.time)
            sim_time = self.sim.time
        self._wake.set()
        response.success = True
        state = 'paused' if self._paused else 'running'
        response.message = f'{state} at t = {sim_time:.6f} s'
        self.get_logger().info(response.message)
        return response

    def _on_step(self, request, response):
        if not self._paused:
            response.success = False
            response.message = 'refused: the simulation is running; pause it first (~/pause)'
        elif request.steps < 1 or request.steps > MAX_STEPS_PER_REQUEST:
            response.success = False
            response.message = (f'refused: steps must be in [1, {MAX_STEPS_PER_REQUEST}], '
                                f'got {request.steps}')
        else:
            response.success = True
            response.message = f'advanced {request.steps} steps'
            for done in range(request.steps):
                if self.advance() is None:
                    response.success = False
                    response.message = (f'step {done + 1} of {request.steps} failed; the '
                                        'simulation was reset (see the log)')
                    break
        if not response.success:
            self.get_logger().warning(f'step request {response.message}')
        response.sim_time = float(self.sim.time)
        return response

    def _on_open(self, request, response):
        if self._jaw_owner is not None:
            response.success = False
            response.message = (f'refused: a {self._jaw_owner.kind} goal is driving the '
                                'jaws (cancel it first)')
            self.get_logger().warning(f'open request {response.message}')
        else:
            self.enqueue('open command', self.sim.command_open)
            response.success = True
            response.message = 'opening the jaws to the initial gap'
        return response

    # ------------------------------------------------------------- lifecycle
    def stop(self, timeout: float = 5.0) -> None:
        """Stop the physics thread; abort the active goal and let its result go out."""
        self._stop.set()
        self._wake.set()
        if self._thread.is_alive():
            self._thread.join(timeout=timeout)
        with self._owner_guard:
            owner = self._jaw_owner
        if owner is not None:
            owner.abort('the simulator is shutting down')
            with self._owner_changed:
                self._owner_changed.wait_for(lambda: self._jaw_owner is None, timeout)

    def destroy_node(self):
        self.stop()
        self._finish_recording()
        return super().destroy_node()


def main(args: list[str] | None = None) -> int:
    """Run the node: console script ``sim_node``, ``gripper-sim node``, ``python -m``.

    Args:
        args: the full command line (default ``sys.argv``): ``[--fruit NAME]
            [--config FILE] [--ros-args ...]``; the two options take precedence over
            the ``fruit`` and ``config_file`` parameters.

    Returns:
        0 after a clean shutdown, 2 if the configuration or a parameter is invalid.

    The Jazzy main idiom, with one change: SIGINT/SIGTERM set a flag instead of
    shutting the context down at once, so an active goal is aborted and its result
    delivered before the node goes.
    """
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    argv = list(sys.argv if args is None else args)
    parser = argparse.ArgumentParser(prog='sim_node', description='The gripper_sim node.')
    parser.add_argument('--fruit', help='fruit preset name')
    parser.add_argument('--config', help='YAML configuration file')
    options = parser.parse_args(remove_ros_args(argv)[1:])
    # Our own SIGINT/SIGTERM handling instead of rclpy's, which shuts the context down
    # at once: an active goal must still get its (aborted) result out before we stop.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stopping = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stopping.set())
    node = None
    executor = MultiThreadedExecutor(num_threads=4)
    try:
        try:
            node = SimNode(fruit=options.fruit, config_file=options.config)
        except ConfigError as err:
            rclpy.logging.get_logger(NODE_NAME).error(f'cannot start: {err}')
            return 2
        executor.add_node(node)
        while not stopping.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.stop()
            # deliver the aborted goal's result to its client, then go
            deadline = time.monotonic() + 1.0
            while time.monotonic() < deadline and rclpy.ok():
                executor.spin_once(timeout_sec=0.05)
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
