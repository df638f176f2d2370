"""The ROS verbs of ``gripper-sim`` against a node in a subprocess."""
import re
import signal
import subprocess
import sys
import time

import pytest

from gripper_sim.ros.process import node_process, pick_domain_id, ros_environment
from ros_client import SimClient

pytestmark = [pytest.mark.ros, pytest.mark.slow]

DOMAIN = pick_domain_id(40)
ENV = ros_environment(DOMAIN)


def cli(*args, timeout=180, env=ENV):
    return subprocess.run([sys.executable, '-m', 'gripper_sim.cli.main', *args], env=env,
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope='module')
def running(tmp_path_factory):
    log = tmp_path_factory.mktemp('cli') / 'node.log'
    process = node_process({'real_time_factor': 0.0}, env=ENV, log_path=log).start()
    client = SimClient(DOMAIN, name='cli_test_client')
    try:
        client.wait_ready(timeout=120)
        yield process, client
    finally:
        client.close()
        assert process.stop() == 0, process.log()


@pytest.fixture
def client(running, restarted):
    return restarted(running)


def test_jaw_gap_is_delivered_and_acted_on(client):
    run = cli('jaw', 'gap', '0.06')
    assert run.returncode == 0, run.stderr
    assert 'delivered to /gripper_sim/jaw/gap_command' in run.stdout
    assert 'gap now' in run.stdout
    client.spin_until(lambda: client.latest['fruit/state'].gap < 0.0605, 60, 'the jaws')


def test_jaw_force_open_and_lift(client):
    run = cli('jaw', 'force', '4')
    assert run.returncode == 0, run.stderr
    client.spin_until(lambda: abs(client.latest['fruit/state'].grip_force - 4.0) < 0.1, 60,
                      'a 4 N grip')
    run = cli('lift', '0.05')
    assert run.returncode == 0, run.stderr
    client.spin_until(lambda: client.latest['joint_states'].position[2] > 0.049, 60, 'lift')
    run = cli('jaw', 'open')
    assert run.returncode == 0 and 'opening' in run.stdout, run.stderr
    client.spin_until(lambda: client.latest['fruit/state'].gap > 0.0734, 60, 'open jaws')


@pytest.mark.parametrize('args, message', [
    (('jaw', 'gap', 'nan'), 'gap must be finite'),
    (('jaw', 'gap', '-0.01'), 'gap must be >= 0'),
    (('jaw', 'force', '-2'), 'force must be > 0'),
    (('grasp', '--force', 'inf'), '--force must be finite'),
    (('lift', 'abc'), 'height must be a number'),
])
def test_bad_arguments_are_refused_before_sending(args, message):
    run = cli(*args)
    assert run.returncode == 2
    assert message in run.stderr and 'Traceback' not in run.stderr


def test_a_command_the_node_rejects_fails_with_its_reason(client):
    run = cli('jaw', 'gap', '5')
    assert run.returncode == 1
    assert 'the node rejected it' in run.stderr and 'out of range' in run.stderr


def test_jaw_commands_are_accepted_or_rejected_while_paused(client):
    client.pause(True)
    try:
        run = cli('jaw', 'gap', '0.06')
        assert run.returncode == 0, run.stderr
        assert 'accepted; no new state' in run.stdout
        # out of the core's range: refused by the simulation itself, while paused
        run = cli('jaw', 'gap', '5')
        assert run.returncode == 1
        assert 'the node rejected it' in run.stderr and 'out of range' in run.stderr
        # the accepted command acts at the next step
        assert client.step(50).success
        client.spin_until(lambda: client.latest['fruit/state'].gap < 0.0735 - 1e-4, 60,
                          'the jaws to move on the next steps')
    finally:
        client.pause(False)


def test_grasp_prints_feedback_and_succeeds(client):
    run = cli('grasp', '--force', '8', '--lift', '0.01', '--hold', '0.2')
    assert run.returncode == 0, run.stdout + run.stderr
    assert 'closing' in run.stdout and 'lifting' in run.stdout
    assert 'result: SUCCESS' in run.stdout


