"""The ``gripper_sim`` node: a thin ROS 2 adapter around the physics core (``Simulation``, or
``Simulation3D`` with the physics parameter ``dimension`` 3: ``core.make_simulation``).

The node composes one module per job: ``sync`` (the simulation lock, the jaw
ownership), ``physics_thread`` (stepping and pacing), ``commands`` (the command queue
and the jaw topics), ``publishing`` (state topics in step order), ``runtime_parameters``
(what a parameter change does), ``description`` (``/tf_static``, the URDF on
``robot_description``), ``recording_control`` (``record_path``, ``~/record``),
``services`` (``~/reset``, ``~/pause``, ``~/step``, ``~/jaw/open``),
``simulation_standard`` (the simulation_interfaces services over them) and the three
action servers (Grasp, control_msgs GripperCommand and ParallelGripperCommand). What
stays here is the step itself (commands, physics, listeners, publishing) and the reset,
which touch all of them.

See the README section "ROS interface" for every topic, service, action and parameter.
"""
from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
import time
from typing import Any, Callable, Mapping

import rclpy
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.utilities import remove_ros_args

from gripper_sim import configuration, interrupts
from gripper_sim.convert import messages
from gripper_sim.convert.messages import MessageContext
from gripper_sim.core.results import StepResult
from gripper_sim.errors import (CommandError, ConvergenceError, FingersClosed,
                                GripperSimError)
from gripper_sim.ros.commands import CommandQueue, DoneCallback, JawCommandTopics
from gripper_sim.ros.description import RobotDescription
from gripper_sim.ros.entities import EntityServices
from gripper_sim.ros.grasp_server import GraspServer
from gripper_sim.ros.gripper_command_server import GripperCommandServer
from gripper_sim.ros.namesakes import NAMESAKE_WAIT, NamesakeWatch, refuse_namesake
from gripper_sim.ros.parallel_gripper_server import ParallelGripperCommandServer
from gripper_sim.ros.params import SimParameters
from gripper_sim.ros.physics_thread import PhysicsLoop
from gripper_sim.ros.publishing import OrderedPublisher, PublishObserver
from gripper_sim.ros.recording_control import RecordingControl
from gripper_sim.ros.runtime_parameters import RuntimeParameters, log_rejections
from gripper_sim.ros.services import SimServices
from gripper_sim.ros.simulation_standard import SimulationStandard
from gripper_sim.ros.sync import JawOwner, JawOwnership, SimLock
from gripper_sim.ros.watchdog import CHECK_PERIOD, STALL_TIMEOUT, PhysicsWatchdog
from gripper_sim.view.foxglove import start_node_view
from gripper_sim.workflows.compile_kernels import warm_kernels
from gripper_sim.workflows.factory import make_simulation

NODE_NAME = 'gripper_sim'
# GIL switch interval of the node process (Python's default: 5 ms). The physics thread
# computes without pause at real_time_factor 0; every other thread (executor, service
# and action callbacks) that gives up the GIL for a moment waits up to this long to get
# it back, many times per callback. At 5 ms a ~/reset or ~/pause took up to 1 s on a
# busy 2-core machine, at 1 ms under 0.2 s.
GIL_SWITCH_INTERVAL = 0.001   # s
# At shutdown the node spins this long to deliver an aborted goal's result.
RESULT_DELIVERY = 1.0   # s
# Set by ``main`` while its node is built, until the node starts anything (threads, a
# recording, the live view's server; ``SimNode.__init__`` clears it): a SIGINT or
# SIGTERM then stops it at once, the kernels' warm-up (minutes when it compiles) too.
STARTING = threading.Event()


