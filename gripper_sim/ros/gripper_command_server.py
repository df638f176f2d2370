"""The ``~/gripper_cmd`` action (``control_msgs/action/GripperCommand``), with the
semantics of the ros2_controllers gripper controllers, done properly.

Goal ``command.position`` is the jaw gap (m), ``command.max_effort`` the grip force
limit (N; 0 = parameter ``max_effort``). ``GripperCommandServer`` is also the base of
``parallel_gripper_server`` (ParallelGripperCommand): a subclass maps its goal to a
``JawTarget`` and the run back to its result and feedback messages; the motion, the
force limit, the goal and stall checks and preemption are the same.

The jaws move to the gap in position mode; once the grip force reaches ``max_effort``
the node switches to force mode and holds that force (so the fruit is never squeezed
harder than asked).

- reached: |gap - position| < ``goal_tolerance`` -> succeeded, ``reached_goal``.
- stalled: the gap moved less than ``stall_velocity_threshold`` x ``stall_timeout``
  over the last ``stall_timeout`` s of sim time (net motion over a window, so a
  jittering finger still counts as stalled) -> succeeded if ``allow_stalling``,
  aborted otherwise, with ``stalled`` set.
- Feedback (position, real effort, stalled, reached_goal) on every state change and
  every 0.05 s of sim or wall time. Effort is the real mean contact normal force.
- A new goal of any jaw action (Grasp, GripperCommand, ParallelGripperCommand)
  preempts the active one (which is aborted). Cancel holds the jaws where they are.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

from control_msgs.action import GripperCommand
from rclpy.action import ActionServer, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup

from gripper_sim.errors import CommandError
from gripper_sim.ros.goal_end import end_stopped_goal
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


@dataclass(frozen=True)
class JawTarget:
    """What a goal asks of the jaws.

    Attributes:
        gap: m, target jaw gap.
        max_effort: N, grip force limit; 0 = parameter ``max_effort``.
        speed: m/s, gap rate; None = ``gripper.close_speed``.
        tolerance_scale: the goal is reached when |gap - target| < this x
            ``goal_tolerance`` (2 for a goal on one jaw joint, which moves half the gap).
    """

    gap: float
    max_effort: float = 0.0
    speed: float | None = None
    tolerance_scale: float = 1.0


class GoalProblem(ValueError):
    """Why a goal cannot be executed (the message is logged with the rejection)."""


class _CommandRun(ActiveGoal):
    def __init__(self, goal_handle, ticket: int, kind: str, target: JawTarget,
                 max_effort: float, tolerance: float, stall: StallDetector):
        super().__init__(goal_handle, ticket)
        self.kind = kind
        self.position = target.gap
        self.speed = target.speed
        self.max_effort = max_effort
        self.tolerance = tolerance * target.tolerance_scale
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
    """Serves ``~/gripper_cmd`` (control_msgs GripperCommand) for a ``SimNode``.

    Subclasses set ``kind``, ``action_type`` and ``action_name`` and override
    ``target``, ``_result`` and ``_feedback_message``.
    """

    kind = 'GripperCommand'
    action_type = GripperCommand
    action_name = '~/gripper_cmd'

    def __init__(self, node):
        self._node = node
        self._goals = JawGoals(node.jaws)
        self._server = ActionServer(
            node, self.action_type, self.action_name, execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._goals.cancel,
            callback_group=ReentrantCallbackGroup(), feedback_pub_qos_profile=FEEDBACK_QOS)

    def target(self, goal, config) -> JawTarget:
        """The jaw target of a goal request in the flat ``config``; GoalProblem, in the
        goal's own terms, if it is unusable."""
        command = goal.command
        problem = goal_problem(command.position, command.max_effort, config)
        if problem:
            raise GoalProblem(problem)
        return JawTarget(gap=command.position, max_effort=command.max_effort)

    def _on_goal(self, goal) -> GoalResponse:
        try:
            self.target(goal, self._node.params.config)
        except GoalProblem as err:
            self._node.get_logger().warning(f'{self.kind} goal rejected: {err}')
            return GoalResponse.REJECT
        return self._goals.accept(goal)

    def _execute(self, goal_handle):
        node = self._node
        params = node.params
        target = self.target(goal_handle.request, params.config)
        max_effort = target.max_effort or float(params.get('max_effort'))
        run = _CommandRun(goal_handle, self._goals.ticket(goal_handle), self.kind, target,
                          max_effort, float(params.get('goal_tolerance')),
                          StallDetector(float(params.get('stall_velocity_threshold')),
                                        float(params.get('stall_timeout'))))
        reason = node.claim_jaws(run, run.ticket)
        if reason is not None:
            node.get_logger().warning(f'{self.kind} goal aborted before it started: {reason}')
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
                node.sim.command_gap(run.position, run.speed, run.max_effort)
            except CommandError as err:
                goal_handle.abort()
                node.get_logger().warning(f'{self.kind} goal aborted: {err}')
                return self._result(run, node.sim.last)
            node.add_step_listener(on_step)
        node.get_logger().info(f'{self.kind} goal: gap {run.position:g} m, max effort '
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
            ended = end_stopped_goal(goal_handle, run.preempted and not run.error)
            node.get_logger().warning(f'{self.kind} goal {ended} ({why}); {state}')
        elif run.reached:
            node.get_logger().info(f'{self.kind} goal reached; {state}')
            goal_handle.succeed()
        elif run.stalled:
            node.get_logger().info(f'{self.kind} goal stalled; {state}'
                                   + ('' if allow_stalling else ' (aborted: allow_stalling '
                                      'is false)'))
            if allow_stalling:
                goal_handle.succeed()
            else:
                goal_handle.abort()
        else:
            node.get_logger().info(f'{self.kind} goal canceled; jaws held at {state}')
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
            sim.command_gap(run.position, run.speed, run.max_effort)
            run.mode = 'position'
        if abs(result.gap - run.position) < run.tolerance:
            run.reached = True
            run.finished.set()
        elif run.stall.update(result.time, result.gap):
            run.stalled = True
            run.finished.set()

    def _result(self, run: _CommandRun, last) -> GripperCommand.Result:
        """The action's result for ``run`` ending at step result ``last``."""
        return GripperCommand.Result(position=float(last.gap), effort=float(last.grip_force),
                                     stalled=run.stalled, reached_goal=run.reached)

    def _maybe_feedback(self, run: _CommandRun, result) -> None:
        sim_last, wall_last = run.last_feedback
        if (run.reached or run.stalled or result.time - sim_last >= FEEDBACK_PERIOD
                or time.monotonic() - wall_last >= FEEDBACK_PERIOD):
            self._feedback(run, result)

    def _feedback_message(self, run: _CommandRun, result) -> GripperCommand.Feedback:
        """The action's feedback for ``run`` at step result ``result``."""
        return GripperCommand.Feedback(position=float(result.gap),
                                       effort=float(result.grip_force),
                                       stalled=run.stalled, reached_goal=run.reached)

    def _feedback(self, run: _CommandRun, result) -> None:
        feedback = self._feedback_message(run, result)
        run.last_feedback = (result.time, time.monotonic())
        run.goal_handle.publish_feedback(feedback)
