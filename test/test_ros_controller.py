"""The example PI force controller, in its own process, closes the loop through topics."""
import pytest

from gripper_sim.ros.process import (controller_process, node_process, pick_domain_id,
                                     ros_environment)
from ros_client import SimClient

pytestmark = [pytest.mark.ros, pytest.mark.slow]

SETPOINT = 6.0


def test_controller_settles_the_grip_force_within_5_percent(tmp_path):
    domain = pick_domain_id(20)
    env = ros_environment(domain)
    node = node_process({'real_time_factor': 1.0}, env=env,
                        log_path=tmp_path / 'node.log').start()
    controller = controller_process(['--force', str(SETPOINT)], env=env,
                                    log_path=tmp_path / 'controller.log')
    client = SimClient(domain, name='controller_test_client')
    try:
        client.wait_ready(120)
        controller.start()

        # settled: every state over 1 s of sim time within 5 % of the setpoint
        def settled():
            states = list(client.states)
            if not states or abs(states[-1].grip_force - SETPOINT) > 0.05 * SETPOINT:
                return False
            end = states[-1].header.stamp.sec + states[-1].header.stamp.nanosec * 1e-9
            window = [s for s in states
                      if s.header.stamp.sec + s.header.stamp.nanosec * 1e-9 >= end - 1.0]
            start = window[0].header.stamp.sec + window[0].header.stamp.nanosec * 1e-9
            return end - start >= 0.95 and all(
                abs(s.grip_force - SETPOINT) <= 0.05 * SETPOINT for s in window)
        client.spin_until(settled, 240, 'the grip force to settle at the setpoint')
        assert controller.running, controller.log()
        state = client.latest['fruit/state']
        assert state.left_jaw_contact and state.right_jaw_contact
        # the controller commanded the jaws: the sim was never told a force
        joints = client.latest['joint_states']
        assert joints.effort[0] == pytest.approx(SETPOINT, rel=0.1)
    finally:
        client.close()
        assert controller.stop() in (0, None), controller.log()
        assert node.stop() == 0, node.log()
    assert 'Traceback' not in controller.log() + node.log()


def test_controller_without_a_simulator_says_what_it_waits_for(tmp_path):
    env = ros_environment(pick_domain_id(21))
    controller = controller_process(['--force', str(SETPOINT)], env=env,
                                    log_path=tmp_path / 'controller.log').start()
    try:
        assert controller.wait_for_log('no wrench on /gripper_sim/left_jaw/wrench', 60), \
            controller.log()
        assert f"ROS_DOMAIN_ID ({env['ROS_DOMAIN_ID']})" in controller.log()
        assert controller.running   # it waits on
    finally:
        assert controller.stop() in (0, None), controller.log()
    assert 'Traceback' not in controller.log()
