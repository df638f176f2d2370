"""The pure StepResult -> ROS message conversion shared by the node and the recorder."""
import math

import numpy as np
import pytest

from gripper_sim.convert import messages
from gripper_sim.convert.messages import MessageContext, build_messages
from gripper_sim.core.results import Deformation, Energies, JawWrench, StepResult

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
    assert list(joints.name) == ['left_jaw_joint', 'right_jaw_joint', 'lift_joint',
                                 'transport_joint']
    assert joints.position[0] == pytest.approx(0.029)
    assert joints.position[1] == pytest.approx(0.029)
    assert joints.position[2] == pytest.approx(0.03)
    # closing at 0.01 m/s: the opening joints move at -0.01 m/s
    assert joints.velocity[0] == pytest.approx(-0.01)
    assert joints.effort[0] == pytest.approx(6.0)
    assert joints.effort[1] == pytest.approx(6.0)
    assert joints.effort[2] == pytest.approx(0.3)   # the fruit hangs 0.3 N on the jaws
    assert joints.position[3] == 0.0 and joints.velocity[3] == 0.0   # not transported
    assert len(joints.effort) == 4


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


# ---------------------------------------------------------------- 3D (StepResult3D)

BRUISE_3D = 2.0e4    # Pa: low, so the 3 N squeeze below bruises part of the patch


@pytest.fixture(scope='module')
def squeezed_3d():
    """A real 3D step: the apple (coarse mesh) squeezed to 3 N by the flat jaws."""
    from gripper_sim.configuration import load_config
    from gripper_sim.workflows.factory import make_simulation
    config = load_config(overrides={
        'dimension': 3, 'fruit.mesh.subdivisions': 3, 'fruit.mesh.jaw_refinement': 0.5,
        'gripper.initial_gap': 0.0645,
        'gripper.close_speed': 0.05, 'sim.dt': 0.002, 'fruit.bruise_pressure': BRUISE_3D})
    sim = make_simulation(config)
    context = MessageContext.from_config(config, initial=sim.last)
    sim.command_force(3.0)
    for _ in range(60):
        result = sim.step()
    return result, context


def independent_pressure(result):
    """(n,) Pa: normal contact force over vertex area (2/3 of nothing off contact)."""
    from gripper_sim.core3d.meshes import vertex_areas
    normals = {0: np.array([1.0, 0, 0]), 1: np.array([-1.0, 0, 0]), 2: np.array([0, 0, 1.0])}
    areas = vertex_areas(result.positions, result.triangles, len(result.positions))
    pressure = np.zeros(len(result.positions))
    for i in np.flatnonzero(result.contact_obstacle >= 0):
        normal = normals[int(result.contact_obstacle[i])]
        pressure[i] = max(result.contact_forces[i] @ normal, 0.0) / areas[i]
    return pressure


def test_3d_mesh_marker_has_the_skin_triangles_coloured_red_where_bruising(squeezed_3d):
    result, context = squeezed_3d
    array = build_messages(result, context.snapshot())['markers']
    by_ns = {m.ns: m for m in array.markers}
    assert 'fruit_outline' not in by_ns
    mesh = by_ns['fruit_mesh']
    assert mesh.type == mesh.TRIANGLE_LIST and mesh.id == 0
    assert mesh.header.frame_id == 'world'
    corners = np.asarray(result.triangles).ravel()
    assert len(mesh.points) == 3 * len(result.triangles) == len(mesh.colors)
    drawn = np.array([(p.x, p.y, p.z) for p in mesh.points])
    np.testing.assert_allclose(drawn, result.positions[corners], atol=1e-12)
    pressure = independent_pressure(result)[corners]
    red = np.array([c.r == 1.0 and c.g == 0.0 for c in mesh.colors])
    assert np.any(pressure >= BRUISE_3D) and np.any((pressure > 0) & (pressure < BRUISE_3D))
    np.testing.assert_array_equal(red, pressure >= BRUISE_3D * (1 + 1e-9))
    untouched = pressure == 0
    assert all(c.g == pytest.approx(0.8) for c, free in zip(mesh.colors, untouched) if free)
    jaws = [m for m in array.markers if m.ns == 'jaws']
    assert [j.scale.y for j in jaws] == [pytest.approx(context.jaw_width)] * 2


