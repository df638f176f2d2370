"""Everything downstream of the 3D model: the offline verbs with ``--set dimension=3``,
their MCAP recordings (point cloud and ``fruit_mesh`` marker intact), ``analyze`` in 3D
(contact area, mesh and contact patch figures) and the damage in the analysis report.

Coarse meshes (geodesic frequency 3-4) and a 5 ms step keep the 3D runs short; every
expected value comes from the simulation itself (re-run from the configuration the
recording stores) or from closed-form mechanics, never from hard-coded outputs.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim import configuration  # noqa: E402
from gripper_sim.cli.main import main  # noqa: E402
from gripper_sim.recording.analysis import (analyze, cloud_array, jaw_contact_nodes,  # noqa: E402
                                            patch_outline, read_config)
from gripper_sim.recording.offline import SimRecorder  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

pytestmark = pytest.mark.ros

COARSE = ['--set', 'dimension=3', '--set', 'fruit.mesh.subdivisions=4',
          '--set', 'sim.dt=0.005']
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def replay_squeeze(config: dict, to_force: float, speed: float) -> list:
    """The squeeze ``gripper-sim squeeze --to-force`` runs, re-run from ``config``:
    every step's result, the initial state first."""
    sim = make_simulation(config)
    results = [sim.last]
    sim.add_observer(results.append)
    sim.command_gap(0.0, speed)
    while results[-1].grip_force < to_force:
        sim.step()
    return results


def test_squeeze_in_3d_end_to_end_recording_and_analysis(tmp_path, capsys):
    path = tmp_path / 'squeeze3d.mcap'
    assert main(['squeeze', '--to-force', '3', '--speed', '0.02', *COARSE, '--json',
                 '--out', str(path)]) == 0
    summary = json.loads(capsys.readouterr().out)['summary']
    assert summary['dimension'] == 3 and summary['peak_grip_force'] >= 3.0

    with BagReader(path) as bag:
        config = configuration.validate(read_config(bag))
        topics = {t: info.type for t, info in bag.topics.items()}
        clouds = [m for _, m in bag.decoded_messages(['/gripper_sim/fruit/nodes'])]
        arrays = [m for _, m in bag.decoded_messages(['/gripper_sim/markers'])]
    assert config['dimension'] == 3 and config['fruit.mesh.subdivisions'] == 4
    results = replay_squeeze(config, 3.0, 0.02)
    assert len(clouds) == len(arrays) == len(results)
    assert summary['peak_grip_force'] == max(r.grip_force for r in results)

    # the 3D point cloud and the skin mesh of the last step, intact
    last = results[-1]
    cloud = cloud_array(clouds[-1])
    assert cloud[:, :3] == pytest.approx(last.positions, abs=1e-6)      # float32
    assert cloud[:, 3:] == pytest.approx(last.contact_forces, abs=1e-5)
    assert np.ptp(cloud[:, 1]) > 0.9 * np.ptp(cloud[:, 0])              # a real y
    mesh = next(m for m in arrays[-1].markers if m.ns == 'fruit_mesh')
    corners = np.array([(p.x, p.y, p.z) for p in mesh.points])
    assert mesh.type == 11 and len(mesh.colors) == len(mesh.points)     # TRIANGLE_LIST
    assert corners == pytest.approx(last.positions[last.triangles.ravel()], abs=1e-12)

    # gripper-sim info reads it
    assert main(['info', '--json', str(path)]) == 0
    info = json.loads(capsys.readouterr().out)
    counts = {t['name']: t['count'] for t in info['topics']}
    assert counts['/gripper_sim/fruit/nodes'] == counts['/gripper_sim/markers'] == len(results)
    assert topics['/gripper_sim/markers'] == 'visualization_msgs/msg/MarkerArray'

    # analyze: the contact area is the simulation's own, and the 3D figures are written
    out = tmp_path / 'analysis'
    s = analyze(path, out).summary
    peak = int(np.argmax([r.grip_force for r in results]))
    assert s['dimension'] == 3
    assert s['contact_area_at_peak_force_m2'] == pytest.approx(
        results[peak].deformation.contact_area, rel=1e-12)
    assert s['peak_contact_area_m2'] == pytest.approx(
        max(r.deformation.contact_area for r in results), rel=1e-12)
    assert s['contact_area_at_peak_force_m2'] > 0
    for name in ('force_vs_time.png', 'force_vs_compression.png', 'mesh_snapshots.png',
                 'contact_patch.png'):
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, name
    assert not (out / 'outline_snapshots.png').exists()
    # the patch figure's nodes are the nodes the simulation held on each jaw
    patches = s['contact_patches_at_peak_force']
    names = results[peak].obstacle_names
    for side in ('left', 'right'):
        held = np.count_nonzero(results[peak].contact_obstacle == names.index(f'{side}_jaw'))
        assert patches[side]['nodes'] == held > 3
        radius = results[peak].deformation.jaw_contact_radii[0 if side == 'left' else 1]
        # the hull of the held nodes lies inside the patch the simulation measured
        assert 0 < patches[side]['hull_area_m2'] <= np.pi * radius ** 2


