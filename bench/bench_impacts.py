"""Impacts with restitution: energy across the impact, two-face rebounds, 1 m drops.

    PYTHONPATH=. python bench/bench_impacts.py

Prints, for the default fruit dropped 5 cm in 2D (the shell) and in 3D (a coarse shell,
dt 5 ms) at restitution e = 0.3, 0.6, 0.9, the largest rise of the total energy (kinetic
+ elastic + gravitational) over one step, per m g h (it must not be positive beyond
rounding; free fall alone loses (g dt)^2 / (2 g h) per step); the velocity of a point
fruit after it hits the table and a wall in the same step (the wall's rebound is -e u,
the table's e times its approach speed); and, for
fruits dropped 1 m at dt 1 ms, whether the drop completes, the largest number of
sub-steps a step took and the CPU time. CPU time by ``time.process_time``, single
thread; the machine's load is printed.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gripper_sim.configuration import load_config  # noqa: E402
from gripper_sim.errors import ConvergenceError  # noqa: E402
from gripper_sim.workflows.factory import make_simulation  # noqa: E402

COARSE_3D = ['dimension=3', 'fruit.mesh.subdivisions=4', 'fruit.mesh.jaw_refinement=1']


def _total(result) -> float:
    e = result.energies
    return e.kinetic + e.elastic + e.gravitational


def energy_rise(overrides, height=0.05, duration=0.3) -> tuple[float, float]:
    """(largest one-step rise of total energy per m g h, CPU s) of a drop by ``height``."""
    base = list(overrides) + ['gripper.initial_lift=5']
    resting = make_simulation(load_config(overrides=base)).last.centroid[-1]
    sim = make_simulation(load_config(overrides=base + [
        f'fruit.initial_height={resting + height}']))
    mgh = sim.fruit.total_mass * sim.config['world.gravity'] * height
    start = time.process_time()
    before, rise = _total(sim.last), -np.inf
    for _ in range(int(round(duration / sim.dt))):
        total = _total(sim.step())
        rise = max(rise, (total - before) / mgh)
        before = total
    return rise, time.process_time() - start


def corner_rebound(restitution=0.6, speed=0.5) -> np.ndarray:
    """Velocity (2,) m/s of a point fruit after it hit the table and a wall in one step."""
    dt, meet = 1e-3, 10.5e-3
    sim = make_simulation(load_config(overrides=[
        'fruit.model=point', f'sim.dt={dt}', f'contact.restitution={restitution}',
        f'fruit.initial_height={speed * meet + 0.5 * 9.81 * meet ** 2}',
        'gripper.initial_lift=5', 'world.walls=true', f'world.wall_half_width={speed * meet}',
        f'fruit.initial_velocity.x={speed}', f'fruit.initial_velocity.z={-speed}']))
    for _ in range(11):
        result = sim.step()
    return result.velocities[0]


def metre_drop(fruit, restitution, sideways) -> str:
    sim = make_simulation(load_config(fruit=fruit, overrides=[
        'sim.dt=1e-3', 'fruit.initial_height=1.0', f'contact.restitution={restitution}',
        f'fruit.initial_velocity.x={sideways}']))
    start = time.process_time()
    most = 1
    try:
        for _ in range(650):
            most = max(most, sim.step().substeps)
    except ConvergenceError as err:
        return f'failed: {err}'
    cpu = time.process_time() - start
    return f'completes, at most {most} sub-step(s) in a step, {cpu:.2f} s CPU'


def main() -> int:
    print(f'load average {os.getloadavg()[0]:.2f}; CPU time (time.process_time)')
    print('total energy rise over one step across a 5 cm drop, per m g h:')
    for label, overrides in (('2D shell', []),
                             ('3D shell, dt 5 ms', COARSE_3D + ['sim.dt=0.005'])):
        for e in (0.3, 0.6, 0.9):
            rise, cpu = energy_rise(overrides + [f'contact.restitution={e}'])
            print(f'  {label:18s} e = {e}: {rise:+.2e}  ({cpu:.2f} s CPU)')
    v = corner_rebound()
    print(f'point fruit into table and wall at (0.5, -0.5) m/s, e = 0.6: leaves at '
          f'({v[0]:+.3f}, {v[1]:+.3f}) m/s')
    print('1 m drops at dt 1 ms:')
    for fruit, e, vx in (('apple', 0.0, 0.0), ('apple', 0.9, 0.3), ('orange', 0.9, 0.3),
                         ('plum', 0.0, 0.3)):
        print(f'  {fruit:7s} e = {e}, sideways {vx} m/s: {metre_drop(fruit, e, vx)}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
