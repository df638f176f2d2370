"""The ``~/grasp`` action (gripper_sim_interfaces/action/Grasp).

The goal runs ``gripper_sim.core.grasp.GraspSequence``, updated after every physics
step in the physics thread. Feedback goes out on every phase change and at least
every 0.05 s of sim time or of wall time (20 Hz at real time). One grasp at a time:
a goal that arrives while one runs, or while a GripperCommand goal drives the jaws,
is rejected and the reason is logged. Cancel stops the motion and holds the jaws
where they are.
"""
from __future__ import annotations

import math
import threading
import time

from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup

from gripper_sim_interfaces.action import Grasp

from gripper_sim.errors import GripperSimError
from gripper_sim.ros.node import JawOwner

FEEDBACK_PERIOD = 0.05     # s, sim time and wall time
MAX_LIFT_HEIGHT = 1.0      # m
MAX_HOLD_TIME = 3600.0     # s


def goal_problem(goal, config) -> str | None:
    """Why a Grasp goal is out of range, or None. ``config`` is the flat configuration."""
    fields = {'target_force': goal.target_force, 'close_speed': goal.close_speed,
              'lift_height': goal.lift_height, 'hold_time': goal.hold_time}
    for name, value in fields.items():
        if not math.isfinite(value):
            return f'{name} must be finite, got {value}'
    max_force = config['gripper.max_force']
    if not 0.0 < goal.target_force <= max_force:
        return f'target_force must be in (0, {max_force:g}] N, got {goal.target_force:g} N'
    max_speed = config['gripper.max_speed']
    if not 0.0 <= goal.close_speed <= max_speed:
        return (f'close_speed must be in [0, {max_speed:g}] m/s (0 = default), got '
                f'{goal.close_speed:g} m/s')
    if not 0.0 <= goal.lift_height <= MAX_LIFT_HEIGHT:
        return (f'lift_height must be in [0, {MAX_LIFT_HEIGHT:g}] m, got '
                f'{goal.lift_height:g} m')
    if not 0.0 <= goal.hold_time <= MAX_HOLD_TIME:
        return f'hold_time must be in [0, {MAX_HOLD_TIME:g}] s, got {goal.hold_time:g} s'
    return None


class _GraspRun(JawOwner):
    kind = 'Grasp'

    def __init__(self, goal_handle):
        self.goal_handle = goal_handle
        self.sequence = None
        self.finished = threading.Event()
        self.abort_reason: str | None = None
        self.error: str | None = None
        self.last_phase = None
        self.last_feedback = (-math.inf, -math.inf)   # (sim time, wall time)

    def abort(self, reason: str) -> None:
        """Stop from outside (reset, solver failure, shutdown, preemption): non-blocking."""
        if self.abort_reason is None:
            self.abort_reason = reason
        self.finished.set()


