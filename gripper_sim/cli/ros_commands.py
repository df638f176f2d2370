"""ROS verbs of ``gripper-sim``: node, jaw, lift, grasp, status, controller, and the node's
services (reset, pause, resume, step, record), so that no ``ros2`` command line is needed.

Every handler imports rclpy lazily (offline verbs run without ROS). Discovery defaults
to LOCALHOST when ``ROS_AUTOMATIC_DISCOVERY_RANGE`` is unset.
"""
from __future__ import annotations

import argparse
import math
import os
import signal
import sys
import threading
import time

DEFAULT_NODE = '/gripper_sim'
WARN = 30   # rcl_interfaces/Log level
# After Ctrl-C a verb cancels its goal and waits this long for the answer, then exits.
CANCEL_WAIT = 0.8   # s
# Feedback history of the Grasp client: every phase change is printed even when this
# process reads late.
FEEDBACK_DEPTH = 200


def _finite(minimum: float | None = 0.0, positive: bool = False, what: str = 'value'):
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError as err:
            raise argparse.ArgumentTypeError(f'{what} must be a number, got {text!r}') from err
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f'{what} must be finite, got {text}')
        if positive and value <= 0:
            raise argparse.ArgumentTypeError(f'{what} must be > 0, got {text}')
        if minimum is not None and value < minimum:
            raise argparse.ArgumentTypeError(f'{what} must be >= {minimum:g}, got {text}')
        return value
    return parse


def _common(parser: argparse.ArgumentParser) -> None:
    parser.add_argument('--node', default=DEFAULT_NODE,
                        help=f'simulator node to talk to (default {DEFAULT_NODE})')
    parser.add_argument('--timeout', type=_finite(positive=True, what='--timeout'),
                        default=15.0, help='seconds to wait for the node (default 15)')