def test_grasp_and_place_prints_the_outcome(client):
    run = cli('grasp', '--force', '5', '--place', '--transport', '0.04', '--retreat')
    assert run.returncode == 0, run.stdout + run.stderr
    for phase in ('transporting', 'lowering', 'opening', 'retreating'):
        assert phase in run.stdout
    assert 'result: SUCCESS (placed)' in run.stdout
    assert 'transport 0.04 m, retreat 0.02 m' in run.stdout


def test_place_options_need_place_and_the_node_refuses_contradictions(client):
    run = cli('grasp', '--force', '5', '--transport', '0.04')
    assert run.returncode == 2 and 'need --place' in run.stderr
    run = cli('grasp', '--force', '5', '--place', '--hold', '1')
    assert run.returncode == 1
    assert 'goal rejected' in run.stderr and 'hold_time is not used' in run.stderr


def test_weak_grasp_exits_1(client):
    run = cli('grasp', '--force', '0.4', '--lift', '0.03', '--hold', '0.2', '--quiet')
    assert run.returncode == 1, run.stdout + run.stderr
    assert 'result: FAILED' in run.stdout and 'slipped True' in run.stdout


def test_ctrl_c_cancels_the_grasp(client, running):
    process = subprocess.Popen(
        [sys.executable, '-m', 'gripper_sim.cli.main', 'grasp', '--force', '6', '--lift',
         '0.01', '--hold', '3000'], env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True)
    try:
        lines = []
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = process.stdout.readline()
            lines.append(line)
            if 'holding' in line or not line:
                break
        assert any('holding' in line for line in lines), ''.join(lines)
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, out + err
    assert 'canceling the goal' in out, out
    assert 'Traceback' not in err and 'KeyboardInterrupt' not in err, err
    # the node canceled it (the CLI prints the result if it came within its second)
    node_process, _ = running
    assert node_process.wait_for_log('Grasp goal canceled during holding', 60), \
        node_process.log()[-3000:]


