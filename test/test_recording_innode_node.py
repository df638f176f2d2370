"""In-node recording on the real node process: ``~/record`` and the ``record_path`` parameter.

The node runs in a subprocess (``real_time_factor`` 0); a test client starts recording
through ``~/record``, closes the jaws by topic, lets physics run free, stops, and reads
the file with the ``mcap`` library: every physics step is there (consecutive sim-time
stamps exactly dt apart, not only the published ones), with the ``gripper_sim_config``
metadata record, and that configuration run offline reproduces the recorded states.
"""
from __future__ import annotations

import re
from pathlib import Path

import pytest

import rclpy
import gripper_sim_interfaces.msg  # noqa: F401
import mcap.reader as mcap_reader

from gripper_sim_interfaces.msg import FruitState  # noqa: E402
from rcl_interfaces.srv import GetParameters  # noqa: E402
from rclpy.parameter import parameter_value_to_python  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402
from std_srvs.srv import SetBool  # noqa: E402

from gripper_sim import configuration  # noqa: E402
from gripper_sim.core.simulation import Simulation  # noqa: E402
from gripper_sim.recording.offline import CONFIG_METADATA  # noqa: E402
from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment  # noqa: E402
from ros_client import SimClient  # noqa: E402

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(37)
STATE = '/gripper_sim/fruit/state'
# Start-up parameters that differ from the defaults: the recorded configuration must
# carry them (a structural key and a dynamic one).
PHYSICS = {'fruit.nodes': 48, 'contact.jaw.static_friction': 0.7}
TIMEOUT = 120.0


@pytest.fixture(scope='module')
def running(tmp_path_factory, node_and_client):
    """The node, started in its own working directory (where timestamped files go)."""
    workdir = tmp_path_factory.mktemp('node_cwd')
    parameters = {'real_time_factor': 0.0,
                  **{f'physics.{key}': value for key, value in PHYSICS.items()}}
    with node_and_client(parameters, DOMAIN, workdir.parent / 'innode_node.log',
                         client_name='innode_recording_client', cwd=workdir,
                         timeout=TIMEOUT) as (process, client):
        record = client.node.create_client(SetBool, '/gripper_sim/record')
        get_params = client.node.create_client(GetParameters, '/gripper_sim/get_parameters')
        yield process, client, record, get_params, workdir


@pytest.fixture
def node(running):
    process, client, record, get_params, workdir = running
    assert process.running, process.log()
    client.pause(False)
    return running


def record_path_param(client, get_params) -> str:
    response = client.call(get_params, GetParameters.Request(names=['record_path']))
    return parameter_value_to_python(response.values[0])


def read_states(path: Path) -> tuple[list[FruitState], dict[str, str], list[str]]:
    """FruitState messages, the config metadata and the topics, with the mcap library
    (``path`` is a one-file bag folder or an .mcap file)."""
    if path.is_dir():
        assert sorted(p.name for p in path.iterdir()) == [f'{path.name}_0.mcap',
                                                           'metadata.yaml']
        path = path / f'{path.name}_0.mcap'
    with open(path, 'rb') as stream:
        reader = mcap_reader.make_reader(stream)
        states = [deserialize_message(message.data, FruitState)
                  for _, _, message in reader.iter_messages(topics=[STATE])]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        topics = sorted(c.topic for c in reader.get_summary().channels.values())
    return states, metadata.get(CONFIG_METADATA, {}), topics


def ns(state: FruitState) -> int:
    return state.header.stamp.sec * 1_000_000_000 + state.header.stamp.nanosec