def test_squeeze_text_output_in_3d_speaks_of_areas(capsys):
    assert main(['squeeze', '--to-force', '2', '--speed', '0.02', *COARSE]) == 0
    out = capsys.readouterr().out
    assert '3D' in out and 'mm^2' in out and 'patch radius' in out
    assert 'planar' not in out and 'Hertz' not in out and 'outline' not in out
    assert main(['squeeze', '--to-force', '2']) == 0     # 2D keeps its own labels
    out = capsys.readouterr().out
    assert 'contact length' in out and 'planar' in out and 'mm^2' not in out


@pytest.mark.parametrize('dimension', [2, 3])
def test_damage_in_the_analysis_report_matches_the_last_step(tmp_path, dimension):
    """A squeeze past the bruise threshold: the report's damage is the step's estimate."""
    overrides = {'dimension': dimension, 'world.gravity': 0.0, 'world.table': False,
                 'fruit.bruise_pressure': 20e3}
    if dimension == 3:
        overrides.update({'fruit.mesh.subdivisions': 4, 'sim.dt': 0.005})
    config = configuration.load_config(overrides=overrides)
    sim = make_simulation(config)
    path = tmp_path / 'bruise.mcap'
    seen = [sim.last]
    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        sim.add_observer(seen.append)
        sim.command_gap(0.0, 0.02)
        while sim.last.grip_force < 4.0:
            sim.step()
    damage = seen[-1].damage
    assert damage.bruised and damage.bruised_fraction > 0    # past the threshold
    s = analyze(path, tmp_path / 'a', figures=False).summary
    assert s['bruised'] is True and s['damage_note'] is None
    assert s['bruised_fraction'] == pytest.approx(damage.bruised_fraction, rel=1e-12)
    assert s['final_bruised_fraction'] == pytest.approx(damage.bruised_fraction, rel=1e-12)
    assert s['peak_damage_pressure_pa'] == pytest.approx(damage.peak_pressure, rel=1e-12)
    assert s['crushed'] is bool(damage.crushed)
    assert s['peak_damage_pressure_pa'] > config['fruit.bruise_pressure']
    assert s['peak_flesh_stress_pa'] == pytest.approx(damage.peak_flesh_stress, rel=1e-12)
    times = np.array([r.time for r in seen])
    above = np.array([r.damage.pressure > config['fruit.bruise_pressure'] for r in seen])
    dt = np.diff(times, append=times[-1])
    assert s['time_above_bruise_threshold_s'] == pytest.approx(float(dt[above].sum()))
    assert s['time_above_bruise_threshold_s'] > 0
    text = '\n'.join(analyze(path, tmp_path / 'b', figures=False).describe())
    assert 'bruised True' in text
    assert ('of the surface' if dimension == 3 else 'of the outline') in text


