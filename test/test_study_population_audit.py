"""Audit of `gripper-sim study` on bad populations and failed fruits: every fruit's
set-up is built before a cluster starts or a file is written, and a fruit whose task
failed is reported as such, never counted as a fruit without a window."""
from __future__ import annotations

import textwrap
from pathlib import Path

import yaml

from test_cli_offline import gripper_sim

#: one design point, two fruits of the default apple with short grasps
SMALL = '''
name: small
base:
  fruit: apple
  finger: flat
  scenario_set: {transport.distance: 0.0, lift.height: 0.02, squeeze.time: 0.05,
                 close.speed: 0.1}
  set: {sim.dt: 0.004}
axes:
  contact.jaw.static_friction: [0.5]
population:
  samples: 2
  seed: 1
  distributions:
    fruit.shape.diameter: {distribution: normal, mean: 0.0635, std: 0.0044}
window: {fraction: 0.5, tolerance: 0.1}
'''


def write_study(directory: Path, name: str, **population_keys) -> Path:
    """SMALL with ``population_keys`` added to its distributions, as ``name.yaml``."""
    data = yaml.safe_load(textwrap.dedent(SMALL))
    data['population']['distributions'].update(population_keys)
    path = directory / f'{name}.yaml'
    path.write_text(yaml.safe_dump(data))
    return path


def run(study: Path, out: Path, *extra: str):
    return gripper_sim('study', str(study), '--out', str(out), '--workers', '1',
                       '--no-progress', '--no-report', *extra)


def test_a_sample_no_configuration_takes_is_refused_before_anything_is_written(tmp_path):
    """A mass in grams (150 for 0.15 kg) makes a density far out of range: the error
    names the population key and comes before the cluster and the results directory,
    so that the corrected study then runs into the same directory."""
    grams = write_study(tmp_path, 'grams', mass={'distribution': 'normal', 'mean': 150,
                                                 'std': 20})
    out = tmp_path / 'out'
    refused = run(grams, out)
    assert refused.returncode == 2, refused.stderr
    assert "population key 'mass' = " in refused.stderr
    assert "kg sets fruit.density: config key 'fruit.density'" in refused.stderr
    assert 'Traceback' not in refused.stderr
    assert not out.exists()


def test_a_fruit_whose_search_raises_returns_its_error(tmp_path):
    """Without friction nothing holds the fruit and its window search cannot start: the
    task returns the error (Dask neither logs a traceback nor retries it) instead of
    raising."""
    from gripper_sim.workflows.study_spec import load_study
    from gripper_sim.workflows.study_tasks import run_fruit
    study = load_study(write_study(tmp_path, 'small'))
    setup = study.trial(study.points[0], 0, {})
    config = dict(setup.config, **{'contact.jaw.static_friction': 0.0,
                                   'contact.jaw.kinetic_friction': 0.0})
    value = run_fruit(config, setup.scenario, study.tolerance, study.forces, {})
    assert value['result'] is None and value['new'] == []
    assert value['error'].startswith('GripperSimError: the grasp window needs a positive, '
                                     'finite force estimate (window.py:')


def failed_study_summary(tmp_path: Path) -> dict:
    """The summary of SMALL's two fruits at window fraction 0.5: the first with a
    window of 2-15 N, the second's task failed."""
    from gripper_sim.workflows.study import _Chain, summarise
    from gripper_sim.workflows.study_results import RowStore
    from gripper_sim.workflows.study_spec import load_study
    study = load_study(write_study(tmp_path, 'small'))
    chains = [_Chain(setup) for setup in study.setups(study.population.draw())]
    for chain in chains:
        chain.done = True
    chains[0].result = (2.0, 15.0, 'bruise', None)
    chains[1].result = (None, None, None, None)
    chains[1].error = 'KilledWorker: the fruit killed its workers'
    return summarise(study, chains, RowStore(tmp_path / 'out'), True)


def test_a_failed_fruit_is_not_counted_as_a_fruit_without_a_window(tmp_path):
    """At fraction 0.5 the one fruit with a window would make a population window of its
    own if the failed one counted as a fruit that holds nowhere: no window is claimed,
    the failure is listed and the study's line says so."""
    from gripper_sim.cli.study import describe_point
    point = failed_study_summary(tmp_path)['points'][0]
    assert 'population' not in point
    assert point['failed'] == [dict(sample=1,
                                    error='KilledWorker: the fruit killed its workers')]
    assert [s['sample'] for s in point['samples']] == [0]
    assert describe_point(point, '50 %') == (
        '1 of 2 fruits failed (KilledWorker: the fruit killed its workers): no population '
        'window (run the study again to retry them)')


def test_the_study_command_exits_2_when_a_fruit_failed(tmp_path, monkeypatch, capsys):
    from gripper_sim.cli.main import main
    from gripper_sim.workflows import study as study_module
    summary = failed_study_summary(tmp_path)
    summary.update(computed=1, reused=0, superseded=0)
    monkeypatch.setattr(study_module, 'run_study', lambda *args, **kwargs: (
        study_module.StudyRun(computed=1, reused=0, interrupted=False, summary=summary)))
    code = main(['study', str(write_study(tmp_path, 'small')), '--out',
                 str(tmp_path / 'out'), '--no-report', '--no-progress'])
    out, err = capsys.readouterr()
    assert code == 2
    assert 'contact.jaw.static_friction=0.5: 1 of 2 fruits failed (KilledWorker' in out
    assert err.strip() == ('error: 1 fruit task failed (see above and summary.json): their '
                           'design points have no population window')