def register(subparsers) -> None:
    node = subparsers.add_parser(
        'node', help='run the gripper_sim ROS 2 node',
        description='Run the simulator node. Anything after --ros-args goes to ROS '
                    '(e.g. --ros-args -p real_time_factor:=0.0 --params-file p.yaml).')
    node.add_argument('--fruit', help='fruit preset name')
    node.add_argument('--config', help='YAML configuration file')
    node.set_defaults(handler=_node, accepts_extra=True)

    jaw = subparsers.add_parser('jaw', help='command the jaws of a running node')
    jaw_verbs = jaw.add_subparsers(dest='jaw_verb', metavar='{gap,force,open}')
    jaw_verbs.required = True
    gap = jaw_verbs.add_parser('gap', help='position mode: move to a gap (m)')
    gap.add_argument('value', type=_finite(what='gap'), help='jaw gap, m')
    _common(gap)
    gap.set_defaults(handler=_jaw, topic='jaw/gap_command', unit='m', what='gap')
    force = jaw_verbs.add_parser('force', help='force mode: close to a grip force (N)')
    force.add_argument('value', type=_finite(positive=True, what='force'), help='force, N')
    _common(force)
    force.set_defaults(handler=_jaw, topic='jaw/force_command', unit='N', what='force')
    opener = jaw_verbs.add_parser('open', help='open the jaws to the initial gap')
    _common(opener)
    opener.set_defaults(handler=_open)

    lift = subparsers.add_parser('lift', help='move the gripper to a height (m)')
    lift.add_argument('value', type=_finite(minimum=None, what='height'), help='height, m')
    _common(lift)
    lift.set_defaults(handler=_jaw, topic='lift/command', unit='m', what='lift')

    grasp = subparsers.add_parser('grasp', help='run a Grasp goal; exit 0 on success')
    grasp.add_argument('--force', required=True, type=_finite(positive=True, what='--force'),
                       help='grip force to close to, N')
    grasp.add_argument('--lift', type=_finite(what='--lift'), default=None,
                       help='lift height after closing, m (default 0; 0.03 with --place)')
    grasp.add_argument('--hold', type=_finite(what='--hold'), default=0.0,
                       help='hold time after lifting, s (default 0)')
    grasp.add_argument('--close-speed', type=_finite(what='--close-speed'), default=0.0,
                       help='jaw closing speed, m/s (default: the node default)')
    grasp.add_argument('--release', action='store_true', help='open the jaws at the end')
    grasp.add_argument('--place', action='store_true',
                       help='pick-and-place: lift, carry --transport m sideways, lower onto '
                            'the table, open, retreat (implies --release)')
    grasp.add_argument('--transport', type=_finite(minimum=None, what='--transport'),
                       default=None, help='with --place: sideways travel along x, m, signed '
                                          '(default 0.05)')
    grasp.add_argument('--retreat', type=_finite(what='--retreat'), nargs='?', const=0.02,
                       default=None, help='with --place: rise after opening, m (0.02 when '
                                          'given without a value; default 0)')
    grasp.add_argument('--quiet', action='store_true', help='no feedback lines')
    _common(grasp)
    grasp.set_defaults(handler=_grasp)

    status = subparsers.add_parser('status', help='print the fruit state')
    status.add_argument('--follow', action='store_true', help='keep printing (Ctrl-C stops)')
    status.add_argument('--rate', type=_finite(positive=True, what='--rate'), default=2.0,
                        help='lines per second with --follow (default 2)')
    _common(status)
    status.set_defaults(handler=_status)

    reset = subparsers.add_parser(
        'reset', help="back to t = 0 and the initial commands (the node's ~/reset)")
    _common(reset)
    reset.set_defaults(handler=_service, service='reset', kind='trigger')
    for verb, value, text in (('pause', True, 'pause the physics (~/pause true)'),
                              ('resume', False, 'resume the physics (~/pause false)')):
        paused = subparsers.add_parser(verb, help=text)
        _common(paused)
        paused.set_defaults(handler=_service, service='pause', kind='bool', value=value)
    step = subparsers.add_parser('step', help='take N physics steps while paused (~/step)')
    step.add_argument('steps', type=_steps, help='steps to take, 1 to 1,000,000')
    _common(step)
    step.set_defaults(handler=_step)
    record = subparsers.add_parser(
        'record-node', help="start or stop the node's own recording (~/record)",
        description="Start (to the node's record_path, or a new bag folder "
                    'gripper_sim_<date>_<time> in its working directory) or stop the '
                    "node's in-node recording of every physics step.")
    record.add_argument('action', choices=('start', 'stop'))
    _common(record)
    record.set_defaults(handler=_service, service='record', kind='bool')

    controller = subparsers.add_parser(
        'controller', help='run the example PI grip force controller node')
    controller.add_argument('--force', type=_finite(positive=True, what='--force'),
                            default=None, help='grip force setpoint, N')
    controller.add_argument('--node', default=None, help='simulator node')
    controller.set_defaults(handler=_controller, accepts_extra=True)


# ----------------------------------------------------------------- helpers
def _default_environment() -> None:
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    if 'FASTRTPS_DEFAULT_PROFILES_FILE' not in os.environ:
        from gripper_sim.ros.process import fastdds_profile
        os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = fastdds_profile()


