"""``bench/fin_ray_convergence.py``: a bad length or setting is a usage error before
anything runs; its consistent press is the same load whatever the nodes, and under it the
finger as a structure converges with its rod element length (docs/fin_ray_convergence.md).
"""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'bench'))

import fin_ray_convergence as convergence  # noqa: E402

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.core.fin_ray import fin_ray_body  # noqa: E402
from gripper_sim.geometry.fin_ray import FinRayGeometry  # noqa: E402
from gripper_sim.geometry.finger_materials import MATERIALS  # noqa: E402


@pytest.mark.parametrize('argv, words', [
    (['--lengths', '0'], "--lengths: config key 'gripper.finger.fin_ray.element_length'"),
    (['--lengths', '1e-6'], 'too fine'),
    (['--set', 'fruit.nodes=1'], "--set: config key 'fruit.nodes' = 1 is out of range"),
    (['--set', 'fruit.nodes'], 'must look like dotted.key=value'),
])
def test_a_bad_length_or_setting_is_a_usage_error(argv, words, capsys, monkeypatch):
    monkeypatch.setattr(convergence, 'grasp', lambda *args: pytest.fail('ran'))
    with pytest.raises(SystemExit) as stop:
        convergence.main(argv)
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert words in err and 'Traceback' not in err


def _body(length: float):
    config = load_config(overrides=['gripper.finger.type=fin_ray',
                                    f'{convergence.KEY}={length}'])
    return fin_ray_body(FinRayGeometry.from_config(config, 0.02), MATERIALS['tpu'])


@pytest.mark.parametrize('length', [0.001, 0.003, 0.004])
def test_the_consistent_press_is_the_same_load_whatever_the_nodes(length):
    """Its resultant is the force along the front beam's inward normal, centred at
    mid-height: the hat functions share a uniform load out exactly."""
    forces, front, arc, mid, normal = convergence.consistent_press(_body(length), 6.0)
    np.testing.assert_allclose(forces.sum(axis=0), -6.0 * normal, atol=1e-9)
    loads = -forces[front] @ normal
    assert np.sum(loads * arc) / np.sum(loads) == pytest.approx(mid, abs=1e-7)


def test_under_the_consistent_press_4_mm_elements_give_the_1_mm_structure():
    """Pressed travel and tip within 3 % at 1 and 6 N (the tip's Fin Ray effect at 6 N)."""
    fine, coarse = convergence.structure_consistent(0.001), convergence.structure_consistent(0.004)
    for force in (1.0, 6.0):
        assert coarse[force][0] == pytest.approx(fine[force][0], rel=0.03)
    assert coarse[6.0][1] == pytest.approx(fine[6.0][1], rel=0.03)
    assert coarse[6.0][1] > 0.5e-3