def test_a_recording_without_the_damage_pressure_field_is_reported_as_such(tmp_path):
    """Older recordings: a FruitState schema without ``peak_damage_pressure``."""
    from mcap_ros2._dynamic import serialize_dynamic

    from gripper_sim.recording import schemas
    from gripper_sim.recording.writer import BagWriter
    state_type = 'gripper_sim_interfaces/msg/FruitState'
    new_fields = ('damage_pressure', 'peak_damage_pressure', 'peak_flesh_stress')
    current = schemas.message_definition(state_type)
    old_lines = [line for line in current.splitlines()
                 if not any(line.split('#')[0].split()[1:2] == [f] for f in new_fields)]
    old = '\n'.join(old_lines) + '\n'
    assert 'peak_damage_pressure' not in old and 'bruised_fraction' in old
    encode = serialize_dynamic(state_type, old)[state_type]
    path = tmp_path / 'old.mcap'
    pressures = [1e4, 3e4, 2e4]
    with BagWriter(path) as bag:
        bag.add_topic('/gripper_sim/fruit/state', state_type, definition=old)
        for i, p in enumerate(pressures):
            msg = {'header': {'stamp': {'sec': 0, 'nanosec': i * 1_000_000},
                              'frame_id': 'world'},
                   'dimension': 2, 'node_count': 10, 'grip_force': 1.0 + i,
                   'peak_contact_pressure': p, 'left_jaw_contact': True,
                   'right_jaw_contact': True, 'bruised': i > 0, 'bruised_fraction': 0.1 * i,
                   'centroid': {'x': 0.0, 'y': 0.0, 'z': 0.0}}
            bag.write('/gripper_sim/fruit/state', encode(msg), log_time=i * 1_000_000)
    s = analyze(path, tmp_path / 'a', figures=False).summary
    assert s['peak_damage_pressure_pa'] is None
    assert 'peak_damage_pressure' in s['damage_note']
    assert s['bruised'] is True and s['bruised_fraction'] == pytest.approx(0.2)
    assert s['peak_contact_pressure_pa'] == max(pressures)


def test_contact_patch_helpers():
    """The jaw classification and the patch outline on a hand-made cloud."""
    angles = np.linspace(0, 2 * np.pi, 8, endpoint=False)
    ring = np.column_stack([0.004 * np.cos(angles), 0.004 * np.sin(angles)])
    cloud = np.zeros((20, 6))
    cloud[:8, 1:3], cloud[:8, 3] = ring, 0.4            # left jaw pushes +x
    cloud[8:16, 1:3], cloud[8:16, 3] = ring, -0.4       # right jaw
    cloud[8:16, 5] = 0.3                                # with friction below mu = 1
    cloud[16:, 5], cloud[16:, 3] = 1.0, 0.3             # table: mostly +z
    sides = jaw_contact_nodes(cloud)
    assert list(sides['left']) == list(range(8)) and list(sides['right']) == list(range(8, 16))
    loop, area = patch_outline(ring)
    # a regular octagon of circumradius r: 2 sqrt(2) r^2
    assert area == pytest.approx(2 * np.sqrt(2) * 0.004 ** 2, rel=1e-12)
    assert np.allclose(loop[0], loop[-1])
    assert patch_outline(ring[:2])[1] == 0.0


