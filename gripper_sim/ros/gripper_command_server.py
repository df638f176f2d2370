"""The ``~/gripper_cmd`` action: control_msgs/GripperCommand semantics, done properly.

Goal ``command.position`` is the jaw gap (m), ``command.max_effort`` the grip force
limit (N; 0 = parameter ``max_effort``). The jaws move to the gap in position mode;
once the grip force reaches ``max_effort`` the node switches to force mode and holds
that force (so the fruit is never squeezed harder than asked).

- reached: |gap - position| < ``goal_tolerance`` -> succeeded, ``reached_goal``.
- stalled: the gap moved less than ``stall_velocity_threshold`` x ``stall_timeout``
  over the last ``stall_timeout`` s of sim time (net motion over a window, so a
  jittering finger still counts as stalled) -> succeeded if ``allow_stalling``,
  aborted otherwise, with ``stalled`` set.
- Feedback (position, real effort, stalled, reached_goal) on every state change and
  every 0.05 s of sim or wall time. Effort is the real mean contact normal force.
- A new GripperCommand goal preempts the active GripperCommand or Grasp goal (which
  is aborted). Cancel holds the jaws where they are.
"""
from __future__ import annotations

import math
import time
from collections import deque

from rclpy.action import ActionServer, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup

from gripper_sim_interfaces.action import GripperCommand

from gripper_sim.errors import CommandError
from gripper_sim.ros.jaw_goals import FEEDBACK_PERIOD, FEEDBACK_QOS, JawGoals
from gripper_sim.ros.sync import ActiveGoal



class StallDetector:
    """Stalled when the gap moved less than ``threshold x timeout`` over ``timeout`` s.

    Net motion over a sliding window, not the instantaneous speed, so noise on the
    jaw velocity neither hides a stall nor restarts the timer.
    """

    def __init__(self, threshold: float, timeout: float):
        self.threshold = threshold
        self.timeout = timeout
        self._history: deque[tuple[float, float]] = deque()

    def reset(self) -> None:
        self._history.clear()

    def update(self, t: float, gap: float) -> bool:
        history = self._history
        history.append((t, gap))
        while len(history) > 2 and history[1][0] <= t - self.timeout:
            history.popleft()
        t0, gap0 = history[0]
        return t - t0 >= self.timeout - 1e-12 and abs(gap - gap0) < self.threshold * self.timeout


class _CommandRun(ActiveGoal):
    kind = 'GripperCommand'

    def __init__(self, goal_handle, ticket: int, position: float, max_effort: float,
                 tolerance: float, stall: StallDetector):
        super().__init__(goal_handle, ticket)
        self.position = position
        self.max_effort = max_effort
        self.tolerance = tolerance
        self.stall = stall
        self.mode = 'position'
        self.reached = False
        self.stalled = False


def goal_problem(position: float, max_effort: float, config) -> str | None:
    """Why a GripperCommand goal is unusable, or None."""
    if not math.isfinite(position) or not math.isfinite(max_effort):
        return f'position and max_effort must be finite, got {position}, {max_effort}'
    max_gap = config['gripper.max_gap']
    if not 0.0 <= position <= max_gap:
        return f'position (gap) must be in [0, {max_gap:g}] m, got {position:g} m'
    max_force = config['gripper.max_force']
    if not 0.0 <= max_effort <= max_force:
        return (f'max_effort must be in [0, {max_force:g}] N (0 = parameter max_effort), '
                f'got {max_effort:g} N')
    return None