class _Session:
    """An rclpy context with one node, spun by hand.

    Ctrl-C (SIGINT) only sets ``interrupted``; ``spin_until`` and ``spin_once`` then
    raise KeyboardInterrupt between two spins, never inside rclpy (a KeyboardInterrupt
    raised in, e.g., a future's ``__del__`` is swallowed, and the verb would go on).
    """

    def __init__(self, name: str):
        _default_environment()
        import rclpy
        self.rclpy = rclpy
        self.interrupted = threading.Event()
        self._previous_handler = None
        if threading.current_thread() is threading.main_thread():
            self._previous_handler = signal.signal(
                signal.SIGINT, lambda *_: self.interrupted.set())
        self.context = rclpy.Context()
        from rclpy.signals import SignalHandlerOptions
        # rclpy's handler would shut the context down first, and a Grasp goal could
        # no longer be canceled.
        rclpy.init(context=self.context, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node(name, context=self.context,
                                      start_parameter_services=False)
        from rclpy.executors import SingleThreadedExecutor
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.rejections: list[str] = []
        self._target_name = None

    def spin_once(self, timeout: float, interruptible: bool = True) -> None:
        if interruptible and self.interrupted.is_set():
            raise KeyboardInterrupt
        self.executor.spin_once(timeout_sec=timeout)

    def spin_until(self, condition, timeout: float, interruptible: bool = True) -> bool:
        """Spin until ``condition()`` (True) or ``timeout`` s (False); Ctrl-C raises
        KeyboardInterrupt unless not ``interruptible``."""
        deadline = time.monotonic() + timeout
        while not condition():
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return False
            self.spin_once(min(0.05, remaining), interruptible)
        return True

    def watch_rejections(self, node_path: str) -> None:
        """Collect the target node's warnings from /rosout (the reasons for rejections)."""
        from rcl_interfaces.msg import Log
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        self._target_name = node_path.strip('/').replace('/', '.')
        since = self.node.get_clock().now().nanoseconds

        def on_log(msg):
            stamp = msg.stamp.sec * 1_000_000_000 + msg.stamp.nanosec
            if (msg.name == self._target_name and msg.level >= WARN and stamp >= since
                    - 50_000_000):
                self.rejections.append(msg.msg)
        self.node.create_subscription(Log, '/rosout', on_log, QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE))

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        self.rclpy.try_shutdown(context=self.context)
        if self._previous_handler is not None:
            signal.signal(signal.SIGINT, self._previous_handler)

    def __enter__(self) -> '_Session':
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _error(text: str) -> int:
    print(f'error: {text}', file=sys.stderr)
    return 1


def _no_node(what: str, node_path: str, timeout: float) -> int:
    return _error(f'no {what} answered within {timeout:g} s: is `gripper-sim node` running '
                  f'as {node_path} with the same ROS_DOMAIN_ID '
                  f"({os.environ.get('ROS_DOMAIN_ID', '0')})?")


# ----------------------------------------------------------------- handlers
def _node(args) -> int:
    from gripper_sim.ros.node import main
    argv = ['gripper-sim node']
    if args.fruit:
        argv += ['--fruit', args.fruit]
    if args.config:
        argv += ['--config', args.config]
    return main(argv + list(args.extra))


def _controller(args) -> int:
    from gripper_sim.ros.controller import main
    argv = ['gripper-sim controller']
    if args.force is not None:
        argv += ['--force', repr(args.force)]
    if args.node:
        argv += ['--sim-node', args.node]
    return main(argv + list(args.extra))


def _jaw(args) -> int:
    """Publish one command, confirm delivery, wait for the node to accept or reject it
    (``~/jaw/command_status``), then show the next state."""
    from rclpy.duration import Duration
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64, String
    node_path = args.node.rstrip('/')
    topic = f'{node_path}/{args.topic}'
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    with _Session('gripper_sim_cli') as session:
        joints: list[JointState] = []
        session.node.create_subscription(JointState, 'joint_states', joints.append, 10)
        statuses: list[str] = []
        status = session.node.create_subscription(
            String, f'{node_path}/jaw/command_status', lambda m: statuses.append(m.data),
            reliable)
        publisher = session.node.create_publisher(Float64, topic, reliable)
        if not session.spin_until(lambda: publisher.get_subscription_count() > 0,
                                  args.timeout):
            return _no_node(f'subscriber on {topic}', node_path, args.timeout)
        if not session.spin_until(lambda: status.get_publisher_count() > 0, args.timeout):
            return _no_node(f'publisher of {node_path}/jaw/command_status', node_path,
                            args.timeout)
        # the node's description of this command, e.g. 'gap command 0.06 m'
        what = f'{args.what} command {args.value:g} {args.unit}'
        publisher.publish(Float64(data=float(args.value)))
        if not publisher.wait_for_all_acked(Duration(seconds=args.timeout)):
            return _error(f'{args.what} command on {topic} was not acknowledged within '
                          f'{args.timeout:g} s')
        print(f'{args.what} command {args.value:g} {args.unit} delivered to {topic}')

        def answer() -> str | None:
            return next((text for text in statuses if text.split(': ', 2)[1:2] == [what]),
                        None)
        if not session.spin_until(lambda: answer() is not None, args.timeout):
            return _error(f'the node did not answer the {args.what} command within '
                          f'{args.timeout:g} s')
        reply = answer()
        if reply.startswith('rejected'):
            return _error(f'the node rejected it: {reply.split(": ", 2)[2]}')
        if reply.startswith('superseded'):   # another command arrived before the next step
            return _error(f'not applied: {reply.split(": ", 2)[2]} (only the latest '
                          'command counts)')
        count = len(joints)
        if not session.spin_until(lambda: len(joints) > count, 1.0):
            print('accepted; no new state within 1 s (is the simulation paused?)')
        elif args.what == 'force':
            print(f'accepted; jaw contact force now {_measure(joints[-1], args.what):.3f} N')
        else:
            print(f'accepted; {args.what} now {_measure(joints[-1], args.what):.4f} m '
                  f'(moving towards {args.value:g} m)')
    return 0


