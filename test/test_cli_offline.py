"""The offline CLI as a user runs it: JSON outputs and clear errors on bad input."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def gripper_sim(*args, timeout=600):
    env = dict(os.environ)
    env['PYTHONPATH'] = str(ROOT) + os.pathsep + env.get('PYTHONPATH', '')
    return subprocess.run([sys.executable, '-m', 'gripper_sim.cli.main', *args],
                          capture_output=True, text=True, timeout=timeout, env=env,
                          stdin=subprocess.DEVNULL)


def test_squeeze_json_reports_series_and_summary():
    run = gripper_sim('squeeze', '--to-force', '4', '--speed', '0.01', '--json')
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    n = len(data['time'])
    assert n > 10 and len(data['gap']) == n and len(data['force']) == n
    assert data['force'][-1] >= 4.0
    assert all(b < a for a, b in zip(data['gap'], data['gap'][1:]))
    summary = data['summary']
    assert summary['peak_grip_force'] == pytest.approx(max(data['force']))
    assert 0 < summary['peak_compression'] < 0.01
    assert summary['peak_jaw_pressure'] > 0


def test_squeeze_to_gap_stops_at_the_gap():
    run = gripper_sim('squeeze', '--to-gap', '0.062', '--speed', '0.01', '--json')
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data['gap'][-1] == pytest.approx(0.062, abs=1e-6)
    assert data['force'][-1] > 0


@pytest.mark.parametrize('dimension', [2, 3])
def test_squeeze_with_solid_pads_stops_at_the_force(dimension):
    """The jaws close towards the smallest gap the pads allow (not 0) and stop at the
    force; in 3D the pads are the extruded block."""
    run = gripper_sim('squeeze', '--set', f'dimension={dimension}', '--set',
                      'gripper.finger.type=solid_pad', '--to-force', '2', '--json')
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data['force'][-1] >= 2.0
    assert data['gap'][-1] > 2 * 0.006  # two default pads


def test_pick_json_reports_outcome():
    run = gripper_sim('pick', '--force', '3', '--lift', '0.02', '--hold', '0.3', '--json')
    assert run.returncode == 0, run.stderr
    data = json.loads(run.stdout)
    assert data['outcome'] == 'held'
    assert 0 <= data['slip_distance'] < 1e-3
    assert max(data['force']) == pytest.approx(3.0, rel=0.05)


@pytest.mark.parametrize('args,message', [
    (['squeeze', '--fruit', 'banana', '--to-force', '5'], "unknown fruit 'banana'"),
    (['squeeze', '--set', 'fruit.nodez=30', '--to-force', '5'], "unknown config key"),
    (['squeeze', '--set', 'fruit.nodes=0', '--to-force', '5'], "'fruit.nodes'"),
    (['squeeze', '--to-force', '-3'], 'must be a finite number > 0'),
    (['squeeze', '--to-force', 'nan'], 'must be a finite number > 0'),
    (['pick', '--force', '-1'], 'must be a finite number > 0'),
    (['pick', '--force', 'inf'], 'must be a finite number > 0'),
    (['squeeze', '--set', 'sim.dt=abc', '--to-force', '5'], "'sim.dt'"),
    (['squeeze', '--config', '/nonexistent.yaml', '--to-force', '5'], 'cannot read'),
    (['window', '--workers', '0'], 'must be at least 1'),
    (['window', '--workers', '2.5'], 'is not an integer'),
])
def test_bad_input_gives_a_clear_error(args, message):
    run = gripper_sim(*args, timeout=120)
    assert run.returncode != 0
    assert message in run.stderr
    assert 'Traceback' not in run.stderr + run.stdout


def test_malformed_config_file_is_reported(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('fruit: {model: [unclosed\n')
    run = gripper_sim('squeeze', '--config', str(bad), '--to-force', '5', timeout=120)
    assert run.returncode != 0
    assert 'not valid YAML' in run.stderr
    assert 'Traceback' not in run.stderr


def test_force_grasp_closes_at_full_speed_while_one_jaw_pushes_the_fruit():
    """A grip of 0.15 N on the strawberry resting on the table: the first jaw to touch
    pushes the fruit along the table (a force of about mu m g that is no grip). The
    jaws keep closing at the commanded speed until the free jaw lands on the fruit
    (``GripperKinematics.advance``: at most its clearance per step), and the closing ends
    only with both jaws at the force (it used to end on the first jaw's impact, or
    crawl at (F - F_push) / (k tau) and time out)."""
    from gripper_sim.configuration import load_config
    from gripper_sim.workflows.grasp import CLOSING, GraspSequence, run_grasp
    from gripper_sim.workflows.scenario import grasp_height
    from gripper_sim.core.simulation import Simulation
    config = load_config(fruit='strawberry')
    config = load_config(fruit='strawberry',
                         overrides={'gripper.initial_lift': grasp_height(config)})
    sim = Simulation(config)
    target, speed = 0.15, config['gripper.close_speed']
    one_jaw_rates, transitions = [], []

    def watch(result, phase):
        left, right = result.in_contact_with('left_jaw'), result.in_contact_with('right_jaw')
        if phase == CLOSING and left != right:
            one_jaw_rates.append(sim.gripper_state.gap_rate)
        if phase != CLOSING and not transitions:
            transitions.append((left and right, result.grip_force, sim.time))

    sequence = GraspSequence(sim, target, lift_height=0.0, hold_time=0.0)
    summary = run_grasp(sim, sequence, on_step=watch, time_limit=5.0)
    assert summary['outcome'] == 'held'
    assert len(one_jaw_rates) > 10                       # the push did happen
    # full speed until the free jaw is within one step of the fruit, where it lands on it
    # instead of driving through its surface
    full = [rate for rate in one_jaw_rates if rate == pytest.approx(-speed, rel=1e-12)]
    assert len(full) >= len(one_jaw_rates) - 2
    assert all(-speed * (1 + 1e-9) <= rate < 0 for rate in one_jaw_rates), one_jaw_rates[-5:]
    both, force, t_reached = transitions[0]
    assert both and force >= 0.97 * target
    # closing took about the time to close the free gap at full speed
    free_gap = sim.initial_gap - sim.fruit.rest_width
    assert t_reached < 1.5 * free_gap / speed + 0.2


#: ``gripper-sim pick`` interrupted (SIGINT) while numba loads one of its kernels from
#: the cache, inside the Python that LLVM's object cache calls back through ctypes: a
#: KeyboardInterrupt raised there is swallowed by ctypes and LLVM goes on broken (the
#: node segfaulted so in CI); ``gripper_sim.interrupts`` raises it once out of there
PICK_INTERRUPTED_IN_CACHE_LOAD = """
import os, signal, sys, time
# as from a terminal: a shell's background job (CI's) starts with SIGINT ignored
signal.signal(signal.SIGINT, signal.default_int_handler)
from llvmlite.binding.executionengine import ExecutionEngine
from gripper_sim.cli import main
real = ExecutionEngine._find_module_ptr
calls = []
def find_module_ptr(self, module_ptr):
    if not calls:
        calls.append(1)
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.2)
    return real(self, module_ptr)
ExecutionEngine._find_module_ptr = find_module_ptr
code = main.main(['pick', '--force', '4'])
print('interrupted in a cache load:', bool(calls))
sys.exit(code)
"""


def test_ctrl_c_while_a_kernel_loads_from_the_cache_exits_130_cleanly():
    env = dict(os.environ)
    env['PYTHONPATH'] = str(ROOT) + os.pathsep + env.get('PYTHONPATH', '')
    run = subprocess.run([sys.executable, '-c', PICK_INTERRUPTED_IN_CACHE_LOAD],
                         capture_output=True, text=True, timeout=300, env=env,
                         stdin=subprocess.DEVNULL)
    log = run.stdout + run.stderr
    assert run.returncode == 130, log
    assert 'interrupted in a cache load: True' in log, log
    assert 'Traceback' not in log and 'Exception ignored' not in log, log
