"""Audit fixes of `gripper-sim study` and `gripper-sim calibrate`: a results directory
holds one study (another one, or a changed definition, is refused and nothing is
written), nothing is created when the cluster cannot be reached, '1e1' is a number in
every numeric field of a study file, a 3D calibration's preset is checked in 3D (no
wrong warning), and a fitted key without effect or an empty --fit is an error."""
from __future__ import annotations

import io
import json
import shutil
import socket
import textwrap
import warnings
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
import yaml

from gripper_sim.cli.main import main
from gripper_sim.configuration import package_config_dir
from gripper_sim.errors import ConfigWarning, GripperSimError
from gripper_sim.workflows.calibrate_preset import write_preset
from gripper_sim.workflows.study_spec import load_study
from test_cli_offline import ROOT, gripper_sim

#: one design point, one fruit, a grid of two forces, short grasps: two evaluations;
#: its numbers are written as YAML 1.1 reads as text ('4e-3', '1e1', '5e-1', ...)
TINY = '''
name: tiny
base:
  fruit: apple
  finger: flat
  scenario_set: {transport.distance: 0.0, lift.height: 0.02, squeeze.time: 0.05,
                 close.speed: 0.1}
  set: {sim.dt: 4e-3}
axes:
  force: [1e1, 4]
  contact.jaw.static_friction: [5e-1]
  scenario.close.speed: [1e-1]
population: {samples: 1e0, seed: 7}
window: {fraction: 9e-1, confidence: 0.95, tolerance: 5e-2}
'''


def write_study(directory: Path, file: str, **changes) -> Path:
    """TINY with top-level keys changed, as ``directory/file.yaml``."""
    data = yaml.safe_load(textwrap.dedent(TINY))
    data.update(changes)
    path = directory / f'{file}.yaml'
    path.write_text(yaml.safe_dump(data) if changes else textwrap.dedent(TINY))
    return path


def run(study: Path, out: Path, *extra: str):
    return gripper_sim('study', str(study), '--out', str(out), '--workers', '1',
                       '--no-progress', '--no-report', *extra)


def snapshot(directory: Path) -> dict:
    """Every file under ``directory``: its bytes and modification time."""
    return {p.relative_to(directory): (p.read_bytes(), p.stat().st_mtime_ns)
            for p in sorted(directory.rglob('*')) if p.is_file()}


@pytest.fixture(scope='module')
def tiny_results(tmp_path_factory):
    """The tiny study run once: (its file, its results directory)."""
    directory = tmp_path_factory.mktemp('tiny')
    study = write_study(directory, 'tiny')
    out = directory / 'study1'
    first = run(study, out)
    assert first.returncode == 0, first.stderr
    return study, out


def test_another_study_into_a_results_directory_is_refused_and_writes_nothing(
        tiny_results, tmp_path):
    _, out = tiny_results
    before = snapshot(out)
    other = write_study(tmp_path, 'other', name='other')
    refused = run(other, out, '--csv')
    assert refused.returncode == 2
    assert refused.stderr.startswith(f"error: {out} holds study 'tiny' "), refused.stderr
    assert 'Traceback' not in refused.stderr
    assert snapshot(out) == before
    # results written before directories named their study: the rows' study column
    legacy = tmp_path / 'legacy'
    shutil.copytree(out, legacy)
    (legacy / 'study.json').unlink()
    before = snapshot(legacy)
    refused = run(other, legacy)
    assert refused.returncode == 2
    assert refused.stderr.startswith(f"error: {legacy} holds study 'tiny' ")
    assert snapshot(legacy) == before


def test_a_changed_definition_of_the_same_study_is_refused(tiny_results, tmp_path):
    _, out = tiny_results
    before = snapshot(out)
    data = yaml.safe_load(textwrap.dedent(TINY))
    data['axes']['force'] = [4, 6, 10]
    changed = tmp_path / 'tiny.yaml'
    changed.write_text(yaml.safe_dump(data))
    refused = run(changed, out)
    assert refused.returncode == 2
    assert refused.stderr.startswith(f"error: {out} holds study 'tiny' run from another "
                                     'definition'), refused.stderr
    assert snapshot(out) == before


def test_the_same_study_resumes_into_its_directory(tiny_results, tmp_path):
    study, out = tiny_results
    # a new description and fraction change the summary, not the rows: the same study
    again = write_study(tmp_path, 'again', description='re-summarised',
                        window={'fraction': 0.8, 'tolerance': 0.05})
    resumed = run(again, out)
    assert resumed.returncode == 0, resumed.stderr
    assert {r['study'] for r in pq.read_table(out / 'rows').to_pylist()} == {'tiny'}
    assert run(study, out).returncode == 0


def test_a_complete_run_drops_the_rows_of_earlier_code(tiny_results, tmp_path):
    """A row of earlier code (another code version in its case_key) is never reused: a
    complete run leaves only its own rows, so the dataset has one row per evaluation."""
    _, out = tiny_results
    study = write_study(tmp_path, 'tiny')
    copy = tmp_path / 'copy'
    shutil.copytree(out, copy)
    rows = pq.read_table(copy / 'rows').to_pylist()
    stale = dict(rows[0], case_key='earlier-code-' + rows[0]['case_key'])
    pq.write_table(pa.Table.from_pylist([stale]), copy / 'rows' / 'part-0-old.parquet')
    assert len(pq.read_table(copy / 'rows')) == len(rows) + 1
    again = run(study, copy)
    assert again.returncode == 0, again.stderr
    assert '1 rows of earlier code dropped' in again.stdout
    kept = pq.read_table(copy / 'rows').to_pylist()
    assert sorted(r['case_key'] for r in kept) == sorted(r['case_key'] for r in rows)
    assert json.loads((copy / 'summary.json').read_text())['rows'] == len(rows)


