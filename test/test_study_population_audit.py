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
