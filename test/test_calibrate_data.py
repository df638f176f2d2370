"""Calibration input: the CSV reader's units and checks, and bad data through the CLI
(a one-line error naming the problem, exit 2, nothing written)."""
import hashlib

import numpy as np
import pytest

from gripper_sim.cli.main import main
from gripper_sim.workflows.calibrate_data import CalibrationError, read_curve
from gripper_sim.workflows.calibrate_model import fit_keys

GOOD_ROWS = '0.5,1.0\n1.0,2.5\n1.5,4.4\n2.0,6.6\n2.5,9.1\n'


def write(tmp_path, text, name='curve.csv'):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_units_from_the_header_in_mm_and_m_give_the_same_curve(tmp_path):
    in_mm = read_curve(write(tmp_path, 'deformation_mm,force_N\n' + GOOD_ROWS))
    rows_m = ''.join(f'{float(d) / 1000},{f}\n' for d, f in
                     (line.split(',') for line in GOOD_ROWS.split()))
    in_m = read_curve(write(tmp_path, 'deformation [m], force (N)\n' + rows_m, 'm.csv'))
    np.testing.assert_allclose(in_mm.deformation, [0.5e-3, 1e-3, 1.5e-3, 2e-3, 2.5e-3])
    np.testing.assert_allclose(in_m.deformation, in_mm.deformation)
    np.testing.assert_allclose(in_m.force, [1.0, 2.5, 4.4, 6.6, 9.1])
    assert in_mm.max_deformation == pytest.approx(2.5e-3)
    assert in_mm.speed is None


def test_plate_speed_comment_units_flags_and_hash(tmp_path):
    text = '# a test\n# plate_speed: 20 mm/min\ndeformation,force\n' + GOOD_ROWS
    path = write(tmp_path, text)
    curve = read_curve(path, deformation_unit='mm', force_unit='N')
    assert curve.speed == pytest.approx(20e-3 / 60)
    assert curve.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()
    assert read_curve(path, 'mm', 'N', speed=0.004).speed == 0.004
    headerless = read_curve(write(tmp_path, GOOD_ROWS, 'bare.csv'), 'm', 'N')
    assert headerless.max_deformation == pytest.approx(2.5)


def test_fit_keys_default_per_model_and_named():
    assert fit_keys(None, 'shell') == ('fruit.flesh.youngs_modulus', 'fruit.pressure.turgor')
    assert fit_keys(None, 'solid') == ('fruit.flesh.youngs_modulus',)
    assert fit_keys('pressure.turgor, fruit.skin.youngs_modulus', 'shell') == (
        'fruit.pressure.turgor', 'fruit.skin.youngs_modulus')
    with pytest.raises(CalibrationError, match="'shape.diameter' cannot be fitted"):
        fit_keys('shape.diameter', 'shell')
    with pytest.raises(CalibrationError, match='named twice'):
        fit_keys('pressure.turgor,pressure.turgor', 'shell')


BAD_DATA = [
    ('deformation_mm,force_N\n0.5,1\n1.0,2\n0.8,3\n1.5,4\n2.0,5\n',
     'row 4: the deformation does not increase'),
    ('deformation_mm,force_N\n0.5,1\n1.0,nan\n1.5,3\n2.0,4\n2.5,5\n',
     "row 3: force is not a finite number ('nan')"),
    ('deformation_mm,force_N\n0.5,1\n1.0,-2\n1.5,3\n2.0,4\n2.5,5\n',
     'row 3: negative force -2'),
    ('deformation_mm\n0.5\n1.0\n1.5\n2.0\n2.5\n', 'has a single column'),
    ('deformation,force\n' + GOOD_ROWS, 'the deformation unit is missing'),
    ('deformation_mm,force\n' + GOOD_ROWS, 'the force unit is missing'),
    ('deformation_cm,force_N\n' + GOOD_ROWS, "unknown deformation unit 'cm'"),
    ('deformation_mm,force_lbf\n' + GOOD_ROWS, "unknown force unit 'lbf'"),
    ('deformation_mm,force_N\n0.5,1\n1.0,2\n1.5,3\n', 'only 3 data point(s)'),
    ('deformation_mm,force_N\n0.5,1\n1.0,abc\n1.5,3\n2.0,4\n2.5,5\n',
     "row 3: force 'abc' is not a number"),
    ('deformation_mm,force_N\n0.5,1\n1.0\n1.5,3\n2.0,4\n2.5,5\n', 'row 3 has 1 value(s)'),
    ('# plate_speed: 20 furlongs\ndeformation_mm,force_N\n' + GOOD_ROWS,
     "unknown unit 'furlongs'"),
    ('deformation_mm,force_N\n0.5,0\n1.0,0\n1.5,0\n2.0,0\n2.5,0\n', 'every force is zero'),
    ('deformation_mm,force_N\n5,1\n10,2\n15,3\n20,4\n25,5\n',
     "the largest deformation 25 mm is beyond the model's range"),
]


