"""The Fin Ray benchmarks: their configuration overrides (``--set KEY=VALUE`` of
``bench/bench_fin_ray.py``, ``bench/bench_soft_fingers.py``, ``bench/newton_rates.py`` and
``bench/fin_ray_searle.py``) reach the deformable finger's grasp only, a bad key or value
is a usage error before anything runs; the front beam's curvature change that
``fin_ray_searle.py`` reads."""
import json
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))

import bench_fin_ray  # noqa: E402
import bench_soft_fingers  # noqa: E402
import fin_ray_searle  # noqa: E402
import newton_rates  # noqa: E402
import numpy as np  # noqa: E402

ELEMENT = 'gripper.finger.fin_ray.element_length'


@pytest.mark.parametrize('setting, words', [
    (f'{ELEMENT}=-1', 'must be > 0.0 m'),
    ('gripper.finger.fin_ray.no_such_key=1', 'unknown config key'),
    (f'{ELEMENT}', 'KEY=VALUE'),
])
@pytest.mark.parametrize('bench', [bench_fin_ray, newton_rates, fin_ray_searle])
def test_a_bad_setting_is_a_usage_error(bench, setting, words, capsys):
    with pytest.raises(SystemExit) as stop:
        bench.main(['--set', setting])
    assert stop.value.code == 2
    assert words in capsys.readouterr().err


def test_a_setting_reaches_the_fin_ray_grasp_only(monkeypatch, capsys):
    built = []
    simulation = bench_soft_fingers.Simulation

    def recording(config, *args, **kwargs):
        built.append(config)
        return simulation(config, *args, **kwargs)
    monkeypatch.setattr(bench_soft_fingers, 'Simulation', recording)
    assert bench_fin_ray.main(['--plain', '--set', f'{ELEMENT}=0.006']) == 0
    rows = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    lengths = {(config['gripper.finger.type'], config[ELEMENT]) for config in built}
    assert lengths == {('flat', None), ('fin_ray', 0.006)}   # the flat finger's is the default
    assert rows['fin_ray']['outcome'] == rows['flat']['outcome'] == 'held'
    assert rows['flat']['unknowns'] == 2 * 64  # the apple's outline nodes in the plane
    assert rows['fin_ray']['unknowns'] > rows['flat']['unknowns']
    # the contact on the apple is its outline nodes' (3.9 mm apart), not the finger's
    assert rows['fin_ray']['contact'] == pytest.approx(0.0187, abs=2e-4)


def test_the_table_gives_the_size_ratio_of_the_two_grasps(capsys):
    """Unknowns times Newton iterations, the deformable finger's over the rigid one's:
    the CPU ratio at which both would cost the same per unknown and iteration."""
    def row(cpu, newton, unknowns):
        return dict(cpu=cpu, solve_cpu=0.0, outcome='held', steps=10, solves=10,
                    newton=newton, unknowns=unknowns, force=4.0, contact=0.01,
                    pressure=1e5)
    rows = {'flat': row(0.1, 300, 100), 'flat unwatched': row(0.05, -1, 100),
            'fin_ray': row(0.4, 400, 300), 'fin_ray unwatched': row(0.4, -1, 300)}
    bench_soft_fingers._print_rows(rows, ('flat', 'fin_ray'))
    lines = capsys.readouterr().out.splitlines()
    assert lines[-3:-1] == ['watched: fin_ray / flat: 4.0x', 'unwatched: fin_ray / flat: 8.0x']
    assert lines[-1].startswith('size: fin_ray 300 unknowns x 400 Newton iterations / flat '
                                '100 x 300: 4.0x')


def test_a_bad_force_is_a_usage_error(capsys):
    for force in ('-1', 'nan', '0'):
        with pytest.raises(SystemExit) as stop:
            fin_ray_searle.main(['--force', force])
        assert stop.value.code == 2
        assert 'finite number > 0' in capsys.readouterr().err


def test_a_straight_strip_bent_to_an_arc_changes_its_curvature_by_one_over_r():
    radius, count = 0.05, 21
    s = np.linspace(0.0, 0.03, count)
    straight = np.stack([s, np.zeros(count)], axis=1)
    arc = np.stack([radius * np.sin(s / radius), radius * (1 - np.cos(s / radius))], axis=1)
    change = fin_ray_searle.curvature_change(straight, arc)
    # the turning angle over half the two chords: 1 / R to second order in the chord
    assert change == pytest.approx(np.full(count - 2, 1 / radius), rel=1e-4)
    # moved and turned as a whole, nothing changes
    turn = np.array([[math.cos(0.3), -math.sin(0.3)], [math.sin(0.3), math.cos(0.3)]])
    assert fin_ray_searle.curvature_change(arc, arc @ turn.T + 0.1) == pytest.approx(
        np.zeros(count - 2), abs=1e-9)


def test_the_default_grasp_bends_the_front_beam_most_where_it_presses_the_apple():
    grip, change, depth, thickness = fin_ray_searle.squeezed([], 4.0)
    assert grip == pytest.approx(4.0, rel=5e-3)
    assert (depth, thickness) == (pytest.approx(0.0423, abs=1e-4), 0.0012)
    # the contact zone bends to a few centimetres, the beam as a whole far less
    assert 0.02 < 1 / change.max() < 0.08
    assert np.median(change) < 0.25 * change.max()
