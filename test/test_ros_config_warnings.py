"""The node warns, in its log and once, about a physics parameter that has no effect in
its set-up, naming the one that does (the configuration's ``ConfigWarning``)."""
import pytest

from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment

pytestmark = pytest.mark.ros

WARNING = ("config key 'contact.jaw.static_friction' has no effect: a soft pad covers the "
           "jaws ('gripper.finger.pad.enabled'): the friction there is "
           "'contact.pad.friction'")


def test_jaw_friction_under_a_pad_is_a_warning_in_the_nodes_log(tmp_path):
    process = node_process({'physics.gripper.finger.pad.enabled': True,
                            'physics.contact.jaw.static_friction': 0.9,
                            'real_time_factor': 0.0},
                           env=ros_environment(pick_domain_id(3)),
                           log_path=tmp_path / 'node.log').start()
    try:
        assert process.wait_for_log(WARNING, 120), process.log()
    finally:
        assert process.stop() == 0, process.log()
    text = process.log()
    assert text.count(WARNING) == 1 and 'Traceback' not in text
    assert '[WARN]' in next(line for line in text.splitlines() if WARNING in line)
