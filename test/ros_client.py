"""A client of a running ``gripper_sim`` node, for the integration tests and the benchmark.

Everything waits by condition (matching, a received message) with a timeout, never by
a fixed sleep. The client has its own rclpy context, so several can coexist in a
process and none disturbs another's shutdown.
"""
from __future__ import annotations

import contextlib
import os
import time
from collections import deque
from typing import Any, Callable

import rclpy
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy

from control_msgs.action import GripperCommand, ParallelGripperCommand
from geometry_msgs.msg import WrenchStamped
from gripper_sim_interfaces.action import Grasp
from gripper_sim_interfaces.msg import FruitState
from gripper_sim_interfaces.srv import Step
from gripper_sim.ros.goal_feedback import GoalFeedback
from rcl_interfaces.msg import Log, Parameter as ParameterMsg
from rcl_interfaces.srv import SetParameters
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState, PointCloud2
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage
from visualization_msgs.msg import MarkerArray

from gripper_sim.ros.process import apply_ros_environment, ros_environment

RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
# Action feedback: as deep as the servers' history, so a slow client misses no phase.
FEEDBACK = QoSProfile(depth=200, reliability=ReliabilityPolicy.RELIABLE)


class TimeoutError_(AssertionError):
    """A condition did not come true in time (an AssertionError: pytest shows it)."""


