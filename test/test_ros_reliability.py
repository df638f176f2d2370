"""Reliability of the node in this process: extreme parameter values, a physics loop that
survives and is watched, ``~/step`` that other services interrupt, set-point commands,
``/clock``, ``~/markers`` and the state topics each at their own rate.

Every wait is a condition with a generous deadline, never a fixed sleep.
"""
import gc
import math
import threading
import time

import pytest
import rclpy
from rclpy.action import ActionServer
from rclpy.parameter import Parameter
from std_msgs.msg import Float64
from std_srvs.srv import SetBool, Trigger

from diagnostic_msgs.msg import DiagnosticStatus
from gripper_sim_interfaces.srv import Step
from gripper_sim.configuration import fruit_property_keys, load_config
from gripper_sim.core.simulation import Simulation
from gripper_sim.errors import ConfigError
from gripper_sim.ros.namesakes import NameInUseError
from gripper_sim.ros.node import SimNode
from gripper_sim.ros.physics_thread import MAX_WAIT, pacing_delay
from gripper_sim.ros.process import apply_ros_environment, pick_domain_id
from ros_client import ros_context
from gripper_sim.ros.sync import JawOwner, JawOwnership

pytestmark = [pytest.mark.ros]

DOMAIN = pick_domain_id(60)


def wait_for(condition, timeout=60.0, what='condition'):
    """Poll ``condition()`` until true (returns it); AssertionError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value:
            return value
        assert time.monotonic() < deadline, f'timed out waiting for {what}'
        time.sleep(0.01)


@pytest.fixture
def context():
    with ros_context(DOMAIN) as context:
        yield context


def make_node(context, factory=Simulation, start=True, **parameters):
    overrides = [Parameter(name, value=value) for name, value in parameters.items()]
    return SimNode(context=context, simulation_factory=factory, start=start,
                   parameter_overrides=overrides, watchdog_period=0.0)


class StatusLog:
    """Stands in for the ``~/jaw/command_status`` publisher: keeps what it was given."""

    def __init__(self):
        self.texts = []

    def publish(self, msg):
        self.texts.append(msg.data)


# --------------------------------------------------------------- item 1: parameters
@pytest.mark.parametrize('rate', [5e-324, 1e-310, 5.6e-306, 1e-4, 0.0])
def test_a_publish_rate_the_node_cannot_use_is_refused_with_a_reason(context, rate):
    node = make_node(context, start=False, real_time_factor=0.0)
    try:
        result, = node.set_parameters([Parameter('publish_rate', value=rate)])
        assert not result.successful
        assert 'publish_rate' in result.reason and '0.001' in result.reason
        every = node.state_publisher.publish_every
        assert node.advance() is not None and node.state_publisher.publish_every == every
    finally:
        node.destroy_node()


@pytest.mark.parametrize('rate', [5e-324, 1e-310])
def test_a_tiny_publish_rate_at_start_up_is_a_config_error(context, rate):
    with pytest.raises(ConfigError, match='publish_rate'):
        make_node(context, start=False, publish_rate=rate)


def test_the_lowest_publish_rate_publishes_once_per_1000_s():
    node_rate = 0.001
    assert round(1.0 / (node_rate * 1e-7)) == 10_000_000_000   # the smallest dt: an int


# ------------------------------------------------------- item 2: the physics thread
@pytest.mark.parametrize('factor', [1e-300, 5e-324, 1e-13, 1e-9])
def test_a_tiny_real_time_factor_neither_kills_nor_freezes_the_physics(context, factor):
    node = make_node(context, real_time_factor=0.0)
    try:
        wait_for(lambda: node.sim.time > 0.005, what='steps at real_time_factor 0')
        assert node.set_parameters([Parameter('real_time_factor', value=factor)])[0].successful
        beat = node.physics.heartbeat
        wait_for(lambda: node.physics.heartbeat > beat + MAX_WAIT, what='a pacing wait')
        assert node.physics.alive
        assert node.set_parameters([Parameter('real_time_factor', value=0.0)])[0].successful
        t = node.sim.time
        wait_for(lambda: node.sim.time > t + 0.005, what='steps after the factor is back')
        assert node.physics.errors == 0
    finally:
        node.destroy_node()


def test_pacing_delay_is_bounded_for_every_factor():
    for factor in (5e-324, 1e-300, 1e-13, 1e-3, 1.0, 1000.0):
        for ahead in (-1.0, 0.0, 1e-3, 1.0, 1e300):
            delay = pacing_delay(ahead, factor)
            assert 0.0 <= delay <= MAX_WAIT and math.isfinite(delay)
    assert pacing_delay(0.01, 1.0) == pytest.approx(0.01)


class RaisingSimulation(Simulation):
    """Raises ``error`` from step number ``at`` (counted over its life)."""

    at = 3
    error: BaseException = OverflowError('injected')

    def __init__(self, config):
        super().__init__(config)
        self.calls = 0

    def step(self):
        self.calls += 1
        if self.calls == self.at:
            raise self.error
        return super().step()


def test_the_physics_thread_survives_any_exception(context):
    RaisingSimulation.error = OverflowError('injected overflow')
    node = make_node(context, factory=RaisingSimulation, real_time_factor=0.0)
    try:
        wait_for(lambda: node.physics.errors == 1, what='the injected error')
        wait_for(lambda: node.steps_taken > 5, what='steps after the error')
        assert node.physics.alive and node.failures == 1   # reported, reset, went on
    finally:
        node.destroy_node()


@pytest.mark.filterwarnings('ignore::pytest.PytestUnhandledThreadExceptionWarning')
def test_a_physics_thread_that_ended_is_restarted_by_the_watchdog(context):
    RaisingSimulation.error = SystemExit('injected exit')   # ends a thread silently
    node = make_node(context, factory=RaisingSimulation, real_time_factor=0.0)
    try:
        wait_for(lambda: not node.physics.alive, what='the thread to end')
        status = node.watchdog.check()
        assert status.level == DiagnosticStatus.ERROR and 'restarted' in status.message
        assert node.physics.alive
        steps = node.steps_taken
        wait_for(lambda: node.steps_taken > steps + 5, what='steps of the new thread')
        assert node.watchdog.check().level == DiagnosticStatus.OK
    finally:
        node.destroy_node()


class BlockingSimulation(Simulation):
    """Step number ``at`` blocks until ``release`` is set."""

    at = 3

    def __init__(self, config):
        super().__init__(config)
        self.calls = 0
        self.blocked = threading.Event()
        self.release = threading.Event()

    def step(self):
        self.calls += 1
        if self.calls == self.at:
            self.blocked.set()
            self.release.wait()
        return super().step()


def test_a_stalled_physics_loop_is_reported_and_recovers(context):
    node = SimNode(context=context, simulation_factory=BlockingSimulation,
                   parameter_overrides=[Parameter('real_time_factor', value=0.0)],
                   watchdog_period=0.0, physics_stall_timeout=0.2)
    try:
        wait_for(node.sim.blocked.is_set, what='the blocking step')
        status = wait_for(lambda: (s := node.watchdog.check()).level == DiagnosticStatus.ERROR
                          and s, what='the stall to be reported')
        assert 'stalled' in status.message and node.watchdog.stalls == 1
        values = {v.key: v.value for v in status.values}
        assert values['steps_taken'] == '2' and 'real_time_factor' in values
        node.sim.release.set()
        wait_for(lambda: node.steps_taken > 10, what='steps after the stall')
        assert node.watchdog.check().level == DiagnosticStatus.OK
        assert node.watchdog.stalled_since is None and node.physics.alive
    finally:
        node.sim.release.set()
        node.destroy_node()


class InterfacesAtWarmUp(SimNode):
    """A node that notes which of its interfaces exist when it warms its kernels."""

    def _warm_up(self):
        self.at_warm_up = {'services': [s.srv_name for s in self.services],
                           'topics': [p.topic_name for p in self.publishers],
                           'actions': [w for w in self.waitables if isinstance(w, ActionServer)]}
        return super()._warm_up()


def test_the_node_warms_its_kernels_before_it_offers_any_interface(context, monkeypatch):
    """Kernels compile at their first call (minutes from a cold numba cache): the node
    makes that call on a throw-away simulation of its configuration before it creates
    a topic, service or action, so no client finds it and then waits for a first step
    that compiles under the simulation lock (a ~/pause timed out after 60 s)."""
    warmed = []
    monkeypatch.setattr('gripper_sim.ros.node.warm_kernels',
                        lambda config: warmed.append(dict(config)) or 0.0)
    node = InterfacesAtWarmUp(context=context, start=False, watchdog_period=0.0,
                              parameter_overrides=[Parameter('foxglove_port', value=0)])
    try:
        assert warmed == [node.params.config]
        # only what rclpy's Node creates itself: the parameter services and events, the
        # type descriptions
        assert all('parameter' in name or name.endswith('/get_type_description')
                   for name in node.at_warm_up['services']), node.at_warm_up
        assert node.at_warm_up['topics'] == ['/parameter_events']
        assert node.at_warm_up['actions'] == []
        assert any(name.endswith('/pause') for name in (s.srv_name for s in node.services))
    finally:
        node.destroy_node()


# -------------------------------------------------------------- item 3: ~/step
def call_step(node, steps, answers):
    answers.append(node.sim_services._on_step(Step.Request(steps=steps), Step.Response()))


@pytest.mark.parametrize('interrupt', ['reset', 'pause', 'resume'])
def test_a_long_step_request_is_interrupted_by_reset_and_pause(context, interrupt):
    node = make_node(context, real_time_factor=0.0)
    try:
        node.sim_services._on_pause(SetBool.Request(data=True), SetBool.Response())
        answers = []
        caller = threading.Thread(target=call_step, args=(node, 1_000_000, answers))
        caller.start()
        wait_for(lambda: node.steps_taken > 3, what='the requested steps to start')
        # another request meanwhile is refused, not queued behind it
        refused = node.sim_services._on_step(Step.Request(steps=5), Step.Response())
        assert not refused.success and 'in progress' in refused.message
        if interrupt == 'reset':
            answer = node.sim_services._on_reset(Trigger.Request(), Trigger.Response())
        else:
            answer = node.sim_services._on_pause(
                SetBool.Request(data=interrupt == 'pause'), SetBool.Response())
        assert answer.success
        caller.join(timeout=60)
        assert not caller.is_alive()
        step, = answers
        assert not step.success and 'stopped after' in step.message
        assert ('~/reset' if interrupt == 'reset' else '~/pause') in step.message
        if interrupt == 'pause':   # still paused: no step after the answer
            taken = node.steps_taken
            assert node.sim_services._on_step(Step.Request(steps=2),
                                              Step.Response()).success
            assert node.steps_taken == taken + 2
    finally:
        node.destroy_node()


# ----------------------------------------------------------- item 4: burst commands
def test_only_the_latest_set_point_counts_and_each_command_is_answered(context):
    node = make_node(context, start=False)
    try:
        status = StatusLog()
        node.jaw_topics._status = status
        node.jaw_topics._on_gap(Float64(data=0.05))
        node.jaw_topics._on_gap(Float64(data=0.06))
        node.jaw_topics._on_lift(Float64(data=0.05))
        node.jaw_topics._on_force(Float64(data=3.0))
        node.jaw_topics._on_gap(Float64(data=float('nan')))
        node.advance()
        assert status.texts == [
            'superseded: gap command 0.05 m: superseded by gap command 0.06 m',
            'superseded: gap command 0.06 m: superseded by force command 3 N',
            'rejected: gap command nan m: gap command must be a finite number of m, got nan',
            'accepted: lift command 0.05 m',
            'accepted: force command 3 N',
        ]
        assert node.sim.gripper_state.mode == 'force'
        assert node.sim.gripper_state.target_force == 3.0
    finally:
        node.destroy_node()


# ----------------------------------------------------------- item 6: namesakes
def test_a_namesake_is_refused_at_start_up_and_warned_about_later():
    # a domain of its own: nodes of the tests above may linger in their domain's graph
    domain = pick_domain_id(61)
    apply_ros_environment(domain)
    context, other = rclpy.Context(), rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    rclpy.init(context=other, domain_id=domain)
    try:
        first = make_node(context, start=False)
        try:
            assert not first.namesake_watch.check()
            namesake = rclpy.create_node('gripper_sim', context=other)
            assert wait_for(first.namesake_watch.check, what='the namesake to be seen')
            namesake.destroy_node()
            wait_for(lambda: not first.namesake_watch.check(), what='the namesake to go')
        finally:
            first.destroy_node()
        holder = rclpy.create_node('gripper_sim', context=other)
        try:
            with pytest.raises(NameInUseError, match='another node named /gripper_sim'):
                SimNode(context=context, start=False, namesake_wait=5.0)
        finally:
            holder.destroy_node()
    finally:
        rclpy.try_shutdown(context=other)
        rclpy.try_shutdown(context=context)


# ------------------------------------------------------- item 5: the newest goal wins
class Owner(JawOwner):
    kind = 'Grasp'

    def __init__(self):
        self.reasons = []

    def abort(self, reason):
        self.reasons.append(reason)


def test_the_newest_goal_drives_the_jaws_whatever_order_they_start_in():
    jaws = JawOwnership()
    older, newer, newest = Owner(), Owner(), Owner()
    older_ticket, newer_ticket = jaws.ticket(), jaws.ticket()
    assert jaws.claim(newer, newer_ticket) is None            # started first
    assert 'newer goal' in jaws.claim(older, older_ticket)    # started late: refused
    assert jaws.owner is newer and not newer.reasons
    assert jaws.claim(newest, jaws.ticket()) is None          # a new goal preempts
    assert newer.reasons == ['preempted by a new Grasp goal'] and jaws.owner is newest
    jaws.release(newest)
    jaws.close('shutting down', timeout=1.0)
    assert 'shutting down' in jaws.claim(Owner(), jaws.ticket())


# ------------------------------------------------ /clock, markers, state: own rates
def _batches(node, steps):
    """{step: set of topic suffixes published} over ``steps`` hand-taken steps."""
    seen = {}

    def observe(batch, ns):
        seen.setdefault(round(ns * 1e-9 / node.sim.dt), set()).update(batch)
    node.add_publish_observer(observe)
    for _ in range(steps):
        assert node.advance() is not None
    node.remove_publish_observer(observe)
    return seen


def test_clock_markers_and_state_go_out_at_their_own_rates(context):
    node = make_node(context, start=False, foxglove_port=0,
                     **{'physics.sim.dt': 0.0005, 'publish_rate': 200.0, 'clock_rate': 1000.0,
                        'marker_rate': 100.0})
    try:
        seen = _batches(node, 40)
    finally:
        node.destroy_node()
    # dt 0.5 ms: /clock every 2 steps (1 kHz), state every 10 (200 Hz), markers every 20
    assert {s for s, topics in seen.items() if 'clock' in topics} == set(range(2, 41, 2))
    assert {s for s, topics in seen.items() if 'fruit/state' in topics} == {10, 20, 30, 40}
    assert {s for s, topics in seen.items() if 'tf' in topics} == {10, 20, 30, 40}
    assert {s for s, topics in seen.items() if 'markers' in topics} == {20, 40}
    assert seen[2] == {'clock'}


def test_the_clock_goes_out_at_every_step_when_a_step_is_longer_than_its_period(context):
    node = make_node(context, start=False, foxglove_port=0,
                     **{'physics.sim.dt': 0.002, 'publish_rate': 100.0, 'marker_rate': 10.0})
    try:
        assert node.get_parameter('clock_rate').value == 1000.0   # the default
        seen = _batches(node, 10)
        node.set_parameters([Parameter('clock_rate', value=100.0),
                             Parameter('publish_clock', value=False)])
        later = _batches(node, 10)
    finally:
        node.destroy_node()
    assert {s for s, topics in seen.items() if 'clock' in topics} == set(range(1, 11))
    assert {s for s, topics in seen.items() if 'fruit/state' in topics} == {5, 10}
    assert not any('markers' in topics for topics in seen.values())   # every 50 steps
    assert set(later) == {15, 20} and not any('clock' in topics for topics in later.values())


def test_a_spawned_fruit_takes_no_property_of_the_fruit_it_replaces(context):
    """Strawberry, then apple: the apple's shape, skin and friction, not the strawberry's
    (a key the apple's preset leaves out takes its default)."""
    node = make_node(context, start=False, foxglove_port=0)
    try:
        assert node.replace_fruit('strawberry') is None
        assert node.params.config['fruit.name'] == 'strawberry'
        assert node.replace_fruit('apple') is None
        apple = load_config(fruit='apple')
        config = node.params.config
        assert {key: config[key] for key in fruit_property_keys()} == \
            {key: apple[key] for key in fruit_property_keys()}
        assert node.sim.last.positions.shape == Simulation(apple).last.positions.shape
    finally:
        node.destroy_node()


def test_a_node_that_fails_to_build_leaves_the_logs_of_the_next_one_alone(context):
    """rcl keeps one rosout publisher per node name: a SimNode whose construction failed
    and was not destroyed carried the next SimNode's logs to a dead end (a test module
    then waited in vain for a node's warnings)."""
    from rcl_interfaces.msg import Log
    # both nodes under a name of their own: a SimNode of the usual name that an earlier
    # test left to the garbage collector would, when collected, end the rosout publisher
    # its namesakes share (rcl's rule), whenever that happens
    renamed = dict(cli_args=['--ros-args', '-r', '__node:=rosout_namesake_check'])
    overrides = [Parameter('physics.gripper.initial_gap', value=0.01)]
    with pytest.raises(ConfigError):
        SimNode(context=context, simulation_factory=Simulation, start=False,
                parameter_overrides=overrides, watchdog_period=0.0, **renamed)
    node = SimNode(context=context, simulation_factory=Simulation, start=False,
                   parameter_overrides=[Parameter('foxglove_port', value=0)],
                   watchdog_period=0.0, **renamed)
    assert node.get_name() == 'rosout_namesake_check'
    gc.collect()  # what is left of the failed node goes now, not at some later time
    probe = rclpy.create_node('rosout_probe', context=context)
    seen = []
    probe.create_subscription(Log, '/rosout', lambda msg: seen.append(msg.msg), 100)
    executor = rclpy.executors.SingleThreadedExecutor(context=context)
    executor.add_node(probe)
    try:
        deadline = time.monotonic() + 30
        while 'the next node speaks' not in seen and time.monotonic() < deadline:
            node.get_logger().warning('the next node speaks')
            executor.spin_once(timeout_sec=0.2)
        assert 'the next node speaks' in seen
    finally:
        executor.shutdown()
        probe.destroy_node()
        node.destroy_node()


def test_the_node_does_not_start_with_its_jaws_in_the_fruit_nor_moves_them_there(context):
    """The start gap check (``factory.check_start_gap``) at start-up and for a change."""
    with pytest.raises(ConfigError, match='inside the fruit'):
        make_node(context, start=False, **{'physics.gripper.initial_gap': 0.01})
    running = make_node(context, start=False, foxglove_port=0)
    try:
        result, = running.set_parameters([Parameter('physics.gripper.initial_gap',
                                                    value=0.01)])
        assert not result.successful and result.reason
        assert running.sim.initial_gap > running.sim.touching_gap
    finally:
        running.destroy_node()

