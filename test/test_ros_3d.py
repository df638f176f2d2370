"""The node with the 3D model (``physics.dimension`` 3): stepping, the 3D messages, the
GripperCommand and Grasp actions, on a coarse mesh (geodesic frequency 3) to stay fast."""
import numpy as np
import pytest
from action_msgs.msg import GoalStatus

from control_msgs.action import GripperCommand
from control_msgs.msg import GripperCommand as GripperCommandMsg
from gripper_sim.convert import messages
from gripper_sim.ros.process import pick_domain_id
from gripper_sim_interfaces.action import Grasp

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(30)
DIAMETER = 0.0635          # apple
INITIAL_GAP = 0.068
PARAMETERS = {'real_time_factor': 0.0, 'physics.dimension': 3,
              'physics.fruit.mesh.subdivisions': 3, 'physics.sim.dt': 0.002,
              'physics.gripper.initial_gap': INITIAL_GAP,
              'marker_rate': 100.0}   # markers with every state batch (publish_rate 100)


@pytest.fixture(scope='module')
def client(tmp_path_factory, node_and_client):
    log = tmp_path_factory.mktemp('node3d') / 'node.log'
    with node_and_client(PARAMETERS, DOMAIN, log, client_name='test_3d_client') as (_, client):
        client.restart(run=False)
        yield client


def mesh_of(markers):
    return next(m for m in markers.markers if m.ns == 'fruit_mesh')


def test_stepping_the_3d_node_publishes_the_3d_messages(client):
    response = client.step(5)
    assert response.success and response.sim_time == pytest.approx(0.010)
    client.spin_until(lambda: client.sim_time() >= 0.010 - 1e-9, 60, 'the stepped state')
    client.catch_up(['fruit/nodes', 'markers'])
    state = client.latest['fruit/state']
    assert state.dimension == 3 and state.gap == pytest.approx(INITIAL_GAP, abs=1e-9)
    points = messages.read_point_cloud(client.latest['fruit/nodes'])
    assert len(points) == state.node_count
    assert np.ptp(points[:, 1]) == pytest.approx(DIAMETER, rel=0.05)   # real y
    assert state.centroid.y == pytest.approx(points[:, 1].mean(), abs=2e-3)
    mesh = mesh_of(client.latest['markers'])
    assert mesh.type == mesh.TRIANGLE_LIST and len(mesh.points) % 3 == 0
    assert len(mesh.points) == len(mesh.colors) > 3 * state.node_count   # n_tri ~ 2 n
    drawn = np.array([(p.x, p.y, p.z) for p in mesh.points])
    # every corner is a fruit node (float32 in the cloud)
    distance = np.min(np.linalg.norm(drawn[:, None, :] - points[None, :, :3], axis=2), axis=1)
    assert distance.max() < 1e-6


def test_gripper_command_and_grasp_in_3d(client):
    client.pause(False)
    try:
        handle = client.send_goal(client.gripper_cmd, GripperCommand.Goal(
            command=GripperCommandMsg(position=0.070, max_effort=5.0)))
        assert handle.accepted
        status, result = client.result(handle)
        assert status == GoalStatus.STATUS_SUCCEEDED and result.reached_goal
        assert result.position == pytest.approx(0.070, abs=1e-3)

        feedback = []
        handle = client.send_goal(client.grasp, Grasp.Goal(
            target_force=3.0, lift_height=0.01, hold_time=0.1), feedback)
        assert handle.accepted
        status, result = client.result(handle, timeout=300)
    finally:
        client.pause(True)
    assert status == GoalStatus.STATUS_SUCCEEDED, result.message
    assert result.success and not result.slipped
    assert result.max_grip_force == pytest.approx(3.0, rel=0.15)
    assert 0.0 < result.max_compression < 0.01
    # every phase change is sent; feedback may still be on its way when the result is in
    client.spin_until(lambda: {'closing', 'lifting', 'holding'} <= {f.phase for f in feedback},
                      60, 'every phase in the feedback')
    client.catch_up(['left_jaw/wrench', 'fruit/nodes'])
    state = client.latest['fruit/state']
    assert state.dimension == 3 and state.contact_area > 0
    assert state.centroid.z > DIAMETER / 2 + 0.005         # lifted off the table
    wrench = client.latest['left_jaw/wrench'].wrench
    assert -wrench.force.x == pytest.approx(state.grip_force, rel=0.1)
    points = messages.read_point_cloud(client.latest['fruit/nodes'])
    assert np.ptp(points[:, 1]) > 0.05
