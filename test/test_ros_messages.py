"""The pure StepResult -> ROS message conversion shared by the node and the recorder."""
import math

import numpy as np
import pytest

from gripper_sim.core.results import Deformation, Energies, JawWrench, StepResult
from gripper_sim.ros import messages
from gripper_sim.ros.messages import MessageContext, build_messages

pytestmark = pytest.mark.ros

RADIUS = 0.03


def make_result(*, squeeze=4.0, pressure=1.0e5, time=0.25, lift=0.03, gap=0.058,
                slipping=False, nan=False):
    """A hand-made step: a ring of 16 nodes pinched by two jaws at x = -/+ gap/2."""
    n = 16
    angles = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    positions = np.column_stack([RADIUS * np.cos(angles), lift + RADIUS * np.sin(angles)])
    forces = np.zeros((n, 2))
    obstacle = np.full(n, -1)
    forces[0] = (-squeeze, 0.1)     # right-most node, pushed left by the right jaw
    forces[n // 2] = (squeeze, 0.1)  # left-most node, pushed right by the left jaw
    obstacle[0], obstacle[n // 2] = 1, 0
    node_pressure = np.zeros(n)
    node_pressure[0] = node_pressure[n // 2] = pressure
    if nan:
        positions[3, 0] = float('nan')
    return StepResult(
        time=time, step=250, positions=positions, velocities=np.zeros((n, 2)),
        contact_forces=forces, contact_obstacle=obstacle,
        contact_sticking=obstacle >= 0, obstacle_names=('left_jaw', 'right_jaw', 'table'),
        surface=np.arange(n),
        left_wrench=JawWrench(force=np.array([-squeeze, 0.0, -0.025 * squeeze]),
                              torque=np.zeros(3)),
        right_wrench=JawWrench(force=np.array([squeeze, 0.0, -0.025 * squeeze]),
                               torque=np.zeros(3)),
        left_jaw_x=-gap / 2, right_jaw_x=gap / 2, jaw_velocity=0.01, lift=lift,
        lift_velocity=0.02, gap=gap, grip_force=squeeze, slip_distance=1e-4,
        slipping=slipping, centroid=np.array([0.0, lift]),
        energies=Energies(kinetic=1e-4, elastic=2e-3, gravitational=0.03),
        deformation=Deformation(compression=0.002, compression_ratio=0.002 / 0.06,
                                max_skin_strain=0.01, contact_length=0.004,
                                peak_contact_pressure=pressure, node_pressure=node_pressure),
        newton_iterations=3, substeps=1)


def context():
    return MessageContext(rest_width=0.06, depth=0.04, bruise_pressure=2.0e5,
                          failure_stress=3.0e5)


def test_point_cloud_round_trips_positions_and_forces_in_the_xz_plane():
    result = make_result()
    cloud = build_messages(result, context())['fruit/nodes']
    assert cloud.header.frame_id == 'world'
    assert [f.name for f in cloud.fields] == ['x', 'y', 'z', 'fx', 'fy', 'fz']
    assert cloud.width == 16 and cloud.row_step == 16 * 24
    points = messages.read_point_cloud(cloud)
    np.testing.assert_allclose(points[:, 0], result.positions[:, 0], atol=1e-7)
    np.testing.assert_allclose(points[:, 2], result.positions[:, 1], atol=1e-7)
    np.testing.assert_array_equal(points[:, 1], 0.0)
    np.testing.assert_allclose(points[:, 3], result.contact_forces[:, 0], atol=1e-6)
    np.testing.assert_allclose(points[:, 5], result.contact_forces[:, 1], atol=1e-6)


def test_wrenches_are_in_the_jaw_frames_and_stamped_in_sim_time():
    msgs = build_messages(make_result(squeeze=5.0), context(), stamp=1_500_000_123)
    left, right = msgs['left_jaw/wrench'], msgs['right_jaw/wrench']
    assert left.header.frame_id == 'left_jaw' and right.header.frame_id == 'right_jaw'
    assert left.wrench.force.x == pytest.approx(-5.0)
    assert right.wrench.force.x == pytest.approx(5.0)
    assert (left.header.stamp.sec, left.header.stamp.nanosec) == (1, 500_000_123)
    assert msgs['clock'].clock == left.header.stamp


def test_default_stamp_is_the_result_time():
    msgs = build_messages(make_result(time=2.75), context())
    stamp = msgs['fruit/state'].header.stamp
    assert stamp.sec == 2 and stamp.nanosec == 750_000_000


def test_joint_states_measure_from_the_centre_and_carry_the_real_contact_effort():
    joints = build_messages(make_result(squeeze=6.0, gap=0.058), context())['joint_states']
    assert list(joints.name) == ['left_jaw_joint', 'right_jaw_joint', 'lift_joint']
    assert joints.position[0] == pytest.approx(0.029)
    assert joints.position[1] == pytest.approx(0.029)
    assert joints.position[2] == pytest.approx(0.03)
    # closing at 0.01 m/s: the opening joints move at -0.01 m/s
    assert joints.velocity[0] == pytest.approx(-0.01)
    assert joints.effort[0] == pytest.approx(6.0)
    assert joints.effort[1] == pytest.approx(6.0)
    assert joints.effort[2] == pytest.approx(0.3)   # the fruit hangs 0.3 N on the jaws


def test_joint_positions_use_the_gripper_centre_of_the_initial_state():
    initial = make_result(gap=0.07)
    shifted = make_result(gap=0.05)
    ctx = MessageContext.from_config({'fruit.shape.diameter': 0.06}, initial=initial)
    joints = build_messages(shifted, ctx)['joint_states']
    assert joints.position[0] + joints.position[1] == pytest.approx(0.05)


def test_fruit_state_copies_the_result_and_derives_the_area():
    result = make_result(slipping=True)
    state = build_messages(result, context())['fruit/state']
    assert state.header.frame_id == 'world'
    assert state.node_count == 16 and state.dimension == 2
    assert state.compression == pytest.approx(0.002)
    assert state.contact_area == pytest.approx(0.004 * 0.04)
    assert state.peak_contact_pressure == pytest.approx(1.0e5)
    assert state.elastic_energy == pytest.approx(2e-3)
    assert state.centroid.z == pytest.approx(0.03) and state.centroid.y == 0.0
    assert state.left_jaw_contact and state.right_jaw_contact
    assert state.slipping and not state.bruised and not state.crushed
    assert state.grip_force == pytest.approx(4.0)


def test_bruising_is_latched_over_the_run_and_cleared_by_reset():
    ctx = context()
    hurt = build_messages(make_result(pressure=2.5e5), ctx)['fruit/state']
    assert hurt.bruised and not hurt.crushed
    assert hurt.bruised_fraction == pytest.approx(2 / 16)
    later = build_messages(make_result(pressure=1.0e4), ctx)['fruit/state']
    assert later.bruised and later.bruised_fraction == pytest.approx(2 / 16)
    crushed = build_messages(make_result(pressure=3.5e5), ctx)['fruit/state']
    assert crushed.crushed
    ctx.reset()
    fresh = build_messages(make_result(pressure=1.0e4), ctx)['fruit/state']
    assert not fresh.bruised and not fresh.crushed and fresh.bruised_fraction == 0.0


def test_markers_draw_a_closed_outline_coloured_by_pressure_jaws_table_and_arrows():
    array = build_messages(make_result(pressure=2.0e5), context())['markers']
    by_ns = {}
    for marker in array.markers:
        by_ns.setdefault(marker.ns, []).append(marker)
        assert marker.header.frame_id == 'world'
    outline = by_ns['fruit_outline'][0]
    assert len(outline.points) == 17 and outline.points[0] == outline.points[-1]
    assert len(outline.colors) == len(outline.points)
    assert outline.colors[0].r == pytest.approx(1.0) and outline.colors[0].g == 0.0
    assert outline.colors[1].g == pytest.approx(0.8)   # no pressure: green
    assert len(by_ns['jaws']) == 2 and len(by_ns['table']) == 1
    left_arrow = by_ns['jaw_forces'][0]
    assert left_arrow.points[1].x < left_arrow.points[0].x  # fruit pushes the left jaw out
    assert len(by_ns['contact_forces'][0].points) == 4


def test_zero_forces_delete_the_arrows_instead_of_drawing_zero_length_ones():
    array = build_messages(make_result(squeeze=0.0), context())['markers']
    arrows = [m for m in array.markers if m.ns == 'jaw_forces']
    assert arrows and all(m.action == m.DELETE for m in arrows)


def test_a_configuration_mapping_works_as_context_and_topics_can_be_selected():
    config = {'dimension': 2, 'fruit.shape.diameter': 0.06, 'fruit.depth': None,
              'fruit.bruise_pressure': 2.0e5, 'world.table': False}
    msgs = build_messages(make_result(), config, topics=['fruit/state', 'markers'])
    assert set(msgs) == {'fruit/state', 'markers'}
    assert msgs['fruit/state'].contact_area == pytest.approx(0.004 * 0.04)
    assert not [m for m in msgs['markers'].markers if m.ns == 'table']
    with pytest.raises(ValueError, match='unknown topic'):
        build_messages(make_result(), config, topics=['fruit/nope'])


def test_resolved_topic_names():
    assert messages.resolved_topic('fruit/state') == '/gripper_sim/fruit/state'
    assert messages.resolved_topic('joint_states') == '/joint_states'
    assert messages.resolved_topic('clock', namespace='/a') == '/clock'
    assert messages.resolved_topic('markers', 'sim', '/a/') == '/a/sim/markers'


def test_non_finite_results_are_detected():
    assert messages.result_is_finite(make_result())
    assert not messages.result_is_finite(make_result(nan=True))


def test_time_conversion_is_exact_for_integer_nanoseconds():
    stamp = messages.time_msg(12_345_678_901)
    assert (stamp.sec, stamp.nanosec) == (12, 345_678_901)
    assert messages.time_msg(0.1).nanosec == 100_000_000
    assert not math.isnan(messages.time_msg(0.0).sec)