class SimNode(Node):
    """The simulator node.

    Args:
        fruit, config_file: take precedence over the parameters of the same name.
        simulation_factory: builds the simulation from the flat configuration.
        start: start the physics thread (tests may drive ``advance`` by hand).
        physics_stall_timeout: wall s without progress of the physics loop that the
            watchdog reports as a stall.
        watchdog_period: wall s between watchdog checks (0: none; call
            ``watchdog.check()``).
        namesake_wait: wall s after its creation the node looks for another node of
            its name before it goes on (``namesakes``); None (the default, for a node
            embedded in a process): no look. ``main`` looks ``NAMESAKE_WAIT`` s.
        **kwargs: passed to ``rclpy.node.Node`` (e.g. ``parameter_overrides``).

    Raises:
        ConfigError: a parameter or the configuration is invalid.
        NameInUseError: another node of this name is in the ROS graph.
    """

    def __init__(self, *, fruit: str | None = None, config_file: str | None = None,
                 simulation_factory: Callable[[dict], Any] = make_simulation, start: bool = True,
                 physics_stall_timeout: float = STALL_TIMEOUT,
                 watchdog_period: float = CHECK_PERIOD,
                 namesake_wait: float | None = None, **kwargs):
        created, started = time.monotonic(), time.time()
        super().__init__(NODE_NAME, **kwargs)
        try:
            self._build(fruit, config_file, simulation_factory, start, physics_stall_timeout,
                        watchdog_period, namesake_wait, created, started)
        except BaseException:
            # rcl keeps one rosout publisher per logger name: a node left undestroyed
            # would carry the logs of every later node of its name to a dead end
            Node.destroy_node(self)
            raise

    def _build(self, fruit, config_file, simulation_factory, start, physics_stall_timeout,
               watchdog_period, namesake_wait, created, started) -> None:
        """The constructor's work after rclpy's ``Node`` (its arguments, and the monotonic
        and wall times it began)."""
        self.params = SimParameters(self, fruit=fruit, config_file=config_file)
        self.lock = SimLock()
        self.jaws = JawOwnership()
        self._sequence = 0          # +1 per step and per reset, under ``lock``
        self._simulation_factory = simulation_factory
        self.sim = simulation_factory(dict(self.params.config))
        self.message_context = MessageContext.from_config(
            self.params.config, initial=self.sim.last,
            frame_prefix=str(self.params.get('frame_prefix')))
        # after building the simulation: discovery has had that time to find a namesake
        if namesake_wait is not None:
            refuse_namesake(self, created, namesake_wait)
        # Before any topic, service or action exists: a client that finds them is served
        # at once, not after a first step that compiles (``_warm_up``).
        warmed = self._warm_up()
        self.namesake_watch = NamesakeWatch(self, started)
        self._step_listeners: list[Callable[[StepResult], None]] = []
        self._observers: list[Callable[[StepResult], None]] = []
        self._reset_listeners: list[Callable[[StepResult], None]] = []
        self.failures = 0
        self.steps_taken = 0
        self.physics = PhysicsLoop(
            lock=self.lock, step=lambda: self.advance(unless_paused=True),
            force_step=self.advance, run_commands=self._run_commands,
            has_commands=lambda: bool(self.commands),
            sim_time=lambda: self.sim.time, recover=self._recover, logger=self.get_logger(),
            real_time_factor=float(self.params.get('real_time_factor')))
        self.commands = CommandQueue(self.get_logger(), self.physics.wake)
        qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
        self.state_publisher = OrderedPublisher(self, qos, bool(self.params.get('publish_clock')))
        for group, name in (('state', 'publish_rate'), ('clock', 'clock_rate'),
                            ('markers', 'marker_rate')):
            self.state_publisher.set_rate(float(self.params.get(name)), self.sim.dt, group)
        self.runtime_parameters = RuntimeParameters(self)
        self.description = RobotDescription(self, self.message_context.frames)
        services = MutuallyExclusiveCallbackGroup()
        # Registered last: it starts or stops the recording, so every other check of
        # the same change has already accepted it.
        self.recording_control = RecordingControl(self, services)
        self.jaw_topics = JawCommandTopics(self, qos)
        self.sim_services = SimServices(self, services)
        self.simulation_standard = SimulationStandard(self, services)
        self.entities = EntityServices(self, services, self.replace_fruit)
        self.grasp_server = GraspServer(self)
        self.gripper_command_server = GripperCommandServer(self)
        self.parallel_gripper_server = ParallelGripperCommandServer(self)
        self.watchdog = PhysicsWatchdog(self, stall_timeout=physics_stall_timeout,
                                        period=watchdog_period)

        config = self.params.config
        publish_every = self.state_publisher.publish_every
        self.get_logger().info(
            f"ready: fruit '{config['fruit.name']}' ({config['fruit.model']} model, "
            f"{getattr(self.sim, 'dimension', 2)}D, {len(self.sim.last.positions)} nodes), "
            f'dt {self.sim.dt:g} s, publishing every '
            f'{publish_every} steps ({1.0 / (publish_every * self.sim.dt):g} Hz '
            f'sim time), real-time factor {self.physics.real_time_factor:g}, physics '
            f'kernels warmed up in {warmed:.1f} s')
        self.state_publisher.publish(self.sim.last, self.message_context.snapshot(),
                                     self._sequence)
        STARTING.clear()   # from here a signal stops the built node (``main``)
        self.recording_control.start_at_startup()
        # Foxglove live view (foxglove_port, 0 = off): observes published batches while a
        # client watches; None when off or its port is taken (a warning).
        self.live_view = start_node_view(self)
        if start:
            self.physics.start()

    def _warm_up(self) -> float:
        """Compile, or load from numba's cache, the kernels the configuration's steps
        use (``compile_kernels.warm_kernels``), before any topic, service or action
        exists; wall seconds taken."""
        self.get_logger().info('warming up the physics kernels: about a second from '
                               "numba's cache, minutes to compile them if `make install` "
                               'has not')
        return warm_kernels(self.params.config)

    # ------------------------------------------------------------------ hooks
    def add_observer(self, callback: Callable[[StepResult], None]) -> None:
        """Call ``callback(result)`` after every physics step (physics thread, under ``lock``).

        The hook for in-node recording; keep it fast, it runs in the physics loop.
        """
        self._observers.append(callback)

    def add_publish_observer(self, callback: PublishObserver) -> None:
        """Call ``callback({suffix: msg}, stamp_ns)`` with every batch the node publishes."""
        self.state_publisher.add_observer(callback)

    def remove_publish_observer(self, callback: PublishObserver) -> None:
        """Stop calling ``callback`` with published batches."""
        self.state_publisher.remove_observer(callback)

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

    def claim_jaws(self, owner: JawOwner, ticket: int) -> str | None:
        """Make ``owner`` the only driver of the jaws (preempting the active one); the
        reason it cannot, or None (``JawOwnership.claim``)."""
        return self.jaws.claim(owner, ticket)

    def release_jaws(self, owner: JawOwner) -> None:
        self.jaws.release(owner)

    @property
    def jaw_owner(self) -> JawOwner | None:
        return self.jaws.owner

    @property
    def paused(self) -> bool:
        return self.physics.paused

    @property
    def publish_count(self) -> int:
        return self.state_publisher.publish_count

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
                on_done: DoneCallback | None = None) -> None:
        """Run ``command()`` in the physics thread before the next step (at once while
        paused); then ``on_done(None)``, or ``on_done(reason)`` if the core refused it."""
        self.commands.put(description, command, on_done)

    # --------------------------------------------------------------- physics
    def advance(self, *, unless_paused: bool = False) -> StepResult | None:
        """Apply queued commands and take one physics step; None if the step failed.

        Args:
            unless_paused: take no step (None) if the node is paused, checked under the
                lock (the physics thread: no step starts after ``~/pause`` answered).
        """
        batch = None
        with self.lock:
            if unless_paused and self.physics.paused:
                return None
            self.commands.run_all()
            try:
                result = self.sim.step()
            except ConvergenceError as err:
                what = ('the step could not go on' if isinstance(err, FingersClosed)
                        else 'solver did not converge')
                self._recover(f'{what} at t = {self.sim.time:.4f} s: {err}')
                return None
            if not messages.result_is_finite(result):
                self._recover(f'step produced non-finite values at t = {result.time:.4f} s')
                return None
            self.steps_taken += 1
            self._sequence += 1
            self.message_context.observe(result)
            for listener in list(self._step_listeners):
                listener(result)
            if self.state_publisher.due(result):
                # built outside the lock from a copy of the run history as of this step
                batch = (result, self.message_context.snapshot(), self._sequence)
            # Under the lock, so a recording started or stopped (also under the lock)
            # holds exactly the steps taken in between, none twice.
            for observer in self._observers:
                observer(result)
        if batch is not None:
            self.state_publisher.publish(*batch)
        return result

    def _run_commands(self) -> None:
        self.commands.run_all()

    def _recover(self, reason: str) -> None:
        """Log a failed step, abort the goals, reset: nothing non-finite is published."""
        self.failures += 1
        self.get_logger().error(f'{reason}; nothing was published for this step. '
                                'Recovering: resetting the simulation to t = 0 and '
                                'aborting the active goal')
        self.reset_simulation(f'the simulation was reset after a failed step ({reason})')

    def reset_simulation(self, reason: str,
                         replacement: tuple[Any, dict, MessageContext] | None = None) -> None:
        """Abort the active goal (with ``reason``), drop queued commands, reset to t = 0;
        with ``replacement`` (simulation, configuration, message context) that new
        simulation takes the old one's place instead."""
        self.jaws.abort_owner(reason)
        with self.lock:
            self.physics.interrupt_steps(reason)
            self.commands.clear()
            if replacement is None:
                self.sim.reset()
                self.message_context.reset()
            else:
                self.sim, self.params.config, self.message_context = replacement
            self.physics.reanchor()
            self._sequence += 1
            initial = self.sim.last
            batch = (initial, self.message_context.snapshot(), self._sequence)
            for listener in self._reset_listeners:
                listener(initial)
        self.state_publisher.publish(*batch)

    def replace_fruit(self, fruit: str) -> str | None:
        """Swap the fruit for the preset ``fruit`` (a name or a preset file path): the
        keys the preset sets, and every fruit property another preset could set
        (``configuration.fruit_property_keys``: a key the preset leaves out takes its
        default, not the former fruit's, e.g. a strawberry's shape), take the preset's
        values; everything else stays. The new fruit starts at rest at t = 0, as after a
        reset. Returns an error message, or None when the fruit was replaced."""
        dimension = self.params.config['dimension']
        try:
            keys = configuration.flatten(configuration.read_yaml(
                configuration.fruit_preset_path(fruit)))
            preset = configuration.load_config(fruit=fruit, overrides={'dimension': dimension})
        except (GripperSimError, ValueError) as error:
            return f"fruit '{fruit}' not loaded: {error}"
        changed = (set(keys) | configuration.fruit_property_keys()) & set(preset)
        return self.set_fruit({key: preset[key] for key in changed},
                              f"the fruit was replaced by '{fruit}' (spawn_entity)")

    def set_fruit(self, values: Mapping[str, Any], reason: str) -> str | None:
        """Put the flat configuration ``values`` (a fruit's keys) in place and restart the
        simulation with them at t = 0 (``reason``: for the log and an interrupted goal).
        Returns an error message, or None when the fruit was replaced."""
        config = dict(self.params.config)
        config.update(values)
        try:
            config = configuration.validate(config)
            sim = self._simulation_factory(dict(config))
            warm_kernels(config)   # a new fruit model's kernels: compiled before it steps
            context = MessageContext.from_config(
                config, initial=sim.last, frame_prefix=str(self.params.get('frame_prefix')))
        except (GripperSimError, ValueError) as error:
            return f"fruit '{values.get('fruit.name', '?')}' not loaded: {error}"
        self.params.fruit = str(config['fruit.name'])
        self.reset_simulation(reason, (sim, config, context))
        self.get_logger().info(f"fruit '{config['fruit.name']}' in place: {reason}")
        return None

    # ------------------------------------------------------------ parameters
    def set_parameters(self, parameter_list):
        results = super().set_parameters(parameter_list)
        log_rejections(self.get_logger(), parameter_list, results)
        return results

    def set_parameters_atomically(self, parameter_list):
        result = super().set_parameters_atomically(parameter_list)
        log_rejections(self.get_logger(), parameter_list, [result] * len(parameter_list))
        return result

    # ------------------------------------------------------------- lifecycle
    def stop(self, timeout: float = 5.0) -> None:
        """Stop the physics thread; abort the active goal and let its result go out."""
        self.physics.stop(timeout)
        self.jaws.close('the simulator is shutting down', timeout)

    def destroy_node(self):
        self.stop()
        self.recording_control.finish()
        if getattr(self, 'live_view', None) is not None:
            self.live_view.close()
        return super().destroy_node()