def test_record_service_writes_every_step_and_a_config_that_reproduces_the_run(
        node, tmp_path):
    process, client, record, get_params, workdir = node
    dt = configuration.load_config()['sim.dt']
    dt_ns = int(round(dt * 1e9))
    client.pause(True)
    client.reset()
    t_start = client.step(1).sim_time

    started = client.call(record, SetBool.Request(data=True))
    assert started.success, started.message
    match = re.search(r'(/\S+/gripper_sim_\S+)', started.message)
    assert match, started.message
    path = Path(match.group(1))
    # record_path empty: a timestamped bag folder in the node's working directory
    assert path.parent == workdir, started.message
    assert re.fullmatch(r'gripper_sim_\d{8}_\d{6}(_\d+)?', path.name), path.name
    assert record_path_param(client, get_params) == str(path)
    again = client.call(record, SetBool.Request(data=True))
    assert not again.success and 'already recording' in again.message

    # close the jaws by topic, stepping by hand until they touch the fruit
    client.publish('gap', 0.058)
    stepped = 0
    while client.step(20).sim_time < t_start + 1.0:
        stepped += 20
        client.spin_until(lambda: client.sim_time() >= t_start + stepped * dt - 0.01 - 1e-9,
                          30, 'the stepped state')
        if client.latest['fruit/state'].grip_force > 0.5:
            break
    assert client.latest['fruit/state'].grip_force > 0.5
    # then free-running physics at full speed: recorded at every step as well
    client.pause(False)
    client.wait_sim_time(0.2)
    client.pause(True)
    t_end = client.step(1).sim_time
    stopped = client.call(record, SetBool.Request(data=False))
    assert stopped.success and str(path) in stopped.message, stopped.message
    assert record_path_param(client, get_params) == ''
    assert not client.call(record, SetBool.Request(data=False)).success
    client.pause(False)

    states, meta, topics = read_states(path)
    steps_taken = int(round((t_end - t_start) / dt))
    assert ns(states[0]) == int(round(t_start * 1e9))   # the state when recording started
    assert ns(states[-1]) == int(round(t_end * 1e9))    # the last step before the stop
    assert len(states) == steps_taken + 1                # it, then every step after it
    assert all(ns(b) - ns(a) == dt_ns for a, b in zip(states, states[1:]))
    assert steps_taken > 200 and '/clock' in topics and STATE in topics
    assert states[-1].grip_force > 0.5 and states[-1].gap < states[0].gap
    assert all(s.node_count == PHYSICS['fruit.nodes'] for s in states)

    # the configuration record: every key, the start-up overrides included
    assert meta['source'] == 'node'
    config_file = tmp_path / 'recorded.yaml'
    config_file.write_text(meta['yaml'])
    recorded = configuration.load_config(config_file=config_file)
    expected = configuration.load_config(overrides=PHYSICS)
    assert set(recorded) == set(configuration.SCHEMA)
    assert recorded == expected

    # ... and reproduces the run: the same command at the same step, the same states
    # (t = 0 is the reset state, the file starts at t_start; the gap command took
    # effect on the first step whose gap moved)
    first_step = int(round(t_start / dt))
    moved = next(i for i, s in enumerate(states) if s.gap != states[0].gap)
    sim = Simulation(recorded)
    for _ in range(first_step + moved - 1):
        sim.step()
    assert sim.last.gap == states[0].gap
    sim.command_gap(0.058)
    replayed = [sim.step() for _ in range(len(states) - moved)]
    for result, state in zip(replayed, states[moved:]):
        assert int(round(result.time * 1e9)) == ns(state)
        assert result.gap == pytest.approx(state.gap, rel=1e-12, abs=1e-15)
        assert result.grip_force == pytest.approx(state.grip_force, rel=1e-9, abs=1e-12)
        assert result.deformation.compression == pytest.approx(state.compression, rel=1e-9,
                                                               abs=1e-15)


