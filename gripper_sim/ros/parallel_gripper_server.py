"""The ``~/parallel_gripper_cmd`` action (``control_msgs/action/ParallelGripperCommand``),
as the ros2_controllers parallel gripper controller serves it, on one jaw joint.

Goal ``command`` (``sensor_msgs/JointState``): ``name`` empty or one jaw joint
(``left_jaw_joint`` or ``right_jaw_joint``, as on ``joint_states``); ``position[0]`` the
joint's target (m from the gripper centre, open > 0: both jaws move, the gap goes to
twice it); ``velocity[0]`` (optional, m/s, > 0) the joint's speed (the gap closes at
twice it; none = ``gripper.close_speed``); ``effort[0]`` (optional, N) the grip force
limit (none or 0 = parameter ``max_effort``). Reached when the joint is within
``goal_tolerance`` of its target; stall, force limit, preemption and cancel as
``~/gripper_cmd`` (``gripper_command_server``). Result and feedback ``state``: the joint's
name, position (m), opening velocity (m/s) and effort (the real grip force, N), stamped
in sim time; the result's ``stalled`` and ``reached_goal`` as the controller's.
"""
from __future__ import annotations

import math

from control_msgs.action import ParallelGripperCommand
from sensor_msgs.msg import JointState
from std_msgs.msg import Header

from gripper_sim.convert.frames import joint_positions
from gripper_sim.convert.messages import time_msg
from gripper_sim.ros.gripper_command_server import GoalProblem, GripperCommandServer, JawTarget

JAW_JOINTS = ('left_jaw_joint', 'right_jaw_joint')
DEFAULT_JOINT = JAW_JOINTS[0]


def _single(values, what: str, required: bool) -> float | None:
    """The one value of a JointState field (None when optional and empty)."""
    values = list(values)
    if not values and not required:
        return None
    if len(values) != 1:
        raise GoalProblem(f'command.{what} must hold one value (one jaw joint), '
                          f'got {len(values)}')
    value = float(values[0])
    if not math.isfinite(value):
        raise GoalProblem(f'command.{what} must be finite, got {value}')
    return value


def _in_range(what: str, value: float, low: float, high: float, unit: str,
              open_low: bool = False, note: str = '') -> None:
    """GoalProblem unless low <= value <= high (low < value if ``open_low``)."""
    if value > high or value < low or (open_low and value == low):
        bounds = f"{'(' if open_low else '['}{low:g}, {high:g}]"
        raise GoalProblem(f'{what} must be in {bounds} {unit}{note}, got {value:g} {unit}')


class ParallelGripperCommandServer(GripperCommandServer):
    """Serves ``~/parallel_gripper_cmd`` for a ``SimNode``."""

    kind = 'ParallelGripperCommand'
    action_type = ParallelGripperCommand
    action_name = '~/parallel_gripper_cmd'

    def target(self, goal, config) -> JawTarget:
        """The jaw target of a goal on one jaw joint; GoalProblem, in the joint's terms
        (its position and speed are half the gap's), if it is unusable."""
        command = goal.command
        names = list(command.name)
        if names and (len(names) != 1 or names[0] not in JAW_JOINTS):
            raise GoalProblem(f"command.name must be empty or one of {', '.join(JAW_JOINTS)}, "
                              f'got {names}')
        position = _single(command.position, 'position', required=True)
        velocity = _single(command.velocity, 'velocity', required=False)
        effort = _single(command.effort, 'effort', required=False)
        _in_range('command.position[0]', position, 0.0, 0.5 * config['gripper.max_gap'], 'm')
        if velocity is not None:
            _in_range('command.velocity[0]', velocity, 0.0, 0.5 * config['gripper.max_speed'],
                      'm/s', open_low=True)
        if effort is not None:
            _in_range('command.effort[0]', effort, 0.0, config['gripper.max_force'], 'N',
                      note=' (0 = parameter max_effort)')
        return JawTarget(gap=2.0 * position, max_effort=effort or 0.0,
                         speed=None if velocity is None else 2.0 * velocity,
                         tolerance_scale=2.0)

    def _state(self, run, result) -> JointState:
        names = list(run.goal_handle.request.command.name) or [DEFAULT_JOINT]
        position = joint_positions(result, self._node.message_context.frames)[names[0]]
        return JointState(header=Header(stamp=time_msg(result.time)), name=names,
                          position=[position], velocity=[-float(result.jaw_velocity)],
                          effort=[float(result.grip_force)])

    def _result(self, run, last) -> ParallelGripperCommand.Result:
        return ParallelGripperCommand.Result(state=self._state(run, last),
                                             stalled=run.stalled, reached_goal=run.reached)

    def _feedback_message(self, run, result) -> ParallelGripperCommand.Feedback:
        return ParallelGripperCommand.Feedback(state=self._state(run, result))
