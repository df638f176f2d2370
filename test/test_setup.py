"""The set-up itself: the venv's ROS, the interface package, the packaging, the ROS env."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from gripper_sim.ros.process import domain_in_use

ROOT = Path(__file__).resolve().parent.parent
IFACE = ROOT / 'interfaces' / 'gripper_sim_interfaces'
INTERFACE_FILES = ('msg/FruitState.msg', 'action/Grasp.action', 'srv/Step.srv')


def prefix() -> Path:
    return Path(os.environ['AMENT_PREFIX_PATH'].split(os.pathsep)[0])


def test_ros_environment_is_loopback_only():
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    assert os.environ['RMW_IMPLEMENTATION'] == 'rmw_fastrtps_cpp'
    assert 1 <= int(os.environ['ROS_DOMAIN_ID']) <= 101
    assert 'ROS_STATIC_PEERS' not in os.environ
    profile = ET.parse(os.environ['FASTRTPS_DEFAULT_PROFILES_FILE']).getroot()
    ns = {'f': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    announcements = profile.find('.//f:initialAnnouncements', ns)
    assert announcements.find('f:count', ns).text == '30'
    assert announcements.find('f:period/f:nanosec', ns).text == '100000000'
    addresses = [a.text for a in profile.findall('.//f:interfaceWhiteList/f:address', ns)]
    assert addresses == ['127.0.0.1']


def test_rclpy_imports_and_creates_a_node():
    import rclpy
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('gripper_sim_setup_check', context=context)
        assert node.get_name() == 'gripper_sim_setup_check'
        # the probe the domain picking relies on sees this participant's ports (the
        # domain the context really uses; other participants may hold the low indexes)
        domain = context.get_domain_id()
        deadline = time.monotonic() + 5.0
        while not domain_in_use(domain, participants=32) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert domain_in_use(domain, participants=32), domain
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_numpy_scipy_import_beside_rclpy():
    import numpy
    import rclpy  # noqa: F401
    import scipy.sparse
    assert scipy.sparse.eye(3).dot(numpy.ones(3)).sum() == 3.0


def test_fruit_state_round_trip():
    from gripper_sim_interfaces.msg import FruitState
    from rclpy.serialization import deserialize_message, serialize_message
    msg = FruitState(dimension=2, node_count=64, compression=0.0012, grip_force=7.5,
                     gap=0.061, left_jaw_contact=True, bruised=True, bruised_fraction=0.25)
    msg.header.frame_id = 'world'
    msg.header.stamp.sec = 12
    msg.header.stamp.nanosec = 345
    msg.centroid.z = 0.04
    data = serialize_message(msg)
    back = deserialize_message(data, FruitState)
    assert back == msg
    assert back.header.frame_id == 'world' and back.centroid.z == 0.04


def test_grasp_goal_and_gripper_command_round_trip():
    from control_msgs.action import GripperCommand
    from gripper_sim_interfaces.action import Grasp
    from rclpy.serialization import deserialize_message, serialize_message
    goal = Grasp.Goal(target_force=8.0, close_speed=0.01, lift_height=0.03, hold_time=1.0,
                      release=True)
    assert deserialize_message(serialize_message(goal), Grasp.Goal) == goal
    result = Grasp.Result(success=True, message='held', max_grip_force=8.1)
    assert deserialize_message(serialize_message(result), Grasp.Result) == result
    command = GripperCommand.Goal()
    command.command.position = 0.05
    command.command.max_effort = 10.0
    assert deserialize_message(serialize_message(command), GripperCommand.Goal) == command


def test_step_request_round_trip():
    from gripper_sim_interfaces.srv import Step
    from rclpy.serialization import deserialize_message, serialize_message
    request = Step.Request(steps=250)
    assert deserialize_message(serialize_message(request), Step.Request) == request
    response = Step.Response(success=True, message='ok', sim_time=0.25)
    assert deserialize_message(serialize_message(response), Step.Response) == response


@pytest.mark.parametrize('name', INTERFACE_FILES)
def test_interface_files_installed(name):
    installed = prefix() / 'share' / 'gripper_sim_interfaces' / name
    assert installed.is_file(), f'{installed} missing: run make interfaces'
    assert installed.read_text() == (IFACE / name).read_text(), \
        f'{installed} is older than the source: run make interfaces'


def test_ament_index_finds_both_packages():
    from ament_index_python.packages import get_package_share_directory
    share = Path(get_package_share_directory('gripper_sim'))
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'fruits').is_dir()
    assert (share / 'config' / 'fastdds_localhost.xml').is_file()
    iface_share = Path(get_package_share_directory('gripper_sim_interfaces'))
    assert (iface_share / 'msg' / 'FruitState.msg').is_file()


def test_console_script_help():
    script = shutil.which('gripper-sim')
    assert script, 'gripper-sim is not on PATH (source scripts/env.sh, or make venv)'
    done = subprocess.run([script, '--help'], capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr
    assert 'usage: gripper-sim' in done.stdout


def test_package_manifests_parse():
    from catkin_pkg.package import parse_package
    package = parse_package(str(ROOT))
    assert package.name == 'gripper_sim' and package.package_format == 3
    assert package.get_build_type() == 'ament_python'
    assert {'rclpy', 'gripper_sim_interfaces', 'python3-numpy', 'python3-scipy'} <= {
        d.name for d in package.exec_depends}
    iface = parse_package(str(IFACE))
    assert iface.get_build_type() == 'ament_cmake'
    assert 'rosidl_interface_packages' in [g.name for g in iface.member_of_groups]
    assert {'ament_cmake', 'rosidl_default_generators'} <= {
        d.name for d in iface.buildtool_depends}


def test_setup_py_installs_the_colcon_layout(tmp_path):
    """What colcon's ament_python build does: setup.py install into a prefix."""
    source = tmp_path / 'src'
    source.mkdir()
    for name in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy(ROOT / name, source / name)
    for name in ('resource', 'config', 'gripper_sim'):
        shutil.copytree(ROOT / name, source / name,
                        ignore=shutil.ignore_patterns('__pycache__'))
    install = tmp_path / 'install'
    done = subprocess.run(
        [sys.executable, 'setup.py', '-q', 'egg_info', '--egg-base', str(tmp_path),
         'build', '--build-base', str(tmp_path / 'build'),
         'install', '--prefix', str(install), '--single-version-externally-managed',
         '--record', str(tmp_path / 'record.txt')],
        cwd=source, capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr
    for script in ('gripper-sim', 'sim_node', 'controller'):
        assert (install / 'lib' / 'gripper_sim' / script).is_file(), script
    share = install / 'share'
    assert (share / 'ament_index' / 'resource_index' / 'packages' / 'gripper_sim').is_file()
    assert (share / 'gripper_sim' / 'package.xml').is_file()
    assert (share / 'gripper_sim' / 'config' / 'fastdds_localhost.xml').is_file()
    presets = sorted(p.name for p in (ROOT / 'config' / 'fruits').glob('*.yaml'))
    assert presets and presets == sorted(
        p.name for p in (share / 'gripper_sim' / 'config' / 'fruits').glob('*.yaml'))
    site = next(install.glob('lib/python3*/site-packages'))
    assert (site / 'gripper_sim' / 'cli' / 'main.py').is_file()
    assert not (site / 'test').exists()


def test_make_targets_are_up_to_date():
    """After `make install` a second run has nothing to do (no reinstall)."""
    if Path(sys.prefix).resolve() != (ROOT / '.venv').resolve():
        pytest.fail(f'tests must run in the Makefile venv ({ROOT / ".venv"}), '
                    f'not {sys.prefix}: use make test')
    done = subprocess.run(['make', '-q', 'install'], cwd=ROOT, capture_output=True, text=True,
                          timeout=60, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, 'make install would do work again: ' + done.stdout


PUBLISHER = textwrap.dedent('''
    import sys
    import rclpy
    from gripper_sim_interfaces.msg import FruitState
    rclpy.init()
    node = rclpy.create_node('setup_check_publisher')
    pub = node.create_publisher(FruitState, 'setup_check_state', 10)
    while rclpy.ok() and sys.stdin.readline():  # one message per line the test writes
        pub.publish(FruitState(node_count=64, grip_force=4.5))
    node.destroy_node()
    rclpy.try_shutdown()
''')


@pytest.mark.ros
def test_two_processes_talk_on_loopback(ros_env):
    """A publisher in a subprocess (the ros_env fixture) reaches this process."""
    import rclpy
    from gripper_sim_interfaces.msg import FruitState
    from rclpy.executors import SingleThreadedExecutor
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('setup_check_subscriber', context=context)
    received = []
    node.create_subscription(FruitState, 'setup_check_state', received.append, 10)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    publisher = subprocess.Popen([sys.executable, '-c', PUBLISHER], env=ros_env,
                                 stdin=subprocess.PIPE, text=True)
    try:
        start = time.monotonic()
        while not node.count_publishers('setup_check_state'):
            assert time.monotonic() - start < 60, 'the publisher was never discovered'
            assert publisher.poll() is None, 'the publisher process died'
            executor.spin_once(timeout_sec=0.05)
        matched = time.monotonic() - start
        while not received:
            assert time.monotonic() - start < 60, 'no message arrived'
            publisher.stdin.write('\n')
            publisher.stdin.flush()
            executor.spin_once(timeout_sec=0.1)
        assert received[0].grip_force == 4.5 and received[0].node_count == 64
        print(f'publisher matched {matched:.2f} s after its start')
    finally:
        publisher.stdin.close()
        publisher.wait(timeout=30)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    assert publisher.returncode == 0


def test_new_domain_ids_are_distinct_and_unused(new_domain_id):
    ids = [new_domain_id() for _ in range(3)]
    assert len(set(ids + [int(os.environ['ROS_DOMAIN_ID'])])) == 4
    assert all(1 <= i <= 101 and not domain_in_use(i) for i in ids)


def _free_domain_id_in_new_process(first: int, hold: bool) -> subprocess.Popen:
    """A process that prints ``free_domain_id`` searched from domain ``first`` and, with
    ``hold``, keeps running until its standard input closes."""
    code = ('import sys; from gripper_sim.ros.process import free_domain_id; '
            'print(free_domain_id(int(sys.argv[1])), flush=True)'
            + ('; sys.stdin.read()' if hold else ''))
    return subprocess.Popen([sys.executable, '-c', code, str(first - 1)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True,
                            env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_a_domain_another_run_picked_is_not_picked_again():
    """Two runs of ours at once (a test session beside the demo or another session) must
    not share a domain: between a pick and its node's first port the domain looks free."""
    holder = _free_domain_id_in_new_process(os.getpid() % 101 + 1, hold=True)
    try:
        taken = int(holder.stdout.readline())
        assert not domain_in_use(taken)  # no node holds it: only the claim keeps it
        second = _free_domain_id_in_new_process(taken, hold=False)
        picked, _ = second.communicate(timeout=60)
        assert second.returncode == 0 and int(picked) != taken
    finally:
        holder.stdin.close()
        holder.wait(timeout=30)
    assert holder.returncode == 0
    again = _free_domain_id_in_new_process(taken, hold=False)
    assert int(again.communicate(timeout=60)[0]) == taken  # the claim ends with its process


def test_a_session_that_handed_out_every_domain_recycles_the_oldest_free_one(tmp_path,
                                                                           monkeypatch):
    """A test session hands out about as many domains as there are: it keeps claims on
    its last ``KEPT_CLAIMS`` only, and once it has handed out every domain it takes
    again the one it handed out longest ago (free, unclaimed), never a reserved one."""
    from gripper_sim.ros import process
    monkeypatch.setattr(process, '_handed_out', {})
    monkeypatch.setattr(process, '_reserved', {7})
    monkeypatch.setattr(process, '_claims', {})
    monkeypatch.setattr(process, '_claims_folder', lambda: tmp_path)
    monkeypatch.setattr(process, 'domain_in_use', lambda domain, participants=4: False)
    try:
        first = [process.free_domain_id(1) for _ in range(100)]
        assert len(set(first)) == 100 and 7 not in first
        assert len(process._claims) == process.KEPT_CLAIMS
        recycled = [process.free_domain_id(1) for _ in range(3)]
        assert recycled == first[:3]   # the oldest, their claims long released
        assert 7 not in [process.free_domain_id(1) for _ in range(200)]
        assert len(process._claims) == process.KEPT_CLAIMS
    finally:
        for handle in process._claims.values():
            os.close(handle)