def test_record_path_parameter_starts_and_stops_and_bad_paths_are_refused(node, tmp_path):
    process, client, record, get_params, workdir = node
    since = len(client.logs)
    taken = tmp_path / 'taken.mcap'
    taken.write_bytes(b'keep me')
    for bad, why in ((tmp_path / 'no_such_dir' / 'run.mcap', 'does not exist'),
                     (taken, 'already exists'), (Path('/proc/run.mcap'), 'cannot create'),
                     (tmp_path, 'existing directory')):
        result, = client.set_parameters(record_path=str(bad))
        assert not result.successful and why in result.reason, (bad, result.reason)
        assert record_path_param(client, get_params) == ''
    assert taken.read_bytes() == b'keep me'
    client.wait_log('record_path', since=since)           # the reason is logged too
    client.wait_sim_time(0.05)                             # still stepping
    assert process.running

    out = tmp_path / 'by_param.mcap'
    ok, = client.set_parameters(record_path=str(out))
    assert ok.successful, ok.reason
    assert record_path_param(client, get_params) == str(out)
    client.wait_sim_time(0.1)
    # switching to a bad file keeps recording to the good one
    refused, = client.set_parameters(record_path=str(taken))
    assert not refused.successful
    assert record_path_param(client, get_params) == str(out)
    client.wait_sim_time(0.05)
    ok, = client.set_parameters(record_path='')
    assert ok.successful
    states, meta, _ = read_states(out)
    assert len(states) > 100 and meta['source'] == 'node'
    assert all(ns(b) - ns(a) == 1_000_000 for a, b in zip(states, states[1:]))
    # ~/record true now starts to record_path when it is set
    second = tmp_path / 'second.mcap'
    assert client.set_parameters(record_path=str(second))[0].successful
    stopped = client.call(record, SetBool.Request(data=False))
    assert stopped.success and str(second) in stopped.message
    assert client.set_parameters(record_path=str(tmp_path / 'third'))[0].successful
    assert record_path_param(client, get_params) == str(tmp_path / 'third')
    assert client.call(record, SetBool.Request(data=False)).success
    # a name without .mcap is a bag folder of that name, as ros2 bag record -o writes
    assert sorted(p.name for p in (tmp_path / 'third').iterdir()) == ['metadata.yaml',
                                                                       'third_0.mcap']
    assert not (tmp_path / 'third.mcap').exists()


def test_record_path_at_start_up_records_until_the_node_stops(tmp_path):
    out = tmp_path / 'startup.mcap'
    domain = pick_domain_id(41)
    process = node_process({'real_time_factor': 0.0, 'record_path': str(out)},
                           env=ros_environment(domain), log_path=tmp_path / 'node.log')
    with process:
        assert process.wait_for_log('recording every step to', timeout=TIMEOUT), process.log()
        assert out.is_file()
        client = SimClient(domain, name='innode_startup_client')
        try:
            client.wait_ready(timeout=TIMEOUT)
            client.wait_sim_time(0.1)
        finally:
            client.close()
        assert process.stop() == 0, process.log()
    text = process.log()
    assert 'Traceback' not in text and 'recording stopped: wrote' in text, text
    states, meta, _ = read_states(out)           # finished by the node on shutdown
    assert ns(states[0]) == 0 and len(states) > 100
    assert all(ns(b) - ns(a) == 1_000_000 for a, b in zip(states, states[1:]))
    assert meta['source'] == 'node'


def test_a_bad_record_path_at_start_up_is_refused_and_the_node_runs(tmp_path):
    taken = tmp_path / 'taken.mcap'
    taken.write_bytes(b'keep me')
    domain = pick_domain_id(43)
    process = node_process({'real_time_factor': 0.0, 'record_path': str(taken)},
                           env=ros_environment(domain), log_path=tmp_path / 'node.log')
    with process:
        assert process.wait_for_log('ready', timeout=TIMEOUT), process.log()
        client = SimClient(domain, name='innode_bad_startup_client')
        try:
            client.wait_ready(timeout=TIMEOUT)
            client.wait_sim_time(0.05)
        finally:
            client.close()
        assert process.stop() == 0, process.log()
    text = process.log()
    assert 'already exists' in text and 'running without recording' in text, text
    assert 'Traceback' not in text
    assert taken.read_bytes() == b'keep me'
