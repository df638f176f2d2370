"""Studies on real Dask clusters: a scheduler and two workers started here on 127.0.0.1,
the local default, a worker killed mid-study, Ctrl-C and resume."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from gripper_sim.workflows.study_results import RowStore
from test_cli_offline import ROOT, gripper_sim

#: output columns that depend on the machine, not on the case
MACHINE_COLUMNS = ('cpu_time', 'worker')
#: a study small enough for a loaded machine: 2 design points x 3 fruits, short grasps
STUDY = '''
name: small
base:
  fruit: apple
  finger: flat
  scenario_set: {transport.distance: 0.0, lift.height: 0.02, squeeze.time: 0.05,
                 close.speed: 0.1}
  set: {sim.dt: 0.004}
axes:
  contact.jaw.static_friction: [0.5, 0.8]
population:
  samples: 3
  seed: 7
  distributions:
    fruit.shape.diameter: {distribution: normal, mean: 0.0635, std: 0.003}
    fruit.flesh.youngs_modulus: {distribution: lognormal, mean: 2.0e+6, std: 3.0e+5}
window: {tolerance: 0.1}
'''
#: runs the CLI with a row buffer of one row (a part file per finished row); with
#: STUDY_HOOK=interrupt it sends itself SIGINT (Ctrl-C), with STUDY_HOOK=terminate SIGTERM
#: (kill), when the STUDY_HOOK_ROWS-th row is stored; with STUDY_HOOK=pause it then writes STUDY_HOOK_FILE + '.paused' and waits
#: for STUDY_HOOK_FILE, so a test acts while the study is surely still running
CHILD = textwrap.dedent('''
    import os, signal, sys, time
    from pathlib import Path
    import gripper_sim.workflows.study_results as results
    from gripper_sim.cli.main import main
    results.FLUSH_ROWS = 1
    # Ctrl-C as in a terminal, even where this test runs as a background job (whose
    # children start with SIGINT ignored, so Python would not raise KeyboardInterrupt)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    action = os.environ.get('STUDY_HOOK', '')
    after = int(os.environ.get('STUDY_HOOK_ROWS', '0'))
    go = Path(os.environ.get('STUDY_HOOK_FILE', 'unused'))
    store_row = results.RowStore.add
    stored = []

    def store_then_act(self, row):
        store_row(self, row)
        stored.append(row)
        if len(stored) != after:
            return
        if action == 'interrupt':
            os.kill(os.getpid(), signal.SIGINT)
        elif action == 'terminate':
            os.kill(os.getpid(), signal.SIGTERM)
        elif action == 'pause':
            Path(str(go) + '.paused').touch()
            end = time.monotonic() + 300
            while not go.exists() and time.monotonic() < end:
                time.sleep(0.05)

    results.RowStore.add = store_then_act
    sys.exit(main(sys.argv[1:]))
''')


def env(**hook):
    values = dict(os.environ, **hook)
    values['PYTHONPATH'] = str(ROOT) + os.pathsep + values.get('PYTHONPATH', '')
    return values


def wait_for(condition, what, timeout=300.0):
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f'timed out waiting for {what}')
        time.sleep(0.05)


class DaskCluster:
    """A `dask scheduler` and `dask worker` processes (no nanny: a SIGKILL kills the
    worker itself) on 127.0.0.1 with free ports and no dashboard (the scheduler's HTTP
    server too: with --no-dashboard alone it listens on 0.0.0.0:8787)."""

    def __init__(self, directory: Path, workers: int = 2):
        self.file = directory / 'scheduler.json'
        self.scheduler = subprocess.Popen(
            [sys.executable, '-m', 'distributed.cli.dask_scheduler', '--host', '127.0.0.1',
             '--port', '0', '--no-dashboard', '--dashboard-address', '127.0.0.1:0',
             '--scheduler-file', str(self.file)],
            env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        wait_for(self.file.exists, 'the scheduler file')
        wait_for(lambda: self.file.stat().st_size > 0, 'the scheduler address')
        self.address = json.loads(self.file.read_text())['address']
        self.workers = [self.start_worker() for _ in range(workers)]
        self.wait_for_workers(workers)

    def start_worker(self) -> subprocess.Popen:
        return subprocess.Popen(
            [sys.executable, '-m', 'distributed.cli.dask_worker', self.address,
             '--nthreads', '1', '--no-nanny', '--host', '127.0.0.1', '--no-dashboard'],
            env=env(), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)

    def wait_for_workers(self, count: int) -> None:
        from distributed import Client
        with Client(self.address, timeout='60s') as client:
            client.wait_for_workers(count, timeout=300)

    def close(self) -> None:
        for process in self.workers + [self.scheduler]:
            if process.poll() is None:
                process.terminate()
        for process in self.workers + [self.scheduler]:
            try:
                process.wait(timeout=30)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()


@pytest.fixture(scope='module')
def study_file(tmp_path_factory):
    path = tmp_path_factory.mktemp('study') / 'small.yaml'
    path.write_text(textwrap.dedent(STUDY))
    return path


@pytest.fixture(scope='module')
def cluster(tmp_path_factory):
    started = DaskCluster(tmp_path_factory.mktemp('cluster'))
    yield started
    started.close()


@pytest.fixture(scope='module')
def reference(study_file, tmp_path_factory):
    """The study on the local default cluster: its rows by key."""
    out = tmp_path_factory.mktemp('local')
    run = gripper_sim('study', str(study_file), '--out', str(out), '--no-progress',
                      '--workers', '2', '--no-report')
    assert run.returncode == 0, run.stderr
    return out, comparable(out)


def comparable(out: Path) -> dict:
    rows = pq.read_table(out / 'rows').to_pylist()
    assert len({r['case_key'] for r in rows}) == len(rows)
    return {r['case_key']: {k: v for k, v in r.items() if k not in MACHINE_COLUMNS}
            for r in rows}


def test_a_study_on_an_existing_cluster_gives_the_local_rows(study_file, reference,
                                                            cluster, tmp_path):
    local_out, local = reference
    out = tmp_path / 'remote'
    run = gripper_sim('study', str(study_file), '--out', str(out), '--no-progress',
                      '--scheduler', cluster.address, '--csv')
    assert run.returncode == 0, run.stderr
    remote = comparable(out)
    assert remote == local
    workers = {r['worker'] for r in pq.read_table(out / 'rows').to_pylist()}
    assert workers == {p.pid for p in cluster.workers}  # both workers computed rows
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['computed'] == len(remote) and summary['reused'] == 0
    assert summary['points'] == json.loads((local_out / 'summary.json').read_text())['points']
    csv_lines = (out / 'rows.csv').read_text().splitlines()
    assert len(csv_lines) == len(remote) + 1
    for column in ('config_hash', 'sample', 'seed', 'package_version', 'code_version',
                   'contact.jaw.static_friction', 'fruit.shape.diameter', 'outcome',
                   'slip_distance', 'peak_grip_force', 'peak_compression',
                   'peak_jaw_pressure', 'peak_table_pressure', 'peak_damage_pressure',
                   'bruised_fraction',
                   'error'):
        assert column in csv_lines[0].split(',')
    # run again: nothing is computed, the table is unchanged
    again = gripper_sim('study', str(study_file), '--out', str(out), '--no-progress',
                        '--scheduler', cluster.address, '--no-report')
    assert again.returncode == 0, again.stderr
    assert json.loads((out / 'summary.json').read_text())['computed'] == 0
    assert comparable(out) == local


def test_a_worker_killed_mid_study_loses_no_row(study_file, reference, cluster, tmp_path):
    _, local = reference
    out = tmp_path / 'killed'
    go = tmp_path / 'go'
    study = subprocess.Popen(
        [sys.executable, '-c', CHILD, 'study', str(study_file), '--out', str(out),
         '--no-progress', '--scheduler', cluster.address, '--no-report'],
        env=env(STUDY_HOOK='pause', STUDY_HOOK_ROWS='2', STUDY_HOOK_FILE=str(go)),
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: (tmp_path / 'go.paused').exists() or study.poll() is not None,
             'two rows')
    assert study.poll() is None, study.communicate()[1]
    victim = cluster.workers[0]
    victim.send_signal(signal.SIGKILL)
    go.touch()
    stdout, stderr = study.communicate(timeout=600)
    assert study.returncode == 0, stderr
    assert victim.wait() == -signal.SIGKILL
    assert comparable(out) == local
    cluster.workers[0] = cluster.start_worker()  # two workers again for the next test
    cluster.wait_for_workers(2)


@pytest.mark.parametrize('hook, code, word', [('interrupt', 130, 'interrupted'),
                                               ('terminate', 143, 'terminated')])
def test_an_interrupted_study_resumes_without_recomputing(study_file, reference, cluster,
                                                         tmp_path, hook, code, word):
    """Ctrl-C, or SIGTERM as ``kill`` and batch systems send it, keeps every finished
    row (the row buffer flushed, not lost with the process) and says so."""
    _, local = reference
    out = tmp_path / 'interrupted'
    args = ['study', str(study_file), '--out', str(out), '--no-progress',
            '--scheduler', cluster.address, '--no-report']
    study = subprocess.Popen([sys.executable, '-c', CHILD, *args],
                             env=env(STUDY_HOOK=hook, STUDY_HOOK_ROWS='3'),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _, stderr = study.communicate(timeout=120)
    assert study.returncode == code, stderr
    assert f'{word}: ' in stderr and 'Traceback' not in stderr
    assert json.loads((out / 'summary.json').read_text())['complete'] is False
    kept = RowStore(out).rows
    assert 3 <= len(kept) < len(local)
    for key, row in kept.items():  # what was kept is finished and right
        assert {k: v for k, v in row.items() if k not in MACHINE_COLUMNS} == local[key]
    resumed = gripper_sim(*args)
    assert resumed.returncode == 0, resumed.stderr
    summary = json.loads((out / 'summary.json').read_text())
    assert summary['computed'] == len(local) - len(kept)
    assert summary['reused'] >= len(kept)
    assert comparable(out) == local


def test_an_unreachable_scheduler_is_a_clear_error(study_file, tmp_path):
    import socket
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    run = gripper_sim('study', str(study_file), '--out', str(tmp_path / 'out'),
                      '--scheduler', f'tcp://127.0.0.1:{port}', '--no-progress')
    assert run.returncode == 2
    assert run.stderr.startswith(f'error: cannot reach the Dask scheduler at '
                                 f'tcp://127.0.0.1:{port}')
    assert 'Traceback' not in run.stderr