def test_a_window_search_without_friction_is_refused_before_the_cluster(tmp_path):
    """A frictionless design point has no hold estimate to start its search from: the
    study says so and writes nothing, instead of failing every fruit on the cluster."""
    data = yaml.safe_load(textwrap.dedent(SMALL))
    data['axes']['contact.jaw.static_friction'] = [0.0, 0.5]
    study = tmp_path / 'dry.yaml'
    study.write_text(yaml.safe_dump(data))
    out = tmp_path / 'out'
    refused = run(study, out)
    assert refused.returncode == 2, refused.stderr
    assert refused.stderr.strip() == (
        'error: design point 0 (contact.jaw.static_friction=0.0), sample 0: '
        'contact.jaw.static_friction is 0, so no grip force holds the fruit and its window '
        "search cannot start; give a 'force' axis to evaluate grip forces without friction")
    assert not out.exists()
    # a force grid evaluates the frictionless point: nothing to refuse
    from gripper_sim.workflows.study_spec import load_study
    data['axes']['force'] = [2.0, 5.0]
    study.write_text(yaml.safe_dump(data))
    grid = load_study(study)
    assert len(grid.setups(grid.population.draw())) == 4


#: opens a local cluster of one worker as a study does, with a Ctrl-C (SIGINT to the
#: process) arriving while the cluster starts; prints what happened and whether the
#: worker process is still alive afterwards
CTRL_C_DURING_START = '''
import os, signal, sys
import distributed, psutil
from gripper_sim.workflows.study import open_client
real, pids = distributed.LocalCluster, []
def starting(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGINT)
    cluster = real(*args, **kwargs)
    pids.extend(nanny.pid for nanny in cluster.workers.values())
    return cluster
distributed.LocalCluster = starting
try:
    with open_client(None, 1):
        print('ran the study')
except KeyboardInterrupt:
    print('interrupted')
alive = [pid for pid in pids if psutil.pid_exists(pid)
         and psutil.Process(pid).status() != psutil.STATUS_ZOMBIE]
print('workers started', len(pids), 'alive', len(alive))
'''


def test_ctrl_c_while_the_local_cluster_starts_stops_the_study():
    """The local cluster's start is no longer deaf to Ctrl-C (it ignored SIGINT, so a
    study interrupted in its first tens of seconds ran to the end): the interrupt is
    held back until the cluster can be closed, then raised, and no worker is left."""
    import subprocess
    import sys
    done = subprocess.run([sys.executable, '-c', CTRL_C_DURING_START], capture_output=True,
                          text=True, timeout=600)
    assert done.stdout.split('\n')[:2] == ['interrupted', 'workers started 1 alive 0'], (
        done.stdout + done.stderr)


def test_the_local_workers_ignore_ctrl_c():
    """A terminal's Ctrl-C reaches the whole process group: the workers ignore it (the
    client stops the study), now from their preload rather than by inheriting an
    ignored SIGINT from a client deaf to it while the cluster started."""
    from gripper_sim.workflows.study import open_client
    with open_client(None, 1) as client:
        pids = [nanny.pid for nanny in client.cluster.workers.values()]
        masks = [next(line for line in Path(f'/proc/{pid}/status').read_text().splitlines()
                      if line.startswith('SigIgn:')) for pid in pids]
    assert len(pids) == 1
    sigint = 1 << (2 - 1)
    assert all(int(mask.split()[1], 16) & sigint for mask in masks), masks


