"""Offline recording of simulation steps (``SimRecorder``) and the ``analyze`` verb.

Expected values come from the inputs of each test (the results fed in, or a closed-form
curve they were built from), never from hard-coded outputs.
"""
from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
import yaml

import rclpy  # noqa: F401
import gripper_sim_interfaces.msg  # noqa: F401

from gripper_sim.cli.main import main  # noqa: E402
from gripper_sim.convert import messages  # noqa: E402
from gripper_sim.core.results import (Deformation, Energies, JawWrench,  # noqa: E402
                                      StepResult)
from gripper_sim.recording.analysis import COLUMNS, analyze  # noqa: E402
from gripper_sim.recording.errors import RecordingError  # noqa: E402
from gripper_sim.recording.offline import CONFIG_METADATA, SimRecorder  # noqa: E402
from gripper_sim.recording.reader import BagReader  # noqa: E402

pytestmark = pytest.mark.ros

N_NODES = 24
RADIUS = 0.03
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'


def make_result(step: int, dt: float, *, compression: float, force: float,
                pressure: float = 0.0, slip: float = 0.0, contact: bool = True,
                slipping: bool = False) -> StepResult:
    """A hand-made step: a ring squeezed along x by ``compression``, pushed by ``force``."""
    angles = np.linspace(0.0, 2.0 * np.pi, N_NODES, endpoint=False)
    half = RADIUS - compression / 2.0
    positions = np.column_stack([half * np.cos(angles), 0.03 + RADIUS * np.sin(angles)])
    forces = np.zeros((N_NODES, 2))
    obstacle = np.full(N_NODES, -1)
    node_pressure = np.zeros(N_NODES)
    if contact:
        forces[0], forces[N_NODES // 2] = (-force, 0.0), (force, 0.0)
        obstacle[0], obstacle[N_NODES // 2] = 1, 0
        node_pressure[0] = node_pressure[N_NODES // 2] = pressure
    return StepResult(
        time=step * dt, step=step, positions=positions, velocities=np.zeros((N_NODES, 2)),
        contact_forces=forces, contact_obstacle=obstacle, contact_sticking=obstacle >= 0,
        obstacle_names=('left_jaw', 'right_jaw', 'table'), surface=np.arange(N_NODES),
        left_wrench=JawWrench(force=np.array([-force, 0.0, 0.0]), torque=np.zeros(3)),
        right_wrench=JawWrench(force=np.array([force * 1.01, 0.0, 0.0]), torque=np.zeros(3)),
        left_jaw_x=-half, right_jaw_x=half, jaw_velocity=0.0, lift=0.03, lift_velocity=0.0,
        gap=2 * half, grip_force=force, slip_distance=slip, slipping=slipping,
        centroid=np.array([0.0, 0.03]),
        energies=Energies(kinetic=1e-6 * step, elastic=0.5 * force * compression,
                          gravitational=0.1),
        deformation=Deformation(compression=compression,
                                compression_ratio=compression / (2 * RADIUS),
                                max_skin_strain=0.5 * compression / RADIUS,
                                contact_length=0.002 if contact else 0.0,
                                peak_contact_pressure=pressure, node_pressure=node_pressure),
        newton_iterations=2, substeps=1)


def config(bruise: float = 2.0e5) -> dict:
    from gripper_sim.configuration import load_config
    return load_config(overrides={'fruit.bruise_pressure': bruise})


def squeeze_results(k: float = 2500.0, f0: float = 0.2, dt: float = 0.001, n: int = 200,
                    bruise: float = 2.0e5):
    """Load linearly (force = f0 + k c) to a peak, then unload; pressure follows force."""
    out = []
    c_peak = 0.004
    for step in range(n):
        s = step / (n - 1)
        c = c_peak * (1 - abs(2 * s - 1))        # up, then down
        force = f0 + k * c
        pressure = bruise * force / (f0 + k * c_peak) * 1.2   # above bruise near the peak
        out.append(make_result(step, dt, compression=c, force=force, pressure=pressure,
                               slip=2e-6 * step))
    return out


def record(path, results, cfg, **kwargs):
    with SimRecorder(path, cfg, **kwargs) as rec:
        for r in results:
            rec.on_step(r)
    return rec


def test_offline_recording_holds_the_node_topics_and_the_configuration(tmp_path):
    cfg = config()
    results = squeeze_results(n=50)
    path = tmp_path / 'offline.mcap'
    rec = record(path, results, cfg)
    assert rec.samples == len(results)
    with BagReader(path) as bag:
        expected_topics = {messages.resolved_topic(s): t for s, (_, t) in
                           messages.TOPICS.items()}
        latched = {'/tf_static': 'tf2_msgs/msg/TFMessage',
                   '/robot_description': 'std_msgs/msg/String'}
        assert {n: i.type for n, i in bag.topics.items()} == {**expected_topics, **latched}
        assert all(i.message_count == (1 if n in latched else len(results))
                   for n, i in bag.topics.items())
        stored = bag.metadata_named(CONFIG_METADATA)
        assert yaml.safe_load(stored['yaml']) == yaml.safe_load(
            __import__('gripper_sim.configuration', fromlist=['to_yaml']).to_yaml(cfg))
        states = list(bag.decoded_messages(['/gripper_sim/fruit/state']))
        assert [s.grip_force for _, s in states] == [r.grip_force for r in results]
        assert [s.compression for _, s in states] == \
            [r.deformation.compression for r in results]
        for raw, s in states:
            stamp = s.header.stamp.sec * 1_000_000_000 + s.header.stamp.nanosec
            assert raw.log_time == stamp == raw.publish_time
        assert bag.start_time == 0 and bag.end_time == messages.time_msg(
            results[-1].time).nanosec


def test_every_and_topics_and_closed_recorder(tmp_path):
    results = squeeze_results(n=30)
    path = tmp_path / 'sparse.mcap'
    rec = record(path, results, config(), every=3, topics=['fruit/state', 'clock'])
    rec.on_step(results[0])  # after close: ignored, no error
    with BagReader(path) as bag:
        assert set(bag.topics) == {'/gripper_sim/fruit/state', '/clock'}
        assert bag.topics['/clock'].message_count == len(results[::3])
    with pytest.raises(RecordingError, match='unknown topic suffix'):
        SimRecorder(tmp_path / 'x.mcap', config(), topics=['nope'])
    with pytest.raises(RecordingError, match='every'):
        SimRecorder(tmp_path / 'x.mcap', config(), every=0)


def test_analysis_reproduces_peaks_stiffness_and_bruise_time(tmp_path):
    k, f0, bruise = 2500.0, 0.2, 2.0e5
    results = squeeze_results(k=k, f0=f0, bruise=bruise)
    path = tmp_path / 'squeeze.mcap'
    record(path, results, config(bruise))
    out = tmp_path / 'analysis'
    result = analyze(path, out)
    s = result.summary
    forces = [r.grip_force for r in results]
    assert s['samples'] == len(results)
    assert s['peak_grip_force_n'] == max(forces)
    assert s['peak_compression_m'] == max(r.deformation.compression for r in results)
    assert s['peak_left_force_n'] == max(abs(r.left_wrench.force[0]) for r in results)
    assert s['peak_right_force_n'] == max(abs(r.right_wrench.force[0]) for r in results)
    assert s['stiffness_n_per_m'] == pytest.approx(k, rel=1e-6)
    # the chord of the loading curve: from the grip (the first step) to where the force
    # first reaches 97 % of its peak (before the unloading)
    end = next(i for i, f in enumerate(forces) if f >= 0.97 * max(forces))
    chord = (forces[end] - forces[0]) / (results[end].deformation.compression
                                         - results[0].deformation.compression)
    assert s['secant_stiffness_n_per_m'] == pytest.approx(chord)
    times = np.array([r.time for r in results])
    dt = np.diff(times, append=times[-1])
    above = np.array([r.deformation.peak_contact_pressure > bruise for r in results])
    assert s['bruised'] is True
    assert s['time_above_bruise_threshold_s'] == pytest.approx(float(dt[above].sum()))
    assert s['bruise_threshold_pa'] == bruise
    assert s['held'] is None and s['slipped'] is None   # a squeeze: not lifted
    assert s['max_slip_distance_m'] == pytest.approx(max(r.slip_distance for r in results))
    assert json.loads((out / 'summary.json').read_text()) == s
    with open(out / 'timeseries.csv') as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS and len(rows) == len(results)
    assert [float(r['grip_force_n']) for r in rows] == forces
    assert [float(r['time_s']) for r in rows] == pytest.approx(list(times), abs=1e-9)
    for name in ('force_vs_time.png', 'force_vs_compression.png', 'outline_snapshots.png'):
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 10_000, name


def test_slip_and_release_are_reported(tmp_path):
    dt = 0.001
    results = []
    for step in range(100):
        slip = 0.0 if step < 40 else 1e-4 * (step - 40)       # slides 6 mm
        contact = step < 90                                     # then lets go
        results.append(make_result(step, dt, compression=0.002, force=3.0, slip=slip,
                                   contact=contact, slipping=40 <= step < 90))
    path = tmp_path / 'slip.mcap'
    record(path, results, config())
    s = analyze(path, tmp_path / 'a', figures=False).summary
    assert s['slipped'] is None and s['held'] is None   # never lifted: not judged
    assert s['max_slip_distance_m'] == pytest.approx(max(r.slip_distance for r in results))
    assert s['slipping_time_s'] == pytest.approx(50 * dt)
    assert not (tmp_path / 'a' / 'force_vs_time.png').exists()


def test_analysis_of_a_real_simulation_run(tmp_path):
    from gripper_sim.core.simulation import Simulation
    cfg = config()
    sim = Simulation(cfg)
    path = tmp_path / 'sim.mcap'
    seen = []
    with SimRecorder(path, sim.config, initial=sim.last) as rec:
        sim.add_observer(rec.on_step)
        sim.add_observer(seen.append)
        sim.command_force(3.0)
        while sim.time < 0.15:
            sim.step()
    s = analyze(path, tmp_path / 'out').summary
    assert s['samples'] == len(seen) + 1  # and the initial state
    assert s['peak_grip_force_n'] == max([r.grip_force for r in seen] +
                                         [sim_initial_force(cfg)])
    assert s['peak_compression_m'] == max(
        [r.deformation.compression for r in seen] + [initial_compression(cfg)])
    assert (tmp_path / 'out' / 'outline_snapshots.png').read_bytes().startswith(PNG_MAGIC)


def sim_initial_force(cfg) -> float:
    from gripper_sim.core.simulation import Simulation
    return Simulation(cfg).last.grip_force


def initial_compression(cfg) -> float:
    from gripper_sim.core.simulation import Simulation
    return Simulation(cfg).last.deformation.compression


def test_cli_analyze(tmp_path, capsys):
    results = squeeze_results(n=40)
    path = tmp_path / 'cli.mcap'
    record(path, results, config())
    capsys.readouterr()
    assert main(['analyze', str(path), '-o', str(tmp_path / 'o')]) == 0
    out = capsys.readouterr().out
    assert 'peak grip force' in out and 'summary.json' in out
    default_dir = tmp_path / 'cli_analysis'
    assert main(['analyze', str(path), '--no-figures']) == 0
    assert (default_dir / 'summary.json').is_file()
    # a recording without the sim's FruitState topic: a clear error, exit 2
    other = tmp_path / 'other.mcap'
    record(other, results[:3], config(), topics=['clock'])
    capsys.readouterr()
    assert main(['analyze', str(other)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: ') and 'FruitState' in err and 'Traceback' not in err
    assert main(['analyze', str(path), '--namespace', '/elsewhere']) == 2
    assert "no FruitState topic '/elsewhere/fruit/state'" in capsys.readouterr().err


def test_finite_check_skips_nan_steps(tmp_path):
    results = squeeze_results(n=10)
    bad = make_result(10, 0.001, compression=math.nan, force=1.0)
    path = tmp_path / 'nan.mcap'
    rec = record(path, results + [bad], config())
    assert rec.failures == 1 and rec.samples == len(results)


def test_info_analyze_and_recover_never_import_ros(tmp_path):
    """They work from the file alone: no rclpy, no ROS message packages imported."""
    import subprocess
    import sys
    from pathlib import Path
    path = tmp_path / 'noros.mcap'
    record(path, squeeze_results(n=30), config())
    code = (
        'import sys\n'
        'from gripper_sim.cli.main import main\n'
        f'assert main(["info", {str(path)!r}]) == 0\n'
        f'assert main(["analyze", {str(path)!r}, "-o", {str(tmp_path / "o")!r}]) == 0\n'
        f'assert main(["recover", {str(path)!r}, {str(tmp_path / "r.mcap")!r}]) == 0\n'
        'ros = sorted(m for m in sys.modules if m.split(".")[0] in '
        '("rclpy", "gripper_sim_interfaces", "std_msgs", "geometry_msgs", "rosidl_parser"))\n'
        'assert not ros, ros\n'
        'print("no ROS imported")\n')
    root = Path(__file__).resolve().parents[1]
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          cwd=root, timeout=300)
    assert done.returncode == 0, done.stderr
    assert 'no ROS imported' in done.stdout
