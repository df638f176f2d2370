"""The Fin Ray benchmarks' configuration overrides (``--set KEY=VALUE`` of
``bench/bench_fin_ray.py``, ``bench/bench_soft_fingers.py`` and ``bench/newton_rates.py``):
they reach the deformable finger's grasp only, and a bad key or value is a usage error
before anything runs."""
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))

import bench_fin_ray  # noqa: E402
import bench_soft_fingers  # noqa: E402
import newton_rates  # noqa: E402

ELEMENT = 'gripper.finger.fin_ray.element_length'


@pytest.mark.parametrize('setting, words', [
    (f'{ELEMENT}=-1', 'must be > 0.0 m'),
    ('gripper.finger.fin_ray.no_such_key=1', 'unknown config key'),
    (f'{ELEMENT}', 'KEY=VALUE'),
])
@pytest.mark.parametrize('bench', [bench_fin_ray, newton_rates])
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
    assert lengths == {('flat', 0.002), ('fin_ray', 0.006)}
    assert rows['fin_ray']['outcome'] == rows['flat']['outcome'] == 'held'
    # the contact on the apple is its outline nodes' (3.9 mm apart), not the finger's
    assert rows['fin_ray']['contact'] == pytest.approx(0.0187, abs=2e-4)
