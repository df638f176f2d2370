"""Grasp, GripperCommand and ParallelGripperCommand actions against the node in a
subprocess; the gripper goals use only the control_msgs types."""
import math

import pytest
from action_msgs.msg import GoalStatus

from control_msgs.action import GripperCommand, ParallelGripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from gripper_sim_interfaces.action import Grasp
from sensor_msgs.msg import JointState
from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment
from ros_client import SimClient

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(10)
INITIAL_GAP = 0.0735      # apple: diameter 63.5 mm + 10 mm


@pytest.fixture(scope='module')
def running(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('actions') / 'node.log'
    with node_and_client({'real_time_factor': 0.0}, DOMAIN, log,
                         client_name='actions_test_client') as process_and_client:
        yield process_and_client


@pytest.fixture
def client(running, restarted):
    return restarted(running)


def grasp_goal(force, lift=0.0, hold=0.0, release=False, close_speed=0.0):
    return Grasp.Goal(target_force=force, close_speed=close_speed, lift_height=lift,
                      hold_time=hold, release=release)


def gripper_goal(position, max_effort=0.0):
    return GripperCommand.Goal(command=GripperCommandMsg(position=position,
                                                         max_effort=max_effort))


def assert_rejected(client, server, goal, kind, reason):
    """``goal`` is rejected by ``server`` and the node logs why, naming ``reason``."""
    since = len(client.logs)
    handle = client.send_goal(server, goal)
    assert not handle.accepted
    log = client.wait_log(f'{kind} goal rejected', since=since)
    assert reason in log.msg


def parallel_goal(position, effort=(), name=('left_jaw_joint',), velocity=()):
    """A ParallelGripperCommand goal on one jaw joint (m from the centre, open > 0)."""
    return ParallelGripperCommand.Goal(command=JointState(
        name=list(name), position=list(position) if isinstance(position, tuple)
        else [position], velocity=list(velocity), effort=list(effort)))


def test_grasp_succeeds_with_real_feedback(client):
    # At real time, as a user's client sees it: as fast as possible the node can send
    # feedback faster than this client reads (the depth-10 history drops the surplus),
    # and be well past the goal's end before the client sees its result.
    assert client.set_parameters(real_time_factor=1.0)[0].successful
    try:
        feedback = []
        start = client.sim_time()
        handle = client.send_goal(client.grasp, grasp_goal(8.0, lift=0.02, hold=0.3),
                                  feedback)
        assert handle.accepted
        status, result = client.result(handle)
        duration = client.sim_time() - start
    finally:
        client.set_parameters(real_time_factor=0.0)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.success and not result.slipped and not result.bruised
    assert result.max_grip_force == pytest.approx(8.0, rel=0.1)
    assert 0.0 < result.max_compression < 0.01
    assert result.final_gap < INITIAL_GAP - 0.005
    assert result.slip_distance < 1e-3
    # every phase change is sent; feedback may still be on its way when the result is in
    client.spin_until(lambda: {'closing', 'squeezing', 'lifting', 'holding'}
                      <= {f.phase for f in feedback}, 60, 'every phase in the feedback')
    phases = [f.phase for f in feedback]
    assert phases.index('closing') < phases.index('lifting') < phases.index('holding')
    # feedback carries the real state, at >= 10 Hz of sim time
    assert max(f.grip_force for f in feedback) > 7.0
    assert min(f.gap for f in feedback) < INITIAL_GAP - 0.005
    assert len(feedback) >= 10 * duration * 0.9
    # the fruit is up in the air, held
    assert client.latest['fruit/state'].centroid.z > 0.0635 / 2 + 0.015


def test_a_weak_grasp_slips(client):
    handle = client.send_goal(client.grasp, grasp_goal(0.4, lift=0.03, hold=0.3))
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_ABORTED
    assert not result.success and result.slipped, result.message
    assert result.slip_distance > 1e-3


def test_a_new_goal_preempts_the_active_grasp_and_cancel_holds_the_jaws(client):
    feedback = []
    # held far longer than the exchanges below take, however fast the node steps
    first = client.send_goal(client.grasp, grasp_goal(6.0, lift=0.02, hold=3000.0),
                             feedback)
    assert first.accepted
    client.spin_until(lambda: any(f.phase in ('lifting', 'holding') for f in feedback), 120,
                      'the first grasp to lift')
    # a new Grasp goal takes over: the first one ends canceled (as ros2_controllers'
    # gripper controllers end a preempted goal), with the reason
    feedback = []
    second = client.send_goal(client.grasp, grasp_goal(6.0, hold=3000.0), feedback)
    assert second.accepted
    status, result = client.result(first)
    assert status == GoalStatus.STATUS_CANCELED and not result.success
    assert result.outcome == 'canceled'
    assert 'preempted by a new Grasp goal' in result.message
    client.spin_until(lambda: any(f.phase == 'holding' for f in feedback), 120,
                      'the second grasp to hold')

    cancel = client.cancel(second)
    assert cancel.return_code == 0   # ERROR_NONE
    status, result = client.result(second)
    assert status == GoalStatus.STATUS_CANCELED
    assert 'canceled' in result.message and not result.success
    # the jaws are held: gap and lift stay where the cancel left them
    client.wait_sim_time(0.05)
    client.caught_up('joint_states')
    gap = client.latest['fruit/state'].gap
    lift = client.latest['joint_states'].position[2]
    client.wait_sim_time(0.3)
    client.caught_up('joint_states')
    assert client.latest['fruit/state'].gap == pytest.approx(gap, abs=2e-5)
    assert client.latest['joint_states'].position[2] == pytest.approx(lift, abs=2e-5)
    assert client.latest['fruit/state'].grip_force > 3.0   # still gripping

    # a GripperCommand goal preempts a Grasp too
    feedback = []
    third = client.send_goal(client.grasp, grasp_goal(6.0, hold=3000.0), feedback)
    assert third.accepted
    client.spin_until(lambda: bool(feedback), 120, 'the third grasp to start')
    fourth = client.send_goal(client.gripper_cmd, gripper_goal(0.070, 10.0))
    assert fourth.accepted
    status, result = client.result(third)
    assert status == GoalStatus.STATUS_CANCELED
    assert 'preempted by a new GripperCommand goal' in result.message
    status, result = client.result(fourth)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.reached_goal, result


@pytest.mark.parametrize('goal', [
    grasp_goal(float('nan')), grasp_goal(-2.0), grasp_goal(0.0), grasp_goal(1e7),
    grasp_goal(5.0, lift=-0.1), grasp_goal(5.0, hold=float('inf')),
    grasp_goal(5.0, close_speed=50.0),
], ids=['nan-force', 'negative-force', 'zero-force', 'huge-force', 'negative-lift',
        'inf-hold', 'fast-close'])
def test_out_of_range_grasp_goals_are_rejected_with_a_reason(client, goal):
    since = len(client.logs)
    handle = client.send_goal(client.grasp, goal)
    assert not handle.accepted
    log = client.wait_log('Grasp goal rejected', since=since)
    assert 'must' in log.msg
    client.wait_sim_time(0.05)    # the node keeps running


def place_goal(force, transport=0.05, lift=0.02, retreat=0.01, release=True, hold=0.0):
    return Grasp.Goal(target_force=force, lift_height=lift, hold_time=hold, release=release,
                      place=True, transport_distance=transport, retreat_height=retreat)


def test_a_place_goal_carries_the_fruit_sideways_and_puts_it_down(client):
    # 5 N: inside the apple's window (1.7 - 16 N, README "Grasp window")
    x0 = client.latest['fruit/state'].centroid.x
    feedback = []
    handle = client.send_goal(client.grasp, place_goal(5.0, transport=0.05), feedback)
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.success and result.outcome == 'placed', result.message
    assert not (result.slipped or result.bruised or result.crushed)
    assert result.dropped_at == -1.0
    assert result.max_grip_force == pytest.approx(5.0, rel=0.15)
    assert 0.0 < result.peak_damage_pressure < 0.26e6        # below the apple's bruise
    assert result.final_gap == pytest.approx(INITIAL_GAP, abs=1e-6)   # opened
    order = ['closing', 'lifting', 'transporting', 'lowering', 'opening', 'retreating']
    seen = [f.phase for f in feedback if f.phase in order]
    changes = [p for i, p in enumerate(seen) if i == 0 or seen[i - 1] != p]
    assert changes == order
    client.spin_until(lambda: client.latest['fruit/state'].centroid.x > x0 + 0.04, 30,
                      'the placed state')
    state = client.latest['fruit/state']
    assert state.centroid.x == pytest.approx(x0 + 0.05, abs=0.01)   # moved 5 cm
    assert state.centroid.z == pytest.approx(0.0635 / 2, abs=0.003)  # back on the table
    assert not state.left_jaw_contact and not state.right_jaw_contact


def test_a_place_goal_too_weak_to_hold_reports_when_it_dropped(client):
    handle = client.send_goal(client.grasp, place_goal(0.6))
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_ABORTED
    assert not result.success and result.outcome == 'dropped'
    assert result.dropped_at > 0.0 and 'dropped at t =' in result.message


@pytest.mark.parametrize('goal, reason', [
    (place_goal(5.0, release=False), 'release must be true'),
    (place_goal(5.0, transport=float('nan')), 'transport_distance must be finite'),
    (place_goal(5.0, retreat=-0.01), 'retreat_height must be in'),
    (place_goal(5.0, lift=0.0), 'lift_height > 0'),
    (place_goal(5.0, hold=1.0), 'hold_time is not used'),
    (place_goal(5.0, transport=9.0), 'transport_distance must be in'),
    (Grasp.Goal(target_force=5.0, transport_distance=0.05), 'place options'),
], ids=['no-release', 'nan-transport', 'negative-retreat', 'no-lift', 'hold', 'far',
        'transport-without-place'])
def test_bad_place_goals_are_rejected_with_a_clear_reason(client, goal, reason):
    assert_rejected(client, client.grasp, goal, 'Grasp', reason)


def test_gripper_command_reaches_a_free_gap(client):
    feedback = []
    handle = client.send_goal(client.gripper_cmd, gripper_goal(0.068, 10.0), feedback)
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert result.reached_goal and not result.stalled
    assert result.position == pytest.approx(0.068, abs=0.001)
    assert result.effort == pytest.approx(0.0, abs=1e-6)   # no contact yet: real zero
    assert feedback and all(math.isfinite(f.position) for f in feedback)


def test_gripper_command_stalls_on_the_fruit_with_the_real_effort(client):
    feedback = []
    handle = client.send_goal(client.gripper_cmd, gripper_goal(0.040, 5.0), feedback)
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_ABORTED   # allow_stalling is false
    assert result.stalled and not result.reached_goal
    assert result.effort == pytest.approx(5.0, rel=0.05)
    assert 0.05 < result.position < 0.0635
    # the last feedback reports the stall (it may arrive here after the result)
    client.spin_until(lambda: feedback and feedback[-1].stalled, 30, 'the stalled feedback')
    assert max(f.effort for f in feedback) > 4.5


def test_a_gap_of_0_stops_at_the_maximum_effort(client):
    """Gap 0 asks more than the fruit gives: the jaws stop where the grip force reaches
    the maximum effort (the goal's max_effort; gripper.max_force for the gap topic) and
    hold it, within 2 % (it used to reach 8x gripper.max_force)."""
    feedback = []
    handle = client.send_goal(client.gripper_cmd, gripper_goal(0.0, 20.0), feedback)
    status, result = client.result(handle)
    assert result.stalled and not result.reached_goal
    assert result.effort == pytest.approx(20.0, rel=0.02)
    client.spin_until(lambda: feedback and feedback[-1].stalled, 30, 'the stalled feedback')
    assert max(f.effort for f in feedback) <= 1.02 * 20.0
    client.states.clear()
    client.publish('gap', 0.0)
    limit = 200.0   # gripper.max_force
    client.spin_until(lambda: client.states and client.states[-1].grip_force > 0.98 * limit,
                      120, 'the grip force to reach gripper.max_force')
    client.wait_sim_time(0.2)
    assert max(s.grip_force for s in client.states) <= 1.02 * limit
    assert client.latest['fruit/state'].grip_force == pytest.approx(limit, rel=0.02)


def test_gripper_command_with_allow_stalling_succeeds_on_a_stall(client):
    ok, = client.set_parameters(allow_stalling=True)
    assert ok.successful
    try:
        handle = client.send_goal(client.gripper_cmd, gripper_goal(0.040, 4.0))
        status, result = client.result(handle)
        assert status == GoalStatus.STATUS_SUCCEEDED and result.stalled
    finally:
        client.set_parameters(allow_stalling=False)


@pytest.mark.parametrize('server, first_goal, second_goal', [
    ('gripper_cmd', gripper_goal(0.040, 5.0), gripper_goal(0.070, 5.0)),
    ('parallel_gripper_cmd', parallel_goal(0.020, (5.0,)), parallel_goal(0.035, (5.0,))),
], ids=['GripperCommand', 'ParallelGripperCommand'])
def test_a_new_gripper_goal_preempts_the_active_one(client, server, first_goal, second_goal):
    client.pause(True)    # keep the first goal running until the second arrives
    started = []
    first = client.send_goal(getattr(client, server), first_goal, started)
    assert first.accepted
    # executing (it has the jaws: its first feedback went out), then the second goal
    client.spin_until(lambda: started, 30, "the first goal's feedback")
    second = client.send_goal(getattr(client, server), second_goal)
    assert second.accepted
    status, result = client.result(first)
    assert status == GoalStatus.STATUS_CANCELED and not result.reached_goal
    client.pause(False)
    status, result = client.result(second)
    assert status == GoalStatus.STATUS_SUCCEEDED and result.reached_goal
    if server == 'parallel_gripper_cmd':
        assert result.state.position[0] == pytest.approx(0.035, abs=0.001)


def test_gripper_command_cancel_holds_the_jaws(client):
    # Paused and stepped by hand: canceled part-way to the goal, however fast the node
    # steps and however slowly this client's cancel gets there.
    client.pause(True)
    feedback = []
    handle = client.send_goal(client.gripper_cmd, gripper_goal(0.066, 5.0), feedback)
    assert handle.accepted
    client.spin_until(lambda: feedback, 30, "the goal's first feedback")   # it drives
    client.step(150)      # 0.15 s at 0.02 m/s: 3 mm of the 7.5 mm to the goal
    client.spin_until(lambda: feedback[-1].position < 0.072, 60, 'the jaws to start closing')
    client.cancel(handle)
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_CANCELED
    assert result.position > 0.066 + 0.0005 and not result.reached_goal
    client.pause(False)
    client.wait_sim_time(0.05)
    gap = client.latest['fruit/state'].gap
    client.wait_sim_time(0.3)
    assert client.latest['fruit/state'].gap == pytest.approx(gap, abs=1e-6)
    assert gap > 0.066 + 0.0005    # stopped before the goal


@pytest.mark.parametrize('goal', [
    gripper_goal(float('nan'), 5.0), gripper_goal(-0.01, 5.0), gripper_goal(3.0, 5.0),
    gripper_goal(0.05, -1.0), gripper_goal(0.05, float('inf')),
], ids=['nan-gap', 'negative-gap', 'huge-gap', 'negative-effort', 'inf-effort'])
def test_out_of_range_gripper_commands_are_rejected(client, goal):
    since = len(client.logs)
    handle = client.send_goal(client.gripper_cmd, goal)
    assert not handle.accepted
    client.wait_log('GripperCommand goal rejected', since=since)
    client.wait_sim_time(0.05)


def test_parallel_gripper_command_reaches_a_free_joint_position(client):
    feedback = []
    handle = client.send_goal(client.parallel_gripper_cmd, parallel_goal(0.034, (10.0,)),
                              feedback)
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_SUCCEEDED
    assert result.reached_goal and not result.stalled
    assert list(result.state.name) == ['left_jaw_joint']
    assert result.state.position[0] == pytest.approx(0.034, abs=0.001)
    assert result.state.effort[0] == pytest.approx(0.0, abs=1e-6)
    # the state topic may still be on its way when the result arrives (a loaded machine)
    client.spin_until(lambda: abs(client.latest['fruit/state'].gap - 0.068) < 0.002, 30,
                      'a fruit state at the goal gap')
    assert feedback and all(list(f.state.name) == ['left_jaw_joint'] for f in feedback)
    assert feedback[0].state.position[0] > feedback[-1].state.position[0]   # it closed


def test_parallel_gripper_command_stalls_on_the_fruit_at_its_effort_limit(client):
    feedback = []
    handle = client.send_goal(client.parallel_gripper_cmd,
                              parallel_goal(0.020, (5.0,), name=('right_jaw_joint',)), feedback)
    assert handle.accepted
    status, result = client.result(handle)
    assert status == GoalStatus.STATUS_ABORTED   # allow_stalling is false
    assert result.stalled and not result.reached_goal
    assert result.state.effort[0] == pytest.approx(5.0, rel=0.05)
    assert 0.025 < result.state.position[0] < 0.0318
    client.spin_until(lambda: feedback and max(f.state.effort[0] for f in feedback) > 4.5,
                      30, 'feedback with the real effort')


@pytest.mark.parametrize('goal, reason', [
    (parallel_goal(0.03, name=('left_jaw_joint', 'right_jaw_joint')), 'command.name'),
    (parallel_goal(0.03, name=('elbow',)), 'command.name'),
    (parallel_goal(()), 'command.position must hold one value'),
    (parallel_goal(float('nan')), 'must be finite'),
    (parallel_goal(-0.01), 'command.position[0] must be in [0, 0.1] m, got -0.01 m'),
    (parallel_goal(0.15), 'command.position[0] must be in [0, 0.1] m, got 0.15 m'),
    (parallel_goal(0.03, (-1.0,)), 'command.effort[0] must be in [0, '),
    (parallel_goal(0.03, velocity=(0.0,)), 'command.velocity[0] must be in (0, 0.1] m/s'),
    (parallel_goal(0.03, velocity=(1e9,)), 'command.velocity[0] must be in (0, 0.1] m/s'),
], ids=['two-joints', 'unknown-joint', 'no-position', 'nan', 'negative', 'too-open',
        'negative-effort', 'zero-velocity', 'too-fast'])
def test_bad_parallel_gripper_commands_are_rejected_with_the_reason(client, goal, reason):
    assert_rejected(client, client.parallel_gripper_cmd, goal, 'ParallelGripperCommand', reason)


def test_stopping_the_node_aborts_the_goal_and_delivers_its_result(tmp_path):
    domain = pick_domain_id(11)
    process = node_process({'real_time_factor': 0.0}, env=ros_environment(domain),
                           log_path=tmp_path / 'node.log').start()
    client = SimClient(domain, name='shutdown_test_client')
    try:
        client.wait_ready(120)
        feedback = []
        handle = client.send_goal(client.grasp, grasp_goal(6.0, hold=3000.0), feedback)
        assert handle.accepted
        client.spin_until(lambda: feedback, 60, 'feedback')
        future = handle.get_result_async()
        assert process.stop() == 0
        client.spin_until(future.done, 30, 'the result of the interrupted goal')
        response = future.result()
        assert response.status == GoalStatus.STATUS_ABORTED
        assert 'shutting down' in response.result.message
    finally:
        client.close()
        process.stop()
    assert 'Traceback' not in process.log(), process.log()