class SimClient:
    """Subscribes to every topic of the node and offers its commands, services, actions.

    Attributes:
        latest: ``{suffix: last message}`` for 'fruit/state', 'fruit/nodes',
            'left_jaw/wrench', 'right_jaw/wrench', 'joint_states', 'markers', 'clock',
            'tf'.
        counts: messages received per suffix.
        states: the last 2000 FruitState messages.
        logs: /rosout messages of the node (warnings and above).
    """

    def __init__(self, domain_id: int, node_path: str = '/gripper_sim',
                 name: str = 'gripper_sim_test_client'):
        apply_ros_environment(domain_id)
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=domain_id)
        self.node = rclpy.create_node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.path = node_path.rstrip('/')
        self.latest: dict[str, Any] = {}
        self.counts: dict[str, int] = {}
        self.states: deque = deque(maxlen=2000)
        self.logs: list[Log] = []
        node_name = self.path.strip('/').replace('/', '.')
        topics = {
            'fruit/state': (FruitState, f'{self.path}/fruit/state'),
            'fruit/nodes': (PointCloud2, f'{self.path}/fruit/nodes'),
            'left_jaw/wrench': (WrenchStamped, f'{self.path}/left_jaw/wrench'),
            'right_jaw/wrench': (WrenchStamped, f'{self.path}/right_jaw/wrench'),
            'joint_states': (JointState, '/joint_states'),
            'markers': (MarkerArray, f'{self.path}/markers'),
            'clock': (Clock, '/clock'),
            'tf': (TFMessage, '/tf'),
        }
        for suffix, (kind, topic) in topics.items():
            self.node.create_subscription(kind, topic, self._store(suffix),
                                          1 if suffix == 'clock' else RELIABLE)

        def on_log(msg: Log) -> None:
            if msg.name == node_name and msg.level >= 30:
                self.logs.append(msg)
        self.node.create_subscription(Log, '/rosout', on_log,
                                      QoSProfile(depth=200,
                                                 reliability=ReliabilityPolicy.RELIABLE))
        self.publishers = {
            what: self.node.create_publisher(Float64, f'{self.path}/{topic}', RELIABLE)
            for what, topic in (('gap', 'jaw/gap_command'), ('force', 'jaw/force_command'),
                                ('lift', 'lift/command'))}
        self.reset_client = self.node.create_client(Trigger, f'{self.path}/reset')
        self.pause_client = self.node.create_client(SetBool, f'{self.path}/pause')
        self.step_client = self.node.create_client(Step, f'{self.path}/step')
        self.open_client = self.node.create_client(Trigger, f'{self.path}/jaw/open')
        self.param_client = self.node.create_client(SetParameters,
                                                    f'{self.path}/set_parameters')
        self._feedback: dict[ActionClient, GoalFeedback] = {}   # client -> its feedback topic
        self.grasp = self.action_client(Grasp, f'{self.path}/grasp')
        self.gripper_cmd = self.action_client(GripperCommand, f'{self.path}/gripper_cmd')
        self.parallel_gripper_cmd = self.action_client(ParallelGripperCommand,
                                                       f'{self.path}/parallel_gripper_cmd')

    def action_client(self, kind, name: str) -> ActionClient:
        """An action client of ``kind`` for the action ``name``, whose goals' feedback
        ``send_goal`` collects from the action's feedback topic itself (``GoalFeedback``:
        rclpy's client drops what is unread when the result comes)."""
        client = ActionClient(self.node, kind, name, feedback_sub_qos_profile=FEEDBACK)
        self._feedback[client] = GoalFeedback(self.node, kind, name, FEEDBACK)
        return client

    def _store(self, suffix: str) -> Callable[[Any], None]:
        def store(msg) -> None:
            self.latest[suffix] = msg
            self.counts[suffix] = self.counts.get(suffix, 0) + 1
            if suffix == 'fruit/state':
                self.states.append(msg)
        return store

    # ----------------------------------------------------------------- waiting
    def spin_until(self, condition: Callable[[], Any], timeout: float = 30.0,
                   what: str = 'condition') -> Any:
        """Spin until ``condition()`` is truthy; returns it; AssertionError on timeout."""
        deadline = time.monotonic() + timeout
        while True:
            value = condition()
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError_(f'timed out after {timeout:g} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.05)

    def wait_ready(self, timeout: float = 60.0) -> None:
        """Until every service, both actions and the state topic are matched."""
        clients = (self.reset_client, self.pause_client, self.step_client, self.open_client,
                   self.param_client)
        self.spin_until(lambda: all(c.service_is_ready() for c in clients)
                        and self.grasp.server_is_ready() and self.gripper_cmd.server_is_ready()
                        and self.parallel_gripper_cmd.server_is_ready()
                        and all(p.get_subscription_count() > 0
                                for p in self.publishers.values())
                        and 'fruit/state' in self.latest, timeout, 'the node to be ready')

    def sim_time(self) -> float:
        stamp = self.latest['fruit/state'].header.stamp
        return stamp.sec + stamp.nanosec * 1e-9

    def stamp_ns(self, suffix: str) -> int | None:
        """Sim-time stamp (ns) of the latest message on ``suffix``; None if none yet."""
        msg = self.latest.get(suffix)
        if msg is None:
            return None
        if suffix == 'clock':
            stamp = msg.clock
        elif suffix == 'markers':
            if not msg.markers:
                return None
            stamp = msg.markers[0].header.stamp
        elif suffix == 'tf':
            if not msg.transforms:
                return None
            stamp = msg.transforms[0].header.stamp
        else:
            stamp = msg.header.stamp
        return stamp.sec * 1_000_000_000 + stamp.nanosec

    def catch_up(self, suffixes, since: str = 'fruit/state', timeout: float = 30.0) -> None:
        """Until the latest message on each of ``suffixes`` is as recent as ``since``'s.

        Every topic arrives on its own: when a condition on one topic came true, another
        topic's latest message may still be from an earlier step.
        """
        stamp = self.stamp_ns(since)
        self.spin_until(lambda: all((self.stamp_ns(s) or -1) >= stamp for s in suffixes),
                        timeout, f"{', '.join(suffixes)} as recent as {since}")

    def restart(self, run: bool = True, timeout: float = 60.0) -> None:
        """Reset the node; return once every topic seen so far shows the t = 0 state.

        Paused around the reset: the reset state is then the last one the node
        publishes, so every topic here ends on it however fast the node steps. (Reset
        while running, a fast node is many steps past t = 0, and the reset state long
        gone from a depth-10 history, before this client looks.) Then running again,
        unless ``run`` is false.
        """
        self.pause(True)
        self.reset()
        topics = list(self.latest)
        self.spin_until(lambda: all(self.stamp_ns(s) == 0 for s in topics), timeout,
                        f"the reset state (t = 0) on {', '.join(topics)}")
        if run:
            self.pause(False)

    def caught_up(self, *suffixes: str, timeout: float = 60.0) -> None:
        """Until the latest messages on ``suffixes`` are at least as recent (sim time) as
        the latest ``fruit/state``: topics arrive independently, and under load one can
        lag another by several steps."""
        now = self.stamp_ns('fruit/state')
        self.spin_until(lambda: all((self.stamp_ns(s) or -1) >= now for s in suffixes),
                        timeout, f'{", ".join(suffixes)} to catch up with fruit/state')

    def wait_sim_time(self, seconds: float, timeout: float = 60.0) -> None:
        """Until the node's published sim time has advanced by ``seconds``."""
        start = self.spin_until(lambda: 'fruit/state' in self.latest, timeout) and \
            self.sim_time()
        self.spin_until(lambda: self.sim_time() >= start + seconds - 1e-9, timeout,
                        f'{seconds} s of sim time')

    def wait_log(self, text: str, timeout: float = 20.0, since: int = 0) -> Log:
        """Until the node logged a warning containing ``text`` (at index >= ``since``)."""
        def found():
            return next((m for m in self.logs[since:] if text in m.msg), None)
        return self.spin_until(found, timeout, f'node log containing {text!r}')

    # ---------------------------------------------------------------- commands
    def publish(self, what: str, value: float) -> None:
        publisher = self.publishers[what]
        self.spin_until(lambda: publisher.get_subscription_count() > 0, 30.0,
                        f'a subscriber for the {what} command')
        publisher.publish(Float64(data=float(value)))

    def call(self, client, request, timeout: float = 60.0):
        self.spin_until(client.service_is_ready, timeout, f'service {client.srv_name}')
        future = client.call_async(request)
        self.spin_until(future.done, timeout, f'a response from {client.srv_name}')
        return future.result()

    def reset(self):
        return self.call(self.reset_client, Trigger.Request())

    def pause(self, on: bool = True):
        return self.call(self.pause_client, SetBool.Request(data=on))

    def step(self, steps: int):
        return self.call(self.step_client, Step.Request(steps=steps))

    def set_parameters(self, **values) -> list:
        """Set node parameters (``physics__x`` for ``physics.x``); the SetParametersResults."""
        request = SetParameters.Request()
        request.parameters = [Parameter(name.replace('__', '.'), value=value).to_parameter_msg()
                              for name, value in values.items()]
        return list(self.call(self.param_client, request).results)

    # ----------------------------------------------------------------- actions
    def send_goal(self, client: ActionClient, goal, feedback: list | None = None,
                  timeout: float = 30.0):
        """Send ``goal``; returns the goal handle (check ``.accepted``). ``feedback``
        (with a ``client`` from ``action_client``) receives every feedback of the goal,
        also what arrives after its result."""
        self.spin_until(client.server_is_ready, timeout, 'the action server')
        topic = self._feedback.get(client)
        goal_id = (topic.new_goal(feedback.append) if topic is not None and feedback is not None
                   else None)
        future = client.send_goal_async(goal, goal_uuid=goal_id)
        return self.spin_until(lambda: future.done() and future.result(), timeout,
                               'the goal response')

    def result(self, handle, timeout: float = 120.0):
        """Wait for the result of an accepted goal: ``(status, result)``."""
        future = handle.get_result_async()
        self.spin_until(future.done, timeout, 'the action result')
        response = future.result()
        return response.status, response.result

    def cancel(self, handle, timeout: float = 30.0):
        future = handle.cancel_goal_async()
        self.spin_until(future.done, timeout, 'the cancel response')
        return future.result()

    def close(self) -> None:
        self.grasp.destroy()
        self.gripper_cmd.destroy()
        self.parallel_gripper_cmd.destroy()
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def param_value(msg: ParameterMsg) -> Any:
    """The Python value of an ``rcl_interfaces/Parameter`` message."""
    return Parameter.from_parameter_msg(msg).value


@contextlib.contextmanager
def ros_context(domain_id: int):
    """An rclpy context of this process on ``domain_id``, the ROS environment set for it
    (``apply_ros_environment``); shut down afterwards."""
    apply_ros_environment(domain_id)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)


