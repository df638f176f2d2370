"""The ``~/grasp`` action (gripper_sim_interfaces/action/Grasp).

The goal runs ``gripper_sim.workflows.grasp.GraspSequence``, or with ``place`` the
pick-and-place ``gripper_sim.workflows.scenario.PickAndPlace`` (``grasp_goal.GoalRun``),
updated after every physics step in the physics thread. Feedback goes out on every
phase change and at least every 0.05 s of sim time or of wall time (20 Hz at real
time), kept in a deep history so a slow client still gets every phase. One goal
drives the jaws at a time: a new Grasp goal preempts (aborts) the active Grasp or
GripperCommand goal, so a goal whose client has gone never blocks the next. Cancel
stops the motion and holds the jaws where they are.
"""
from __future__ import annotations

import time

from rclpy.action import ActionServer, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup

from gripper_sim_interfaces.action import Grasp

from gripper_sim.errors import GripperSimError
from gripper_sim.ros.grasp_goal import GoalRun, goal_problem
from gripper_sim.ros.goal_end import end_stopped_goal
from gripper_sim.ros.jaw_goals import FEEDBACK_PERIOD, FEEDBACK_QOS, JawGoals
from gripper_sim.ros.sync import ActiveGoal

__all__ = ['GraspServer', 'goal_problem']

class _GraspRun(ActiveGoal):
    kind = 'Grasp'

    def __init__(self, goal_handle, ticket: int):
        super().__init__(goal_handle, ticket)
        self.sequence = None
        self.last_phase = None


class GraspServer:
    """Serves ``~/grasp`` for a ``SimNode``."""

    def __init__(self, node):
        self._node = node
        self._goals = JawGoals(node.jaws)
        self._server = ActionServer(
            node, Grasp, '~/grasp', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._goals.cancel,
            callback_group=ReentrantCallbackGroup(), feedback_pub_qos_profile=FEEDBACK_QOS)

    def _on_goal(self, goal) -> GoalResponse:
        problem = goal_problem(goal, self._node.params.config)
        if problem:
            self._node.get_logger().warning(f'Grasp goal rejected: {problem}')
            return GoalResponse.REJECT
        return self._goals.accept(goal)

    def _execute(self, goal_handle):
        node = self._node
        goal = goal_handle.request
        run = _GraspRun(goal_handle, self._goals.ticket(goal_handle))
        reason = node.claim_jaws(run, run.ticket)
        if reason is not None:
            node.get_logger().warning(f'Grasp goal aborted before it started: {reason}')
            goal_handle.abort()
            return Grasp.Result(success=False, outcome='failed',
                                message=f'not started: {reason}', dropped_at=-1.0)
        self._goals.add(run)
        try:
            return self._drive(run, goal)
        finally:
            self._goals.remove(run)
            node.release_jaws(run)

    def _drive(self, run: _GraspRun, goal):
        node = self._node
        goal_handle = run.goal_handle
        config = node.params.config
        close_speed = goal.close_speed or config['gripper.close_speed']

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
                run.sequence = GoalRun(node.sim, goal, config)
            except GripperSimError as err:
                node.get_logger().warning(f'Grasp goal aborted: {err}')
                goal_handle.abort()
                return Grasp.Result(success=False, outcome='failed',
                                    message=f'not started: {err}', dropped_at=-1.0)
            node.add_step_listener(on_step)
        what = (f'place: transport {goal.transport_distance:g} m, retreat '
                f'{goal.retreat_height:g} m' if goal.place else
                f'hold {goal.hold_time:g} s, release {goal.release}')
        node.get_logger().info(
            f'Grasp goal accepted: {goal.target_force:g} N at {close_speed:g} m/s, lift '
            f'{goal.lift_height:g} m, {what}')
        self._feedback(run, node.sim.last)
        while not run.finished.wait(FEEDBACK_PERIOD):
            if run.canceled:
                break
            with node.lock:
                if node.paused:   # no steps: keep the client informed anyway
                    self._maybe_feedback(run, node.sim.last)
        node.remove_step_listener(on_step)

        with node.lock:
            last = node.sim.last
            summary = run.sequence.summary()
            phase = run.sequence.phase
            canceled = run.canceled and not run.sequence.done
            # Stop the motion, hold the jaws where they are. Not after an abort: that
            # came with a reset (or the shutdown), and holding now could override a
            # command sent since the reset.
            if run.abort_reason is None and (canceled or run.error):
                node.hold_jaws()
            result = run.sequence.result(summary)
        if run.abort_reason or run.error:
            why = run.abort_reason or f'grasp sequence failed: {run.error}'
            preempted = run.preempted and not run.error
            result.success = False
            result.outcome = 'canceled' if preempted else 'failed'
            result.message = f"{'canceled' if preempted else 'aborted'} during {phase}: {why}"
            node.get_logger().warning(f'Grasp goal {result.message}')
            end_stopped_goal(goal_handle, preempted)
        elif canceled:
            result.success = False
            result.outcome = 'canceled'
            result.message = (f'canceled during {phase}; jaws held at gap {last.gap:.4f} m, '
                              f'grip force {last.grip_force:.2f} N')
            node.get_logger().info(f'Grasp goal {result.message}')
            goal_handle.canceled() if run.cancel_confirmed() else goal_handle.abort()
        elif result.success:
            node.get_logger().info(f'Grasp goal succeeded ({result.outcome}): '
                                   f'{result.message}')
            goal_handle.succeed()
        else:
            node.get_logger().info(f'Grasp goal failed ({result.outcome}): {result.message}')
            goal_handle.abort()
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
