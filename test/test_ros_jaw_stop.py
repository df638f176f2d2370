"""A force command whose jaws reach their stop short of its force is told so on
``~/jaw/command_status`` (``stopped: ...``), against a node in a subprocess whose solid
pads close on nothing: they are far above the fruit, and meet at a 12 mm gap."""
import pytest
from std_msgs.msg import Float64, String

from gripper_sim.ros.process import pick_domain_id
from ros_client import RELIABLE

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(73)


def test_a_force_command_that_ends_at_the_jaws_stop_is_reported(tmp_path, node_and_client):
    parameters = {'real_time_factor': 0.0, 'physics.gripper.finger.type': 'solid_pad',
                  'physics.gripper.initial_lift': 0.3}
    with node_and_client(parameters, DOMAIN, tmp_path / 'node.log',
                         client_name='jaw_stop_test_client') as (process, client):
        answers = []
        client.node.create_subscription(String, '/gripper_sim/jaw/command_status',
                                        lambda m: answers.append(m.data), RELIABLE)
        client.spin_until(lambda: client.publishers['force'].get_subscription_count() > 0, 30)
        client.publishers['force'].publish(Float64(data=5.0))
        stopped = client.spin_until(
            lambda: next((a for a in answers if a.startswith('stopped:')), None), 120,
            'the stop reported')
        assert answers[0] == 'accepted: force command 5 N'
        assert stopped == ("stopped: force command 5 N: the grip is 0 N: the jaws are at "
                           "their stop, a 12 mm gap, where the two fingers meet")
        client.spin_until(lambda: abs(client.latest['fruit/state'].gap - 0.012) < 1e-9, 60,
                          'the published gap at the stop')
        assert process.wait_for_log('stopped: force command 5 N', 30)
        client.wait_sim_time(client.sim_time() + 0.05)    # it stays there, told once
        assert client.latest['fruit/state'].gap == pytest.approx(0.012, abs=1e-9)
        assert sum(a.startswith('stopped:') for a in answers) == 1