@pytest.mark.parametrize('text,message', BAD_DATA)
def test_bad_data_is_one_line_error_exit_2(tmp_path, capsys, text, message):
    data = write(tmp_path, text)
    output = tmp_path / 'fruit.yaml'
    code = main(['calibrate', '--data', str(data), '-o', str(output), '--set', 'fruit.nodes=16'])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('error: '), err
    assert message in lines[0], err
    assert not output.exists() and not output.with_suffix('.png').exists()


@pytest.mark.parametrize('args,message', [
    (['--data', 'missing.csv', '-o', 'x.yaml'], "cannot read data file 'missing.csv'"),
    (['-o', 'x.txt'], 'the preset file must end in .yaml'),
    (['--fit', 'nodes', '-o', 'x.yaml'], "'nodes' cannot be fitted"),
    (['--model', 'solid', '--set', 'fruit.model=shell', '-o', 'x.yaml'],
     '--model solid contradicts'),
    (['--fruit', 'durian', '-o', 'x.yaml'], "unknown fruit 'durian'"),
    (['--fruit', 'nowhere.yaml', '-o', 'x.yaml'], "fruit preset file 'nowhere.yaml' not found"),
    (['--speed', '9', '-o', 'x.yaml'], 'exceeds gripper.max_speed'),
])
def test_bad_requests_are_one_line_errors(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    write(tmp_path, 'deformation_mm,force_N\n' + GOOD_ROWS, 'good.csv')
    if '--data' not in args:
        args = ['--data', 'good.csv', *args]
    assert main(['calibrate', *args, '--set', 'fruit.nodes=16']) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith('error: ') and message in err, err


def test_an_existing_output_is_not_overwritten(tmp_path, capsys):
    data = write(tmp_path, 'deformation_mm,force_N\n' + GOOD_ROWS)
    output = write(tmp_path, 'keep me', 'fruit.yaml')
    assert main(['calibrate', '--data', str(data), '-o', str(output)]) == 2
    assert 'exists (use --force' in capsys.readouterr().err
    assert output.read_text() == 'keep me'


def test_a_data_error_is_reported_before_an_existing_output(tmp_path, capsys):
    """With bad data and an existing preset, the error is the data's: the output check
    comes after the inputs' (else fixing one reveals the other)."""
    data = write(tmp_path, 'deformation_mm,force_N\n0.5,1.0\n')
    output = write(tmp_path, 'keep me', 'fruit.yaml')
    assert main(['calibrate', '--data', str(data), '-o', str(output)]) == 2
    err = capsys.readouterr().err
    assert 'exists (use --force' not in err and err.startswith('error: '), err
    assert output.read_text() == 'keep me'


def test_an_unwritable_output_directory_is_refused_before_the_fit(tmp_path, capsys):
    """/proc takes no new file: that is said before the fit (which may take minutes in
    3D), not after it when the preset is written."""
    data = write(tmp_path, 'deformation_mm,force_N\n' + GOOD_ROWS)
    preset = '/proc/gripper_sim_preset.yaml'
    assert main(['calibrate', '--data', str(data), '-o', preset, '--no-plots',
                 '--set', 'fruit.nodes=16']) == 2
    out, err = capsys.readouterr()
    assert out == ''   # no 'calibrating ...' line: nothing was simulated
    assert err == f"error: cannot write '{preset}': No such file or directory\n"


def test_a_deformation_in_m_under_a_mm_header_is_named_as_a_unit_mistake(tmp_path, capsys):
    """Metres under a 'deformation_mm' header make a test of 2.5 um: the fit ran, ended at
    the ends of the keys' ranges with a 50 % force error and wrote a preset."""
    metres = ''.join(f'{float(d) * 1e-3:g},{f}' + '\n' for d, f in
                     (row.split(',') for row in GOOD_ROWS.split()))
    data = write(tmp_path, 'deformation_mm,force_N\n' + metres)
    preset = tmp_path / 'fruit.yaml'
    assert main(['calibrate', '--data', str(data), '-o', str(preset), '--no-plots',
                 '--fruit', 'peach']) == 2
    err = capsys.readouterr().err
    assert err.startswith('error: the largest deformation 0.0025 mm is 0.00% of the '
                          "fruit's width (")
    assert err.endswith('is the deformation column in m rather than mm?\n')
    assert not preset.exists()