def interrupted(error: BaseException) -> bool:
    """Whether ``error`` came of a KeyboardInterrupt (one in its chain of causes): the one
    ``main``'s signal handler raises while the node is built may come out as the error of
    whatever it interrupted (an extension module's import: ImportError 'initialization
    failed')."""
    seen: set[int] = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False


def main(args: list[str] | None = None) -> int:
    """Run the node: console script ``sim_node``, ``gripper-sim node``, ``python -m``.

    Args:
        args: the full command line (default ``sys.argv``): ``[--fruit NAME]
            [--config FILE] [--ros-args ...]``; the two options take precedence over
            the ``fruit`` and ``config_file`` parameters.

    Returns:
        0 after a clean shutdown, 2 if the configuration or a parameter is invalid or
        a node of the same name started earlier (``namesakes``).

    The Jazzy main idiom, with one change: SIGINT/SIGTERM set a flag instead of
    shutting the context down at once, so an active goal is aborted and its result
    delivered before the node goes. While the node is built (its kernels' warm-up too),
    before it has started anything, they stop it at once, where the start-up can take a
    KeyboardInterrupt (``gripper_sim.interrupts``).
    """
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    argv = list(sys.argv if args is None else args)
    parser = argparse.ArgumentParser(prog='sim_node', description='The gripper_sim node.')
    parser.add_argument('--fruit', help='fruit preset name')
    parser.add_argument('--config', help='YAML configuration file')
    try:
        options = parser.parse_args(remove_ros_args(argv)[1:])
    except rclpy_implementation.RCLError as err:   # malformed --ros-args
        print(f'error: {err}', file=sys.stderr)
        return 2
    # Our own SIGINT/SIGTERM handling instead of rclpy's, which shuts the context down
    # at once: an active goal must still get its (aborted) result out before we stop.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL)
    rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    stopping = threading.Event()
    node = None

    def on_signal(signum, frame) -> None:
        if signum != signal.SIGALRM:
            stopping.set()
        # a node being built has started nothing yet (its warm-up may compile for
        # minutes): stop it now, unless the signal came where an exception breaks what
        # it interrupts (then at a timer's tick that finds it elsewhere); once it has
        # started, it is stopped as a built node
        if STARTING.is_set() and stopping.is_set():
            interrupts.interrupt(frame)

    interrupts.install(on_signal, (signal.SIGINT, signal.SIGTERM))
    code = 0
    # Threads: a running goal (Grasp, GripperCommand, ParallelGripperCommand; one
    # drives, a preempted one finishes) and a step request (~/step, step_simulation,
    # simulate_steps) each wait in one; the services, topics, parameters and the
    # watchdog need the rest.
    executor = MultiThreadedExecutor(num_threads=8)
    try:
        STARTING.set()
        try:
            node = SimNode(fruit=options.fruit, config_file=options.config,
                           namesake_wait=NAMESAKE_WAIT)
        except Exception as err:
            if interrupted(err):   # a stop while it was built: no error of its own
                return 0
            if not isinstance(err, GripperSimError):
                raise
            # a configuration, parameter or name problem
            rclpy.logging.get_logger(NODE_NAME).error(f'cannot start: {err}')
            return 2
        finally:
            STARTING.clear()
            interrupts.cancel()
        executor.add_node(node)
        while not stopping.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
            if node.namesake_watch.later.is_set():   # found late: as at start-up
                rclpy.logging.get_logger(NODE_NAME).error(
                    f'cannot start: {node.namesake_watch.reason}')
                code = 2
                break
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            had_goal = node.jaw_owner is not None
            node.stop()
            # deliver the aborted goal's result to its client, then go
            deadline = time.monotonic() + (RESULT_DELIVERY if had_goal else 0.0)
            while time.monotonic() < deadline and rclpy.ok():
                executor.spin_once(timeout_sec=0.05)
            node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == '__main__':
    sys.exit(main())
