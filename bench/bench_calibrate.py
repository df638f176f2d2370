"""CPU time of calibrations (``gripper-sim calibrate``) on synthetic tests.

    PYTHONPATH=. python bench/bench_calibrate.py [--quick]

Each case simulates a plate compression test of known parameters with 2 % noise (fixed
seed, at half the step the fit takes), fits it back and prints the CPU time of the fit
(time.process_time of this process: the machine's load does not count), the number of
simulations, the CPU time per simulation and each key's error. Targets: a two-key 2D fit
under 30 s, a one-key 3D fit under 5 minutes. ``--quick`` skips the 3D case.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.workflows.calibrate_fit import fit  # noqa: E402
from gripper_sim.workflows.calibrate_model import CompressionTest, synthetic_curve  # noqa: E402

SPEED = 0.005
NOISE = 0.02

#: (label, fruit, overrides, truth, largest deformation m, points, target CPU s)
CASES = [
    ('2D shell, two keys (turgor, skin modulus)', 'apple',
     {'fruit.model': 'shell'},
     {'fruit.pressure.turgor': 45e3, 'fruit.skin.youngs_modulus': 40e6}, 0.015, 40, 30.0),
    ('2D shell, one key (turgor)', 'apple', {'fruit.model': 'shell'},
     {'fruit.pressure.turgor': 45e3}, 0.010, 30, 30.0),
    ('2D solid, one key (flesh modulus), 32 skin nodes', 'apple',
     {'fruit.model': 'solid', 'fruit.nodes': 32},
     {'fruit.flesh.youngs_modulus': 3e6}, 0.006, 20, 30.0),
    ('2D solid, two keys (flesh and skin modulus), 32 skin nodes', 'apple',
     {'fruit.model': 'solid', 'fruit.nodes': 32},
     {'fruit.flesh.youngs_modulus': 3e6, 'fruit.skin.youngs_modulus': 20e6}, 0.006, 20, 30.0),
]
CASES_3D = [
    ('3D solid, one key (flesh modulus), 259 surface vertices', 'peach',
     {'fruit.model': 'solid', 'dimension': 3, 'fruit.mesh.subdivisions': 4},
     {'fruit.flesh.youngs_modulus': 1.5e6}, 0.004, 16, 300.0),
    ('3D solid, one key (flesh modulus), the bench_3d.py solid mesh (2089 tetrahedra)',
     'peach', {'fruit.model': 'solid', 'dimension': 3, 'fruit.skin.enabled': False,
               'fruit.mesh.subdivisions': 6, 'fruit.mesh.jaw_refinement': 1,
               'fruit.mesh.max_tet_volume': 1.5e-7},
     {'fruit.flesh.youngs_modulus': 1.5e6}, 0.004, 16, 300.0),
]


def run(label, fruit, overrides, truth, max_deformation, points, target) -> None:
    d = np.linspace(max_deformation / points, max_deformation, points)
    curve = synthetic_curve(fruit, overrides, truth, d, SPEED, NOISE, seed=1, step_ratio=0.5)
    cpu = time.process_time()
    test = CompressionTest(curve, fruit, overrides)
    result = fit(test, tuple(truth))
    cpu = time.process_time() - cpu
    verdict = 'met' if cpu < target else 'NOT met'
    print(f'{label}: {cpu:.1f} s CPU ({verdict}: target {target:g} s), '
          f'{result.evaluations} simulations of {test.base["sim.dt"] * 1e3:.3g} ms steps, '
          f'{cpu / max(result.evaluations, 1):.2f} s CPU each')
    for key in result.keys:
        error = key.value / truth[key.key] - 1
        print(f'    {key.key:28s} fitted {key.value:.4g} (truth {truth[key.key]:.4g}, '
              f'{error:+.1%}; standard error {key.relative_error:.1%})')
    print(f'    RMS force error {result.rms_error:.3g} N '
          f'({result.relative_rms_error:.1%} of the largest force)')
    for warning in result.warnings:
        print(f'    warning: {warning}')


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='2D cases only')
    args = parser.parse_args()
    print(f'load average {os.getloadavg()[0]:.1f} (CPU times below do not include it)')
    for case in CASES + ([] if args.quick else CASES_3D):
        run(*case)
    return 0


if __name__ == '__main__':
    sys.exit(main())