#: the variables ``ros_process.ros_environment`` sets that an in-process context reads
_ENV_KEYS = ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'ROS_DOMAIN_ID', 'RMW_IMPLEMENTATION',
             'FASTRTPS_DEFAULT_PROFILES_FILE')


@contextlib.contextmanager
def isolated_context(domain_id: int):
    """An rclpy context of this process on ``domain_id``, this process's ROS environment
    set for it meanwhile and restored afterwards; shut down afterwards."""
    env = ros_environment(domain_id)
    saved = {key: os.environ.get(key) for key in _ENV_KEYS}
    os.environ.update({key: env[key] for key in _ENV_KEYS})
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    try:
        yield context
    finally:
        rclpy.try_shutdown(context=context)
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


@contextlib.contextmanager
def ros_node(domain_id: int, name: str):
    """(node, its single-threaded executor) named ``name`` on ``domain_id``, in an
    ``isolated_context``; destroyed afterwards."""
    with isolated_context(domain_id) as context:
        node = rclpy.create_node(name, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        try:
            yield node, executor
        finally:
            executor.shutdown()
            node.destroy_node()


def spin_until(executor, condition: Callable[[], Any], timeout: float = 120.0,
               what: str = 'the condition') -> None:
    """Spin ``executor`` until ``condition()`` holds; AssertionError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f'timed out after {timeout} s waiting for {what}')
        executor.spin_once(timeout_sec=0.05)