def test_pick_in_3d(capsys):
    assert main(['pick', '--force', '3', '--lift', '0.01', '--hold', '0.1', *COARSE,
                 '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    s = data['summary']
    assert data['outcome'] == 'held' and s['dimension'] == 3
    assert s['peak_grip_force'] >= 0.97 * 3.0 and s['contact_area_at_peak_force'] > 0
    assert data['slip_distance'] < 1e-3


def test_run_a_short_scenario_in_3d(tmp_path, capsys):
    """Pick, carry 2 cm and place in 3D; the slip in the jaws is measured along z (the
    planar code read column 1, which is y in 3D, and reported the whole lift as slip)."""
    scenario = tmp_path / 'short.yaml'
    scenario.write_text(
        'name: short\nfruit: apple\napproach: {height: 0.005}\n'
        'close: {mode: force, force: 4.0, speed: 0.05}\nsqueeze: {time: 0.1}\n'
        'lift: {height: 0.01}\ntransport: {distance: 0.02}\n'
        'retreat: {height: 0.06, speed: 0.2}\n'   # the jaws clear the fruit's top
        'settle: {time: 0.1}\n')
    assert main(['run', str(scenario), *COARSE, '--json']) == 0
    data = json.loads(capsys.readouterr().out)
    s = data['summary']
    assert data['outcome'] == 'placed' and s['dimension'] == 3
    assert s['slip_distance'] < 1e-3
    # placed 2 cm along x from where it started (within a quarter of its width)
    assert s['final_centroid'][0] == pytest.approx(0.02, abs=0.25 * 0.0635)


LIVE_TOPICS = ('/gripper_sim/fruit/nodes', '/gripper_sim/markers', '/gripper_sim/fruit/state')


def _wait(condition, timeout: float, what: str) -> None:
    import time
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return
        time.sleep(0.05)
    raise AssertionError(f'timed out after {timeout} s waiting for {what}')


def _same_payload(got: bytes, sent: bytes) -> bool:
    """Equal CDR payloads: DDS may pad a sample with up to 3 zero bytes."""
    extra = got[len(sent):]
    return got[:len(sent)] == sent and len(extra) < 4 and not any(extra)


def _check_3d_sample(bag: BagReader) -> int:
    """The last cloud and fruit_mesh of ``bag`` with the same stamp are one 3D fruit:
    every mesh corner is a cloud node, y is real; returns the FruitState count."""
    states = [m for _, m in bag.decoded_messages(['/gripper_sim/fruit/state'])]
    assert states and all(s.dimension == 3 for s in states)
    clouds = {(m.header.stamp.sec, m.header.stamp.nanosec): cloud_array(m)
              for _, m in bag.decoded_messages(['/gripper_sim/fruit/nodes'])}
    meshes = {}
    for _, array in bag.decoded_messages(['/gripper_sim/markers']):
        for marker in array.markers:
            if marker.ns == 'fruit_mesh':
                meshes[(marker.header.stamp.sec, marker.header.stamp.nanosec)] = marker
    stamp = max(set(clouds) & set(meshes))
    cloud, mesh = clouds[stamp], meshes[stamp]
    corners = np.array([(p.x, p.y, p.z) for p in mesh.points])
    assert len(corners) % 3 == 0 and len(mesh.colors) == len(corners) > 3 * len(cloud)
    distance = np.min(np.linalg.norm(corners[:, None, :] - cloud[None, :, :3], axis=2), axis=1)
    assert distance.max() < 1e-6
    assert np.ptp(cloud[:, 1]) > 0.9 * np.ptp(cloud[:, 0])
    return len(states)


@pytest.mark.slow
def test_live_recording_of_the_3d_node_round_trips_through_info_and_replay(
        tmp_path, new_domain_id, capsys):
    """Record the 3D node live, check the file, replay it and record the replay: the
    point cloud and mesh marker payloads come back byte for byte."""
    from gripper_sim.ros.process import RosProcess, node_process, ros_environment
    from ros_client import SimClient
    domain = new_domain_id()
    env = ros_environment(domain)

    def cli(*args: str, name: str) -> RosProcess:
        return RosProcess('gripper_sim.cli.main', list(args), env=env,
                          log_path=tmp_path / f'{name}.log')

    parameters = {'real_time_factor': 0.0, 'physics.dimension': 3,
                  'physics.fruit.mesh.subdivisions': 3, 'physics.sim.dt': 0.002,
                  'physics.gripper.initial_gap': 0.066,
                  'marker_rate': 100.0}   # markers with every state batch (publish_rate 100)
    live = tmp_path / 'live3d.mcap'
    in_node = tmp_path / 'innode3d.mcap'
    node = node_process(parameters, env=env, log_path=tmp_path / 'node.log').start()
    client = SimClient(domain, name='downstream_3d_client')
    try:
        client.wait_ready(timeout=120)
        client.restart(run=False)
        recorder = cli('record', '-o', str(live), *LIVE_TOPICS, name='record_live')
        with recorder:
            _wait(lambda: recorder.log().count("recording '") == len(LIVE_TOPICS), 120,
                  'the recorder to subscribe')
            started, = client.set_parameters(record_path=str(in_node))   # in-node too
            assert started.successful, started.reason
            for _ in range(3):
                assert client.step(10).success
            client.spin_until(lambda: client.sim_time() >= 0.06 - 1e-9, 60, 'the steps')
            client.catch_up(['fruit/nodes', 'markers'])
            stopped, = client.set_parameters(record_path='')
            assert stopped.successful, stopped.reason
            assert recorder.stop(timeout=60) == 0, recorder.log()
    finally:
        client.close()
        code = node.stop()
        assert 'Traceback' not in node.log() and code == 0, node.log()

    assert main(['info', '--json', str(live)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert {t['name'] for t in info['topics']} == set(LIVE_TOPICS)
    with BagReader(live) as bag:
        samples = _check_3d_sample(bag)
        recorded = {t: [m.data for m in bag.messages([t])] for t in LIVE_TOPICS}
    assert samples >= 5   # 0.06 s of sim time at the 100 Hz publish rate
    # the in-node recording holds every physics step (2 ms) and analyses as a 3D run
    with BagReader(in_node) as bag:
        assert _check_3d_sample(bag) >= 30
    analysis = analyze(in_node, tmp_path / 'innode_analysis')
    assert analysis.summary['dimension'] == 3
    assert (tmp_path / 'innode_analysis' / 'mesh_snapshots.png').is_file()

    replayed = tmp_path / 'replayed3d.mcap'
    recorder = cli('record', '-o', str(replayed), *LIVE_TOPICS, name='record_replay')
    with recorder:
        replay = cli('replay', str(live), '--wait-for-subscribers', '60', name='replay')
        with replay:
            _wait(lambda: recorder.log().count("recording '") == len(LIVE_TOPICS), 120,
                  'the recorder to subscribe to the replayed topics')
            replay.process.wait(120)
            assert replay.process.returncode == 0, replay.log()
        _wait(lambda: replayed.exists(), 60, 'the replayed recording')
        assert recorder.stop(timeout=60) == 0, recorder.log()
    with BagReader(replayed) as bag:
        _check_3d_sample(bag)
        for topic, sent in recorded.items():
            got = [m.data for m in bag.messages([topic])]
            assert len(got) == len(sent), topic
            assert all(_same_payload(g, s) for g, s in zip(got, sent)), topic


@pytest.mark.slow
def test_grasp_window_in_3d(tmp_path, capsys):
    """The window search runs 3D trials: the smallest force that held is above the
    Coulomb bound m g / (2 mu_s) of the 3D fruit's mass, and every trial's bruise flag
    is the resolved peak pressure against the threshold."""
    from gripper_sim.core3d.fruit import build_fruit3d
    scenario = tmp_path / 'carry.yaml'
    scenario.write_text('name: carry\nfruit: apple\nclose: {mode: force, speed: 0.05}\n'
                        'squeeze: {time: 0.1}\nlift: {height: 0.01}\n'
                        'transport: {distance: 0.01}\n')
    # the pressurised 3D shell spreads its contact as the force grows: the resolved peak
    # pressure stays near 32 kPa up to ~8 N and passes 36 kPa only above ~16 N
    bruise = 36e3
    overrides = [*COARSE, '--set', f'fruit.bruise_pressure={bruise}']
    assert main(['window', '--scenario', str(scenario), *overrides, '--tolerance', '0.5',
                 '--json']) == 0
    window = json.loads(capsys.readouterr().out)
    config = configuration.load_config(fruit='apple', overrides={
        'dimension': 3, 'fruit.mesh.subdivisions': 4, 'sim.dt': 0.005})
    mass = build_fruit3d(config).total_mass
    mu = config['contact.jaw.static_friction']
    assert window['mass'] == pytest.approx(mass, rel=1e-12)
    assert window['window'] is True
    assert window['min_force'] >= mass * 9.81 / (2 * mu)
    assert window['max_force'] != 'inf' and window['min_force'] <= window['max_force']
    for trial in window['trials']:
        if trial['outcome'] != 'solver failed':
            assert trial['bruised'] == (trial['peak_damage_pressure'] > bruise), trial
    assert any(t['bruised'] for t in window['trials'])
    assert any(not t['held'] and t['force'] < window['min_force'] for t in window['trials'])


@pytest.mark.parametrize('verb', [['squeeze', '--to-force', '1'], ['pick', '--force', '1'],
                                  ['run', 'pick_and_place'], ['window']])
def test_what_the_3d_model_lacks_is_a_one_line_error(verb, capsys):
    """The point-mass fruit is 2D only: every verb says so, exit 2, no traceback."""
    assert main([*verb, *COARSE, '--set', 'fruit.model=point']) == 2
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith('error: ') and len(err.splitlines()) == 1
    assert 'fruit.model' in err and 'dimension' in err and 'Traceback' not in err