def _measure(msg, what: str) -> float:
    names = list(msg.name)
    if what == 'lift':
        return msg.position[names.index('lift_joint')]
    if what == 'force':
        return 0.5 * (msg.effort[names.index('left_jaw_joint')]
                      + msg.effort[names.index('right_jaw_joint')])
    return msg.position[names.index('left_jaw_joint')] + \
        msg.position[names.index('right_jaw_joint')]


def _steps(text: str) -> int:
    try:
        value = int(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f'steps must be a whole number, got {text!r}') from err
    if not 1 <= value <= 1_000_000:
        raise argparse.ArgumentTypeError(f'steps must be 1 to 1000000, got {value}')
    return value


def _call(args, srv_type, service: str, request, answer_timeout: float | None = None):
    """Call the node's ``service`` (relative to ``--node``) with ``request``; (exit code,
    response): exit 1 with a hint if no node serves it in ``--timeout`` s or answers in
    ``answer_timeout`` s (default ``--timeout``; ``math.inf``: until it answers)."""
    node_path = args.node.rstrip('/')
    name = f'{node_path}/{service}'
    answer_timeout = args.timeout if answer_timeout is None else answer_timeout
    with _Session('gripper_sim_cli') as session:
        client = session.node.create_client(srv_type, name)
        if not session.spin_until(client.service_is_ready, args.timeout):
            return _no_node(f'service {name}', node_path, args.timeout), None
        future = client.call_async(request)
        if not session.spin_until(future.done, answer_timeout):
            return _error(f'the node did not answer {name} within '
                          f'{answer_timeout:g} s'), None
        return 0, future.result()


def _answer(response) -> int:
    """Print a Trigger/SetBool/Step response's message; 0 on success, else 1."""
    print(response.message, file=sys.stdout if response.success else sys.stderr)
    return 0 if response.success else 1


def _service(args) -> int:
    """A Trigger or SetBool service of the node: ``args.service``, ``args.kind``, the
    SetBool value in ``args.value`` (pause/resume) or ``args.action`` (record)."""
    from std_srvs.srv import SetBool, Trigger
    if args.kind == 'trigger':
        code, response = _call(args, Trigger, args.service, Trigger.Request())
    else:
        value = args.value if args.service == 'pause' else args.action == 'start'
        code, response = _call(args, SetBool, args.service, SetBool.Request(data=value))
    return code if response is None else _answer(response)