def test_a_study_that_cannot_reach_its_scheduler_creates_nothing(tmp_path):
    with socket.socket() as probe:  # a port nothing listens on
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    study = write_study(tmp_path, 'tiny')
    out = tmp_path / 'never'
    failed = gripper_sim('study', str(study), '--out', str(out), '--no-progress',
                         '--no-report', '--scheduler', f'tcp://127.0.0.1:{port}')
    assert failed.returncode == 2
    assert failed.stderr.startswith('error: cannot reach the Dask scheduler')
    assert not out.exists()


def test_scientific_notation_without_a_dot_is_a_number_in_every_numeric_field(tmp_path):
    data = yaml.safe_load(textwrap.dedent(TINY))
    assert data['axes']['force'][0] == '1e1'  # YAML 1.1 reads it as text
    data['axes']['contact.jaw.static_friction'] = ['5e-1', 0.8]
    data['population']['distributions'] = {
        'fruit.shape.diameter': {'distribution': 'normal', 'mean': '6e-2', 'std': '3e-3'}}
    path = tmp_path / 'notation.yaml'
    path.write_text(yaml.safe_dump(data))
    study = load_study(path)
    assert study.forces == (4.0, 10.0)
    assert [p.values for p in study.points] == [
        {'contact.jaw.static_friction': mu, 'scenario.close.speed': 0.1}
        for mu in (0.5, 0.8)]
    assert study.population.samples == 1
    assert (study.fraction, study.tolerance) == (0.9, 0.05)
    assert study.population.distributions[0].params == {'mean': 0.06, 'std': 0.003}
    assert study.trial(study.points[0], 0, {}).config['sim.dt'] == 0.004


PEACH_DATA = ROOT / 'config' / 'data' / 'peach_compression.csv'


def test_a_3d_calibration_writes_its_preset_without_a_dimension_warning(tmp_path):
    output = tmp_path / 'my_peach.yaml'
    done = gripper_sim('calibrate', '--data', str(PEACH_DATA), '--fruit', 'peach',
                       '--model', 'solid', '--set', 'dimension=3',
                       '--set', 'fruit.mesh.subdivisions=4',
                       '--set', 'fruit.mesh.jaw_refinement=0.5', '-o', str(output),
                       '--no-plots')
    assert done.returncode == 0, done.stderr
    assert 'calibrated in 3D' not in done.stderr, done.stderr
    assert 'dimension: 3' in output.read_text()


def test_write_preset_checks_the_preset_in_its_dimension(tmp_path):
    peach = yaml.safe_load((package_config_dir() / 'fruits' / 'peach.yaml').read_text())
    peach['calibration'] = {'dimension': 3, 'model': 'solid'}
    path = tmp_path / 'fitted.yaml'
    with warnings.catch_warnings():
        warnings.simplefilter('error', ConfigWarning)
        write_preset(path, yaml.safe_dump(peach), 3)
    with pytest.warns(ConfigWarning, match='calibrated in 3D'):
        write_preset(path, yaml.safe_dump(peach), 2)


@pytest.fixture()
def curve(tmp_path) -> Path:
    path = tmp_path / 'ok.csv'
    path.write_text('deformation_mm,force_N\n0.5,1\n1,2.5\n1.5,4.4\n2,6.6\n2.5,9\n')
    return path


def test_fitting_a_key_without_effect_is_an_error_before_the_fit(curve, tmp_path):
    output = tmp_path / 'c5.yaml'
    refused = gripper_sim('calibrate', '--data', str(curve), '-o', str(output),
                          '--fit', 'pressure.turgor', '--set', 'fruit.model=solid')
    assert refused.returncode == 2
    assert refused.stderr == ("error: --fit: 'fruit.pressure.turgor' has no effect in this "
                              'set-up: only the shell model has an internal pressure '
                              "('fruit.model' is solid)\n")
    assert refused.stdout == ''  # refused before the fit started
    assert list(tmp_path.glob('c5*')) == []


@pytest.mark.parametrize('names', ['', ' ', 'flesh.youngs_modulus,'])
def test_an_empty_fit_is_an_error(curve, tmp_path, names):
    refused = gripper_sim('calibrate', '--data', str(curve), '-o', str(tmp_path / 'c.yaml'),
                          '--fit', names)
    assert refused.returncode == 2
    assert refused.stderr.startswith(f"error: --fit '{names}' names an empty key")
    assert list(tmp_path.glob('c.*')) == []


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.mark.parametrize('stderr, shown', [(io.StringIO, False), (_Terminal, True)])
def test_the_study_shows_its_progress_bar_on_a_terminal_only(monkeypatch, tmp_path,
                                                             stderr, shown):
    asked = []

    def run_study(study, out, *, scheduler=None, workers=None, progress=True):
        asked.append(progress)
        raise GripperSimError('stopped here: the progress setting is what is tested')
    monkeypatch.setattr('gripper_sim.workflows.study.run_study', run_study)
    monkeypatch.setattr('sys.stderr', stderr())
    study = write_study(tmp_path, 'tiny')
    assert main(['study', str(study), '--out', str(tmp_path / 'out')]) == 2
    assert asked == [shown]