def test_step_waits_for_its_answer_however_long_the_steps_take(client):
    """``--timeout`` bounds finding the node; the steps' answer is awaited: here the
    ~/pause that ends a million steps, well after the 2 s timeout."""
    client.pause(True)
    process = subprocess.Popen(
        [sys.executable, '-m', 'gripper_sim.cli.main', 'step', '1000000', '--timeout', '2'],
        env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        start = client.sim_time()
        client.spin_until(lambda: client.sim_time() > start, 120, 'the steps to start')
        later = time.monotonic() + 4.0
        client.spin_until(lambda: time.monotonic() > later, 10, 'the timeout to pass')
        assert process.poll() is None, process.communicate()
        client.pause(True)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 1, out + err
    assert 'stopped after' in err and 'Traceback' not in err, err


def test_status_prints_the_fruit_state(client):
    run = cli('status')
    assert run.returncode == 0, run.stderr
    assert 'gap' in run.stdout and 'grip' in run.stdout and 'mm' in run.stdout


def test_no_node_fails_clearly():
    env = ros_environment(pick_domain_id(41))
    run = cli('status', '--timeout', '2', env=env)
    assert run.returncode == 1
    assert 'no FruitState' in run.stderr and 'ROS_DOMAIN_ID' in run.stderr


def test_node_verb_refuses_an_unknown_fruit():
    run = cli('node', '--fruit', 'durian', env=ros_environment(pick_domain_id(42)))
    assert run.returncode == 2
    assert "unknown fruit 'durian'" in run.stdout + run.stderr
    assert 'Traceback' not in run.stderr


#: a node whose construction gets a SIGINT before its kernels' warm-up (while it reads
#: its parameters), then takes a moment there: the signal must stop it at once
INTERRUPTED_START = """
import os, signal, sys, time
from gripper_sim.ros import node
real = node.SimParameters
def interrupted(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(20)
    return real(*args, **kwargs)
node.SimParameters = interrupted
sys.exit(node.main(['sim_node', '--ros-args', '-p', 'foxglove_port:=0',
                    '-p', 'record_path:=' + sys.argv[1]]))
"""


def _interrupted_start(script: str, domain_offset: int, *args: str) -> str:
    """Run a node start-up ``script`` (``python -c``, with ``args``) that a SIGINT stops:
    its output, after checking it exited 0 (a clean stop) without a traceback and
    before it was ready."""
    run = subprocess.run([sys.executable, '-c', script, *args],
                         env=ros_environment(pick_domain_id(domain_offset)),
                         capture_output=True, text=True, timeout=120)
    log = run.stdout + run.stderr
    assert run.returncode == 0, log
    assert 'ready' not in log and 'Traceback' not in log, log
    return log


def test_ctrl_c_while_the_node_starts_stops_it_at_once(tmp_path):
    bag = tmp_path / 'bag'
    log = _interrupted_start(INTERRUPTED_START, 43, str(bag))
    assert 'warming up' not in log, log
    assert not bag.exists()


#: the same, the signal arriving in an extension module's import, which turns the
#: KeyboardInterrupt into its own ImportError (pymetis' pybind11 init did, in CI)
INTERRUPTED_IMPORT = """
import os, signal, sys, time
from gripper_sim.ros import node
real = node.SimParameters
def interrupted(*args, **kwargs):
    try:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(20)
    except KeyboardInterrupt as interrupt:
        raise ImportError('initialization failed') from interrupt
    return real(*args, **kwargs)
node.SimParameters = interrupted
sys.exit(node.main(['sim_node', '--ros-args', '-p', 'foxglove_port:=0']))
"""


def test_ctrl_c_that_an_import_turns_into_its_own_error_still_stops_the_node_cleanly():
    _interrupted_start(INTERRUPTED_IMPORT, 44)


#: the same, the signal arriving while a module is imported (``importlib``'s frames on the
#: stack, as in numba's cache loading, whose ctypes callbacks of LLVM a KeyboardInterrupt
#: left broken: a segmentation fault in CI): the import runs to its end, then the node stops
INTERRUPTED_IN_IMPORT = """
import os, signal, sys, time
sys.path.insert(0, sys.argv[1])
from gripper_sim.ros import node
real = node.SimParameters
def interrupted(*args, **kwargs):
    import slow_to_import
    time.sleep(20)
    return real(*args, **kwargs)
node.SimParameters = interrupted
sys.exit(node.main(['sim_node', '--ros-args', '-p', 'foxglove_port:=0']))
"""

SLOW_TO_IMPORT = """
import os, pathlib, signal, sys, time
os.kill(os.getpid(), signal.SIGINT)
time.sleep(1.0)
pathlib.Path(sys.argv[1], 'imported').write_text('whole')
"""


def test_ctrl_c_in_an_import_stops_the_node_once_the_import_is_done(tmp_path):
    (tmp_path / 'slow_to_import.py').write_text(SLOW_TO_IMPORT)
    _interrupted_start(INTERRUPTED_IN_IMPORT, 45, str(tmp_path))
    assert (tmp_path / 'imported').read_text() == 'whole'   # not cut short


#: the same, the signal arriving in numba's loading of a cached kernel, inside the Python
#: that LLVM's object cache calls back through ctypes (where CI's segfault came)
INTERRUPTED_IN_CACHE_LOAD = """
import os, signal, sys, time
from llvmlite.binding.executionengine import ExecutionEngine
from gripper_sim.ros import node
real = ExecutionEngine._find_module_ptr
calls = []
def find_module_ptr(self, module_ptr):
    if node.STARTING.is_set() and not calls:
        calls.append(1)
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
    return real(self, module_ptr)
ExecutionEngine._find_module_ptr = find_module_ptr
code = node.main(['sim_node', '--ros-args', '-p', 'foxglove_port:=0'])
print('interrupted in a cache load:', bool(calls))
sys.exit(code)
"""


def test_ctrl_c_in_a_kernels_cache_load_stops_the_node_cleanly():
    log = _interrupted_start(INTERRUPTED_IN_CACHE_LOAD, 46)
    assert 'interrupted in a cache load: True' in log, log
    assert 'Exception ignored' not in log, log


def test_status_follow_prints_lines_until_ctrl_c(client):
    process = subprocess.Popen(
        [sys.executable, '-m', 'gripper_sim.cli.main', 'status', '--follow', '--rate', '5'],
        env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        lines = [process.stdout.readline() for _ in range(3)]
        assert all('gap' in line for line in lines), lines
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 0 and 'Traceback' not in err, err


def test_grasp_prints_feedback_that_comes_in_a_burst_with_the_result():
    """A server that publishes its last phases' feedback in one burst right before the
    result (a loaded machine): every phase is printed (rclpy's own client dropped what
    was unread when the result came)."""
    import threading

    import rclpy
    from rclpy.action import ActionServer
    from rclpy.callback_groups import ReentrantCallbackGroup
    from rclpy.executors import MultiThreadedExecutor
    from gripper_sim_interfaces.action import Grasp

    phases = ('closing', 'lifting', 'holding', 'releasing', 'opening')
    domain = pick_domain_id(41)
    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node('burst_grasp_server', context=context)

    def execute(goal_handle):
        time.sleep(0.5)   # the client has asked for the result by now
        for phase in phases:
            goal_handle.publish_feedback(Grasp.Feedback(phase=phase, gap=0.05))
        goal_handle.succeed()
        return Grasp.Result(success=True, outcome='held', message='burst', dropped_at=-1.0)

    server = ActionServer(node, Grasp, '/burst/grasp', execute,
                          callback_group=ReentrantCallbackGroup())
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    spinning = threading.Thread(target=executor.spin, daemon=True)
    spinning.start()
    try:
        for _ in range(3):
            run = cli('grasp', '--force', '3', '--node', '/burst', '--timeout', '60',
                      env=ros_environment(domain), timeout=120)
            assert run.returncode == 0, run.stdout + run.stderr
            printed = re.findall(r'^  (\S+) +gap ', run.stdout, re.MULTILINE)
            assert printed == list(phases), run.stdout
            assert run.stdout.index('opening') < run.stdout.index('result: SUCCESS')
    finally:
        server.destroy()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        spinning.join(timeout=10)


def test_reset_pause_step_resume_without_a_ros2_command_line(client):
    """The node's services from ``gripper-sim`` (a venv has no ``ros2`` command)."""
    run = cli('pause')
    assert run.returncode == 0, run.stderr
    run = cli('step', '25')
    assert run.returncode == 0, run.stderr
    assert 'sim time' in run.stdout
    stepped = float(re.search(r'sim time ([0-9.e+-]+) s', run.stdout).group(1))
    run = cli('step', '25')
    assert run.returncode == 0, run.stderr
    assert float(re.search(r'sim time ([0-9.e+-]+) s', run.stdout).group(1)) == \
        pytest.approx(stepped + 25 * 0.001, abs=1e-9)
    run = cli('resume')
    assert run.returncode == 0, run.stderr
    run = cli('step', '5')   # refused unless paused: the node's reason, exit 1
    assert run.returncode == 1 and 'pause it first' in run.stderr, run.stderr
    run = cli('jaw', 'gap', '0.05')
    assert run.returncode == 0, run.stderr
    client.spin_until(lambda: client.latest['fruit/state'].gap < 0.0735 - 1e-3, 60,
                      'the jaws to close')
    run = cli('reset')
    assert run.returncode == 0, run.stderr
    client.spin_until(lambda: client.latest['fruit/state'].gap > 0.0735 - 1e-6, 60,
                      'the reset gap')


@pytest.mark.parametrize('args, message', [
    (('step', '0'), 'steps must be 1 to 1000000'),
    (('step', '2.5'), 'steps must be a whole number'),
    (('record-node', 'begin'), "invalid choice: 'begin'"),
])
def test_bad_service_arguments_are_refused_before_sending(args, message):
    run = cli(*args)
    assert run.returncode == 2
    assert message in run.stderr and 'Traceback' not in run.stderr


def test_record_node_starts_and_stops_the_in_node_recording(client, tmp_path):
    run = cli('record-node', 'start')
    assert run.returncode == 0, run.stderr
    assert 'recording every step to' in run.stdout
    path = run.stdout.split('recording every step to ', 1)[1].split()[0].rstrip('.,;')
    run = cli('record-node', 'start')   # refused while recording
    assert run.returncode == 1 and 'already recording' in run.stderr
    run = cli('record-node', 'stop')
    assert run.returncode == 0, run.stderr
    run = cli('info', path)
    assert run.returncode == 0, run.stderr
    assert '/gripper_sim/fruit/state' in run.stdout
    run = cli('record-node', 'stop')
    assert run.returncode == 1 and 'not recording' in run.stderr
    import shutil
    shutil.rmtree(path, ignore_errors=True)
