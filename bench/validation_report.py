"""Print the mechanics validation figures (the README's table) from the test set-ups.

Run: ``python bench/validation_report.py`` (about two minutes).
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from helpers import (RESTITUTION, bounce_apex_ratios, hertz_half_widths,  # noqa: E402
                     hollow_ring_error, membrane, pick)


def main() -> None:
    print('| check | case | result | band |')
    print('|---|---|---|---|')
    for nodes in (32, 64, 128):
        for radius, modulus, thickness in ((0.03, 1e7, 1e-3), (0.05, 5e6, 2e-3)):
            error = hollow_ring_error(radius, modulus, thickness, nodes)
            print(f'| hollow ring, dv = 0.14878 P R^3/EI | N = {nodes}, R = {radius * 1e3:.0f} mm, '
                  f'EI = {modulus * thickness ** 3 / 12 * 0.01:.3g} N m^2 | {error * 100:+.2f} % '
                  f'| 3 % at N = 64 |')
    for ratio in (0.05, 0.1):
        force, predicted, _ = membrane(ratio)
        print(f'| membrane ring, F = p c b | approach {ratio:.2f} R, N = 256 | '
              f'{(force / predicted - 1) * 100:+.2f} % | 5 % |')
    for force in (1.5, 2.6):
        measured, hertz = hertz_half_widths(force)
        print(f'| solid disk, Hertz half-width | F = {force} N, 512 surface nodes | '
              f'{(measured / hertz - 1) * 100:+.1f} % | 10 % |')
    for dt in (1e-3, 1e-4):
        ratios = bounce_apex_ratios(dt) / RESTITUTION ** 2 - 1
        print(f'| bouncing node, apex ratio / e^2 | dt = {dt:g} s | '
              f'{np.max(np.abs(ratios)) * 100:.2f} % worst of 4 | 2 % |')
    for ratio in (1.2, 0.8):
        _, summary = pick(ratio)
        print(f'| friction hold, 2 mu N = {ratio} m g | lift 2 cm, hold 1 s | '
              f"{summary['outcome']}, slip {summary['slip_distance'] * 1e3:.2f} mm | "
              f"{'held, slip < 1 mm' if ratio > 1 else 'slips'} |")


if __name__ == '__main__':
    main()