def test_3d_wrench_torque_is_r_cross_f_about_the_jaw_face_centre(squeezed_3d):
    result, context = squeezed_3d
    msgs = build_messages(result, context.snapshot())
    for side, index, face_x in (('left', 0, result.left_jaw_x),
                                ('right', 1, result.right_jaw_x)):
        held = result.contact_obstacle == index
        on_jaw = -result.contact_forces[held]
        r = result.positions[held] - np.array([face_x, 0.0, result.lift])
        wrench = msgs[f'{side}_jaw/wrench'].wrench
        torque = np.cross(r, on_jaw).sum(axis=0)
        assert np.linalg.norm(torque) > 1e-5      # the fruit hangs below the jaw centre
        np.testing.assert_allclose([wrench.torque.x, wrench.torque.y, wrench.torque.z],
                                   torque, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose([wrench.force.x, wrench.force.y, wrench.force.z],
                                   on_jaw.sum(axis=0), rtol=1e-6, atol=1e-9)
    assert abs(msgs['left_jaw/wrench'].wrench.force.x) == pytest.approx(3.0, rel=0.1)


def test_3d_cloud_and_fruit_state_carry_the_real_y_and_the_contact_area(squeezed_3d):
    from gripper_sim.core3d.meshes import vertex_areas
    result, context = squeezed_3d
    msgs = build_messages(result, context.snapshot())
    points = messages.read_point_cloud(msgs['fruit/nodes'])
    assert np.ptp(points[:, 1]) > 0.05      # a real y spread: the fruit's width
    np.testing.assert_allclose(points[:, :3], result.positions, atol=1e-6)
    np.testing.assert_allclose(points[:, 3:], result.contact_forces, atol=1e-5)
    state = msgs['fruit/state']
    assert state.dimension == 3 and state.node_count == len(result.positions)
    held = np.isin(result.contact_obstacle, (0, 1))
    area = vertex_areas(result.positions, result.triangles, len(result.positions))[held].sum()
    assert area > 0 and state.contact_area == pytest.approx(area, rel=1e-9)
    masses_centroid_y = float(result.centroid[1])
    assert state.centroid.y == pytest.approx(masses_centroid_y) and state.centroid.y != 0.0
    assert state.centroid.z == pytest.approx(float(result.centroid[2]))


# ------------------------------------------------- damage (StepResult.damage, 2D)

def squeezed_apple_state(force=8.0, **overrides):
    """FruitState and jaw wrench of the 2D apple squeezed to ``force`` N for 0.4 s."""
    from gripper_sim.configuration import load_config
    from gripper_sim.workflows.factory import make_simulation
    config = load_config(overrides=overrides)
    sim = make_simulation(config)
    context = MessageContext.from_config(config, initial=sim.last)
    sim.command_force(force)
    result = sim.run(0.6)
    msgs = build_messages(result, context)
    return msgs['fruit/state'], msgs['left_jaw/wrench'].wrench, config


def hertz_p0(load, config):
    """Peak Hertz pressure (Pa) of a round fruit of the config's diameter on a flat jaw."""
    radius = config['fruit.shape.diameter'] / 2
    modulus = config['fruit.flesh.youngs_modulus'] / (1 - config['fruit.flesh.poisson_ratio'] ** 2)
    a = (3 * load * radius / (4 * modulus)) ** (1 / 3)
    return 3 * load / (2 * np.pi * a * a), a


def test_fruit_state_reports_the_hertz_damage_pressure_not_the_line_pressure():
    state, wrench, config = squeezed_apple_state(8.0)
    p0, _ = hertz_p0(abs(wrench.force.x), config)
    assert state.damage_pressure == pytest.approx(p0, rel=0.05)
    assert state.peak_damage_pressure >= state.damage_pressure
    # the planar line pressure understates the round patch several times
    assert state.peak_contact_pressure < 0.5 * state.damage_pressure
    assert p0 < config['fruit.bruise_pressure']
    assert not state.bruised and state.bruised_fraction == 0.0 and not state.crushed


def test_fruit_state_is_bruised_and_crushed_by_the_damage_estimate():
    state, wrench, config = squeezed_apple_state(8.0)
    p0, a = hertz_p0(abs(wrench.force.x), config)
    bruising = 0.8 * p0       # bruised, but below what the old line pressure would show
    assert state.peak_contact_pressure < bruising
    hurt, _, config = squeezed_apple_state(8.0, **{'fruit.bruise_pressure': bruising})
    assert hurt.bruised and not hurt.crushed
    # each jaw bruises the part of its patch above the threshold: 2 a sqrt(1 - 0.8^2)
    patch = 2 * 2 * a * np.sqrt(1 - 0.8 ** 2) / (np.pi * config['fruit.shape.diameter'])
    assert 0.5 * patch < hurt.bruised_fraction < 2.0 * patch
    crushed, _, _ = squeezed_apple_state(8.0, **{'fruit.failure_stress': 0.5 * p0})
    assert crushed.crushed          # Tresca 0.62 p0 above the failure stress


# ------------------------------------------------------- fingers and pads

def finger_run(finger, seconds=0.3):
    """Markers of the 2D apple at t = 0 and after closing for ``seconds`` with ``finger``."""
    from gripper_sim.configuration import load_config
    from gripper_sim.workflows.factory import make_simulation
    config = load_config(finger=finger)
    sim = make_simulation(config)
    context = MessageContext.from_config(config, initial=sim.last)
    first = (sim.last, build_messages(sim.last, context.snapshot())['markers'])
    sim.command_gap(0.05)
    sim.command_lift(sim.last.lift + 0.004)
    result = sim.run(seconds)
    return config, first, (result, build_messages(result, context)['markers'])


def by_key(array):
    return {(m.ns, m.id): m for m in array.markers}


def xyz(marker):
    return np.array([(p.x, p.y, p.z) for p in marker.points])


def test_arc_finger_outline_is_drawn_at_each_jaw_and_moves_with_it():
    from gripper_sim.geometry.fingers import finger_outline
    config, *runs = finger_run('arc')
    radius, h = config['gripper.finger.radius'], config['gripper.jaw_height']
    sagitta = radius - np.sqrt(radius ** 2 - h * h / 4)
    moved = []
    for result, array in runs:
        markers = by_key(array)
        for side, face_x, marker_id in (('left', result.left_jaw_x, 2),
                                        ('right', result.right_jaw_x, 3)):
            section = markers[('fingers', marker_id)]
            assert section.type == section.LINE_STRIP
            expected = finger_outline(config, side) + np.array([face_x, result.lift])
            drawn = xyz(section)
            np.testing.assert_allclose(drawn[:-1][:, [0, 2]], expected, atol=1e-9)
            np.testing.assert_allclose(drawn[-1], drawn[0])          # closed
            assert np.all(drawn[:, 1] == 0.0)
            # the arc's deepest point is the sagitta behind the jaw's front plane
            assert np.min(np.abs(drawn[:, 0] - face_x)[:len(expected) - 2]) == 0.0
            depth = np.abs(drawn[:-3, 0] - face_x).max()
            assert depth == pytest.approx(sagitta, rel=1e-6)
            solid = markers[('fingers', marker_id - 2)]
            assert solid.type == solid.TRIANGLE_LIST and len(solid.points) % 3 == 0
            corners = xyz(solid)
            assert corners[:, 1].max() == pytest.approx(config['fruit.depth'] / 2
                                                         if config['fruit.depth'] else
                                                         config['fruit.shape.diameter'] / 3)
            moved.append(drawn)
        assert ('pads', 0) not in markers
    # the jaws closed and rose: the outlines followed them
    left_before, right_before, left_after, right_after = moved
    shift_left = left_after - left_before
    assert shift_left[:, 0] == pytest.approx(runs[1][0].left_jaw_x - runs[0][0].left_jaw_x)
    assert shift_left[:, 2] == pytest.approx(runs[1][0].lift - runs[0][0].lift)
    assert shift_left[0, 0] > 0.002 and shift_left[0, 2] > 0.001


def test_flat_jaws_have_no_finger_markers_and_a_pad_is_drawn_on_the_face():
    _, _, (_, plain) = finger_run('flat', 0.01)
    assert not [m for m in plain.markers if m.ns in ('fingers', 'pads')]
    config, _, (result, padded) = finger_run('soft_pad', 0.01)
    markers = by_key(padded)
    t = config['gripper.finger.pad.thickness']
    pad = xyz(markers[('pads', 0)])
    # the pad fills [face - t, face] behind the left jaw's front plane
    assert pad[:, 0].max() == pytest.approx(result.left_jaw_x)
    assert pad[:, 0].min() == pytest.approx(result.left_jaw_x - t)
    body = xyz(markers[('fingers', 0)])
    assert body[:, 0].max() == pytest.approx(result.left_jaw_x - t)
    jaw = markers[('jaws', 0)]
    assert jaw.pose.position.x == pytest.approx(
        result.left_jaw_x - t - config['gripper.jaw_thickness'] / 2)


def test_a_frame_prefix_names_every_header_and_the_tf_edges():
    initial = make_result(gap=0.07)
    ctx = MessageContext.from_config({'fruit.shape.diameter': 0.06}, initial=initial,
                                     frame_prefix='g1/')
    batch = build_messages(make_result(squeeze=6.0, gap=0.058), ctx)
    headers = [batch[s].header for s in ('fruit/nodes', 'fruit/state', 'left_jaw/wrench',
                                         'right_jaw/wrench')]
    headers += [m.header for m in batch['markers'].markers]
    assert {h.frame_id for h in headers} == {'g1/world', 'g1/left_jaw', 'g1/right_jaw'}
    edges = {t.child_frame_id: t for t in batch['tf'].transforms}
    assert set(edges) == {'g1/carriage', 'g1/gripper_base', 'g1/left_jaw', 'g1/right_jaw'}
    assert edges['g1/left_jaw'].transform.translation.x == pytest.approx(-0.029)
    assert all(t.header.stamp == batch['clock'].clock for t in edges.values())