class GripperCommandServer:
    """Serves ``~/gripper_cmd`` for a ``SimNode``."""

    def __init__(self, node):
        self._node = node
        self._goals = JawGoals(node.jaws)
        self._server = ActionServer(
            node, GripperCommand, '~/gripper_cmd', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._goals.cancel,
            callback_group=ReentrantCallbackGroup(), feedback_pub_qos_profile=FEEDBACK_QOS)

    def _on_goal(self, goal) -> GoalResponse:
        command = goal.command
        problem = goal_problem(command.position, command.max_effort, self._node.params.config)
        if problem:
            self._node.get_logger().warning(f'GripperCommand goal rejected: {problem}')
            return GoalResponse.REJECT
        return self._goals.accept(goal)

    def _execute(self, goal_handle):
        node = self._node
        params = node.params
        command = goal_handle.request.command
        max_effort = command.max_effort or float(params.get('max_effort'))
        run = _CommandRun(goal_handle, self._goals.ticket(goal_handle), command.position,
                          max_effort,
                          float(params.get('goal_tolerance')),
                          StallDetector(float(params.get('stall_velocity_threshold')),
                                        float(params.get('stall_timeout'))))
        reason = node.claim_jaws(run, run.ticket)
        if reason is not None:
            node.get_logger().warning(f'GripperCommand goal aborted before it started: {reason}')
            goal_handle.abort()
            return self._result(run, node.sim.last)
        self._goals.add(run)
        try:
            return self._drive(run)
        finally:
            self._goals.remove(run)
            node.release_jaws(run)

    def _drive(self, run: _CommandRun):
        node = self._node
        goal_handle = run.goal_handle

        def on_step(result):
            if run.finished.is_set():
                return
            try:
                self._track(run, result)
            except CommandError as err:
                run.error = str(err)
                run.finished.set()
                return
            self._maybe_feedback(run, result)

        with node.lock:
            try:
                node.sim.command_gap(run.position)
            except CommandError as err:
                goal_handle.abort()
                node.get_logger().warning(f'GripperCommand goal aborted: {err}')
                return self._result(run, node.sim.last)
            node.add_step_listener(on_step)
        node.get_logger().info(f'GripperCommand goal: gap {run.position:g} m, max effort '
                               f'{run.max_effort:g} N')
        self._feedback(run, node.sim.last)
        while not run.finished.wait(FEEDBACK_PERIOD):
            if run.canceled:
                break
        node.remove_step_listener(on_step)

        allow_stalling = bool(node.params.get('allow_stalling'))
        with node.lock:
            last = node.sim.last
            canceled = (run.canceled and run.abort_reason is None
                        and not (run.reached or run.stalled))
            if run.abort_reason is None and (canceled or run.error):
                node.hold_jaws()   # not after an abort: a reset or a newer goal moved on
        result = self._result(run, last)
        state = f'gap {last.gap:.4f} m, effort {last.grip_force:.2f} N'
        if run.abort_reason or run.error:
            why = run.abort_reason or run.error
            node.get_logger().warning(f'GripperCommand goal aborted ({why}); {state}')
            goal_handle.abort()
        elif run.reached:
            node.get_logger().info(f'GripperCommand goal reached; {state}')
            goal_handle.succeed()
        elif run.stalled:
            node.get_logger().info(f'GripperCommand goal stalled; {state}'
                                   + ('' if allow_stalling else ' (aborted: allow_stalling '
                                      'is false)'))
            if allow_stalling:
                goal_handle.succeed()
            else:
                goal_handle.abort()
        else:
            node.get_logger().info(f'GripperCommand goal canceled; jaws held at {state}')
            goal_handle.canceled() if run.cancel_confirmed() else goal_handle.abort()
        return result

    def _track(self, run: _CommandRun, result) -> None:
        """Per step (physics thread, under the node lock): force limit, goal, stall."""
        sim = self._node.sim
        if run.mode == 'position' and result.grip_force >= run.max_effort:
            sim.command_force(run.max_effort)
            run.mode = 'force'
        elif run.mode == 'force' and result.gap > run.position + run.tolerance \
                and result.grip_force < 0.5 * run.max_effort:
            # contact lost (e.g. the fruit moved): go back to the position target
            sim.command_gap(run.position)
            run.mode = 'position'
        if abs(result.gap - run.position) < run.tolerance:
            run.reached = True
            run.finished.set()
        elif run.stall.update(result.time, result.gap):
            run.stalled = True
            run.finished.set()

    @staticmethod
    def _result(run: _CommandRun, last) -> GripperCommand.Result:
        return GripperCommand.Result(position=float(last.gap), effort=float(last.grip_force),
                                     stalled=run.stalled, reached_goal=run.reached)

    def _maybe_feedback(self, run: _CommandRun, result) -> None:
        sim_last, wall_last = run.last_feedback
        if (run.reached or run.stalled or result.time - sim_last >= FEEDBACK_PERIOD
                or time.monotonic() - wall_last >= FEEDBACK_PERIOD):
            self._feedback(run, result)

    @staticmethod
    def _feedback(run: _CommandRun, result) -> None:
        feedback = GripperCommand.Feedback(position=float(result.gap),
                                           effort=float(result.grip_force),
                                           stalled=run.stalled, reached_goal=run.reached)
        run.last_feedback = (result.time, time.monotonic())
        run.goal_handle.publish_feedback(feedback)
