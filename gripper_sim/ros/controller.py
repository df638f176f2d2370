"""Example grip force controller: a PI loop closed through topics only.

The template to copy for your own controller. It never touches the simulator's
internals: it reads what any real gripper driver would publish and commands the jaws
by topic.

- in: ``/<sim>/left_jaw/wrench``, ``/<sim>/right_jaw/wrench`` (WrenchStamped: the
  grip force is the mean of the two contact normal forces, |force.x|) and
  ``/joint_states`` (the measured gap is left_jaw_joint + right_jaw_joint);
- out: ``/<sim>/jaw/gap_command`` (Float64, m).

Control law (velocity form, so switching it on is bumpless): with e = setpoint - force,
the gap command moves by ``-(kp * (e - e_prev) + ki * e * dt)`` every wrench sample,
``dt`` taken from the message stamps (sim time: the loop is right at any real-time
factor). The command moves at most ``max_gap_rate`` and stays within ``windup_margin``
of the measured gap (anti-windup while the jaws travel).

Run: ``gripper-sim controller --force 6`` or ``python -m gripper_sim.ros.controller
--ros-args -p force:=6.0``.
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time

import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.utilities import remove_ros_args

from geometry_msgs.msg import WrenchStamped
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

JAW_JOINTS = ('left_jaw_joint', 'right_jaw_joint')
#: s of wall time without a wrench before the controller says what it waits for
WAIT_WARNING = 5.0


def _range(low: float, high: float) -> list[FloatingPointRange]:
    return [FloatingPointRange(from_value=low, to_value=high, step=0.0)]


class ForceController(Node):
    """PI grip-force controller node ``gripper_force_controller``."""

    def __init__(self, **kwargs):
        super().__init__('gripper_force_controller', **kwargs)
        self.declare_parameter('force', 5.0, ParameterDescriptor(
            description='grip force setpoint [N]', floating_point_range=_range(0.0, 1000.0)))
        self.declare_parameter('kp', 1.0e-4, ParameterDescriptor(
            description='proportional gain [m/N]', floating_point_range=_range(0.0, 1.0)))
        self.declare_parameter('ki', 4.0e-3, ParameterDescriptor(
            description='integral gain [m/(N s)]', floating_point_range=_range(0.0, 10.0)))
        self.declare_parameter('max_gap_rate', 0.02, ParameterDescriptor(
            description='fastest change of the gap command [m/s]',
            floating_point_range=_range(1e-5, 1.0)))
        self.declare_parameter('windup_margin', 0.002, ParameterDescriptor(
            description='largest distance of the command from the measured gap [m]',
            floating_point_range=_range(1e-5, 0.1)))
        self.declare_parameter('sim_node', '/gripper_sim', ParameterDescriptor(
            description='the simulator node whose topics to use', read_only=True))
        self.add_on_set_parameters_callback(self._check)
        sim = self.get_parameter('sim_node').value.rstrip('/')
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self._command = self.create_publisher(Float64, f'{sim}/jaw/gap_command', qos)
        self.create_subscription(WrenchStamped, f'{sim}/left_jaw/wrench',
                                 lambda m: self._on_wrench(0, m), qos)
        self.create_subscription(WrenchStamped, f'{sim}/right_jaw/wrench',
                                 lambda m: self._on_wrench(1, m), qos)
        self.create_subscription(JointState, 'joint_states', self._on_joints, qos)
        self._forces: list[tuple[int, float] | None] = [None, None]
        self.gap: float | None = None
        self.force: float | None = None
        self.command: float | None = None
        self._last_t: int | None = None
        self._last_error = 0.0
        self._sim = sim
        self._warned_waiting = False
        self.get_logger().info(
            f"controlling {sim}: grip force setpoint {self.get_parameter('force').value:g} N")

    def warn_if_waiting(self, waited: float) -> None:
        """Once, after ``waited`` s (wall time) with no wrench from the simulator: say
        where it listens, so that a controller without a simulator does not wait in
        silence."""
        if self._warned_waiting or any(self._forces):
            return
        self._warned_waiting = True
        self.get_logger().warning(
            f'no wrench on {self._sim}/left_jaw/wrench after {waited:.0f} s: is '
            f'`gripper-sim node` running as {self._sim} with the same ROS_DOMAIN_ID '
            f"({os.environ.get('ROS_DOMAIN_ID', '0')})? Waiting on.")

    def _check(self, parameters: list[Parameter]) -> SetParametersResult:
        for parameter in parameters:
            value = parameter.value
            if isinstance(value, float) and not math.isfinite(value):
                reason = f"parameter '{parameter.name}' must be finite, got {value}"
                self.get_logger().warning(f'rejected: {reason}')
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _on_joints(self, msg: JointState) -> None:
        try:
            self.gap = sum(msg.position[list(msg.name).index(j)] for j in JAW_JOINTS)
        except (ValueError, IndexError):
            return

    def _on_wrench(self, side: int, msg: WrenchStamped) -> None:
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        self._forces[side] = (stamp, abs(msg.wrench.force.x))
        left, right = self._forces
        if left is None or right is None or left[0] != right[0]:
            return   # wait for the pair of the same step
        self.update(stamp, 0.5 * (left[1] + right[1]))

    def update(self, stamp_ns: int, force: float) -> None:
        """One PI update at sim time ``stamp_ns`` with measured grip force ``force`` (N)."""
        if self.gap is None:
            return
        self.force = force
        setpoint = self.get_parameter('force').value
        error = setpoint - force
        if self._last_t is None or stamp_ns <= self._last_t or self.command is None:
            # first sample, or the simulation was reset (time went back): start afresh
            self._last_t, self._last_error, self.command = stamp_ns, error, self.gap
            return
        dt = (stamp_ns - self._last_t) * 1e-9
        kp, ki = self.get_parameter('kp').value, self.get_parameter('ki').value
        step = -(kp * (error - self._last_error) + ki * error * dt)
        limit = self.get_parameter('max_gap_rate').value * dt
        step = min(max(step, -limit), limit)
        margin = self.get_parameter('windup_margin').value
        command = min(max(self.command + step, self.gap - margin), self.gap + margin)
        self.command = max(command, 0.0)
        self._last_t, self._last_error = stamp_ns, error
        self._command.publish(Float64(data=self.command))


def main(args: list[str] | None = None) -> int:
    """Console script ``controller``; ``gripper-sim controller --force 6``."""
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    argv = list(sys.argv if args is None else args)
    parser = argparse.ArgumentParser(prog='controller', description=__doc__.splitlines()[0])
    parser.add_argument('--force', type=float, help='grip force setpoint, N')
    parser.add_argument('--sim-node', help='simulator node (default /gripper_sim)')
    try:
        options = parser.parse_args(remove_ros_args(argv)[1:])
    except rclpy_implementation.RCLError as err:   # malformed --ros-args
        print(f'error: {err}', file=sys.stderr)
        return 2
    overrides = []
    if options.force is not None:
        if not math.isfinite(options.force) or options.force <= 0:
            print(f'error: --force must be a finite number > 0 N, got {options.force}',
                  file=sys.stderr)
            return 2
        overrides.append(Parameter('force', value=float(options.force)))
    if options.sim_node:
        overrides.append(Parameter('sim_node', value=options.sim_node))
    # Our own SIGINT/SIGTERM handling instead of rclpy's: rclpy's shuts the context down
    # at once, and a spin under way then fails on the invalid context with a traceback.
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stopping = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stopping.set())
    node = None
    try:
        try:
            node = ForceController(parameter_overrides=overrides)
        except Exception as err:   # invalid parameter overrides: say so, no traceback
            rclpy.logging.get_logger('gripper_force_controller').error(f'cannot start: {err}')
            return 2
        started = time.monotonic()
        while not stopping.is_set() and rclpy.ok():
            rclpy.spin_once(node, timeout_sec=0.1)
            if time.monotonic() - started > WAIT_WARNING:
                node.warn_if_waiting(WAIT_WARNING)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