def test_a_scheduler_without_workers_is_said_and_ctrl_c_stops_the_wait(tmp_path):
    """On a scheduler with no workers the study waited without a word (no progress bar
    off a terminal): it now says it waits for them, and Ctrl-C ends the wait within
    seconds: 'interrupted: ...', exit 130, no traceback, the user's scheduler left
    running. The study runs as test_study_dask's CHILD, which restores Ctrl-C as in a
    terminal: run as `-m gripper_sim.cli.main` it inherited the ignored SIGINT of a
    background job of a non-interactive shell (`sh -c 'pytest ... &'`), Python never
    raised KeyboardInterrupt, and the study waited on: that reproduces the earlier 300 s
    timeout; the cancel on the idle scheduler itself takes ~10 ms."""
    import signal
    import subprocess
    import sys
    import threading
    import time
    from test_study_dask import CHILD, DaskCluster, env

    class Scheduler(DaskCluster):
        """A `dask scheduler` alone."""

        def wait_for_workers(self, count: int) -> None:
            assert count == 0

    cluster, process = Scheduler(tmp_path, workers=0), None
    try:
        study = write_study(tmp_path, 'small')
        process = subprocess.Popen(
            [sys.executable, '-c', CHILD, 'study', str(study), '--out',
             str(tmp_path / 'out'), '--scheduler', cluster.address, '--no-progress',
             '--no-report'], env=env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
            text=True)
        noted = threading.Event()
        lines: list[str] = []

        def read() -> None:
            for line in process.stderr:
                lines.append(line)
                if line.startswith('note: '):
                    noted.set()
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        assert noted.wait(timeout=300), ''.join(lines)
        assert process.poll() is None, ''.join(lines)   # still waiting for workers
        process.send_signal(signal.SIGINT)
        sent = time.monotonic()
        try:
            code = process.wait(timeout=60)   # seconds, even on a loaded machine
        except subprocess.TimeoutExpired:
            code = None
        waited = time.monotonic() - sent
        reader.join(timeout=30)
        scheduler_running = cluster.scheduler.poll() is None
    finally:
        if process is not None and process.poll() is None:
            process.kill()
        cluster.close()
    output = ''.join(lines)
    assert code == 130, f'exit {code} {waited:.0f} s after Ctrl-C:\n{output}'
    assert lines[0] == (f'note: the Dask scheduler at {cluster.address} has no workers yet; '
                        'the study waits for them (start some with `dask worker '
                        f'{cluster.address}`; Ctrl-C stops)\n')
    assert lines[-1].startswith('interrupted: 0 rows kept in '), output
    assert 'Traceback' not in output
    assert scheduler_running


def test_workers_with_a_scheduler_is_an_error_not_ignored(tmp_path):
    refused = gripper_sim('study', str(write_study(tmp_path, 'small')), '--out',
                          str(tmp_path / 'out'), '--scheduler', 'tcp://127.0.0.1:1',
                          '--workers', '3')
    assert refused.returncode == 2
    assert refused.stderr == ("error: --workers sizes the local cluster: with --scheduler "
                              "the cluster's own workers run the study (start them with "
                              '`dask worker`)\n')
    assert not (tmp_path / 'out').exists()


def test_the_local_cluster_takes_a_free_loopback_port_for_its_http_server():
    """Dask's scheduler serves HTTP on 8787 unless told otherwise: with 8787 taken (a
    second study, any Dask cluster) every study warned 'Port 8787 is already in use'."""
    import socket
    import warnings
    from gripper_sim.workflows.study import open_client
    blocker = socket.socket()
    try:
        try:
            blocker.bind(('127.0.0.1', 8787))
            blocker.listen()
        except OSError:
            pass   # already taken: as good
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always')
            with open_client(None, 1) as client:
                http = client.cluster.scheduler.http_server
                hosts = {sock.getsockname()[0] for sock in http._sockets.values()}
    finally:
        blocker.close()
    assert [str(w.message) for w in caught if '8787' in str(w.message)] == []
    assert hosts == {'127.0.0.1'}


def test_a_local_worker_on_changed_sources_is_named_as_such(tmp_path):
    """On the local cluster, other code in a worker means the checkout's sources were
    edited while the study started (the workers read them after the client): 'install
    the same gripper_sim on every worker' sent the user after the wrong problem."""
    import pytest
    from gripper_sim.workflows.study import StudyError, _Runner
    from gripper_sim.workflows.study_spec import load_study
    from gripper_sim.workflows.study_tasks import code_version
    study = load_study(write_study(tmp_path, 'small'))
    setup = study.setups(study.population.draw())[0]
    for local, message in ((True, "gripper_sim's sources changed while the study started"),
                           (False, 'install the same gripper_sim on every worker')):
        runner = object.__new__(_Runner)   # its checks only: no client, no store
        runner.code, runner.local = code_version(), local
        with pytest.raises(StudyError, match=message):
            runner._keep(setup, [('hold', 2.0, {'code_version': '0.0.0+other'})])


def test_a_results_directory_that_cannot_be_written_is_refused_before_the_cluster(
        tmp_path):
    study = write_study(tmp_path, 'small')
    a_file = tmp_path / 'a_file'
    a_file.write_text('not a directory')
    for out, reason in ((a_file, f"'{a_file}' is not a directory"),
                        (a_file / 'sub', f"'{a_file}' is not a directory"),
                        (Path('/proc/gripper_sim_study'),
                         "'/proc' takes no file (No such file or directory)")):
        refused = run(study, out)
        assert refused.returncode == 2
        assert refused.stderr == f"error: cannot write results in '{out}': {reason}\n"
    assert a_file.read_text() == 'not a directory'


def test_the_html_success_band_is_drawn_in_steps_like_its_curve():
    from gripper_sim.workflows.study_report import band_traces
    curve = dict(force=[1.0, 2.0, 4.0], p=[0.0, 0.5, 1.0], lower=[0.0, 0.2, 0.7],
                 upper=[0.3, 0.8, 1.0])
    lower, upper = band_traces(curve, '#1f77b4')
    assert [list(t.x) for t in (lower, upper)] == [curve['force']] * 2
    assert (list(lower.y), list(upper.y)) == (curve['lower'], curve['upper'])
    assert lower.line.shape == upper.line.shape == 'hv'
    assert upper.fill == 'tonexty' and lower.fill is None
    assert upper.fillcolor == 'rgba(31, 119, 180, 0.15)'