class GraspServer:
    """Serves ``~/grasp`` for a ``SimNode``."""

    def __init__(self, node):
        self._node = node
        self._pending = threading.Lock()
        self._server = ActionServer(
            node, Grasp, '~/grasp', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._on_cancel,
            callback_group=ReentrantCallbackGroup())
        self._run: _GraspRun | None = None
        self._reserved = False

    def _reject(self, reason: str) -> GoalResponse:
        self._node.get_logger().warning(f'Grasp goal rejected: {reason}')
        return GoalResponse.REJECT

    def _on_goal(self, goal) -> GoalResponse:
        problem = goal_problem(goal, self._node.params.config)
        if problem:
            return self._reject(problem)
        with self._pending:
            owner = self._node.jaw_owner
            if owner is not None or self._reserved:
                kind = owner.kind if owner is not None else 'Grasp'
                return self._reject(f'a {kind} goal is already running (one at a time; '
                                    'cancel it or wait for its result)')
            self._reserved = True
        return GoalResponse.ACCEPT

    def _on_cancel(self, goal_handle) -> CancelResponse:
        run = self._run
        if run is not None and run.goal_handle is goal_handle:
            run.finished.set()
        return CancelResponse.ACCEPT

    def _execute(self, goal_handle):
        node = self._node
        goal = goal_handle.request
        run = _GraspRun(goal_handle)
        reason = node.claim_jaws(run)
        if reason is not None:
            node.get_logger().warning(f'Grasp goal aborted before it started: {reason}')
            goal_handle.abort()
            return Grasp.Result(success=False, message=f'not started: {reason}')
        self._run = run
        try:
            return self._drive(run, goal)
        finally:
            self._run = None
            node.release_jaws(run)
            with self._pending:
                self._reserved = False

    def _drive(self, run: _GraspRun, goal):
        node = self._node
        goal_handle = run.goal_handle
        from gripper_sim.core.grasp import GraspSequence
        close_speed = goal.close_speed or node.params.config['gripper.close_speed']

        def on_step(result):
            if run.finished.is_set() or run.sequence is None:
                return
            try:
                run.sequence.update(result)
            except GripperSimError as err:
                run.error = str(err)
                run.finished.set()
                return
            self._maybe_feedback(run, result)
            if run.sequence.done:
                run.finished.set()

        with node.lock:
            try:
                run.sequence = GraspSequence(node.sim, goal.target_force, close_speed,
                                             goal.lift_height, goal.hold_time, goal.release)
            except GripperSimError as err:
                node.get_logger().warning(f'Grasp goal aborted: {err}')
                goal_handle.abort()
                return Grasp.Result(success=False, message=f'not started: {err}')
            node.add_step_listener(on_step)
        node.get_logger().info(
            f'Grasp goal accepted: {goal.target_force:g} N at {close_speed:g} m/s, lift '
            f'{goal.lift_height:g} m, hold {goal.hold_time:g} s, release {goal.release}')
        self._feedback(run, node.sim.last)
        while not run.finished.wait(FEEDBACK_PERIOD):
            if goal_handle.is_cancel_requested:
                break
            with node.lock:
                if node.paused:   # no steps: keep the client informed anyway
                    self._maybe_feedback(run, node.sim.last)
        node.remove_step_listener(on_step)

        with node.lock:
            last = node.sim.last
            summary = dict(run.sequence.summary())
            phase = run.sequence.phase
            canceled = goal_handle.is_cancel_requested and not run.sequence.done
            # Stop the motion, hold the jaws where they are. Not after an abort: that
            # came with a reset (or the shutdown), and holding now could override a
            # command sent since the reset.
            if run.abort_reason is None and (canceled or run.error):
                node.hold_jaws()
        result = self._result(summary)
        if run.abort_reason or run.error:
            why = run.abort_reason or f'grasp sequence failed: {run.error}'
            result.success = False
            result.message = f'aborted during {phase}: {why}'
            node.get_logger().warning(f'Grasp goal {result.message}')
            goal_handle.abort()
        elif canceled:
            result.success = False
            result.message = (f'canceled during {phase}; jaws held at gap {last.gap:.4f} m, '
                              f'grip force {last.grip_force:.2f} N')
            node.get_logger().info(f'Grasp goal {result.message}')
            goal_handle.canceled()
        elif result.success:
            node.get_logger().info(f'Grasp goal succeeded: {result.message}')
            goal_handle.succeed()
        else:
            node.get_logger().info(f'Grasp goal failed: {result.message}')
            goal_handle.abort()
        return result

    @staticmethod
    def _result(summary: dict) -> Grasp.Result:
        result = Grasp.Result()
        result.success = bool(summary.get('success', False))
        result.slipped = bool(summary.get('slipped', False))
        result.bruised = bool(summary.get('bruised', False))
        result.message = str(summary.get('message', ''))
        for name in ('max_grip_force', 'final_gap', 'max_compression',
                     'max_contact_pressure', 'slip_distance'):
            value = float(summary.get(name, 0.0))
            setattr(result, name, value if math.isfinite(value) else 0.0)
        return result

    def _maybe_feedback(self, run: _GraspRun, result) -> None:
        sim_last, wall_last = run.last_feedback
        phase = run.sequence.phase
        if (phase != run.last_phase or result.time - sim_last >= FEEDBACK_PERIOD
                or time.monotonic() - wall_last >= FEEDBACK_PERIOD):
            self._feedback(run, result)

    @staticmethod
    def _feedback(run: _GraspRun, result) -> None:
        feedback = Grasp.Feedback()
        feedback.phase = str(run.sequence.phase)
        feedback.gap = float(result.gap)
        feedback.grip_force = float(result.grip_force)
        feedback.compression = float(result.deformation.compression)
        run.last_phase = feedback.phase
        run.last_feedback = (result.time, time.monotonic())
        run.goal_handle.publish_feedback(feedback)
