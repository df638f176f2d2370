"""The 3D validation figures against the time step and the surface mesh: what the 3D
defaults (``sim.dt`` 20 ms, ``fruit.mesh.subdivisions`` 8) are chosen from.

Rows (each with its CPU time, ``time.process_time``):
- squeeze: the default apple (3D shell) squeezed to 2 N as ``gripper-sim squeeze
  --set dimension=3 --to-force 2`` does: peak grip force, contact area and peak jaw
  pressure against the finest run (dt 5 ms, f 12);
- friction: the default apple gripped at 2 mu N = 1.2 m g and 0.8 m g (mu 0.5), lifted
  2 cm and held 1 s: outcome, slip, creep during the hold (held: slip < 1 mm; slips);
- drop: the default apple (restitution 0.8) dropped 68 mm on the table: first rebound
  apex over the drop height (a point bounces to e^2 = 0.64 of it);
- membrane: a pressurised shell with a wrinkling skin pressed by plates, F over the
  cap-cut law 2 pi p R delta at delta/R = 0.02 and 0.05 (quasi-static);
- Hertz: a solid sphere of quadratic tetrahedra between plates (6418 nodes), force
  error at D/R = 0.02 / 0.05 (quasi-static).

Run: ``nice python bench/convergence_3d.py [--only squeeze friction drop membrane hertz]``
(about 10 minutes of CPU on a quiet core).
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))

from gripper_sim.cli.main import main as cli  # noqa: E402
from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402
from gripper_sim.workflows.grasp import GraspSequence, run_grasp  # noqa: E402
from helpers import hertz_sphere_errors, pressed_wrinkling_shell  # noqa: E402

#: (dt s, geodesic frequency f) of the default-apple rows: the dt ladder at the default
#: mesh, then the mesh ladder at the default dt
LADDER = ((0.04, 8), (0.02, 8), (0.01, 8), (0.005, 8), (0.02, 6), (0.02, 10), (0.02, 12))
#: the reference of each squeeze row: the smallest step (dt rows), the finest mesh (f rows)
FINEST_DT, FINEST_MESH = (0.005, 8), (0.02, 12)


def timed(function, *args, **kwargs):
    """(function's result, CPU s)."""
    start = time.process_time()
    result = function(*args, **kwargs)
    return result, time.process_time() - start


def squeeze_summary(dt: float, f: int) -> dict:
    """The CLI squeeze's JSON summary for the default 3D apple at (dt, f)."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = cli(['squeeze', '--to-force', '2', '--json', '--set', 'dimension=3',
                    '--set', f'sim.dt={dt}', '--set', f'fruit.mesh.subdivisions={f}'])
    if code != 0:
        raise SystemExit(f'error: the squeeze at dt {dt} s, f {f} failed')
    return json.loads(out.getvalue())['summary']


def squeeze_rows() -> None:
    runs = {key: timed(squeeze_summary, *key) for key in LADDER}
    print('\nsqueeze to 2 N, default apple (3D shell); area and pressure against dt 5 ms '
          '(steps other than 20 ms, f 8), against f 12 (meshes at 20 ms)')
    print('dt ms   f  vertices  peak N   area mm^2 (dev)     pressure kPa (dev)   steps  cpu s')
    for (dt, f), (summary, cpu) in runs.items():
        reference = runs[FINEST_DT if f == 8 and dt != 0.02 else FINEST_MESH][0]
        area = summary['contact_area_at_peak_force']
        pressure = summary['peak_jaw_pressure']
        print(f"{dt * 1e3:5g} {f:3d} {10 * f * f + 2:9d} {summary['peak_grip_force']:7.3f} "
              f"{area * 1e6:9.1f} ({area / reference['contact_area_at_peak_force'] - 1:+6.1%})"
              f"  {pressure * 1e-3:8.2f} ({pressure / reference['peak_jaw_pressure'] - 1:+6.1%})"
              f"  {summary['steps']:6d} {cpu:6.1f}", flush=True)


def friction_hold(dt: float, f: int, ratio: float) -> dict:
    """Grip at 2 mu N = ratio m g (mu 0.5), lift 2 cm, hold 1 s: the grasp summary plus
    the creep (m) during the hold."""
    config = load_config(overrides=['dimension=3', f'sim.dt={dt}',
                                    f'fruit.mesh.subdivisions={f}',
                                    'contact.jaw.static_friction=0.5',
                                    'contact.jaw.kinetic_friction=0.5'])
    sim = make_simulation(config)
    weight = sim.fruit.total_mass * config['world.gravity']
    slips = []
    summary = run_grasp(sim, GraspSequence(sim, ratio * weight / (2 * 0.5), lift_height=0.02,
                                           hold_time=1.0),
                        on_step=lambda r, phase: slips.append(r.slip_distance)
                        if phase == 'holding' else None)
    return dict(summary, creep=(slips[-1] - slips[0]) if slips else float('nan'))


def friction_rows() -> None:
    print('\nfriction hold, default apple (3D shell), mu 0.5, lift 2 cm, hold 1 s '
          '(1.2 m g: held, slip < 1 mm; 0.8 m g: slips)')
    print('dt ms   f  1.2 m g: outcome  slip mm  creep mm  cpu s | 0.8 m g: outcome  slip mm'
          '  cpu s')
    for dt, f in LADDER:
        held, cpu_held = timed(friction_hold, dt, f, 1.2)
        slipped, cpu_slipped = timed(friction_hold, dt, f, 0.8)
        print(f"{dt * 1e3:5g} {f:3d}  {held['outcome']:>16} {held['slip_distance'] * 1e3:8.2f} "
              f"{held['creep'] * 1e3:9.3f} {cpu_held:6.1f} | {slipped['outcome']:>16} "
              f"{slipped['slip_distance'] * 1e3:8.2f} {cpu_slipped:6.1f}", flush=True)


def first_rebound(dt: float, f: int) -> tuple[float, float]:
    """(drop height m, first rebound apex m) of the default apple's centre dropped from
    10 cm on a frictionless table, restitution 0.8, the jaws out of the way."""
    config = load_config(overrides=['dimension=3', f'sim.dt={dt}',
                                    f'fruit.mesh.subdivisions={f}',
                                    'contact.restitution=0.8', 'fruit.initial_height=0.1',
                                    'gripper.initial_lift=5', 'contact.table.static_friction=0',
                                    'contact.table.kinetic_friction=0'])
    sim = make_simulation(config)
    rest = 0.5 * sim.fruit.rest_width
    heights = np.array([sim.step().centroid[2] for _ in range(int(0.6 / dt))]) - rest
    after = heights[int(np.argmin(heights)):]
    return float(heights[0]), float(max(after.max(), 0.0))


def drop_rows() -> None:
    print('\ndrop, default apple (3D shell), restitution 0.8: first rebound / drop height '
          '(a rigid point: 0.64)')
    print('dt ms   f  drop mm  rebound mm  ratio  cpu s')
    for dt, f in ((0.02, 8), (0.005, 8), (0.02, 12)):
        (drop, rebound), cpu = timed(first_rebound, dt, f)
        print(f'{dt * 1e3:5g} {f:3d} {drop * 1e3:8.1f} {rebound * 1e3:11.2f} '
              f'{rebound / drop:6.3f} {cpu:6.1f}', flush=True)


def membrane_rows() -> None:
    print('\nmembrane: wrinkling-skin pressurised shell between plates, F / (2 pi p R delta) '
          '(band 10 %)')
    print('dt ms   f  delta/R 0.02  0.05  cpu s')
    for dt, f in ((0.05, 8), (0.02, 8), (0.05, 12), (0.02, 12)):
        (deltas, forces, p_r), cpu = timed(pressed_wrinkling_shell, True, (0.02, 0.05),
                                           subdivisions=f, dt=dt)
        ratios = forces / (2 * np.pi * p_r * deltas)
        print(f'{dt * 1e3:5g} {f:3d} {ratios[0]:13.3f} {ratios[1]:5.3f} {cpu:6.1f}', flush=True)


def hertz_rows() -> None:
    print('\nHertz: solid sphere of quadratic tetrahedra (f 4, jaw refinement 0.4: 6418 nodes) '
          'between plates, force error (band 10 %)')
    print('dt ms  D/R 0.02   0.05  cpu s')
    for dt in (0.05, 0.02):
        (errors, _), cpu = timed(hertz_sphere_errors, 4, 0.4, dt=dt)
        print(f'{dt * 1e3:5g} {errors[0.02][0]:+9.1%} {errors[0.05][0]:+6.1%} {cpu:6.1f}',
              flush=True)


ROWS = dict(squeeze=squeeze_rows, friction=friction_rows, drop=drop_rows,
            membrane=membrane_rows, hertz=hertz_rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--only', nargs='+', choices=tuple(ROWS), default=list(ROWS))
    args = parser.parse_args(argv)
    print(f'load {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores; CPU times are '
          'time.process_time of each run')
    for name in args.only:
        ROWS[name]()
    return 0


if __name__ == '__main__':
    sys.exit(main())