def _step(args) -> int:
    """``~/step``: the node answers once it has taken the steps, however long they take,
    so the answer is awaited without a limit (Ctrl-C leaves the node stepping)."""
    from gripper_sim_interfaces.srv import Step
    try:
        code, response = _call(args, Step, 'step', Step.Request(steps=args.steps),
                               answer_timeout=math.inf)
    except KeyboardInterrupt:
        print('interrupted: the node goes on with the steps; `gripper-sim pause` ends them',
              file=sys.stderr)
        raise
    if response is None:
        return code
    if response.success:
        print(f'{response.message} (sim time {response.sim_time:.6g} s)'
              if response.message else f'sim time {response.sim_time:.6g} s')
        return 0
    return _answer(response)


def _open(args) -> int:
    from std_srvs.srv import Trigger
    code, response = _call(args, Trigger, 'jaw/open', Trigger.Request())
    if response is None:
        return code
    print(response.message)
    return 0 if response.success else 1


def _grasp(args) -> int:
    from rclpy.action import ActionClient
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from gripper_sim_interfaces.action import Grasp
    from gripper_sim.ros.goal_feedback import GoalFeedback
    node_path = args.node.rstrip('/')
    with _Session('gripper_sim_grasp_cli') as session:
        session.watch_rejections(node_path)
        qos = QoSProfile(depth=FEEDBACK_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        client = ActionClient(session.node, Grasp, f'{node_path}/grasp',
                              feedback_sub_qos_profile=qos)
        feedback = GoalFeedback(session.node, Grasp, f'{node_path}/grasp', qos)
        if not session.spin_until(client.server_is_ready, args.timeout):
            return _no_node(f'Grasp action server {node_path}/grasp', node_path, args.timeout)
        if not args.place and (args.transport is not None or args.retreat is not None):
            print('error: --transport and --retreat need --place', file=sys.stderr)
            return 2
        lift = args.lift if args.lift is not None else (0.03 if args.place else 0.0)
        goal = Grasp.Goal(target_force=args.force, close_speed=args.close_speed,
                          lift_height=lift, hold_time=args.hold,
                          release=args.release or args.place, place=args.place,
                          transport_distance=(0.05 if args.transport is None
                                              else args.transport) if args.place else 0.0,
                          retreat_height=args.retreat or 0.0)
        printed = {'phase': None, 'wall': 0.0}

        def on_feedback(fb):
            if args.quiet:
                return
            now = time.monotonic()
            if fb.phase != printed['phase'] or now - printed['wall'] >= 0.25:
                printed.update(phase=fb.phase, wall=now)
                print(f'  {fb.phase:<12} gap {fb.gap * 1e3:7.2f} mm  grip {fb.grip_force:6.2f} N'
                      f'  compression {fb.compression * 1e3:6.3f} mm', flush=True)
        if args.place:
            print(f'grasp and place: {args.force:g} N, lift {lift:g} m, transport '
                  f'{goal.transport_distance:g} m, retreat {goal.retreat_height:g} m',
                  flush=True)
        else:
            print(f'grasp: {args.force:g} N, lift {lift:g} m, hold {args.hold:g} s'
                  + (', release' if args.release else ''), flush=True)
        sent = client.send_goal_async(goal, goal_uuid=feedback.new_goal(on_feedback))
        try:
            answered = session.spin_until(sent.done, args.timeout)
        except KeyboardInterrupt:   # the goal may be accepted all the same: cancel it
            session.spin_until(sent.done, CANCEL_WAIT, interruptible=False)
            if sent.done() and sent.result().accepted:
                return _cancel(session, sent.result(), sent.result().get_result_async())
            return 130
        if not answered:
            return _error('the Grasp server did not answer the goal request')
        handle = sent.result()
        if not handle.accepted:
            session.spin_until(lambda: bool(session.rejections), 3.0)
            reason = session.rejections[0] if session.rejections else \
                'no reason received (see the node log)'
            return _error(f'goal rejected: {reason}')
        result_future = handle.get_result_async()
        try:
            gone_since = None
            while not result_future.done():
                session.spin_once(0.1)
                if client.server_is_ready():
                    gone_since = None
                elif gone_since is None:
                    gone_since = time.monotonic()
                elif time.monotonic() - gone_since > 5.0:
                    return _error('the node went away before the goal finished')
            feedback.drain(session.spin_once)
        except KeyboardInterrupt:
            return _cancel(session, handle, result_future)
        result = result_future.result().result
        _print_result(result)
        return 0 if result.success else 1


def _cancel(session: _Session, handle, result_future) -> int:
    """Ctrl-C during a goal: cancel it, print its result if it comes within
    ``CANCEL_WAIT`` s, and exit 130."""
    print('canceling the goal...', flush=True)
    cancel = handle.cancel_goal_async()
    deadline = time.monotonic() + CANCEL_WAIT
    session.spin_until(result_future.done, CANCEL_WAIT, interruptible=False)
    if result_future.done():
        _print_result(result_future.result().result)
    else:
        session.spin_until(cancel.done, max(0.0, deadline - time.monotonic()),
                           interruptible=False)
        if cancel.done() and cancel.result().goals_canceling:
            print(f'the node is canceling the goal (no result within {CANCEL_WAIT:g} s)',
                  flush=True)
        else:
            print(f'the node did not confirm the cancel within {CANCEL_WAIT:g} s',
                  flush=True)
    return 130


def _print_result(result) -> None:
    print(f"result: {'SUCCESS' if result.success else 'FAILED'} ({result.outcome}): "
          f'{result.message}')
    dropped = f', dropped at t = {result.dropped_at:.3f} s' if result.dropped_at >= 0 else ''
    print(f'  slipped {result.slipped}, bruised {result.bruised} '
          f'({result.bruised_fraction:.1%} of the surface), crushed {result.crushed}, slip '
          f'distance {result.slip_distance * 1e3:.3f} mm{dropped}')
    print(f'  peak grip force {result.max_grip_force:.3f} N, final gap '
          f'{result.final_gap * 1e3:.2f} mm, peak compression '
          f'{result.max_compression * 1e3:.3f} mm, peak jaw pressure '
          f'{result.max_contact_pressure / 1e3:.1f} kPa, peak damage pressure '
          f'{result.peak_damage_pressure / 1e3:.1f} kPa', flush=True)


def format_state(msg) -> str:
    """A FruitState as a few readable lines."""
    t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
    contact = ('both jaws' if msg.left_jaw_contact and msg.right_jaw_contact else
               'left jaw' if msg.left_jaw_contact else
               'right jaw' if msg.right_jaw_contact else 'no jaw')
    flags = [name for name, on in (('SLIPPING', msg.slipping), ('BRUISED', msg.bruised),
                                   ('CRUSHED', msg.crushed)) if on]
    return (f't {t:8.3f} s  gap {msg.gap * 1e3:7.2f} mm  grip {msg.grip_force:6.2f} N  '
            f'compression {msg.compression * 1e3:6.3f} mm ({msg.compression_ratio:.2%})  '
            f'peak pressure {msg.peak_contact_pressure / 1e3:7.1f} kPa (damage '
            f'{msg.damage_pressure / 1e3:.1f} kPa)  contact {contact}  '
            f'centroid z {msg.centroid.z * 1e3:6.2f} mm  slip {msg.slip_distance * 1e3:.3f} mm'
            + (f"  {' '.join(flags)}" if flags else ''))


def _status(args) -> int:
    from gripper_sim_interfaces.msg import FruitState
    node_path = args.node.rstrip('/')
    with _Session('gripper_sim_status_cli') as session:
        states: list = []
        session.node.create_subscription(FruitState, f'{node_path}/fruit/state',
                                         states.append, 10)
        if not session.spin_until(lambda: bool(states), args.timeout):
            return _no_node(f'FruitState on {node_path}/fruit/state', node_path, args.timeout)
        print(format_state(states[-1]), flush=True)
        if not args.follow:
            return 0
        period = 1.0 / args.rate
        try:
            while True:
                states.clear()
                next_line = time.monotonic() + period
                session.spin_until(lambda: time.monotonic() >= next_line, period + 1.0)
                if states:
                    print(format_state(states[-1]), flush=True)
        except KeyboardInterrupt:
            return 0
