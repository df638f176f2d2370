"""How a goal of the node's jaw actions that was stopped from outside ends.

A goal a newer one preempted ends CANCELED, as ros2_controllers' gripper action
controllers end theirs (``preempt_active_goal`` marks the active goal canceled;
``gripper_action_controller_impl.hpp``, ``parallel_gripper_action_controller_impl.hpp``),
so that a client such as MoveIt tells a preemption from a failure. One stopped by a
reset, the shutdown or a failure ends ABORTED.
"""
from __future__ import annotations

from action_msgs.msg import GoalStatus
from rclpy.action.server import GoalEvent


def end_stopped_goal(goal_handle, preempted: bool) -> str:
    """End ``goal_handle`` (executing, or canceling if its client asked meanwhile) as a
    goal stopped from outside: 'canceled' if ``preempted``, else 'aborted' (returned).

    rclpy moves a goal to CANCELING only when a client's cancel request is accepted; a
    preemption is the server's own cancel, so the move is made here as rclpy's action
    server makes it on an accepted request."""
    if preempted:
        if goal_handle.status == GoalStatus.STATUS_EXECUTING:
            goal_handle._update_state(GoalEvent.CANCEL_GOAL)
        if goal_handle.status == GoalStatus.STATUS_CANCELING:
            goal_handle.canceled()
            return 'canceled'
    goal_handle.abort()
    return 'aborted'
